"""Compiled kernels of the contact models' parameter derivatives (``contact_sensitivity``).

Chains on flat arrays as in ``_contact_kernels``: tube t owns global nodes
``node_off[t]:node_off[t + 1]`` and segments ``node_off[t] - t`` onwards.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _contact_kernels as ck
from ._chain_kernels import chain_kinematics
from ._lapack import PIVOT_DTYPE, lu_factor, lu_solve

__all__ = ["jacobian_rows", "equilibrium_residual", "frozen_factors", "frozen_solve", "gcr_solve"]


@njit(cache=True)
def jacobian_rows(nodes, p, Omega, base, node_off):
    """Position and rotation Jacobians of the nodes ``nodes`` (K,) with respect to all segment
    curvatures (Appendix B of Ha, Fagogenis & Dupont 2019, as in ``_contact_kernels``):

        dp_j/du_k = base_k - [p_j]x Omega_k,   domega_j/du_k = Omega_k   (k before j, same tube)

    Returns (Jp, Jw), each shape (K, 3, 3 S): [m^2] and [m] (spatial rotation per unit
    curvature)."""
    K = nodes.shape[0]
    S = Omega.shape[0]
    n = node_off.shape[0] - 1
    Jp = np.zeros((K, 3, 3 * S))
    Jw = np.zeros((K, 3, 3 * S))
    for i in range(K):
        j = nodes[i]
        t = 0
        while not (node_off[t] <= j < node_off[t + 1]):
            t += 1
            if t >= n:
                break
        k0 = node_off[t] - t
        P0 = p[j, 0]
        P1 = p[j, 1]
        P2 = p[j, 2]
        for m in range(j - node_off[t]):
            k = k0 + m
            for b in range(3):
                o0 = Omega[k, 0, b]
                o1 = Omega[k, 1, b]
                o2 = Omega[k, 2, b]
                Jw[i, 0, 3 * k + b] = o0
                Jw[i, 1, 3 * k + b] = o1
                Jw[i, 2, 3 * k + b] = o2
                Jp[i, 0, 3 * k + b] = base[k, 0, b] - (P1 * o2 - P2 * o1)
                Jp[i, 1, 3 * k + b] = base[k, 1, b] - (P2 * o0 - P0 * o2)
                Jp[i, 2, 3 * k + b] = base[k, 2, b] - (P0 * o1 - P1 * o0)
    return Jp, Jw


@njit(cache=True)
def equilibrium_residual(u, lam, act, arr, scr, F1, F2):
    """The equilibrium F1 = u - uhat - K^-1 (A(u)^T phi + Z(u)^T lam) (S, 3) [1/m] and the active
    constraints F2_a = (|d_a|^2 - c_a^2) / 2 (m,) [m^2] at curvatures ``u`` (S, 3) and multipliers
    ``lam`` (M,) (``contact_sensitivity``), with phi_c = -lam_c M_c d_c and d_c = B_c^T
    (p_(jo, c) - p_(ji, c)) from the kinematics at ``u``; ``arr``, ``scr`` the problem's
    ``OuterArrays`` and ``OuterScratch`` (overwritten)."""
    N = arr.node_off[-1]
    M = arr.c.shape[0]
    R = np.empty((N, 3, 3))
    p = np.empty((N, 3))
    chain_kinematics(u, arr.h, arr.alpha, arr.beta, arr.node_off, R, p)
    ck.linearize(u, arr.uhat, arr.kinv, arr.h, arr.node_off, R, p, scr.Omega, scr.base, scr.H1, scr.H2, scr.F3,
                 scr.Jpv)
    d = np.empty((M, 2))
    for c in range(M):
        a = arr.jo[c]
        b = arr.ji[c]
        for q in range(2):
            s = 0.0
            for r in range(3):
                scr.B[c, r, q] = R[a, r, q]
                s += R[a, r, q] * (p[a, r] - p[b, r])
            d[c, q] = s
    geometry = ck.ContactGeometry(arr.pair, arr.jo, arr.ji, scr.B, scr.Pc, R, p, scr.H1, scr.H2, scr.F3,
                                  scr.Omega, scr.base, arr.kinv, arr.node_off)
    law = ck.ContactLaw(arr.c, arr.Mblk, 1.0, arr.tq_out, arr.tq_in, arr.friction)
    ck._curvature_change(lam, d, geometry, law, True, F1)
    for k in range(u.shape[0]):
        for q in range(3):
            F1[k, q] = u[k, q] - arr.uhat[k, q] - F1[k, q]
    for i in range(act.shape[0]):
        c = act[i]
        F2[i] = 0.5 * (d[c, 0] * d[c, 0] + d[c, 1] * d[c, 1] - arr.c[c] * arr.c[c])


@njit(cache=True)
def frozen_factors(act, lam, d, R, B, Jp, Jw, jo, ji, kinv, tq_out, tq_in, Mblk):
    """The solver's linearization at a solution as the preconditioner of ``contact_sensitivity``
    (``_FrozenJacobian``): with m active contacts ``act``, S3 curvature unknowns, node Jacobian
    rows ``Jp``, ``Jw`` (2m + 1, 3, S3) (outer nodes, inner nodes, tip), contact frames ``B``
    (M, 3, 2), offsets ``d`` (M, 2), flat inverse stiffnesses ``kinv`` (S3,):

        A (2m, S3) = B^T (J_outer - J_inner),  Ut = A K^-1,  L = blockdiag(lam_a M_a),
        Y (m, S3) rows K^-1 (A_a^T (-M_a d_a) + z_a),  ULt = L^T Ut,
        small (3m, 3m) = [[I + A U L, -A Y^T], [D, 0]] factored in place (``lu_factor``).

    Returns (A, ULt, Y, small, piv, ok)."""
    m = act.shape[0]
    S3 = Jp.shape[2]
    A = np.zeros((2 * m, S3))
    Zr = np.zeros((m, S3))
    for i in range(m):
        c = act[i]
        for q in range(2):
            for r in range(3):
                b = B[c, r, q]
                for x in range(S3):
                    A[2 * i + q, x] += b * (Jp[i, r, x] - Jp[m + i, r, x])
        for r in range(3):
            ta = R[jo[c], r, 2] * tq_out[c]
            tb = R[ji[c], r, 2] * tq_in[c]
            for x in range(S3):
                Zr[i, x] += ta * Jw[i, r, x] + tb * Jw[m + i, r, x]
    Ut = np.empty((2 * m, S3))
    for j in range(2 * m):
        for x in range(S3):
            Ut[j, x] = A[j, x] * kinv[x]
    Y = np.empty((m, S3))
    ULt = np.zeros((2 * m, S3))
    for i in range(m):
        c = act[i]
        md0 = -(Mblk[c, 0, 0] * d[c, 0] + Mblk[c, 0, 1] * d[c, 1])
        md1 = -(Mblk[c, 1, 0] * d[c, 0] + Mblk[c, 1, 1] * d[c, 1])
        for x in range(S3):
            Y[i, x] = Ut[2 * i, x] * md0 + Ut[2 * i + 1, x] * md1 + kinv[x] * Zr[i, x]
        # (U L)^T = L^T Ut on the block of contact i
        for q in range(2):
            l0 = lam[c] * Mblk[c, 0, q]
            l1 = lam[c] * Mblk[c, 1, q]
            for x in range(S3):
                ULt[2 * i + q, x] = l0 * Ut[2 * i, x] + l1 * Ut[2 * i + 1, x]
    small = np.zeros((3 * m, 3 * m))
    if m > 0:
        AUL = np.dot(A, ULt.T)
        AY = np.dot(A, Y.T)
        for a in range(2 * m):
            for b in range(2 * m):
                small[a, b] = AUL[a, b]
            small[a, a] += 1.0
            for b in range(m):
                small[a, 2 * m + b] = -AY[a, b]
        for i in range(m):
            c = act[i]
            small[2 * m + i, 2 * i] = d[c, 0]
            small[2 * m + i, 2 * i + 1] = d[c, 1]
    piv = np.empty(3 * m, dtype=PIVOT_DTYPE)
    ok = lu_factor(small, piv) if m > 0 else True
    return A, ULt, Y, small, piv, ok


@njit(cache=True)
def frozen_solve(A, ULt, Y, LU, piv, r, out):
    """The preconditioner's solution for ``r`` (S3 + m,) into ``out`` (``frozen_factors``)."""
    m = Y.shape[0]
    S3 = A.shape[1]
    if m == 0:
        out[:] = r
        return
    z = np.empty(3 * m)
    z[:2 * m] = np.dot(A, r[:S3])
    z[2 * m:] = r[S3:]
    lu_solve(LU, piv, z)
    out[:S3] = r[:S3] - np.dot(ULt.T, z[:2 * m]) + np.dot(Y.T, z[2 * m:])
    out[S3:] = z[2 * m:]


@njit(cache=True)
def _full_product(u, lam, act, arr, scr, Y, v, step, out):
    """The full Jacobian of (F1, F2) times ``v`` (S3 + m,) into ``out``: central differences of
    ``equilibrium_residual`` along the curvature part (relative step ``step`` of the largest
    curvature), exactly -Y^T for the multipliers' part (F1 is linear in them)."""
    S = u.shape[0]
    S3 = 3 * S
    m = act.shape[0]
    nv = 0.0
    for x in range(S3):
        nv = max(nv, abs(v[x]))
    for x in range(S3 + m):
        out[x] = 0.0
    if nv > 0.0:
        scale = 0.0
        for k in range(S):
            for q in range(3):
                scale = max(scale, abs(u[k, q]))
        eps = step * max(scale, 1e-300) / nv
        up = np.empty((S, 3))
        um = np.empty((S, 3))
        for k in range(S):
            for q in range(3):
                up[k, q] = u[k, q] + eps * v[3 * k + q]
                um[k, q] = u[k, q] - eps * v[3 * k + q]
        F1p = np.empty((S, 3))
        F1m = np.empty((S, 3))
        F2p = np.empty(m)
        F2m = np.empty(m)
        equilibrium_residual(up, lam, act, arr, scr, F1p, F2p)
        equilibrium_residual(um, lam, act, arr, scr, F1m, F2m)
        for k in range(S):
            for q in range(3):
                out[3 * k + q] = (F1p[k, q] - F1m[k, q]) / (2.0 * eps)
        for i in range(m):
            out[S3 + i] = (F2p[i] - F2m[i]) / (2.0 * eps)
    if m > 0:
        out[:S3] -= np.dot(Y.T, v[S3:])


@njit(cache=True)
def gcr_solve(u, lam, act, arr, scr, A, ULt, Y, LU, piv, lam_scale, rhs, step, rtol, maxit):
    """Columns of the full Jacobian's solution for ``rhs`` (S3 + m, P): generalized conjugate
    residuals on the left-preconditioned system in multipliers over ``lam_scale``, one memory of
    directions for all columns (``contact_sensitivity``). Returns (solution (S3 + m, P),
    products with the full Jacobian, largest relative residual)."""
    size, P = rhs.shape
    S3 = A.shape[1]
    Z = np.empty((maxit, size))
    W = np.empty((maxit, size))
    k = 0
    sol = np.zeros((size, P))
    worst = 0.0
    b = np.empty(size)
    w = np.empty(size)
    x = np.empty(size)
    tmp = np.empty(size)
    for col in range(P):
        nz = False
        for i in range(size):
            if rhs[i, col] != 0.0:
                nz = True
                break
        if not nz:
            continue
        frozen_solve(A, ULt, Y, LU, piv, np.ascontiguousarray(rhs[:, col]), b)
        b[S3:] /= lam_scale
        nb = np.sqrt(np.dot(b, b))
        if nb == 0.0:
            continue
        x[:] = 0.0
        r = b.copy()
        for i in range(k):
            a = np.dot(W[i], b)
            x += a * Z[i]
            r -= a * W[i]
        while np.sqrt(np.dot(r, r)) > rtol * nb and k < maxit:
            z = r.copy()
            tmp[:] = z
            tmp[S3:] *= lam_scale
            _full_product(u, lam, act, arr, scr, Y, tmp, step, w)
            frozen_solve(A, ULt, Y, LU, piv, w.copy(), w)
            w[S3:] /= lam_scale
            for _ in range(2):     # modified Gram-Schmidt, twice
                for i in range(k):
                    h = np.dot(W[i], w)
                    w -= h * W[i]
                    z -= h * Z[i]
            nw = np.sqrt(np.dot(w, w))
            if nw <= 1e-14 * nb:
                break
            W[k] = w / nw
            Z[k] = z / nw
            a = np.dot(W[k], r)
            x += a * Z[k]
            r -= a * W[k]
            k += 1
        sol[:, col] = x
        sol[S3:, col] *= lam_scale
        worst = max(worst, np.sqrt(np.dot(r, r)) / nb)
    return sol, k, worst
