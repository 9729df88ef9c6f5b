"""Compiled kernels of the clearance and friction solvers (numba, ``cache=True``).

The same mathematics as the slow reference (tests/ctrplan_reference/contact_reference.py), organised so
that nothing of size (number of contacts) x (number of curvature unknowns) is ever formed:

**Chains on one flat array.** The n tubes' nodes are stored one after the other (tube t owns
global nodes ``node_off[t]:node_off[t + 1]`` and segments ``seg_off[t]:seg_off[t + 1]``,
``seg_off[t] = node_off[t] - t``), so every kernel is a loop over flat arrays. Their forward
kinematics (:func:`~ctrplan.mechanics._chain_kernels.chain_kinematics`) lives in
``_chain_kernels``, which does not depend on the contact solver.

**Compliance by prefix sums.** With Omega_k = R_k V(u_k h_k) h_k, the position part
Pi_k = R_k d(V e_z)/dphi h_k^2 and base_k = Pi_k + [p_(k+1)]x Omega_k, the Jacobian rows of
Appendix B (Eqs. (59)-(72) of Ha, Fagogenis & Dupont 2019, re-derived in discrete.py) are

    dp_j/du_k = base_k - [p_j]x Omega_k,     domega_j,z/du_k = t_j^T Omega_k     (k < j)

so the 3x3 spatial compliance between nodes j <= l of one tube, with D_k = K_k^-1, is

    J_p,j K^-1 J_p,l^T = H1_j + H2_j [p_l]x,
    H1_j = F1_j - [p_j]x F2_j,  H2_j = F2_j^T - [p_j]x F3_j,
    F1_j = sum_(k<j) base_k D_k base_k^T,  F2_j = sum_(k<j) Omega_k D_k base_k^T,
    F3_j = sum_(k<j) Omega_k D_k Omega_k^T,

and the block W_ce = A_c K^-1 A_e^T of the contact compliance of Appendix A (Eqs. (50)-(56)),
A_c = B_c^T S_c J_p, is a sum over the (at most two) tubes that contacts c and e share. A
block costs O(1) instead of O(number of unknowns); blocks are computed column by column only
for the contacts the semismooth Newton method actually touches (active or violated ones), and
only on the rows of its working set (the displacements of the other contacts, needed only to
check them for violation, come from the generalized forces, :func:`_complete_displacements`).
The columns are stored as rows (arrays ``Wt`` = W^T and ``Zt`` = Z^T, C order), so that
computing a column and reading it back are both contiguous. W is symmetric: a block whose
transposed block is already computed is copied (:func:`_fill_column`).

**Dense solves by LAPACK.** The active block of Appendix A and the Newton matrix are factored
by LAPACK's ``dgetrf`` (``_lapack``), 2.1-2.5x faster than a compiled triple loop at these sizes.

**Generalized forces by suffix sums.** A^T phi + zt^T lambda of Eqs. (34)-(36), (41) is, for
segment k, base_k^T F_k + Omega_k^T (sum p_j x f_j + sum tau_j t_j) over the contacts distal to k:
the moment of the contact forces about the segment, one backward pass per tube.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ._chain_kernels import _coefficients, _skew_form
from ._lapack import PIVOT_DTYPE, lu_factor, lu_solve, lu_solve_matrix

_SEPARATION_ROUNDS = 3
_NONMONOTONE = 5
# Newton iterations with the natural residual (_residual) without a new smallest merit before
# the solve starts again with Fischer-Burmeister (_complementarity_from)
_NATURAL_STALL = 10
# Working-set rounds that will be followed by another are solved only to this scaled residual
# (solve_contacts); the last round is solved to the caller's tolerance.
_ROUND_TOL = 1e-3


class ContactGeometry(NamedTuple):
    """The contacts of one linearization and the chain data their compliance is built from.

    M contacts, N nodes of all tubes (flat, see the module docstring).

    Attributes
    ----------
    pair : ndarray of int64, shape (M,)
        Pair index i of each contact (tubes i and i + 1).
    jo, ji : ndarray of int64, shape (M,)
        Global node of each contact on the outer and on the inner tube.
    B : ndarray, shape (M, 3, 2)
        Contact frame: the two directions normal to the outer tube's tangent
        (:func:`contact_frames`).
    Pc : ndarray, shape (M, 2, 3, 2, 3)
        ``Pc[c, side]`` = (B_c^T H1_j, B_c^T H2_j, B_c^T [p_j]x) at the contact's node j on the
        outer (side 0) and the inner (side 1) tube (:func:`contact_projections`).
    R : ndarray, shape (N, 3, 3)
        Material frames of the nodes.
    p : ndarray, shape (N, 3)
        Centerline points [m].
    H1, H2, F3 : ndarray, shape (N, 3, 3)
        Prefix-sum compliance factors of :func:`linearize` (module docstring).
    Omega, base : ndarray, shape (S, 3, 3)
        Per-segment Jacobian factors of :func:`linearize` [m], [m^2].
    kinv : ndarray, shape (S, 3)
        Inverse stiffnesses 1 / (k h) [1/(N m^3)].
    node_off : ndarray of int64, shape (n + 1,)
        Tube t owns global nodes ``node_off[t]:node_off[t + 1]``.
    """

    pair: np.ndarray
    jo: np.ndarray
    ji: np.ndarray
    B: np.ndarray
    Pc: np.ndarray
    R: np.ndarray
    p: np.ndarray
    H1: np.ndarray
    H2: np.ndarray
    F3: np.ndarray
    Omega: np.ndarray
    base: np.ndarray
    kinv: np.ndarray
    node_off: np.ndarray


class ContactLaw(NamedTuple):
    """Clearances, friction and scaling of the complementarity conditions (Eqs. (37)-(41)).

    Attributes
    ----------
    c : ndarray, shape (M,)
        Clearance of each contact [m].
    Mblk : ndarray, shape (M, 2, 2)
        I + eta mu J (Eqs. (38), (40)).
    kappa : float
        Scale of the Fischer-Burmeister function: 1 / mean compliance diagonal [N/m].
    tq_out, tq_in : ndarray, shape (M,)
        Friction-torque factors eta mu c r_(i,in) and -eta mu c r_(i+1,out) [m^2] (Eq. (41)).
    friction : bool
        Any contact with eta mu != 0 (the Z columns are computed only then).
    """

    c: np.ndarray
    Mblk: np.ndarray
    kappa: float
    tq_out: np.ndarray
    tq_in: np.ndarray
    friction: bool


class ContactWork(NamedTuple):
    """Compliance columns computed so far, filled on demand by :func:`fill_columns` on the rows
    of :func:`extend_rows`.

    Attributes
    ----------
    Wt : ndarray, shape (2M, 2M)
        W^T [m/N]: column 2e + q of the contact compliance W is row 2e + q.
    Zt : ndarray, shape (M, 2M), or (1, 1) without friction
        Z^T [m/N]: column e of the torque-column matrix Z is row e.
    have : ndarray of bool, shape (M,)
        Block column e of W (and column e of Z) is computed, on the rows ``rows``.
    rows : ndarray of bool, shape (M,)
        The contacts whose rows of every computed column are valid (start all False; the
        solver extends them to its working set: no other row of W or Z is read).
    """

    Wt: np.ndarray
    Zt: np.ndarray
    have: np.ndarray
    rows: np.ndarray


class ContactResult(NamedTuple):
    """Result of :func:`solve_contacts` and :func:`complementarity`.

    Attributes
    ----------
    lam : ndarray, shape (M,)
        Contact multipliers lambda >= 0 [N/m] (force per unit clearance, phi_c = -lam_c M_c d_c).
    d : ndarray, shape (M, 2)
        Contact displacements (offsets of the inner from the outer centerline) [m].
    ok : bool
        Converged: max_k |Phi_k| / (kappa c_k) < tol.
    iterations : int
        Semismooth Newton iterations.
    err : float
        max_k |Phi_k| / (kappa c_k) [-].
    """

    lam: np.ndarray
    d: np.ndarray
    ok: bool
    iterations: int
    err: float


class _TrialPoint(NamedTuple):
    """Buffers of a line-search trial point (all shape (M,) but ``d`` (M, 2))."""

    lam: np.ndarray
    d: np.ndarray
    phi: np.ndarray
    da: np.ndarray
    db: np.ndarray


@njit(cache=True)
def linearize(u, uhat, kinv, h, node_off, R, p, Omega, base, H1, H2, F3, Jpv):
    """Per-segment Jacobian factors and per-node compliance prefix sums at a linearization point.

    Parameters
    ----------
    u, uhat, kinv : ndarray, shape (S, 3)
        Curvatures, precurvatures [1/m] and inverse stiffnesses 1 / (k h) [1/(N m^3)].
    h : ndarray, shape (S,)
    node_off : ndarray of int, shape (n + 1,)
    R, p : ndarray, shape (N, 3, 3), (N, 3)
        Kinematics at ``u`` (:func:`._chain_kernels.chain_kinematics`).
    Omega, base : ndarray, shape (S, 3, 3)
        Output: Omega_k [m] and base_k [m^2] (see the module docstring).
    H1, H2, F3 : ndarray, shape (N, 3, 3)
        Output: compliance prefix sums at every node.
    Jpv : ndarray, shape (N, 3)
        Output: J_p (u - uhat) at every node [m] (Eq. (21) with du = uhat - u).
    """
    n = node_off.shape[0] - 1
    V = np.empty((3, 3))
    dV = np.empty((3, 3))
    F1 = np.empty((3, 3))
    F2 = np.empty((3, 3))
    F3c = np.empty((3, 3))
    OD = np.empty((3, 3))
    bv = np.empty(3)
    ov = np.empty(3)
    for t in range(n):
        j0 = node_off[t]
        k0 = j0 - t
        F1[:] = 0.0
        F2[:] = 0.0
        F3c[:] = 0.0
        bv[:] = 0.0
        ov[:] = 0.0
        nseg = node_off[t + 1] - j0 - 1
        for m in range(nseg + 1):
            j = j0 + m
            # node j: prefix sums over segments k < m
            P0 = p[j, 0]
            P1 = p[j, 1]
            P2 = p[j, 2]
            for b in range(3):
                # [p]x X column b: (P1 X2 - P2 X1, P2 X0 - P0 X2, P0 X1 - P1 X0)
                H1[j, 0, b] = F1[0, b] - (P1 * F2[2, b] - P2 * F2[1, b])
                H1[j, 1, b] = F1[1, b] - (P2 * F2[0, b] - P0 * F2[2, b])
                H1[j, 2, b] = F1[2, b] - (P0 * F2[1, b] - P1 * F2[0, b])
                H2[j, 0, b] = F2[b, 0] - (P1 * F3c[2, b] - P2 * F3c[1, b])
                H2[j, 1, b] = F2[b, 1] - (P2 * F3c[0, b] - P0 * F3c[2, b])
                H2[j, 2, b] = F2[b, 2] - (P0 * F3c[1, b] - P1 * F3c[0, b])
                for a in range(3):
                    F3[j, a, b] = F3c[a, b]
            Jpv[j, 0] = bv[0] - (P1 * ov[2] - P2 * ov[1])
            Jpv[j, 1] = bv[1] - (P2 * ov[0] - P0 * ov[2])
            Jpv[j, 2] = bv[2] - (P0 * ov[1] - P1 * ov[0])
            if m == nseg:
                break
            # segment k = k0 + m between nodes j and j + 1
            k = k0 + m
            hk = h[k]
            x = u[k, 0] * hk
            y = u[k, 1] * hk
            z = u[k, 2] * hk
            th2 = x * x + y * y + z * z
            _, a_, b_, da, db = _coefficients(np.sqrt(th2))
            # V = (1 - b th^2) I + a [phi]x + b phi phi^T
            _skew_form(1.0 - b_ * th2, a_, b_, x, y, z, V)
            # d(V e_z)/dphi = a (-[e_z]x) + da (phi x e_z) phi^T
            #                 + b (phi_z I + phi e_z^T - 2 e_z phi^T) + db (phi phi_z - th^2 e_z) phi^T
            px = (y, -x, 0.0)
            ppx = (x * z, y * z, z * z - th2)
            ph = (x, y, z)
            for a in range(3):
                for b in range(3):
                    val = (da * px[a] + db * ppx[a]) * ph[b]
                    if a == b:
                        val += b_ * z
                    if b == 2:
                        val += b_ * ph[a]
                    if a == 2:
                        val -= 2.0 * b_ * ph[b]
                    dV[a, b] = val
            dV[0, 1] += a_
            dV[1, 0] -= a_
            h2 = hk * hk
            for a in range(3):
                for b in range(3):
                    so = 0.0
                    sp = 0.0
                    for q in range(3):
                        so += R[j, a, q] * V[q, b]
                        sp += R[j, a, q] * dV[q, b]
                    Omega[k, a, b] = so * hk
                    base[k, a, b] = sp * h2
            # base_k += [p_(k+1)]x Omega_k
            Q0 = p[j + 1, 0]
            Q1 = p[j + 1, 1]
            Q2 = p[j + 1, 2]
            for b in range(3):
                o0 = Omega[k, 0, b]
                o1 = Omega[k, 1, b]
                o2 = Omega[k, 2, b]
                base[k, 0, b] += Q1 * o2 - Q2 * o1
                base[k, 1, b] += Q2 * o0 - Q0 * o2
                base[k, 2, b] += Q0 * o1 - Q1 * o0
            # prefix sums
            for a in range(3):
                for b in range(3):
                    OD[a, b] = Omega[k, a, b] * kinv[k, b]
            for a in range(3):
                for b in range(3):
                    s11 = 0.0
                    s21 = 0.0
                    s33 = 0.0
                    for q in range(3):
                        bd = base[k, a, q] * kinv[k, q]
                        s11 += bd * base[k, b, q]
                        s21 += OD[a, q] * base[k, b, q]
                        s33 += OD[a, q] * Omega[k, b, q]
                    F1[a, b] += s11
                    F2[a, b] += s21
                    F3c[a, b] += s33
            for a in range(3):
                sb = 0.0
                so = 0.0
                for q in range(3):
                    v = u[k, q] - uhat[k, q]
                    sb += base[k, a, q] * v
                    so += Omega[k, a, q] * v
                bv[a] += sb
                ov[a] += so


@njit(cache=True)
def contact_frames(R, p, jo, ji, Jpv, B, dfree, diagW, H1, H2, pair):
    """Cross-section bases, force-free displacements and diagonal compliance blocks.

    Parameters
    ----------
    R, p : ndarray, shape (N, 3, 3), (N, 3)
    jo, ji : ndarray of int, shape (M,)
        Global node of each contact on the outer and on the inner tube.
    Jpv : ndarray, shape (N, 3)
        From :func:`linearize`.
    B : ndarray, shape (M, 3, 2)
        Output: B_c = [x_i, y_i] of the outer tube at the contact (B B^T = P_k, Eq. (22)).
    dfree : ndarray, shape (M, 2)
        Output: d_c with no contact force, B_c^T S_c (p* + J_p (uhat - u*)) [m] (Eq. (21)).
    diagW : ndarray, shape (M, 2, 2)
        Output: diagonal blocks W_cc [m/N].
    H1, H2 : ndarray, shape (N, 3, 3)
    pair : ndarray of int, shape (M,)
    """
    M = jo.shape[0]
    G = np.empty((3, 3))
    for c in range(M):
        a = jo[c]
        b = ji[c]
        for q in range(2):
            s = 0.0
            for r in range(3):
                B[c, r, q] = R[a, r, q]
                s += R[a, r, q] * ((p[a, r] - p[b, r]) - (Jpv[a, r] - Jpv[b, r]))
            dfree[c, q] = s
        for r in range(3):
            for q in range(3):
                G[r, q] = 0.0
        for node in (a, b):
            # G(j, j) = H1_j + H2_j [p_j]x
            P0 = p[node, 0]
            P1 = p[node, 1]
            P2 = p[node, 2]
            for r in range(3):
                G[r, 0] += H1[node, r, 0] + H2[node, r, 1] * P2 - H2[node, r, 2] * P1
                G[r, 1] += H1[node, r, 1] - H2[node, r, 0] * P2 + H2[node, r, 2] * P0
                G[r, 2] += H1[node, r, 2] + H2[node, r, 0] * P1 - H2[node, r, 1] * P0
        for q1 in range(2):
            for q2 in range(2):
                s = 0.0
                for r in range(3):
                    for r2 in range(3):
                        s += B[c, r, q1] * G[r, r2] * B[c, r2, q2]
                diagW[c, q1, q2] = s


@njit(cache=True)
def contact_projections(B, p, jo, ji, H1, H2, Pc):
    """Per contact c and side (0: its node jo on the outer tube, 1: its node ji on the inner
    tube), the 2x3 projections onto the cross section B_c of the compliance factors at that node:
    ``Pc[c, side, 0] = B_c^T H1_j``, ``Pc[c, side, 1] = B_c^T H2_j`` and
    ``Pc[c, side, 2] = B_c^T [p_j]x`` (shape (M, 2, 3, 2, 3)), once per linearization, so that a
    block of W or Z costs 24 instead of about 50 multiply-adds in :func:`fill_columns`."""
    M = jo.shape[0]
    for c in range(M):
        for side in range(2):
            j = jo[c] if side == 0 else ji[c]
            P0 = p[j, 0]
            P1 = p[j, 1]
            P2 = p[j, 2]
            for q in range(2):
                b0 = B[c, 0, q]
                b1 = B[c, 1, q]
                b2 = B[c, 2, q]
                for a in range(3):
                    Pc[c, side, 0, q, a] = b0 * H1[j, 0, a] + b1 * H1[j, 1, a] + b2 * H1[j, 2, a]
                    Pc[c, side, 1, q, a] = b0 * H2[j, 0, a] + b1 * H2[j, 1, a] + b2 * H2[j, 2, a]
                # (b^T [p]x)_a = (b x p)_a
                Pc[c, side, 2, q, 0] = b1 * P2 - b2 * P1
                Pc[c, side, 2, q, 1] = b2 * P0 - b0 * P2
                Pc[c, side, 2, q, 2] = b0 * P1 - b1 * P0


@njit(cache=True, inline="always")
def _fill_column(e, rows, cw, geometry, law, PB, U, Vv, w, g1, mirror):
    """Block column e of W and column e of Z (friction) on the contacts ``rows`` (int64 array),
    stored transposed in ``cw.Wt`` and ``cw.Zt``; ``PB``, ``U``, ``Vv`` (3, 2), ``w``, ``g1`` (3,)
    are scratch.

    ``mirror`` True: W is symmetric (W = A K^-1 A^T), so the block of a row c whose own column
    is already computed (``cw.have[c]``, c != e) on the row e (``cw.rows[e]``) is copied,
    transposed, from that column instead of computed (half the blocks of a working set filled
    column by column). The caller must have set ``cw.have[e]`` and no other flag of a column
    not yet computed. Z has no such symmetry and is always computed."""
    Wt, Zt = cw.Wt, cw.Zt
    pair, jo, ji, B, Pc = geometry.pair, geometry.jo, geometry.ji, geometry.B, geometry.Pc
    R, p, H1, H2, F3 = geometry.R, geometry.p, geometry.H1, geometry.H2, geometry.F3
    tq_out, tq_in, friction = law.tq_out, law.tq_in, law.friction
    have = cw.have
    mirror = mirror and cw.rows[e]
    nr = rows.shape[0]
    for idx in range(nr):
        c = rows[idx]
        if mirror and c != e and have[c]:
            Wt[2 * e, 2 * c] = Wt[2 * c, 2 * e]
            Wt[2 * e, 2 * c + 1] = Wt[2 * c + 1, 2 * e]
            Wt[2 * e + 1, 2 * c] = Wt[2 * c, 2 * e + 1]
            Wt[2 * e + 1, 2 * c + 1] = Wt[2 * c + 1, 2 * e + 1]
        else:
            Wt[2 * e, 2 * c] = 0.0
            Wt[2 * e, 2 * c + 1] = 0.0
            Wt[2 * e + 1, 2 * c] = 0.0
            Wt[2 * e + 1, 2 * c + 1] = 0.0
        if friction:
            Zt[e, 2 * c] = 0.0
            Zt[e, 2 * c + 1] = 0.0
    for side in range(2):
        te = pair[e] + side
        je = jo[e] if side == 0 else ji[e]
        se = 1.0 if side == 0 else -1.0
        tau = tq_out[e] if side == 0 else tq_in[e]
        pe = p[je]
        # PB = [p_e]x B_e ; U = H1_je^T B_e ; Vv = H2_je^T B_e
        for q in range(2):
            PB[0, q] = pe[1] * B[e, 2, q] - pe[2] * B[e, 1, q]
            PB[1, q] = pe[2] * B[e, 0, q] - pe[0] * B[e, 2, q]
            PB[2, q] = pe[0] * B[e, 1, q] - pe[1] * B[e, 0, q]
            for a in range(3):
                su = 0.0
                sv = 0.0
                for r in range(3):
                    su += H1[je, r, a] * B[e, r, q]
                    sv += H2[je, r, a] * B[e, r, q]
                U[a, q] = su
                Vv[a, q] = sv
        with_torque = friction and tau != 0.0
        if with_torque:
            # t_e; w = F3_je t_e; g1 = H2_je t_e + [p_e]x w  (for contacts distal to e)
            t0 = R[je, 0, 2]
            t1 = R[je, 1, 2]
            t2 = R[je, 2, 2]
            for a in range(3):
                w[a] = F3[je, a, 0] * t0 + F3[je, a, 1] * t1 + F3[je, a, 2] * t2
                g1[a] = H2[je, a, 0] * t0 + H2[je, a, 1] * t1 + H2[je, a, 2] * t2
            g1[0] += pe[1] * w[2] - pe[2] * w[1]
            g1[1] += pe[2] * w[0] - pe[0] * w[2]
            g1[2] += pe[0] * w[1] - pe[1] * w[0]
        for idx in range(nr):
            c = rows[idx]
            if pair[c] == te:
                jc = jo[c]
                sc = 1.0
                sd = 0
            elif pair[c] + 1 == te:
                jc = ji[c]
                sc = -1.0
                sd = 1
            else:
                continue
            f = sc * se
            nq = 0 if mirror and c != e and have[c] else 2   # 0: the W block was copied
            if nq == 0 and not with_torque:
                continue
            if jc <= je:
                # B_c^T (H1_jc + H2_jc [p_e]x) B_e = Pc0 B_e + Pc1 PB
                for q1 in range(nq):
                    for q2 in range(2):
                        v = 0.0
                        for a in range(3):
                            v += Pc[c, sd, 0, q1, a] * B[e, a, q2] + Pc[c, sd, 1, q1, a] * PB[a, q2]
                        Wt[2 * e + q2, 2 * c + q1] += f * v
                if with_torque:
                    # B_c^T H2_jc t_e
                    for q1 in range(2):
                        Zt[e, 2 * c + q1] += sc * tau * (Pc[c, sd, 1, q1, 0] * R[je, 0, 2]
                                                        + Pc[c, sd, 1, q1, 1] * R[je, 1, 2]
                                                        + Pc[c, sd, 1, q1, 2] * R[je, 2, 2])
            else:
                # B_c^T (H1_je^T - [p_c]x H2_je^T) B_e = B_c^T U - Pc2 Vv
                for q1 in range(nq):
                    for q2 in range(2):
                        v = 0.0
                        for a in range(3):
                            v += B[c, a, q1] * U[a, q2] - Pc[c, sd, 2, q1, a] * Vv[a, q2]
                        Wt[2 * e + q2, 2 * c + q1] += f * v
                if with_torque:
                    # B_c^T ((H2_je - [p_c - p_e]x F3_je) t_e) = B_c^T g1 - Pc2 w
                    for q1 in range(2):
                        v = 0.0
                        for a in range(3):
                            v += B[c, a, q1] * g1[a] - Pc[c, sd, 2, q1, a] * w[a]
                        Zt[e, 2 * c + q1] += sc * tau * v


@njit(cache=True)
def fill_columns(cols, work, geometry, law):
    """Compute the block columns ``e in cols`` of W (2M, 2M) [m/N] and the columns of Z (2M, M)
    [m/N] (torque terms, friction only) that are not computed yet (``work.have[e]`` False), on
    the rows ``work.rows``, stored transposed: column 2e + q of W is row 2e + q of ``work.Wt``
    (2M, 2M), column e of Z is row e of ``work.Zt`` (M, 2M).

    Z column e is A K^-1 zt_e^T: the displacements caused by the friction torques of contact e
    (Eq. (41)) per unit multiplier (Appendix A of Ha, Fagogenis & Dupont 2019).

    Parameters
    ----------
    cols : ndarray of int64, shape (m,)
        Contacts whose columns are needed.
    work : ContactWork
        ``Wt``, ``Zt`` and ``have``, updated in place; ``rows`` read.
    geometry : ContactGeometry
        ``pair``, ``jo``, ``ji``, ``B``, ``Pc`` (from :func:`contact_projections`), ``R``, ``p``,
        ``H1``, ``H2``, ``F3``.
    law : ContactLaw
        Reads ``tq_out``, ``tq_in`` and ``friction``.
    """
    missing = 0
    for idx in range(cols.shape[0]):
        if not work.have[cols[idx]]:
            missing += 1
    if missing == 0:   # the usual case in a line-search trial
        return
    rows = np.nonzero(work.rows)[0]
    PB = np.empty((3, 2))
    U = np.empty((3, 2))
    Vv = np.empty((3, 2))
    w = np.empty(3)
    g1 = np.empty(3)
    for idx in range(cols.shape[0]):
        e = cols[idx]
        if work.have[e]:
            continue
        work.have[e] = True
        _fill_column(e, rows, work, geometry, law, PB, U, Vv, w, g1, True)


@njit(cache=True)
def extend_rows(mask, work, geometry, law):
    """Extend the valid rows ``work.rows`` of the computed columns to the contacts of ``mask``
    (bool, shape (M,)): the entries of every computed column on the contacts added (W is
    symmetric, but the transposed storage keeps a column's rows contiguous, so they are computed
    like a column's other entries, by :func:`fill_columns`' block formulas)."""
    M = mask.shape[0]
    n_new = 0
    for c in range(M):
        if mask[c] and not work.rows[c]:
            n_new += 1
    if n_new == 0:
        return
    new = np.empty(n_new, dtype=np.int64)
    i = 0
    for c in range(M):
        if mask[c] and not work.rows[c]:
            new[i] = c
            i += 1
            work.rows[c] = True
    PB = np.empty((3, 2))
    U = np.empty((3, 2))
    Vv = np.empty((3, 2))
    w = np.empty(3)
    g1 = np.empty(3)
    for e in range(M):
        if work.have[e]:
            _fill_column(e, new, work, geometry, law, PB, U, Vv, w, g1, False)


@njit(cache=True)
def _active_of(lam):
    """Indices of the positive multipliers."""
    return np.nonzero(lam > 0.0)[0]


@njit(cache=True, inline="always")
def _free_displacements(lam, act, dfree, Zt, friction, d, rows):
    """d = dfree + Z lam on the contacts ``rows`` (lam non-zero only on ``act``)."""
    nr = rows.shape[0]
    for idx in range(nr):
        k = rows[idx]
        d[k, 0] = dfree[k, 0]
        d[k, 1] = dfree[k, 1]
    if friction:
        for i in range(act.shape[0]):
            l = act[i]
            for idx in range(nr):
                r = rows[idx]
                d[r, 0] += Zt[l, 2 * r] * lam[l]
                d[r, 1] += Zt[l, 2 * r + 1] * lam[l]


@njit(cache=True, inline="always")
def _active_correction(lam, act, Mblk, Wt, d, rows, LU, piv):
    """d -= W_(:, a) L_a d_a on the contacts ``rows``, with d_a = S^-1 r_a from the LU factors of
    S = I + W_aa L_a and r = d as :func:`_free_displacements` left it."""
    n_act = act.shape[0]
    da = np.empty(2 * n_act)
    for i in range(n_act):
        da[2 * i] = d[act[i], 0]
        da[2 * i + 1] = d[act[i], 1]
    lu_solve(LU, piv, da)
    for j in range(n_act):
        cj = act[j]
        lj = lam[cj]
        y0 = lj * (Mblk[cj, 0, 0] * da[2 * j] + Mblk[cj, 0, 1] * da[2 * j + 1])
        y1 = lj * (Mblk[cj, 1, 0] * da[2 * j] + Mblk[cj, 1, 1] * da[2 * j + 1])
        for idx in range(rows.shape[0]):
            r = rows[idx]
            d[r, 0] -= Wt[2 * cj, 2 * r] * y0 + Wt[2 * cj + 1, 2 * r] * y1
            d[r, 1] -= Wt[2 * cj, 2 * r + 1] * y0 + Wt[2 * cj + 1, 2 * r + 1] * y1


@njit(cache=True)
def _displacements(lam, act, dfree, Mblk, Wt, Zt, friction, d, rows):
    """d (M, 2) on the contacts ``rows`` for multipliers lam that are non-zero only on ``act``
    (a subset of ``rows``): (I + W Lambda M) d = dfree + Z lam reduced to those contacts
    (Appendix A, Eqs. (50)-(56) on the active set). Rows of d outside ``rows`` are left alone.
    Returns (ok, LU, piv) with the LU factors of S = I + W_aa L_a (if not ok, S is singular or
    not finite and d holds dfree + Z lam)."""
    _free_displacements(lam, act, dfree, Zt, friction, d, rows)
    n_act = act.shape[0]
    m2 = 2 * n_act
    S = np.empty((m2, m2))
    piv = np.empty(m2, dtype=PIVOT_DTYPE)
    if n_act == 0:
        return True, S, piv
    # S = I + W_aa L_a, L_a = blockdiag(lam_l M_l)
    for j in range(n_act):
        cj = act[j]
        lj = lam[cj]
        for i in range(n_act):
            ci = act[i]
            for q1 in range(2):
                for q2 in range(2):
                    S[2 * i + q1, 2 * j + q2] = lj * (Wt[2 * cj, 2 * ci + q1] * Mblk[cj, 0, q2]
                                                      + Wt[2 * cj + 1, 2 * ci + q1] * Mblk[cj, 1, q2])
    for i in range(n_act):
        S[2 * i, 2 * i] += 1.0
        S[2 * i + 1, 2 * i + 1] += 1.0
    if not lu_factor(S, piv):
        return False, S, piv
    _active_correction(lam, act, Mblk, Wt, d, rows, S, piv)
    return True, S, piv


@njit(cache=True)
def _complete_displacements(lam, d, known, with_forces, dfree, geometry, law):
    """d on the contacts outside ``known`` (bool, shape (M,)), from the multipliers and the
    displacements d_a of the active contacts, without the columns of W:
    d = dfree + B^T S J_p K^-1 (A^T phi + zt^T lam), phi_a = -lam_a M_a d_a (``with_forces``
    False: phi = 0, d = dfree + Z lam). Costs O(nodes + contacts): one backward pass for the
    generalized forces (:func:`_curvature_change`) and one forward pass for J_p of them.
    Rows in ``known`` are left alone."""
    B, jo, ji, p = geometry.B, geometry.jo, geometry.ji, geometry.p
    Omega, base, node_off = geometry.Omega, geometry.base, geometry.node_off
    v = np.empty((Omega.shape[0], 3))
    _curvature_change(lam, d, geometry, law, with_forces, v)
    Jv = np.empty((p.shape[0], 3))
    n = node_off.shape[0] - 1
    for t in range(n):
        j0 = node_off[t]
        k0 = j0 - t
        nseg = node_off[t + 1] - j0 - 1
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        o0 = 0.0
        o1 = 0.0
        o2 = 0.0
        for m in range(nseg + 1):
            j = j0 + m
            # J_p v at node j = sum_(k<j) base_k v_k - [p_j]x sum_(k<j) Omega_k v_k
            Jv[j, 0] = b0 - (p[j, 1] * o2 - p[j, 2] * o1)
            Jv[j, 1] = b1 - (p[j, 2] * o0 - p[j, 0] * o2)
            Jv[j, 2] = b2 - (p[j, 0] * o1 - p[j, 1] * o0)
            if m == nseg:
                break
            k = k0 + m
            v0 = v[k, 0]
            v1 = v[k, 1]
            v2 = v[k, 2]
            b0 += base[k, 0, 0] * v0 + base[k, 0, 1] * v1 + base[k, 0, 2] * v2
            b1 += base[k, 1, 0] * v0 + base[k, 1, 1] * v1 + base[k, 1, 2] * v2
            b2 += base[k, 2, 0] * v0 + base[k, 2, 1] * v1 + base[k, 2, 2] * v2
            o0 += Omega[k, 0, 0] * v0 + Omega[k, 0, 1] * v1 + Omega[k, 0, 2] * v2
            o1 += Omega[k, 1, 0] * v0 + Omega[k, 1, 1] * v1 + Omega[k, 1, 2] * v2
            o2 += Omega[k, 2, 0] * v0 + Omega[k, 2, 1] * v1 + Omega[k, 2, 2] * v2
    for c in range(known.shape[0]):
        if known[c]:
            continue
        a = jo[c]
        b = ji[c]
        for q in range(2):
            d[c, q] = dfree[c, q] + (B[c, 0, q] * (Jv[a, 0] - Jv[b, 0]) + B[c, 1, q] * (Jv[a, 1] - Jv[b, 1])
                                     + B[c, 2, q] * (Jv[a, 2] - Jv[b, 2]))


@njit(cache=True, inline="always")
def _offset_norm(d, c, k):
    """|d_k| [m], floored at 1e-6 c_k so that the gap c_k / |d_k| - 1 stays finite for
    concentric tubes."""
    return max(np.sqrt(d[k, 0] * d[k, 0] + d[k, 1] * d[k, 1]), 1e-6 * c[k])


@njit(cache=True)
def _residual(lam, d, c, kappa, phi, da, db, work, natural):
    """Complementarity residual Phi_k(c lam, kappa c (c / |d| - 1)) and its partial derivatives
    da, db over the working set ``work`` (contacts outside it count as separated: phi = 0, no
    Newton row); returns the merit |phi|^2 and the stopping measure
    max_k |FB_k| / (kappa c_k), always of the Fischer-Burmeister function.

    Phi_k is the Fischer-Burmeister function FB(a, b) = a + b - sqrt(a^2 + b^2) for a contact
    at lambda = 0 and, when ``natural`` is True, the natural residual min(a, b) for a contact
    with lambda > 0. Both vanish exactly where a >= 0, b >= 0, a b = 0, so the solution is the
    same; they differ in the path. Near a degenerate contact (lambda and gap both near 0) FB
    blends the two conditions and Newton converges linearly; min(a, b) picks one (release the
    contact, or close its gap), which cut the Newton iterations of a bound by a third. At lambda = 0 FB keeps its diagonal term c da in the Newton row of
    a violated contact; min(a, b) has none there, and for neighbouring violated contacts,
    nearly collinear, the Newton matrix became singular (steps 400 times lambda). |FB| lies
    between 2 - sqrt(2) and 2 + sqrt(2) times |min| (about 2 |min| where a is small and
    b < 0), so the stopping measure stays that of FB, as before.

    The gap is measured as c / |d| - 1 rather than (c^2 - |d|^2) / (2 c^2): the two agree to
    first order at |d| = c (same stopping test), but |d| falls roughly like 1 / lambda as a
    contact is loaded, so c / |d| is nearly linear in lambda and Newton from lambda = 0 closes a
    large violation in a few steps instead of growing 1 + w lambda by a factor 1.5 per step
    (measured: 5 instead of 23 iterations on the first working set of a hard start)."""
    merit = 0.0
    err = 0.0
    for k in range(lam.shape[0]):
        if not work[k]:
            phi[k] = 0.0
            da[k] = 1.0
            db[k] = 0.0
            continue
        a = c[k] * lam[k]
        b = kappa * c[k] * (c[k] / _offset_norm(d, c, k) - 1.0)
        r = np.sqrt(a * a + b * b)
        fb = a + b - r
        e = abs(fb) / (kappa * c[k])
        if e > err:
            err = e
        if natural and lam[k] > 0.0:
            if a <= b:
                phi[k] = a
                da[k] = 1.0
                db[k] = 0.0
            else:
                phi[k] = b
                da[k] = 0.0
                db[k] = 1.0
        else:
            phi[k] = fb
            if r < 1e-300:
                da[k] = 1.0 - 1.0 / np.sqrt(2.0)
                db[k] = 1.0 - 1.0 / np.sqrt(2.0)
            else:
                da[k] = 1.0 - a / r
                db[k] = 1.0 - b / r
        merit += phi[k] * phi[k]
    return merit, err


@njit(cache=True, inline="always")
def _c_entry(Wt, Zt, row, l, e0, e1, friction):
    """Entry (row, l) of C = Z - W_(:, l-block) M_l d_l with (e0, e1) = M_l d_l: the change of
    displacement component ``row`` per unit lambda_l at fixed other multipliers [m/N]."""
    v = -(Wt[2 * l, row] * e0 + Wt[2 * l + 1, row] * e1)
    if friction:
        v += Zt[l, row]
    return v


@njit(cache=True)
def _trial(lam, Rs, step, t, dfree, geometry, law, cw, work, rows, trial, natural):
    """Line-search trial point: ``trial.lam`` = max(lam + t step, 0) on the rows ``Rs`` (lam
    elsewhere), its displacements ``trial.d`` and complementarity residual (``trial.phi``,
    ``trial.da``, ``trial.db``; :func:`_residual` with ``natural``) in place.

    Parameters
    ----------
    lam : ndarray, shape (M,)
        Current multipliers [N/m].
    Rs : ndarray of int64, shape (nR,)
        Contacts of the reduced Newton system.
    step : ndarray, shape (nR,)
        Newton direction on those rows [N/m].
    t : float
        Step length [-].
    dfree : ndarray, shape (M, 2)
        Force-free displacements [m].
    geometry : ContactGeometry
    law : ContactLaw
    cw : ContactWork
        Compliance columns, filled for the trial's active set.
    work : ndarray of bool, shape (M,)
        Working set (the merit reads only its rows).
    rows : ndarray of int64
        Rows of the displacements to update (the working set's).
    trial : _TrialPoint
        Output buffers.

    Returns
    -------
    (displacements ok, LU factors, pivots, active set, merit, FB stopping measure).
    """
    lam_t, d_t, phi_t, da_t, db_t = trial.lam, trial.d, trial.phi, trial.da, trial.db
    c, Mblk, kappa, friction = law.c, law.Mblk, law.kappa, law.friction
    Wt, Zt = cw.Wt, cw.Zt
    for k in range(lam.shape[0]):
        lam_t[k] = lam[k]
    for ii in range(Rs.shape[0]):
        k = Rs[ii]
        lam_t[k] = max(lam[k] + t * step[ii], 0.0)
    act_n = _active_of(lam_t)
    fill_columns(act_n, cw, geometry, law)
    fok_t, LU_t, piv_t = _displacements(lam_t, act_n, dfree, Mblk, Wt, Zt, friction, d_t, rows)
    m_t, e_t = _residual(lam_t, d_t, c, kappa, phi_t, da_t, db_t, work, natural)
    return fok_t, LU_t, piv_t, act_n, m_t, e_t


@njit(cache=True)
def _violation(d, c, k):
    """Constraint violation of contact k, max(0, |d_k|^2 - c_k^2) / c_k^2: to first order the
    scaled FB residual |Phi_k| / (kappa c_k) = 2 (1 - c_k / |d_k|) of the contact at
    lambda = 0, which the Newton method's stopping test bounds inside the working set."""
    g = (d[k, 0] * d[k, 0] + d[k, 1] * d[k, 1] - c[k] * c[k]) / (c[k] * c[k])
    return g if g > 0.0 else 0.0


@njit(cache=True)
def _grow_working_set(d, c, pair, tol, work):
    """Add to ``work`` each contact outside it whose constraint is violated (scaled residual at
    lambda = 0 not below ``tol``) and is a local maximum of the violation among its neighbours
    on the same tube pair (adding every violated contact instead brought back the large systems:
    the bound took 38 ms instead of 24). Returns the number added and the largest violation
    outside the set."""
    M = c.shape[0]
    added = 0
    worst = 0.0
    for k in range(M):
        if work[k]:
            continue
        v = _violation(d, c, k)
        if v > worst:
            worst = v
        if v < tol:
            continue
        if k > 0 and pair[k - 1] == pair[k] and _violation(d, c, k - 1) > v:
            continue
        if k + 1 < M and pair[k + 1] == pair[k] and _violation(d, c, k + 1) > v:
            continue
        work[k] = True
        added += 1
    return added, worst


@njit(cache=True)
def solve_contacts(lam0, dfree, geometry, law, cw, tol, maxit):
    """Contact multipliers of one linearization by constraint generation around
    :func:`complementarity`: solve on a working set (the contacts with lambda > 0 and the local
    maxima of the constraint violation along each tube pair), then add the violated local maxima
    outside it and solve again, until no contact outside the set is violated. The result is
    then a solution of the complementarity conditions over all contacts (a separated contact
    with lambda = 0 has a zero Fischer-Burmeister residual), but the Newton systems stay the size
    of the contact regions instead of every contact the force-free shape violates (measured:
    the first linearization from lambda = 0 activated up to 97 of 110 contacts).

    A round stops at the scaled residual ``_ROUND_TOL`` (or ``tol`` if larger): its multipliers
    only decide which contacts are added. When no contact is added, the same set is solved on to
    ``tol``, and the set is checked again. A round whose starting point already meets the loose
    tolerance is solved on to ``tol`` at once (it would end without an iteration and add no
    contact: same iterates, without the empty round's set-up and displacement completion). Only
    the working set's rows of W and Z are computed (``cw.rows``, :func:`extend_rows`); the
    displacements of the other contacts, needed for the violation check, come from
    :func:`_complete_displacements`.

    Parameters
    ----------
    lam0 : ndarray, shape (M,)
        Starting multipliers [N/m] (negative entries are taken as 0).
    dfree : ndarray, shape (M, 2)
        Force-free displacements of this linearization [m] (:func:`contact_frames`).
    geometry : ContactGeometry
    law : ContactLaw
    cw : ContactWork
        Compliance columns, filled on demand (in place).
    tol : float
        Stopping tolerance on max_k |Phi_k| / (kappa c_k) [-].
    maxit : int
        Newton iterations per round (and per phase of :func:`_complementarity_from`).

    Returns
    -------
    ContactResult
        What :func:`complementarity` returns, with the Newton iterations of all rounds and the
        error over all contacts.
    """
    c, Mblk, friction = law.c, law.Mblk, law.friction
    pair = geometry.pair
    M = c.shape[0]
    lam = np.maximum(lam0, 0.0)
    work = lam > 0.0
    d = np.empty((M, 2))
    act = _active_of(lam)
    extend_rows(work, cw, geometry, law)
    fill_columns(act, cw, geometry, law)
    fok, LU, piv = _displacements(lam, act, dfree, Mblk, cw.Wt, cw.Zt, friction, d, act)
    if fok:
        _complete_displacements(lam, d, work, bool(True), dfree, geometry, law)
        _grow_working_set(d, c, pair, tol, work)
    else:
        work[:] = True
    total = 0
    round_tol = max(tol, _ROUND_TOL)
    for _ in range(M + 2):   # at most M growing rounds and one that finishes a loose one
        # a round starts from the multipliers the last one ended with: the factorization of
        # S = I + W_aa L_a is the same (it does not depend on the working set), so it is handed
        # over instead of computed again (2.8 rounds per linearization on the 4x4x4 grid)
        # a round whose start already meets round_tol goes on to tol at once: the working set
        # was just grown from these displacements, so the check after a round of no iterations
        # would add nothing, and the round that finishes to tol would start from the same point
        res, LU, piv, fok = _complementarity_from(lam, dfree, geometry, law, cw, round_tol, maxit, work,
                                                  LU, piv, fok, tol)
        lam, d, ok, its, err = res
        total += its
        if not ok:
            return ContactResult(lam, d, False, total, err)
        added, worst = _grow_working_set(d, c, pair, tol, work)
        if added == 0:
            if err < tol:
                return ContactResult(lam, d, True, total, max(err, worst))
            round_tol = tol
    return ContactResult(lam, d, False, total, err)


@njit(cache=True)
def complementarity(lam0, dfree, geometry, law, cw, tol, maxit, work):
    """Semismooth Newton on the contact complementarity conditions of one linearization, over
    the contacts of the working set ``work`` (bool, shape (M,); the others are held at
    lambda = 0). The reference ``_Complementarity.solve`` uses the Fischer-Burmeister function
    on every contact; here the active contacts use the natural residual min(a, b) unless that
    gives up (:func:`_residual`, :func:`_complementarity_from`). Same conditions, same stopping
    test, fewer iterations.

    The Newton system is reduced exactly to the contacts whose row is not trivial (active,
    violated, or with a non-zero residual): a contact with lambda = 0 and a positive gap has
    phi = 0 and d phi / d b = 0, so its step is zero. Only the W and Z columns of those contacts
    are ever computed (:func:`fill_columns`). Inside the iteration the displacements d are
    updated only on the working set (the merit and the Newton matrix read no other rows); the
    returned d is complete.

    Parameters
    ----------
    lam0 : ndarray, shape (M,)
        Starting multipliers [N/m] (negative entries are taken as 0).
    dfree : ndarray, shape (M, 2)
        Force-free displacements of this linearization [m] (:func:`contact_frames`).
    geometry : ContactGeometry
    law : ContactLaw
    cw : ContactWork
        Compliance columns, filled on demand (in place).
    tol : float
        Stopping tolerance on max_k |Phi_k| / (kappa c_k) [-].
    maxit : int
        Newton iterations at most, for each of the two phases of :func:`_complementarity_from`.
    work : ndarray of bool, shape (M,)
        Working set.

    Returns
    -------
    ContactResult
        ``lam`` (M,) [N/m], ``d`` (M, 2) [m], ``ok``, ``iterations`` and
        ``err`` = max_k |Phi_k| / (kappa c_k).
    """
    lam = np.maximum(lam0, 0.0)
    act = _active_of(lam)
    extend_rows(work, cw, geometry, law)
    fill_columns(act, cw, geometry, law)
    d = np.empty((lam.shape[0], 2))
    lu_ok, LU, piv = _displacements(lam, act, dfree, law.Mblk, cw.Wt, cw.Zt, law.friction, d, act)
    return _complementarity_from(lam, dfree, geometry, law, cw, tol, maxit, work, LU, piv, lu_ok, tol)[0]


@njit(cache=True)
def _complementarity_from(lam0, dfree, geometry, law, cw, tol, maxit, work, LU0, piv0, lu_ok0, tight):
    """:func:`complementarity` given the LU factors ``LU0``, ``piv0`` of S = I + W_aa L_a at
    lam0's active set (``lu_ok0`` False: S was singular or not finite, as
    :func:`_displacements` reports it), and a second tolerance ``tight`` <= ``tol``: if lam0
    already meets ``tol``, the solve goes on to ``tight`` (for :func:`solve_contacts`' rounds).
    Returns (ContactResult, LU, piv, lu_ok) with the factors at the returned multipliers, which
    the next round of :func:`solve_contacts` starts from. With ``tight`` = ``tol`` the
    displacements and iterates are those of :func:`complementarity` to the bit.

    Newton runs first with the natural residual on the active contacts (:func:`_residual`). If
    that gives up (a line search without descent, or ``_NATURAL_STALL`` iterations without a new
    smallest merit), it starts again from lam0 with the Fischer-Burmeister function on every
    contact, with ``maxit`` iterations of its own; the iterations of both are counted. (Going on
    from where the natural residual gave up instead failed on the all-contact solves of
    tests/test_mechanics_fast_vs_reference.py: its iterates had wandered to a merit of the same
    size but 10 times the largest residual, where FB's line search stalled.)"""
    res, LU, piv, lu_ok, gave_up = _newton(lam0, dfree, geometry, law, cw, tol, maxit, work, LU0, piv0,
                                           lu_ok0, bool(True), tight)
    if not gave_up:
        return res, LU, piv, lu_ok
    used = res.iterations
    res, LU, piv, lu_ok, _ = _newton(lam0, dfree, geometry, law, cw, tol, maxit, work, LU0, piv0, lu_ok0,
                                     bool(False), tight)
    return ContactResult(res.lam, res.d, res.ok, used + res.iterations, res.err), LU, piv, lu_ok


@njit(cache=True)
def _newton(lam0, dfree, geometry, law, cw, tol, maxit, work, LU0, piv0, lu_ok0, natural, tight):
    """The Newton iteration of :func:`_complementarity_from`, with the natural residual on the
    active contacts (``natural`` True) or Fischer-Burmeister on all, to ``tol``, or to ``tight``
    if lam0 already meets ``tol``. Returns (ContactResult, LU, piv, lu_ok, gave_up);
    ``gave_up`` is True only with ``natural``, when a line search found no descent or the merit
    made no new minimum in ``_NATURAL_STALL`` iterations, and the result is then to be
    discarded."""
    c, Mblk, kappa, friction = law.c, law.Mblk, law.kappa, law.friction
    Wt, Zt = cw.Wt, cw.Zt
    M = c.shape[0]
    lam = np.maximum(lam0, 0.0)
    d = np.empty((M, 2))
    phi = np.empty(M)
    da = np.empty(M)
    db = np.empty(M)
    d_t = np.empty((M, 2))
    phi_t = np.empty(M)
    da_t = np.empty(M)
    db_t = np.empty(M)
    lam_t = np.empty(M)
    act = _active_of(lam)
    extend_rows(work, cw, geometry, law)
    fill_columns(act, cw, geometry, law)
    rows = np.nonzero(work)[0]
    trial = _TrialPoint(lam_t, d_t, phi_t, da_t, db_t)
    _free_displacements(lam, act, dfree, Zt, friction, d, rows)
    LU, piv, lu_ok = LU0, piv0, lu_ok0
    if lu_ok and act.shape[0] > 0:
        _active_correction(lam, act, Mblk, Wt, d, rows, LU, piv)
    merit, err = _residual(lam, d, c, kappa, phi, da, db, work, natural)
    hist = np.zeros(_NONMONOTONE)
    hist[0] = merit
    best = merit
    it_best = 0
    for it in range(1, maxit + 1):
        if it == 1 and err < tol:
            tol = tight
        if err < tol:
            _complete_displacements(lam, d, work, lu_ok, dfree, geometry, law)
            return ContactResult(lam, d, True, it - 1, err), LU, piv, lu_ok, False
        if natural and it - it_best > _NATURAL_STALL:
            return ContactResult(lam, d, False, it - 1, err), LU, piv, lu_ok, True
        # reduced set: rows with db != 0, lam > 0 or phi != 0
        nR = 0
        for k in range(M):
            if db[k] != 0.0 or lam[k] > 0.0 or phi[k] != 0.0:
                nR += 1
        Rs = np.empty(nR, dtype=np.int64)
        i = 0
        for k in range(M):
            if db[k] != 0.0 or lam[k] > 0.0 or phi[k] != 0.0:
                Rs[i] = k
                i += 1
        fill_columns(Rs, cw, geometry, law)
        # Only the projection d_k . (dd_k / dlambda) enters the Newton matrix, so the derivative
        # D = C - W_(:, a) L_a S^-1 C_a (C[:, l] = Z[:, l] - W[:, l-block] M_l d_l) is formed
        # projected on d_k for the rows of R, and in full only for the active rows (C_a).
        E = np.empty((nR, 2))
        for jj in range(nR):
            l = Rs[jj]
            E[jj, 0] = Mblk[l, 0, 0] * d[l, 0] + Mblk[l, 0, 1] * d[l, 1]
            E[jj, 1] = Mblk[l, 1, 0] * d[l, 0] + Mblk[l, 1, 1] * d[l, 1]
        # Active rows: D_a = C_a - W_aa L_a S^-1 C_a = S^-1 C_a (S = I + W_aa L_a). Other rows:
        # d_k^T D_k = d_k^T C_k - (d_k^T W_(k, a) L_a) S^-1 C_a, the last factor a BLAS product.
        n_act = act.shape[0]
        slot = np.full(nR, -1, dtype=np.int64)
        if n_act > 0:
            ia = 0
            for ii in range(nR):
                if ia < n_act and Rs[ii] == act[ia]:
                    slot[ii] = ia
                    ia += 1
        Dp = np.empty((nR, nR))
        CaT = np.empty((nR, 2 * n_act))   # (S^-1 C_a)^T
        if n_act > 0:
            for jj in range(nR):
                l = Rs[jj]
                for i in range(n_act):
                    k = act[i]
                    for q in range(2):
                        CaT[jj, 2 * i + q] = _c_entry(Wt, Zt, 2 * k + q, l, E[jj, 0], E[jj, 1], friction)
            lu_solve_matrix(LU, piv, CaT)
        n_free = nR - n_act
        free = np.empty(n_free, dtype=np.int64)
        m = 0
        for ii in range(nR):
            k = Rs[ii]
            ia = slot[ii]
            if ia >= 0:
                for jj in range(nR):
                    Dp[ii, jj] = d[k, 0] * CaT[jj, 2 * ia] + d[k, 1] * CaT[jj, 2 * ia + 1]
            else:
                free[m] = ii
                m += 1
        for jj in range(nR):
            l = Rs[jj]
            for f in range(n_free):
                ii = free[f]
                k = Rs[ii]
                Dp[ii, jj] = (d[k, 0] * _c_entry(Wt, Zt, 2 * k, l, E[jj, 0], E[jj, 1], friction)
                              + d[k, 1] * _c_entry(Wt, Zt, 2 * k + 1, l, E[jj, 0], E[jj, 1], friction))
        if n_act > 0 and n_free > 0:
            # Pw[f, :] = d_k^T W_(k, a) L_a (L_a = blockdiag(lambda_l M_l)) for the free rows
            Pw = np.empty((n_free, 2 * n_act))
            for i in range(n_act):
                l = act[i]
                lj = lam[l]
                for f in range(n_free):
                    k = Rs[free[f]]
                    dk0 = d[k, 0]
                    dk1 = d[k, 1]
                    w0 = dk0 * Wt[2 * l, 2 * k] + dk1 * Wt[2 * l, 2 * k + 1]
                    w1 = dk0 * Wt[2 * l + 1, 2 * k] + dk1 * Wt[2 * l + 1, 2 * k + 1]
                    Pw[f, 2 * i] = lj * (w0 * Mblk[l, 0, 0] + w1 * Mblk[l, 1, 0])
                    Pw[f, 2 * i + 1] = lj * (w0 * Mblk[l, 0, 1] + w1 * Mblk[l, 1, 1])
            G = Pw @ CaT.T
            for f in range(n_free):
                ii = free[f]
                for jj in range(nR):
                    Dp[ii, jj] -= G[f, jj]
        # J_RR = diag(da c) + db kappa c dgap,
        # dgap[k, l] = d(c_k / |d_k|) / d lambda_l = -c_k d_k . D[k, l] / |d_k|^3
        J = np.empty((nR, nR))
        rhs = np.empty(nR)
        for ii in range(nR):
            k = Rs[ii]
            nd = _offset_norm(d, c, k)
            f = -db[k] * kappa * c[k] * c[k] / (nd * nd * nd)
            for jj in range(nR):
                J[ii, jj] = f * Dp[ii, jj]
            J[ii, ii] += da[k] * c[k]
            rhs[ii] = -phi[k]
        Jc = J.copy()
        pJ = np.empty(nR, dtype=PIVOT_DTYPE)
        if lu_factor(J, pJ):
            lu_solve(J, pJ, rhs)
            stepR = rhs
        else:
            if not np.all(np.isfinite(Jc)):
                # a non-finite Newton matrix (LAPACK would print an error): no step possible;
                # the natural phase's result is discarded, so its displacements are not completed
                if not natural:
                    _complete_displacements(lam, d, work, lu_ok, dfree, geometry, law)
                return ContactResult(lam, d, False, it, err), LU, piv, lu_ok, natural
            rr = np.empty(nR)
            for ii in range(nR):
                rr[ii] = -phi[Rs[ii]]
            stepR = np.linalg.lstsq(Jc, rr)[0]
        # A full step that drives multipliers negative is projected, and the projected point is
        # usually not a descent point: the line search would then crawl towards the separation
        # with many short steps. Instead re-solve the Newton system with those contacts held at
        # lambda = 0 (their rows replaced by d lambda_k = -lambda_k), up to _SEPARATION_ROUNDS
        # times, and try the full step of that direction first. It is accepted only on the same
        # sufficient decrease of the merit; otherwise the usual backtracking on the Newton step.
        ref_merit = merit
        for q in range(_NONMONOTONE):
            if hist[q] > ref_merit:
                ref_merit = hist[q]
        accepted = False
        held = np.zeros(nR, dtype=np.bool_)
        direction = stepR.copy()
        for _round in range(_SEPARATION_ROUNDS):
            grew = False
            for ii in range(nR):
                if not held[ii] and lam[Rs[ii]] + direction[ii] < 0.0:
                    held[ii] = True
                    grew = True
            if not grew:
                break
            J2 = Jc.copy()
            rhs2 = np.empty(nR)
            for ii in range(nR):
                k = Rs[ii]
                if held[ii]:
                    for jj in range(nR):
                        J2[ii, jj] = 0.0
                    J2[ii, ii] = 1.0
                    rhs2[ii] = -lam[k]
                else:
                    rhs2[ii] = -phi[k]
            if not lu_factor(J2, pJ):
                break
            lu_solve(J2, pJ, rhs2)
            direction = rhs2
            fok_t, LU_t, piv_t, act_n, m_t, e_t = _trial(lam, Rs, direction, 1.0, dfree, geometry, law,
                                                         cw, work, rows, trial, natural)
            if fok_t and m_t <= (1.0 - 1e-4) * ref_merit:
                accepted = True
                break
        t = 1.0
        for _ in range(0 if accepted else 40):
            fok_t, LU_t, piv_t, act_n, m_t, e_t = _trial(lam, Rs, stepR, t, dfree, geometry, law, cw,
                                                         work, rows, trial, natural)
            if fok_t and m_t <= (1.0 - 1e-4 * t) * ref_merit:
                accepted = True
                break
            t *= 0.5
        if not accepted:
            if natural:
                # no descent for the natural residual's merit (a kink of min(a, b) or a nearly
                # singular set of gap rows; on the 8x8x8 grid 10 more solves failed
                # without a fallback)
                return ContactResult(lam, d, False, it, err), LU, piv, lu_ok, True
            _complete_displacements(lam, d, work, lu_ok, dfree, geometry, law)
            return ContactResult(lam, d, False, it, err), LU, piv, lu_ok, False
        lam[:] = lam_t
        d[:, :] = d_t
        phi[:] = phi_t
        da[:] = da_t
        db[:] = db_t
        merit = m_t
        err = e_t
        if natural and merit < best:   # the stall counter is read only in the natural phase
            best = merit
            it_best = it
        hist[it % _NONMONOTONE] = merit
        act = act_n
        LU = LU_t
        piv = piv_t
        lu_ok = True   # an accepted trial's factorization succeeded
    if natural and err >= tol:
        return ContactResult(lam, d, False, maxit, err), LU, piv, lu_ok, True
    _complete_displacements(lam, d, work, lu_ok, dfree, geometry, law)
    return ContactResult(lam, d, err < tol, maxit, err), LU, piv, lu_ok, False


@njit(cache=True)
def generalized_curvature(lam, d, geometry, law, uhat, out):
    """Fixed-point map u -> uhat + K^-1 (A^T phi + zt^T lam) of the outer loop (stationarity,
    Eqs. (34)-(36) and (41) of Ha, Fagogenis & Dupont 2019), in place into ``out``.

    phi_c = -lam_c M_c d_c; the force on the outer tube's centerline is B_c phi_c and minus that
    on the inner tube's; friction torques tau lam about each tube's tangent.

    Parameters
    ----------
    lam : ndarray, shape (M,)
        Contact multipliers [N/m].
    d : ndarray, shape (M, 2)
        Contact displacements [m] (read only where lam > 0).
    geometry : ContactGeometry
        Reads ``pair``, ``jo``, ``ji``, ``B``, ``R``, ``p``, ``Omega``, ``base``, ``kinv`` and
        ``node_off`` (``Pc``, ``H1``, ``H2``, ``F3`` are not used).
    law : ContactLaw
        Reads ``Mblk``, ``tq_out`` and ``tq_in``.
    uhat : ndarray, shape (S, 3)
        Precurvatures [1/m].
    out : ndarray, shape (S, 3)
        Output: the curvatures of the map [1/m].
    """
    _curvature_change(lam, d, geometry, law, bool(True), out)
    for k in range(out.shape[0]):
        for q in range(3):
            out[k, q] += uhat[k, q]


@njit(cache=True)
def _curvature_change(lam, d, geometry, law, with_forces, out):
    """K^-1 (A^T phi + zt^T lam) [1/m] into ``out`` (S, 3): the curvature change caused by the
    contact forces phi_c = -lam_c M_c d_c (zero if not ``with_forces``) and the friction torques
    (Eqs. (34)-(36), (41) of Ha, Fagogenis & Dupont 2019), by suffix sums of the forces and their
    moments along each tube (module docstring). Reads ``Omega``, ``base``, ``kinv`` and
    ``node_off`` from ``geometry``; d only where lam > 0."""
    Omega, base, kinv, node_off = geometry.Omega, geometry.base, geometry.kinv, geometry.node_off
    Mblk, tq_out, tq_in = law.Mblk, law.tq_out, law.tq_in
    B, jo, ji, R, p = geometry.B, geometry.jo, geometry.ji, geometry.R, geometry.p
    N = p.shape[0]
    n = node_off.shape[0] - 1
    Fn = np.zeros((N, 3))
    Tn = np.zeros((N, 3))   # p x f + tau t
    for c in range(lam.shape[0]):
        lc = lam[c]
        if lc == 0.0:
            continue
        f0 = 0.0
        f1 = 0.0
        if with_forces:
            f0 = -lc * (Mblk[c, 0, 0] * d[c, 0] + Mblk[c, 0, 1] * d[c, 1])
            f1 = -lc * (Mblk[c, 1, 0] * d[c, 0] + Mblk[c, 1, 1] * d[c, 1])
        for side in range(2):
            j = jo[c] if side == 0 else ji[c]
            s = 1.0 if side == 0 else -1.0
            tau = (tq_out[c] if side == 0 else tq_in[c]) * lc
            fx = s * (B[c, 0, 0] * f0 + B[c, 0, 1] * f1)
            fy = s * (B[c, 1, 0] * f0 + B[c, 1, 1] * f1)
            fz = s * (B[c, 2, 0] * f0 + B[c, 2, 1] * f1)
            Fn[j, 0] += fx
            Fn[j, 1] += fy
            Fn[j, 2] += fz
            Tn[j, 0] += p[j, 1] * fz - p[j, 2] * fy + tau * R[j, 0, 2]
            Tn[j, 1] += p[j, 2] * fx - p[j, 0] * fz + tau * R[j, 1, 2]
            Tn[j, 2] += p[j, 0] * fy - p[j, 1] * fx + tau * R[j, 2, 2]
    for t in range(n):
        j0 = node_off[t]
        k0 = j0 - t
        nseg = node_off[t + 1] - j0 - 1
        sf0 = 0.0
        sf1 = 0.0
        sf2 = 0.0
        st0 = 0.0
        st1 = 0.0
        st2 = 0.0
        for m in range(nseg - 1, -1, -1):
            j = j0 + m + 1
            sf0 += Fn[j, 0]
            sf1 += Fn[j, 1]
            sf2 += Fn[j, 2]
            st0 += Tn[j, 0]
            st1 += Tn[j, 1]
            st2 += Tn[j, 2]
            k = k0 + m
            for q in range(3):
                g = (base[k, 0, q] * sf0 + base[k, 1, q] * sf1 + base[k, 2, q] * sf2
                     + Omega[k, 0, q] * st0 + Omega[k, 1, q] * st1 + Omega[k, 2, q] * st2)
                out[k, q] = kinv[k, q] * g
