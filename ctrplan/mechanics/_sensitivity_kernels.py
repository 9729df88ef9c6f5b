"""Compiled kernels of the standard model's tip derivatives (``sensitivity``; numba, ``cache=True``).

One configuration (:func:`tip_derivatives`): the RK4 re-sweep of the torsion ODE from the
converged base torsions carrying the exact tangents of every stage with respect to
(sigma0, q), the implicit-function theorem on the shooting residual, the Hermite midpoint
angles and the exponential chain (Eq. (57) of Ha, Fagogenis & Dupont 2019, the Jacobians of
docs/mechanics.md, Sec. 3), on plain float64 arrays, with no temporary arrays inside the loops.
Many configurations (:func:`tip_derivatives_batch`): the grid of each row (``grid._grid``, as
``_standard_batch``), then the same kernel. The formulas are those of the NumPy reference in
the docstrings of ``sensitivity``.

Column layout of the tangents (``Pf = n + P`` columns, ``P = n (3 + 2 S)``): sigma0 (n), then
the parameters q of ``StandardTipDerivatives.jacobian``: alpha (n), the precurvature
components (n, S, 2) in C order, k_xy (n), k_z (n).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._chain_kernels import _coefficients, advance
from .grid import _grid

__all__ = ["section_index", "precurvature_matches", "node_mismatch", "tip_derivatives", "tip_derivatives_batch"]


@njit(cache=True, error_model="numpy")
def section_index(s, present, beta, brk, nbrk):
    """Section of tube i on interval j, shape (G - 1, n) int64, -1 where the tube is absent (the
    rule of ``grid._grid``: the section containing the interval's midpoint).

    s (G,) [m], present (G - 1, n) bool, beta (n,) [m], brk (n, B) tube-local breaks [m],
    nbrk (n,) breaks per tube."""
    G = s.shape[0]
    n = beta.shape[0]
    out = np.full((G - 1, n), -1, dtype=np.int64)
    for i in range(n):
        b = brk[i, :nbrk[i]]
        nsec = nbrk[i] - 1
        for j in range(G - 1):
            if present[j, i]:
                local = 0.5 * (s[j] + s[j + 1]) - beta[i]
                idx = np.searchsorted(b, local, side="right") - 1
                out[j, i] = min(max(idx, 0), nsec - 1)
    return out


@njit(cache=True, error_model="numpy")
def precurvature_matches(sec, uh, curv):
    """Whether the grid's precurvatures ``uh`` (G - 1, n, 2) [1/m] are the robot's section
    precurvatures ``curv`` (n, S, 2) on the sections ``sec`` (G - 1, n) (0 where absent)."""
    for j in range(sec.shape[0]):
        for i in range(sec.shape[1]):
            k = sec[j, i]
            for c in range(2):
                ref = curv[i, k, c] if k >= 0 else 0.0
                if uh[j, i, c] != ref:
                    return False
    return True


@njit(cache=True, error_model="numpy")
def node_mismatch(psi, ref):
    """Largest |psi - ref| [rad] over the entries where ``ref`` (G, n) is finite (NaN if a
    compared entry of ``psi`` is not finite; 0 if none is compared)."""
    m = 0.0
    for j in range(psi.shape[0]):
        for i in range(psi.shape[1]):
            if np.isfinite(ref[j, i]):
                d = abs(psi[j, i] - ref[j, i])
                if not d <= m and m == m:   # d larger, or the first NaN (kept)
                    m = d
    return m


@njit(cache=True, error_model="numpy", inline="always")
def _rotated(angle, pr, u, n, cs, sn, ax, ay):
    """cos, sin of the angles (n,) and rotated precurvatures a_i = R_z(angle_i) uhat_i of the
    tubes present (0 for the others), in place."""
    for i in range(n):
        if pr[i]:
            c = np.cos(angle[i])
            s = np.sin(angle[i])
            cs[i] = c
            sn[i] = s
            ax[i] = c * u[i, 0] - s * u[i, 1]
            ay[i] = s * u[i, 0] + c * u[i, 1]
        else:
            cs[i] = 1.0
            sn[i] = 0.0
            ax[i] = 0.0
            ay[i] = 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _bending_tangent(D, off, pr, sec_j, kxy, inv_k, ucx, ucy, n, S, cs, sn, ax, ay, ducx, ducy):
    """Tangent of the shared bending u_c = sum_i w_i a_i / sum_i w_i (w_i = k_(i,xy) of the
    tubes present) for angle tangents ``D`` (n, m) whose column ``off`` is that of alpha_0
    (n in the sweep's layout, 0 without the sigma0 columns), into ``ducx``, ``ducy`` (m,):
    d a_i = rot90(a_i) d angle_i + R_z(angle_i) d uhat_i, and the weights' derivatives
    d u_c / d k_(i,xy) = (a_i - u_c) / sum_j w_j."""
    m = D.shape[1]
    for p in range(m):
        dx = 0.0
        dy = 0.0
        for i in range(n):
            if pr[i]:
                d = kxy[i] * D[i, p]
                dx -= ay[i] * d
                dy += ax[i] * d
        ducx[p] = dx
        ducy[p] = dy
    for i in range(n):
        if pr[i]:
            cx = off + n + 2 * (i * S + sec_j[i])
            w = kxy[i]
            ducx[cx] += w * cs[i]
            ducx[cx + 1] -= w * sn[i]
            ducy[cx] += w * sn[i]
            ducy[cx + 1] += w * cs[i]
            kc = off + n + 2 * n * S + i
            ducx[kc] += ax[i] - ucx
            ducy[kc] += ay[i] - ucy
    for p in range(m):
        ducx[p] *= inv_k
        ducy[p] *= inv_k


@njit(cache=True, error_model="numpy")
def _rhs(psi, sig, Dp, Ds, pr, u, sec_j, kxy, kz, ratio, inv_k, n, S, cs, sn, ax, ay, ducx, ducy,
         fp, fs, Fp, Fs):
    """Torsion ODE (psi' = sigma, sigma' = (k_xy / k_z) (u_c x R_z(psi) uhat)_z for the tubes
    present; Rucker et al. 2010, Eq. (11)) and its tangent for the state tangents Dp, Ds
    (n, Pf), including the forcing d f / dq of the precurvatures and stiffnesses, in place."""
    Pf = Dp.shape[1]
    _rotated(psi, pr, u, n, cs, sn, ax, ay)
    ucx = 0.0
    ucy = 0.0
    for i in range(n):
        if pr[i]:
            ucx += kxy[i] * ax[i]
            ucy += kxy[i] * ay[i]
    ucx *= inv_k
    ucy *= inv_k
    _bending_tangent(Dp, n, pr, sec_j, kxy, inv_k, ucx, ucy, n, S, cs, sn, ax, ay, ducx, ducy)
    for i in range(n):
        if pr[i]:
            r = ratio[i]
            cross = ucx * ay[i] - ucy * ax[i]
            fp[i] = sig[i]
            fs[i] = r * cross
            g = ucx * ax[i] + ucy * ay[i]
            for p in range(Pf):
                Fp[i, p] = Ds[i, p]
                Fs[i, p] = r * (ducx[p] * ay[i] - ducy[p] * ax[i] + g * Dp[i, p])
            cx = 2 * n + 2 * (i * S + sec_j[i])
            Fs[i, cx] += r * (ucx * sn[i] - ucy * cs[i])
            Fs[i, cx + 1] += r * (ucx * cs[i] + ucy * sn[i])
            kc = 2 * n + 2 * n * S + i
            Fs[i, kc] += cross / kz[i]
            Fs[i, kc + n] -= r / kz[i] * cross
        else:
            fp[i] = 0.0
            fs[i] = 0.0
            for p in range(Pf):
                Fp[i, p] = 0.0
                Fs[i, p] = 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _stage(psi, sig, Dp, Ds, kp, ks, Kp, Ks, f, tp, ts, TP, TS):
    """RK4 stage input (tp, ts, TP, TS) = (psi, sig, Dp, Ds) + f (kp, ks, Kp, Ks)."""
    for i in range(psi.shape[0]):
        tp[i] = psi[i] + f * kp[i]
        ts[i] = sig[i] + f * ks[i]
        for p in range(Dp.shape[1]):
            TP[i, p] = Dp[i, p] + f * Kp[i, p]
            TS[i, p] = Ds[i, p] + f * Ks[i, p]


@njit(cache=True, error_model="numpy")
def _solve_columns(J, B, X):
    """det J and X = J^-1 B (J (n, n), B (n, m)) by Gaussian elimination with partial
    pivoting; X NaN where J is singular. J and B are not modified."""
    n = J.shape[0]
    m = B.shape[1]
    A = J.copy()
    X[:, :] = B
    det = 1.0
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        if p != k:
            det = -det
            for c in range(n):
                t = A[k, c]
                A[k, c] = A[p, c]
                A[p, c] = t
            for c in range(m):
                t = X[k, c]
                X[k, c] = X[p, c]
                X[p, c] = t
        piv = A[k, k]
        det *= piv
        if piv == 0.0:
            X[:, :] = np.nan
            return det
        for i in range(k + 1, n):
            f = A[i, k] / piv
            for c in range(k + 1, n):
                A[i, c] -= f * A[k, c]
            for c in range(m):
                X[i, c] -= f * X[k, c]
    for k in range(n - 1, -1, -1):
        for c in range(m):
            v = X[k, c]
            for q in range(k + 1, n):
                v -= A[k, q] * X[q, c]
            X[k, c] = v / A[k, k]
    return det


@njit(cache=True, error_model="numpy")
def tip_derivatives(s, present, uh, sec, kxy, kz, ratio, alpha, sig0, S, d_sig0, d_pos, d_tan, tip, tangent):
    """Tip and its exact derivatives at one configuration, from its base torsions.

    Parameters
    ----------
    s : ndarray, shape (G,)
        Grid nodes [m].
    present : ndarray of bool, shape (G - 1, n)
    uh : ndarray, shape (G - 1, n, 2)
        Precurvatures on the intervals [1/m] (``grid._grid``).
    sec : ndarray of int64, shape (G - 1, n)
        Section of each tube on each interval (:func:`section_index`).
    kxy, kz, ratio : ndarray, shape (n,)
        k_xy, k_z [N m^2] and k_xy / k_z.
    alpha, sig0 : ndarray, shape (n,)
        Base rotations [rad] and base torsions [1/m].
    S : int
        Largest number of sections.
    d_sig0 : ndarray, shape (n, P)
        Output d sigma0 / dq.
    d_pos, d_tan : ndarray, shape (3, P)
        Output d tip / dq [m per unit of q], d tangent / dq.
    tip, tangent : ndarray, shape (3,)
        Output tip position [m] and unit tangent of the re-swept centerline.

    Returns
    -------
    psi : ndarray, shape (G, n)
        Node angles of the sweep [rad].
    residual : float
        max_i |sigma_i(s_(G-1))| [1/m] of the sweep (the shooting residual).
    det : float
        det(d sigma(L) / d sigma0).
    """
    n = alpha.shape[0]
    G = s.shape[0]
    P = n * (3 + 2 * S)
    Pf = n + P
    psi = np.empty((G, n))
    sig = np.empty((G, n))
    Dp = np.zeros((G, n, Pf))
    Ds = np.zeros((G, n, Pf))
    for i in range(n):
        psi[0, i] = alpha[i]
        sig[0, i] = sig0[i]
        Ds[0, i, i] = 1.0
        Dp[0, i, n + i] = 1.0
    k1p = np.empty(n); k1s = np.empty(n); k2p = np.empty(n); k2s = np.empty(n)
    k3p = np.empty(n); k3s = np.empty(n); k4p = np.empty(n); k4s = np.empty(n)
    K1p = np.empty((n, Pf)); K1s = np.empty((n, Pf)); K2p = np.empty((n, Pf)); K2s = np.empty((n, Pf))
    K3p = np.empty((n, Pf)); K3s = np.empty((n, Pf)); K4p = np.empty((n, Pf)); K4s = np.empty((n, Pf))
    tp = np.empty(n); ts = np.empty(n); TP = np.empty((n, Pf)); TS = np.empty((n, Pf))
    cs = np.empty(n); sn = np.empty(n); ax = np.empty(n); ay = np.empty(n)
    ducx = np.empty(Pf); ducy = np.empty(Pf)
    # RK4 over the intervals, one step each (standard._integrate_general), with the tangents
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        pr = present[j]
        u = uh[j]
        sj = sec[j]
        ksum = 0.0
        for i in range(n):
            if pr[i]:
                ksum += kxy[i]
        inv_k = 1.0 / max(ksum, 1e-300)   # as standard._mean_bending
        x0p = psi[j]; x0s = sig[j]; X0p = Dp[j]; X0s = Ds[j]
        _rhs(x0p, x0s, X0p, X0s, pr, u, sj, kxy, kz, ratio, inv_k, n, S, cs, sn, ax, ay, ducx, ducy,
             k1p, k1s, K1p, K1s)
        _stage(x0p, x0s, X0p, X0s, k1p, k1s, K1p, K1s, 0.5 * h, tp, ts, TP, TS)
        _rhs(tp, ts, TP, TS, pr, u, sj, kxy, kz, ratio, inv_k, n, S, cs, sn, ax, ay, ducx, ducy,
             k2p, k2s, K2p, K2s)
        _stage(x0p, x0s, X0p, X0s, k2p, k2s, K2p, K2s, 0.5 * h, tp, ts, TP, TS)
        _rhs(tp, ts, TP, TS, pr, u, sj, kxy, kz, ratio, inv_k, n, S, cs, sn, ax, ay, ducx, ducy,
             k3p, k3s, K3p, K3s)
        _stage(x0p, x0s, X0p, X0s, k3p, k3s, K3p, K3s, h, tp, ts, TP, TS)
        _rhs(tp, ts, TP, TS, pr, u, sj, kxy, kz, ratio, inv_k, n, S, cs, sn, ax, ay, ducx, ducy,
             k4p, k4s, K4p, K4s)
        f = h / 6.0
        for i in range(n):
            psi[j + 1, i] = x0p[i] + f * (k1p[i] + 2.0 * k2p[i] + 2.0 * k3p[i] + k4p[i])
            sig[j + 1, i] = x0s[i] + f * (k1s[i] + 2.0 * k2s[i] + 2.0 * k3s[i] + k4s[i])
            for p in range(Pf):
                Dp[j + 1, i, p] = X0p[i, p] + f * (K1p[i, p] + 2.0 * K2p[i, p] + 2.0 * K3p[i, p] + K4p[i, p])
                Ds[j + 1, i, p] = X0s[i, p] + f * (K1s[i, p] + 2.0 * K2s[i, p] + 2.0 * K3s[i, p] + K4s[i, p])
    residual = 0.0
    for i in range(n):
        r = abs(sig[G - 1, i])
        if not r <= residual and residual == residual:   # NaN kept
            residual = r
    # implicit-function theorem on r = sigma(s_(G-1)): d sigma0 / dq = -J^-1 dr / dq
    det = _solve_columns(Ds[G - 1, :, :n], Ds[G - 1, :, n:], d_sig0)
    for i in range(n):
        for q in range(P):
            d_sig0[i, q] = -d_sig0[i, q]
    # centerline (standard._centerline: Hermite midpoint angles, shared bending, Eq. (57))
    R = np.empty((G, 3, 3))
    pts = np.empty((G, 3))
    psi_mid = np.empty((G - 1, n))
    ub = np.empty((G - 1, 2))
    E = np.empty((3, 3))
    vz = np.empty(3)
    for a in range(3):
        for b in range(3):
            R[0, a, b] = 1.0 if a == b else 0.0
        pts[0, a] = 0.0
    pts[0, 2] = s[0]
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        ksum = 0.0
        bx = 0.0
        by = 0.0
        for i in range(n):
            pm = 0.5 * (psi[j, i] + psi[j + 1, i]) + h * (sig[j, i] - sig[j + 1, i]) / 8.0
            psi_mid[j, i] = pm
            if present[j, i]:
                ksum += kxy[i]
                u0 = uh[j, i, 0]
                u1 = uh[j, i, 1]
                if u0 != 0.0 or u1 != 0.0:
                    c = np.cos(pm)
                    sn_ = np.sin(pm)
                    bx += kxy[i] * (c * u0 - sn_ * u1)
                    by += kxy[i] * (sn_ * u0 + c * u1)
        ksum = max(ksum, 1e-300)
        ub[j, 0] = bx / ksum
        ub[j, 1] = by / ksum
        advance(R[j], pts[j], ub[j, 0] * h, ub[j, 1] * h, 0.0, h, E, vz, R[j + 1], pts[j + 1])
    for a in range(3):
        tip[a] = pts[G - 1, a]
        tangent[a] = R[G - 1, a, 2]
    # chain: d tip = sum_k Jp_k du_k, d t = sum_k Jt_k du_k over the intervals (only the x, y
    # columns: u_z = 0), Jp_k = R_k dV(phi_k) e_z h_k^2 - [p_tip - p_(k+1)]x Omega_k,
    # Jt_k = -[t]x Omega_k, Omega_k = R_k V(phi_k) h_k, phi_k = u_k h_k
    for a in range(3):
        for q in range(P):
            d_pos[a, q] = 0.0
            d_tan[a, q] = 0.0
    Dmid = np.empty((n, Pf))
    T = np.empty((n, P))
    dux = np.empty(P)
    duy = np.empty(P)
    V = np.empty((3, 2))
    dV = np.empty((3, 2))
    Om = np.empty((3, 2))
    Jp = np.empty((3, 2))
    Jt = np.empty((3, 2))
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        pr = present[j]
        ksum = 0.0
        for i in range(n):
            if pr[i]:
                ksum += kxy[i]
        inv_k = 1.0 / max(ksum, 1e-300)
        # total tangents of the midpoint angles: T = Dmid[:, n:] + Dmid[:, :n] d sigma0 / dq
        for i in range(n):
            for p in range(Pf):
                Dmid[i, p] = 0.5 * (Dp[j, i, p] + Dp[j + 1, i, p]) + h * (Ds[j, i, p] - Ds[j + 1, i, p]) / 8.0
            for q in range(P):
                t = Dmid[i, n + q]
                for l in range(n):
                    t += Dmid[i, l] * d_sig0[l, q]
                T[i, q] = t
        _rotated(psi_mid[j], pr, uh[j], n, cs, sn, ax, ay)
        _bending_tangent(T, 0, pr, sec[j], kxy, inv_k, ub[j, 0], ub[j, 1], n, S, cs, sn, ax, ay, dux, duy)
        # V(phi) and d(V e_z)/d phi, columns x and y, phi = (x, y, 0) (_lie.left_jacobian_so3,
        # _lie.d_left_jacobian_ez)
        x = ub[j, 0] * h
        y = ub[j, 1] * h
        th2 = x * x + y * y
        _, ca, cb, da, db = _coefficients(np.sqrt(th2))
        d0 = 1.0 - cb * th2
        V[0, 0] = d0 + cb * x * x
        V[1, 0] = cb * x * y
        V[2, 0] = -ca * y
        V[0, 1] = cb * x * y
        V[1, 1] = d0 + cb * y * y
        V[2, 1] = ca * x
        dV[0, 0] = da * y * x
        dV[1, 0] = -ca - da * x * x
        dV[2, 0] = -2.0 * cb * x - db * th2 * x
        dV[0, 1] = ca + da * y * y
        dV[1, 1] = -da * x * y
        dV[2, 1] = -2.0 * cb * y - db * th2 * y
        for a in range(3):
            for c in range(2):
                o = 0.0
                w = 0.0
                for b in range(3):
                    o += R[j, a, b] * V[b, c]
                    w += R[j, a, b] * dV[b, c]
                Om[a, c] = o * h
                Jp[a, c] = w * h * h
        r0 = tip[0] - pts[j + 1, 0]
        r1 = tip[1] - pts[j + 1, 1]
        r2 = tip[2] - pts[j + 1, 2]
        for c in range(2):
            o0 = Om[0, c]
            o1 = Om[1, c]
            o2 = Om[2, c]
            Jp[0, c] -= r1 * o2 - r2 * o1
            Jp[1, c] -= r2 * o0 - r0 * o2
            Jp[2, c] -= r0 * o1 - r1 * o0
            Jt[0, c] = -(tangent[1] * o2 - tangent[2] * o1)
            Jt[1, c] = -(tangent[2] * o0 - tangent[0] * o2)
            Jt[2, c] = -(tangent[0] * o1 - tangent[1] * o0)
        for a in range(3):
            p0 = Jp[a, 0]
            p1 = Jp[a, 1]
            t0 = Jt[a, 0]
            t1 = Jt[a, 1]
            for q in range(P):
                d_pos[a, q] += p0 * dux[q] + p1 * duy[q]
                d_tan[a, q] += t0 * dux[q] + t1 * duy[q]
    return psi, residual, det


@njit(cache=True, error_model="numpy")
def tip_derivatives_batch(alpha, beta, sig0, valid, lengths, brk, nbrk, curv, kxy, kz, ratio, ds, merge_tol,
                          refine_ratio, refine_length, tol, tips, tans, d_sig0, d_pos, d_tan, residual, det, ok):
    """:func:`tip_derivatives` at K configurations, each on its own grid (``grid._grid`` with the
    options of ``_standard_batch.BatchOptions``), from the given base torsions.

    alpha, beta, sig0 (K, n) [rad], [m], [1/m]; valid (K,) rows to compute (the others are left
    as initialized); the robot as ``PackedRobot`` arrays; ``tol`` [1/m] the largest residual
    accepted. Outputs row by row: tips, tans (K, 3), d_sig0 (K, n, P), d_pos, d_tan (K, 3, P),
    residual, det (K,), ok (K,) (residual <= tol and det > 0)."""
    K = alpha.shape[0]
    S = curv.shape[1]
    for k in range(K):
        if not valid[k]:
            continue
        s, _, _, present, uh = _grid(beta[k], lengths, brk, nbrk, curv, ds, merge_tol, refine_ratio, refine_length)
        sec = section_index(s, present, beta[k], brk, nbrk)
        _, res, dt = tip_derivatives(s, present, uh, sec, kxy, kz, ratio, alpha[k], sig0[k], S, d_sig0[k],
                                     d_pos[k], d_tan[k], tips[k], tans[k])
        residual[k] = res
        det[k] = dt
        ok[k] = res <= tol and dt > 0.0
