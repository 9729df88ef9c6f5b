"""Standard zero-clearance, torsionally compliant CTR kinematics.

All tubes share one centerline (Section II-A of Ha, Fagogenis & Dupont 2019; the model of its
refs [10] Dupont et al., IEEE T-RO 2010, and [11] Rucker et al., IEEE T-RO 2010). With a
twist-free common frame R(s) and tube angles psi_i(s) (tube i's material frame is
R Rz(psi_i)), no external load and piecewise-constant precurvature uhat_i:

    u_xy(s)      = sum_i k_i Rz(psi_i) uhat_i / sum_i k_i          (bending moment balance)
    psi_i''      = (k_(i,xy) / k_(i,z)) (u_xy x Rz(psi_i) uhat_i)   (torsion, Rucker Eq. (11))
    psi_i(beta_i) = alpha_i,  psi_i'(beta_i + L_i) = 0              (clamped base, free tip)

solved as a boundary-value problem by Newton shooting on the base torsions, with the
variational equations giving the exact shooting Jacobian. The sign of that Jacobian's
determinant and a multistart detect configurations with more than one equilibrium.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..constants import DISTINCT_EQUILIBRIUM_TWIST, PREDICTOR_STEP_FACTOR, PREDICTOR_TOL
from ..errors import ConvergenceError, ElasticInstabilityError
from ._chain_kernels import advance, chain_kinematics
from ._lie import rot_z
from .grid import build_grid
from .packed import pack_robot
from .results import Diagnostics, ModelSettings, StandardSolution

__all__ = ["solve_standard"]

_PREDICTOR_TOL = PREDICTOR_TOL  # module-level constant, frozen into the compiled code
_DISTINCT_TWIST = DISTINCT_EQUILIBRIUM_TWIST
# Newton shooting gives up a start when its residual has not fallen below _STALL_FACTOR times
# its best for _STALL_ITERATIONS iterations
_STALL_FACTOR = 0.9
_STALL_ITERATIONS = 20
# :func:`_shoot` takes the sign of the shooting-Jacobian determinant (the elastic-stability test)
# from the coarse predictor when |det| is at least this (J = d sigma(L) / d sigma0 is
# dimensionless; det = 1 without coupling); below, from a fine sweep with sensitivities.
# Measured on 9634 configurations (the Ha trajectory, the 8x8x8 grid and 3000
# random ones, Table II and VII robots): coarse and fine determinants differ by 8e-8 relative
# (median), 1.3e-5 (p99), 1.9e-3 at most, so above 0.05 the sign cannot differ.
_COARSE_DET_MIN = 0.05
# a multistart restart is abandoned once its coarse Newton iterate is within _RETURN_TWIST [rad]
# (max_i |d sigma_i| L_i) of an equilibrium already found and has at least halved its distance
# to them in the last iteration (_newton_core). Measured on the trajectory, 8x8x8 grid and 3000
# random configurations of both robots (15956 restarts): restarts that end at a distinct
# equilibrium never came closer than 0.124 rad to a known one; those that return reach
# 1e-2 rad one sweep before converging (quadratic convergence: ~0.09, 2e-4, 2e-10 rad)
_RETURN_TWIST = 1e-2
_RETURN_CONTRACTION = 0.5


@njit(cache=True, error_model="numpy", inline="always")
def _torsion_rhs(psi, sig, present, uh, kxy, ratio, ax, ay, dpsi, dsig):
    """Torsion ODE on one interval (module docstring; Rucker et al. 2010, Eq. (11)):
    (dpsi, dsig) = (sigma, (k_xy / k_z) u_xy x R_z(psi) uhat), in place. Leaves the rotated
    precurvatures R_z(psi_i) uhat_i of the tubes present (0 for the others) in ``ax``, ``ay``
    (n,) and returns (u_x, u_y, sum of k_xy) of the tubes present, for :func:`_sensitivity_rhs`."""
    n = psi.shape[0]
    ksum = 0.0
    ucx = 0.0
    ucy = 0.0
    for i in range(n):
        if present[i]:
            c = np.cos(psi[i])
            s = np.sin(psi[i])
            x = c * uh[i, 0] - s * uh[i, 1]
            y = s * uh[i, 0] + c * uh[i, 1]
            ax[i] = x
            ay[i] = y
            ksum += kxy[i]
            ucx += kxy[i] * x
            ucy += kxy[i] * y
        else:
            ax[i] = 0.0     # not used: absent tubes carry no torsion
            ay[i] = 0.0
    if ksum > 0.0:
        ucx /= ksum
        ucy /= ksum
    for i in range(n):
        if present[i]:
            dpsi[i] = sig[i]
            dsig[i] = ratio[i] * (ucx * ay[i] - ucy * ax[i])
        else:
            dpsi[i] = 0.0
            dsig[i] = 0.0
    return ucx, ucy, ksum


@njit(cache=True, error_model="numpy", inline="always")
def _sensitivity_rhs(Sp, Ss, present, kxy, ratio, ax, ay, ucx, ucy, ksum, dSp, dSs):
    """Variational equations of the torsion ODE, d/d sigma0 of (psi, sigma) (n, m), in place,
    from the quantities :func:`_torsion_rhs` left (d u_c / d psi_j = k_j rot90(a_j) / ksum)."""
    n = Sp.shape[0]
    for q in range(Sp.shape[1]):
        ducx = 0.0
        ducy = 0.0
        for j in range(n):
            if present[j]:
                w = kxy[j] / ksum
                ducx += w * (-ay[j]) * Sp[j, q]
                ducy += w * ax[j] * Sp[j, q]
        for i in range(n):
            if present[i]:
                dSp[i, q] = Ss[i, q]
                dax = -ay[i] * Sp[i, q]
                day = ax[i] * Sp[i, q]
                dSs[i, q] = ratio[i] * (ducx * ay[i] - ducy * ax[i] + ucx * day - ucy * dax)
            else:
                dSp[i, q] = 0.0
                dSs[i, q] = 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _stage(x, k, f, out):
    """RK4 stage input ``out = x + f k``, shape (n,)."""
    for i in range(x.shape[0]):
        out[i] = x[i] + f * k[i]


@njit(cache=True, error_model="numpy", inline="always")
def _stage2(x, k, f, out):
    """RK4 stage input ``out = x + f k``, shape (n, m)."""
    for i in range(x.shape[0]):
        for q in range(x.shape[1]):
            out[i, q] = x[i, q] + f * k[i, q]


@njit(cache=True, error_model="numpy", inline="always")
def _combine(x, k1, k2, k3, k4, f):
    """RK4 update ``x += f (k1 + 2 k2 + 2 k3 + k4)`` in place, shape (n,)."""
    for i in range(x.shape[0]):
        x[i] = x[i] + f * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True, error_model="numpy", inline="always")
def _combine2(x, k1, k2, k3, k4, f):
    """RK4 update ``x += f (k1 + 2 k2 + 2 k3 + k4)`` in place, shape (n, m)."""
    for i in range(x.shape[0]):
        for q in range(x.shape[1]):
            x[i, q] = x[i, q] + f * (k1[i, q] + 2.0 * k2[i, q] + 2.0 * k3[i, q] + k4[i, q])


@njit(cache=True, error_model="numpy", inline="always")
def _stages(psi, sig, Sp, Ss, kp, ks, Kp, Ks, f, tp, ts, TP, TS):
    """RK4 stage inputs of the state and its sensitivities: (tp, ts, TP, TS) = (psi, sig, Sp,
    Ss) + f (kp, ks, Kp, Ks)."""
    _stage(psi, kp, f, tp)
    _stage(sig, ks, f, ts)
    _stage2(Sp, Kp, f, TP)
    _stage2(Ss, Ks, f, TS)


@njit(cache=True, error_model="numpy", inline="always")
def _both_rhs(psi, sig, Sp, Ss, present, uh, kxy, ratio, ax, ay, dpsi, dsig, dSp, dSs):
    """Torsion ODE and its variational equations at one stage (in place)."""
    ucx, ucy, ks = _torsion_rhs(psi, sig, present, uh, kxy, ratio, ax, ay, dpsi, dsig)
    _sensitivity_rhs(Sp, Ss, present, kxy, ratio, ax, ay, ucx, ucy, ks, dSp, dSs)


@njit(cache=True, error_model="numpy", inline="always")
def _pair_coefficients(pr, u, kxy, ratio):
    """Coefficients of the pairwise torsion ODE of :func:`_integrate3` on one interval: masks
    m_i (1.0 where tube i is present), direction differences c_ij = phi_j - phi_i [rad] and
    b_ij = (k_(i,xy) / k_(i,z)) k_(j,xy) |uhat_i| |uhat_j| / sum k_xy [1/m^2] (0 with tube i or
    j absent), as (m0, m1, m2, c01, c02, c12, a01, a10, a02, a20, a12, a21) with a_ij = b_ij."""
    m0 = 1.0 if pr[0] else 0.0
    m1 = 1.0 if pr[1] else 0.0
    m2 = 1.0 if pr[2] else 0.0
    ksum = m0 * kxy[0] + m1 * kxy[1] + m2 * kxy[2]
    w = 1.0 / ksum if ksum > 0.0 else 0.0
    n0 = np.hypot(u[0, 0], u[0, 1]) * m0
    n1 = np.hypot(u[1, 0], u[1, 1]) * m1
    n2 = np.hypot(u[2, 0], u[2, 1]) * m2
    f0 = np.arctan2(u[0, 1], u[0, 0])
    f1 = np.arctan2(u[1, 1], u[1, 0])
    f2 = np.arctan2(u[2, 1], u[2, 0])
    return (m0, m1, m2, f1 - f0, f2 - f0, f2 - f1,
            ratio[0] * kxy[1] * n0 * n1 * w, ratio[1] * kxy[0] * n0 * n1 * w,
            ratio[0] * kxy[2] * n0 * n2 * w, ratio[2] * kxy[0] * n0 * n2 * w,
            ratio[1] * kxy[2] * n1 * n2 * w, ratio[2] * kxy[1] * n1 * n2 * w)


@njit(cache=True, error_model="numpy", inline="always")
def _same_interval_data(present, uh, j, last):
    """Intervals ``j`` and ``last`` have the same tubes present and the same precurvatures."""
    for i in range(3):
        if present[j, i] != present[last, i] or uh[j, i, 0] != uh[last, i, 0] or uh[j, i, 1] != uh[last, i, 1]:
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _pair_rates(p0, p1, p2, c01, c02, c12, a01, a10, a02, a20, a12, a21):
    """Torsion rates dsigma_i of three tubes in the pairwise form of :func:`_integrate3`."""
    s01 = np.sin(p1 - p0 + c01) if a01 != 0.0 or a10 != 0.0 else 0.0
    s02 = np.sin(p2 - p0 + c02) if a02 != 0.0 or a20 != 0.0 else 0.0
    s12 = np.sin(p2 - p1 + c12) if a12 != 0.0 or a21 != 0.0 else 0.0
    return -a01 * s01 - a02 * s02, a10 * s01 - a12 * s12, a20 * s02 + a21 * s12


@njit(cache=True, error_model="numpy", inline="always")
def _record_node(rec_psi, rec_sig, rec_dsig, j, p0, p1, p2, q0, q1, q2, e0, e1, e2):
    """Node ``j`` of the three-tube sweeps' records: psi, sigma and sigma' (3,) each."""
    rec_psi[j, 0] = p0
    rec_psi[j, 1] = p1
    rec_psi[j, 2] = p2
    rec_sig[j, 0] = q0
    rec_sig[j, 1] = q1
    rec_sig[j, 2] = q2
    rec_dsig[j, 0] = e0
    rec_dsig[j, 1] = e1
    rec_dsig[j, 2] = e2


@njit(cache=True, error_model="numpy", inline="always")
def _vector3(x0, x1, x2):
    """The array (x0, x1, x2)."""
    v = np.empty(3)
    v[0] = x0
    v[1] = x1
    v[2] = x2
    return v


@njit(cache=True, error_model="numpy")
def _integrate3(s, present, uh, kxy, ratio, psi0, sig0, record):
    """:func:`_integrate` without sensitivities for three tubes, in the pairwise form of the
    torsion ODE: with uhat_i = |uhat_i| (cos phi_i, sin phi_i) and theta_i = psi_i + phi_i,

        sigma_i' = (k_(i,xy) / k_(i,z)) sum_j k_(j,xy) |uhat_i| |uhat_j| sin(theta_i - theta_j)
                   / sum_l k_(l,xy)

    (the same right-hand side: u_xy x R_z(psi_i) uhat_i expanded over the tubes), so each RK4
    stage takes three sines of angle differences instead of a sine and a cosine per tube, and
    the state lives in scalars. The per-interval coefficients are recomputed only where the
    precurvatures or the tubes present change. Same RK4 steps and node records as
    :func:`_integrate_general`; the results agree to rounding, not bitwise (psi within 1.1e-15
    rad and sigma within 2.2e-15 1/m on the Ha trajectory's fine and coarse grids, every 7th row).
    One sweep on the fine grids (Table II robot, CPU time, median of 7 runs, load 0.3-0.5):
    33.7 us against 64.0 us for the general loop; with sensitivities
    (:func:`_integrate3_sens`) 57.5 against 132.5 us.

    Returns what :func:`_integrate_general` returns with ``with_sens`` False.
    """
    n = 3
    G = s.shape[0]
    rec_psi = np.zeros((G if record else 1, n))
    rec_sig = np.zeros((G if record else 1, n))
    rec_dsig = np.zeros((G if record else 1, n))
    p0 = psi0[0]
    p1 = psi0[1]
    p2 = psi0[2]
    q0 = sig0[0]
    q1 = sig0[1]
    q2 = sig0[2]
    m0 = m1 = m2 = 0.0
    c01 = c02 = c12 = 0.0
    a01 = a10 = a02 = a20 = a12 = a21 = 0.0
    last = -1
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        if last < 0 or not _same_interval_data(present, uh, j, last):
            m0, m1, m2, c01, c02, c12, a01, a10, a02, a20, a12, a21 = _pair_coefficients(present[j], uh[j], kxy,
                                                                                          ratio)
            last = j
        hh = 0.5 * h
        e10, e11, e12 = _pair_rates(p0, p1, p2, c01, c02, c12, a01, a10, a02, a20, a12, a21)
        if record:
            _record_node(rec_psi, rec_sig, rec_dsig, j, p0, p1, p2, q0, q1, q2, e10, e11, e12)
        # stage k: psi rates (r) and sigma rates (e); tubes not present keep psi and sigma
        e20, e21, e22 = _pair_rates(p0 + hh * q0 * m0, p1 + hh * q1 * m1, p2 + hh * q2 * m2,
                                    c01, c02, c12, a01, a10, a02, a20, a12, a21)
        r20 = q0 + hh * e10
        r21 = q1 + hh * e11
        r22 = q2 + hh * e12
        e30, e31, e32 = _pair_rates(p0 + hh * r20 * m0, p1 + hh * r21 * m1, p2 + hh * r22 * m2,
                                    c01, c02, c12, a01, a10, a02, a20, a12, a21)
        r30 = q0 + hh * e20
        r31 = q1 + hh * e21
        r32 = q2 + hh * e22
        e40, e41, e42 = _pair_rates(p0 + h * r30 * m0, p1 + h * r31 * m1, p2 + h * r32 * m2,
                                    c01, c02, c12, a01, a10, a02, a20, a12, a21)
        r40 = q0 + h * e30
        r41 = q1 + h * e31
        r42 = q2 + h * e32
        f = h / 6.0
        p0 += m0 * f * (q0 + 2.0 * r20 + 2.0 * r30 + r40)
        p1 += m1 * f * (q1 + 2.0 * r21 + 2.0 * r31 + r41)
        p2 += m2 * f * (q2 + 2.0 * r22 + 2.0 * r32 + r42)
        q0 += m0 * f * (e10 + 2.0 * e20 + 2.0 * e30 + e40)
        q1 += m1 * f * (e11 + 2.0 * e21 + 2.0 * e31 + e41)
        q2 += m2 * f * (e12 + 2.0 * e22 + 2.0 * e32 + e42)
    if record:
        # derivative at the last node, evaluated with the last interval's data
        e10, e11, e12 = _pair_rates(p0, p1, p2, c01, c02, c12, a01, a10, a02, a20, a12, a21)
        _record_node(rec_psi, rec_sig, rec_dsig, G - 1, p0, p1, p2, q0, q1, q2, e10, e11, e12)
    psi = _vector3(p0, p1, p2)
    sig = _vector3(q0, q1, q2)
    return psi, sig, np.zeros((n, 0)), np.zeros((n, 0)), rec_psi, rec_sig, rec_dsig


@njit(cache=True, error_model="numpy", inline="always")
def _pair_jacobian_apply(p0, p1, p2, c01, c02, c12, a01, a10, a02, a20, a12, a21, S, out):
    """out = (d sigma' / d psi) S for the pairwise form of :func:`_integrate3`, S and out (3, 3):
    with C_ij = cos(theta_j - theta_i), row 0 is a01 C01 (S0 - S1) + a02 C02 (S0 - S2), row 1
    -a10 C01 (S0 - S1) + a12 C12 (S1 - S2), row 2 -a20 C02 (S0 - S2) - a21 C12 (S1 - S2)."""
    g01 = np.cos(p1 - p0 + c01) if a01 != 0.0 or a10 != 0.0 else 0.0
    g02 = np.cos(p2 - p0 + c02) if a02 != 0.0 or a20 != 0.0 else 0.0
    g12 = np.cos(p2 - p1 + c12) if a12 != 0.0 or a21 != 0.0 else 0.0
    for q in range(3):
        d01 = S[0, q] - S[1, q]
        d02 = S[0, q] - S[2, q]
        d12 = S[1, q] - S[2, q]
        out[0, q] = a01 * g01 * d01 + a02 * g02 * d02
        out[1, q] = a12 * g12 * d12 - a10 * g01 * d01
        out[2, q] = -a20 * g02 * d02 - a21 * g12 * d12


@njit(cache=True, error_model="numpy", inline="always")
def _sens_stage(Sp, Ss, m0, m1, m2, f, g, K, T):
    """RK4 stage input of the position sensitivities, T = Sp + f m (Ss + g K) (3, 3): Sp's
    rates are m Ss (rows of absent tubes stay), and Ss at the stage is Ss + g K."""
    for q in range(3):
        T[0, q] = Sp[0, q] + f * m0 * (Ss[0, q] + g * K[0, q])
        T[1, q] = Sp[1, q] + f * m1 * (Ss[1, q] + g * K[1, q])
        T[2, q] = Sp[2, q] + f * m2 * (Ss[2, q] + g * K[2, q])


@njit(cache=True, error_model="numpy")
def _integrate3_sens(s, present, uh, kxy, ratio, psi0, sig0, record):
    """:func:`_integrate3` with the variational equations: d(psi, sigma) / d sigma0 (3, 3) by
    the same RK4 steps, with the Jacobian of the pairwise form
    (:func:`_pair_jacobian_apply`; three cosines of angle differences per stage). Agrees with
    :func:`_integrate_general` to rounding.

    Returns what :func:`_integrate_general` returns with ``with_sens`` True.
    """
    G = s.shape[0]
    rec_psi = np.zeros((G if record else 1, 3))
    rec_sig = np.zeros((G if record else 1, 3))
    rec_dsig = np.zeros((G if record else 1, 3))
    p0 = psi0[0]
    p1 = psi0[1]
    p2 = psi0[2]
    q0 = sig0[0]
    q1 = sig0[1]
    q2 = sig0[2]
    Sp = np.zeros((3, 3))
    Ss = np.eye(3)
    T = np.empty((3, 3))
    K1 = np.empty((3, 3))
    K2 = np.empty((3, 3))
    K3 = np.empty((3, 3))
    K4 = np.empty((3, 3))
    m0 = m1 = m2 = 0.0
    c01 = c02 = c12 = 0.0
    a01 = a10 = a02 = a20 = a12 = a21 = 0.0
    last = -1
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        if last < 0 or not _same_interval_data(present, uh, j, last):
            m0, m1, m2, c01, c02, c12, a01, a10, a02, a20, a12, a21 = _pair_coefficients(present[j], uh[j], kxy,
                                                                                          ratio)
            last = j
        hh = 0.5 * h
        e10, e11, e12 = _pair_rates(p0, p1, p2, c01, c02, c12, a01, a10, a02, a20, a12, a21)
        if record:
            _record_node(rec_psi, rec_sig, rec_dsig, j, p0, p1, p2, q0, q1, q2, e10, e11, e12)
        # sensitivities: Sp' = m Ss (rows of absent tubes stay), Ss' = (d sigma' / d psi) Sp;
        # the stage-k rates of Sp are m (Ss + f K_(k-1)), so only K_k (the Ss rates) are kept
        _pair_jacobian_apply(p0, p1, p2, c01, c02, c12, a01, a10, a02, a20, a12, a21, Sp, K1)
        t0 = p0 + hh * q0 * m0
        t1 = p1 + hh * q1 * m1
        t2 = p2 + hh * q2 * m2
        e20, e21, e22 = _pair_rates(t0, t1, t2, c01, c02, c12, a01, a10, a02, a20, a12, a21)
        _sens_stage(Sp, Ss, m0, m1, m2, hh, 0.0, K1, T)
        _pair_jacobian_apply(t0, t1, t2, c01, c02, c12, a01, a10, a02, a20, a12, a21, T, K2)
        r20 = q0 + hh * e10
        r21 = q1 + hh * e11
        r22 = q2 + hh * e12
        t0 = p0 + hh * r20 * m0
        t1 = p1 + hh * r21 * m1
        t2 = p2 + hh * r22 * m2
        e30, e31, e32 = _pair_rates(t0, t1, t2, c01, c02, c12, a01, a10, a02, a20, a12, a21)
        _sens_stage(Sp, Ss, m0, m1, m2, hh, hh, K1, T)
        _pair_jacobian_apply(t0, t1, t2, c01, c02, c12, a01, a10, a02, a20, a12, a21, T, K3)
        r30 = q0 + hh * e20
        r31 = q1 + hh * e21
        r32 = q2 + hh * e22
        t0 = p0 + h * r30 * m0
        t1 = p1 + h * r31 * m1
        t2 = p2 + h * r32 * m2
        e40, e41, e42 = _pair_rates(t0, t1, t2, c01, c02, c12, a01, a10, a02, a20, a12, a21)
        _sens_stage(Sp, Ss, m0, m1, m2, h, hh, K2, T)
        _pair_jacobian_apply(t0, t1, t2, c01, c02, c12, a01, a10, a02, a20, a12, a21, T, K4)
        r40 = q0 + h * e30
        r41 = q1 + h * e31
        r42 = q2 + h * e32
        f = h / 6.0
        p0 += m0 * f * (q0 + 2.0 * r20 + 2.0 * r30 + r40)
        p1 += m1 * f * (q1 + 2.0 * r21 + 2.0 * r31 + r41)
        p2 += m2 * f * (q2 + 2.0 * r22 + 2.0 * r32 + r42)
        q0 += m0 * f * (e10 + 2.0 * e20 + 2.0 * e30 + e40)
        q1 += m1 * f * (e11 + 2.0 * e21 + 2.0 * e31 + e41)
        q2 += m2 * f * (e12 + 2.0 * e22 + 2.0 * e32 + e42)
        # Sp rates: m Ss, m (Ss + hh K1), m (Ss + hh K2), m (Ss + h K3)
        for q in range(3):
            Sp[0, q] += m0 * f * (6.0 * Ss[0, q] + h * (K1[0, q] + K2[0, q] + K3[0, q]))
            Sp[1, q] += m1 * f * (6.0 * Ss[1, q] + h * (K1[1, q] + K2[1, q] + K3[1, q]))
            Sp[2, q] += m2 * f * (6.0 * Ss[2, q] + h * (K1[2, q] + K2[2, q] + K3[2, q]))
        for i in range(3):
            for q in range(3):
                Ss[i, q] += f * (K1[i, q] + 2.0 * K2[i, q] + 2.0 * K3[i, q] + K4[i, q])
    if record:
        e10, e11, e12 = _pair_rates(p0, p1, p2, c01, c02, c12, a01, a10, a02, a20, a12, a21)
        _record_node(rec_psi, rec_sig, rec_dsig, G - 1, p0, p1, p2, q0, q1, q2, e10, e11, e12)
    psi = _vector3(p0, p1, p2)
    sig = _vector3(q0, q1, q2)
    return psi, sig, Sp, Ss, rec_psi, rec_sig, rec_dsig


@njit(cache=True, error_model="numpy", inline="always")
def _integrate(s, present, uh, kxy, ratio, psi0, sig0, record, with_sens):
    """Classical RK4 over the grid intervals, one step per interval: the three-tube kernels
    (:func:`_integrate3`, :func:`_integrate3_sens`) for three tubes, else the general loop
    (:func:`_integrate_general`). Returns what :func:`_integrate_general` returns."""
    # bool(...) passes the flags as run-time values, not literals: numba compiles one
    # specialization of each kernel instead of one per literal combination (compile time)
    if psi0.shape[0] == 3:
        if with_sens:
            return _integrate3_sens(s, present, uh, kxy, ratio, psi0, sig0, bool(record))
        return _integrate3(s, present, uh, kxy, ratio, psi0, sig0, bool(record))
    return _integrate_general(s, present, uh, kxy, ratio, psi0, sig0, bool(record), bool(with_sens))


@njit(cache=True, error_model="numpy")
def _integrate_general(s, present, uh, kxy, ratio, psi0, sig0, record, with_sens):
    """Classical RK4 over the grid intervals for any number of tubes, one step per interval
    (allocation-free inner loop).

    The torsion ODE and its variational equations are separate inline kernels. The earlier
    form (one right-hand side for both, with shared work arrays) took 80-85 us per sweep with
    sensitivities on the Table II robot at ds = 3 mm (uniform grid); this one takes 32-42 us,
    with bitwise-identical results. Without sensitivities (m = 0) the same loop runs with empty
    sensitivity loops: 30 us against 51 us with them on the graded grid (a separate loop for it
    took 71 us).

    Returns final psi, sigma, sensitivities d(psi, sigma)/d sigma0 (n, n; (n, 0) without), and,
    when ``record``, psi, sigma and sigma' at every node.
    """
    n = psi0.shape[0]
    G = s.shape[0]
    m = n if with_sens else 0
    psi = psi0.copy()
    sig = sig0.copy()
    Sp = np.zeros((n, m))
    Ss = np.zeros((n, m))
    for i in range(m):
        Ss[i, i] = 1.0
    rec_psi = np.zeros((G if record else 1, n))
    rec_sig = np.zeros((G if record else 1, n))
    rec_dsig = np.zeros((G if record else 1, n))
    k1p = np.empty(n); k1s = np.empty(n); k2p = np.empty(n); k2s = np.empty(n)
    k3p = np.empty(n); k3s = np.empty(n); k4p = np.empty(n); k4s = np.empty(n)
    K1p = np.empty((n, m)); K1s = np.empty((n, m)); K2p = np.empty((n, m)); K2s = np.empty((n, m))
    K3p = np.empty((n, m)); K3s = np.empty((n, m)); K4p = np.empty((n, m)); K4s = np.empty((n, m))
    tp = np.empty(n); ts = np.empty(n); TP = np.empty((n, m)); TS = np.empty((n, m))
    ax = np.empty(n); ay = np.empty(n)
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        pr = present[j]
        u = uh[j]
        ucx, ucy, ks = _torsion_rhs(psi, sig, pr, u, kxy, ratio, ax, ay, k1p, k1s)
        if record:
            for i in range(n):
                rec_psi[j, i] = psi[i]
                rec_sig[j, i] = sig[i]
                rec_dsig[j, i] = k1s[i]
        # one loop for both sweeps: without sensitivities (m = 0) their loops are empty. A
        # separate loop for the sweep without them took 71 us instead of 30 (ds = 3 mm, graded)
        _sensitivity_rhs(Sp, Ss, pr, kxy, ratio, ax, ay, ucx, ucy, ks, K1p, K1s)
        _stages(psi, sig, Sp, Ss, k1p, k1s, K1p, K1s, 0.5 * h, tp, ts, TP, TS)
        _both_rhs(tp, ts, TP, TS, pr, u, kxy, ratio, ax, ay, k2p, k2s, K2p, K2s)
        _stages(psi, sig, Sp, Ss, k2p, k2s, K2p, K2s, 0.5 * h, tp, ts, TP, TS)
        _both_rhs(tp, ts, TP, TS, pr, u, kxy, ratio, ax, ay, k3p, k3s, K3p, K3s)
        _stages(psi, sig, Sp, Ss, k3p, k3s, K3p, K3s, h, tp, ts, TP, TS)
        _both_rhs(tp, ts, TP, TS, pr, u, kxy, ratio, ax, ay, k4p, k4s, K4p, K4s)
        f = h / 6.0
        _combine(psi, k1p, k2p, k3p, k4p, f)
        _combine(sig, k1s, k2s, k3s, k4s, f)
        _combine2(Sp, K1p, K2p, K3p, K4p, f)
        _combine2(Ss, K1s, K2s, K3s, K4s, f)
        if record and j == G - 2:
            # derivative at the last node, evaluated with the last interval's data
            _torsion_rhs(psi, sig, pr, u, kxy, ratio, ax, ay, k1p, k1s)
            for i in range(n):
                rec_psi[G - 1, i] = psi[i]
                rec_sig[G - 1, i] = sig[i]
                rec_dsig[G - 1, i] = k1s[i]
    return psi, sig, Sp, Ss, rec_psi, rec_sig, rec_dsig


class _Problem:
    """Pre-processed data of one configuration for the shooting method."""

    def __init__(self, robot, alpha, beta, settings):
        self.robot = robot
        self.alpha = np.asarray(alpha, dtype=float)
        self.beta = np.asarray(beta, dtype=float)
        self.grid = build_grid(robot, self.beta, settings.ds, settings.refine_ratio, settings.refine_length)
        self.settings = settings
        self._coarse = None
        packed = pack_robot(robot)
        self.kxy = packed.k_xy
        self.ratio = packed.stiffness_ratio
        self.lengths = packed.lengths

    def newton(self, sig0, settings, predict=False):
        """Newton shooting on the base torsions (``predict``: from the coarse-grid solution, see
        :func:`_shoot`); returns (sig0, residual norm, iterations, ok, detJ, (psi, sigma)) with
        the node angles and torsions (G, n) of the evaluation at sig0."""
        g = self.grid
        c = self._coarse_grid() if predict else g   # the coarse grid is read only when predicting
        sig0, res, it, ok, detJ, psi, sig = _shoot(
            g.s, g.present, g.precurvature, c.s, c.present, c.precurvature, self.kxy, self.ratio,
            self.alpha, np.asarray(sig0, dtype=float), self.lengths, float(settings.shooting_tol),
            int(settings.max_shooting_iterations), bool(predict))
        return sig0, res, it, ok, detJ, (psi, sig)

    def _coarse_grid(self):
        """The predictor's grid (``PREDICTOR_STEP_FACTOR`` times the step), built on first use."""
        if self._coarse is None:
            st = self.settings
            self._coarse = build_grid(self.robot, self.beta, PREDICTOR_STEP_FACTOR * st.ds, st.refine_ratio,
                                      st.refine_length)
        return self._coarse


@njit(cache=True, error_model="numpy")
def _solve_small(J, r):
    """(det J, J^-1 r) for the small shooting Jacobian J (n, n) and r (n,), by Gaussian
    elimination with partial pivoting (x is NaN where J is singular). Replaces
    ``np.linalg.det`` and ``np.linalg.solve``, whose LAPACK calls with their copies took
    about 0.5 us for n = 3 against 0.05 us here (a followed row of the batch takes
    five or six)."""
    n = r.shape[0]
    A = J.copy()
    x = r.copy()
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
            t = x[k]
            x[k] = x[p]
            x[p] = t
        piv = A[k, k]
        det *= piv
        if piv == 0.0:
            x[:] = np.nan
            return det, x
        for i in range(k + 1, n):
            f = A[i, k] / piv
            for c in range(k + 1, n):
                A[i, c] -= f * A[k, c]
            x[i] -= f * x[k]
    for k in range(n - 1, -1, -1):
        v = x[k]
        for c in range(k + 1, n):
            v -= A[k, c] * x[c]
        x[k] = v / A[k, k]
    return det, x


@njit(cache=True, error_model="numpy", inline="always")
def _damping(step, lengths):
    """Largest factor <= 1 by which a base-torsion step (n,) [1/m] can be taken without
    changing any base torsion by more than pi over its tube length ``lengths`` (n,) [m]."""
    scale = 1.0
    for i in range(step.shape[0]):
        if abs(step[i]) > 0.0:
            scale = min(scale, (np.pi / lengths[i]) / abs(step[i]))
    return scale


@njit(cache=True, error_model="numpy", inline="always")
def _newton(s, present, uh, kxy, ratio, alpha, sig0, lengths, tol, maxit, J_out):
    """Damped Newton shooting on the base torsions, compiled (:func:`_newton_core` with no
    known equilibria: the same iteration, arithmetic and results).

    Returns (sig0, residual, iterations, ok, detJ, psi, sigma) with the node angles and torsions
    (G, n) of the evaluation at the returned sig0; on convergence the shooting Jacobian there is
    copied into ``J_out`` (n, n).
    """
    # an empty writable array and int(0), the types _multistart_search passes: one compiled
    # specialization of _newton_core serves both
    x, res, it, ok, detJ, rp, rs, _ = _newton_core(s, present, uh, kxy, ratio, alpha, sig0, lengths, tol, maxit,
                                                   J_out, np.empty((0, sig0.shape[0])), int(0))
    return x, res, it, ok, detJ, rp, rs


@njit(cache=True, error_model="numpy")
def _newton_core(s, present, uh, kxy, ratio, alpha, sig0, lengths, tol, maxit, J_out, known, n_known):
    """Damped Newton shooting on the base torsions, compiled.

    Each iteration solves J step = r with the variational Jacobian J = d sigma(L) / d sigma0,
    limits every base-torsion change to pi over the tube length, and backtracks until the
    residual max|sigma(L)| decreases (Armijo factor 1e-4, 20 halvings at most). The full step is
    evaluated with sensitivities and node records, so an accepted full step is the next
    iteration's evaluation (one integration per iteration instead of two).

    Stops unconverged when the residual has not fallen below ``_STALL_FACTOR`` (0.9) times its
    best for ``_STALL_ITERATIONS`` (20) iterations.

    With ``n_known`` > 0 (the multistart search, :func:`_multistart_search`), also stops
    unconverged, flagged ``near``, once an iterate lies within ``_RETURN_TWIST`` (1e-2 rad) in
    twist (max_i |d sigma_i| L_i) of one of the first ``n_known`` rows of ``known`` (m, n)
    [1/m] and at most ``_RETURN_CONTRACTION`` (0.5) times as far from them as the iterate
    before (so never at the start): it is converging to an equilibrium already found.

    Returns (sig0, residual, iterations, ok, detJ, psi, sigma, near) with the node angles and
    torsions (G, n) of the evaluation at the returned sig0; on convergence the shooting
    Jacobian there is copied into ``J_out`` (n, n).
    """
    n = sig0.shape[0]
    x = sig0.copy()
    _, r, _, Ss, rp, rs, _ = _integrate(s, present, uh, kxy, ratio, alpha, x, True, True)
    res = np.max(np.abs(r))
    detJ = np.nan
    best = res
    best_it = 0
    d_prev = np.nan   # twist distance of the iterate before to the known equilibria (none yet)
    for it in range(1, maxit + 1):
        J = Ss[:, :n].copy()
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
            return x, np.inf, it, False, np.nan, rp, rs, False
        detJ, step = _solve_small(J, r)
        if res < tol:
            J_out[:, :] = J
            return x, res, it, True, detJ, rp, rs, False
        if n_known > 0:
            d = _nearest_twist(x, known, n_known, lengths)
            if d < _RETURN_TWIST and d <= _RETURN_CONTRACTION * d_prev:
                return x, res, it, False, detJ, rp, rs, True
            d_prev = d
        if res < _STALL_FACTOR * best:
            best = res
            best_it = it
        elif it - best_it > _STALL_ITERATIONS:
            # stalled (typically at a local minimum of the residual where J is singular):
            # give up this start, :func:`_shoot` tries others
            return x, res, it, False, detJ, rp, rs, False
        if not (abs(detJ) > 0.0 and np.all(np.isfinite(step))):
            step = np.linalg.lstsq(J, r)[0]
        scale = _damping(step, lengths)
        t = scale
        trial = x - t * step
        _, r_t, _, S_t, rp_t, rs_t, _ = _integrate(s, present, uh, kxy, ratio, alpha, trial, True, True)
        if np.all(np.isfinite(r_t)) and np.max(np.abs(r_t)) < (1.0 - 1e-4 * t) * res:
            x, r, Ss, rp, rs = trial, r_t, S_t, rp_t, rs_t
        else:
            accepted = False
            for _ in range(19):
                t *= 0.5
                trial = x - t * step
                _, r_t, _, _, _, _, _ = _integrate(s, present, uh, kxy, ratio, alpha, trial, False, False)
                if np.all(np.isfinite(r_t)) and np.max(np.abs(r_t)) < (1.0 - 1e-4 * t) * res:
                    accepted = True
                    break
            x = trial if accepted else x - scale * step
            _, r, _, Ss, rp, rs, _ = _integrate(s, present, uh, kxy, ratio, alpha, x, True, True)
        res = np.max(np.abs(r))
    detJ = _solve_small(Ss[:, :n].copy(), r)[0] if np.all(np.isfinite(Ss)) else np.nan
    ok = np.all(np.isfinite(r)) and res < tol
    if ok:
        J_out[:, :] = Ss[:, :n]
    return x, res if np.isfinite(res) else np.inf, maxit, ok, detJ, rp, rs, False


@njit(cache=True, error_model="numpy")
def _chord_step(s, present, uh, kxy, ratio, alpha, x, J, lengths):
    """One chord step x - J^-1 r(x) on the grid ``s`` with a given Jacobian ``J`` (the coarse
    predictor's at x), damped like a Newton step of :func:`_newton`; the sweep at x runs without
    sensitivities. From the predictor's solution this reaches the fine grid's shooting
    tolerance as often as the exact Newton step does (measured: 299 of 300 random
    configurations below 1e-9 1/m with either Jacobian; residual median 1e-14 after the step,
    4e-7 before), for a sweep of 30 instead of 51 us. Returns x unchanged if r or J is not
    usable."""
    _, r, _, _, _, _, _ = _integrate(s, present, uh, kxy, ratio, alpha, x, False, False)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        return x.copy()
    det, step = _solve_small(J, r)
    if not abs(det) > 0.0:
        return x.copy()
    return x - _damping(step, lengths) * step


@njit(cache=True, error_model="numpy")
def _shoot(s, present, uh, cs, cpresent, cuh, kxy, ratio, alpha, sig0, lengths, tol, maxit, predict):
    """Newton shooting on the grid ``s`` started from ``sig0``; with ``predict``, started instead
    from the solution on the coarser grid ``cs`` (``cpresent``, ``cuh``; same breakpoints,
    ``PREDICTOR_STEP_FACTOR`` times the step) found from ``sig0`` to ``PREDICTOR_TOL``, after
    one chord step on the fine grid with the predictor's Jacobian (:func:`_chord_step`). Falls
    back to ``sig0`` if either of those fails. With ``predict``, if that fails too, the same two
    stages restart from ``sig0`` plus pi / L_i of twist on each inner tube i, then minus (the
    multistart guesses of :func:`solve_standard`), until one converges: damped Newton can stall
    at a local minimum of the residual where the shooting Jacobian is singular (seen at
    alpha_3 - alpha_2 near 200 deg with the innermost tube retracted). Returns what
    :func:`_newton` returns for the last start, with the Newton iterations of all stages and
    starts in ``iterations``."""
    total = 0
    n = sig0.shape[0]
    Jc = np.empty((n, n))
    # starts: sig0, then (predict only) sig0 with +pi, then -pi, of extra twist on each inner tube
    n_starts = 1 + (2 * (n - 1) if predict else 0)
    for start in range(n_starts):
        g = sig0.copy()
        if start > 0:
            i = 1 + (start - 1) % (n - 1)
            g[i] += (1.0 if start <= n - 1 else -1.0) * np.pi / lengths[i]
        if predict:
            c0, _, cit, cok, c_det, _, _ = _newton(cs, cpresent, cuh, kxy, ratio, alpha, g, lengths,
                                                   max(tol, _PREDICTOR_TOL), maxit, Jc)
            total += cit
            if cok:
                x1 = _chord_step(s, present, uh, kxy, ratio, alpha, c0, Jc, lengths)
                total += 1
                if abs(c_det) >= _COARSE_DET_MIN:
                    # check x1 with a sweep without sensitivities (it records the node angles and
                    # torsions); the determinant's sign is the predictor's (see _COARSE_DET_MIN)
                    _, r1, _, _, psi, sig, _ = _integrate(s, present, uh, kxy, ratio, alpha, x1, True, False)
                    res = np.max(np.abs(r1))
                    if np.all(np.isfinite(r1)) and res < tol:
                        return x1, res, total + 1, True, c_det, psi, sig
                x, res, it, ok, detJ, psi, sig = _newton(s, present, uh, kxy, ratio, alpha, x1, lengths, tol, maxit,
                                                         Jc)
                total += it
                if ok:
                    return x, res, total, ok, detJ, psi, sig
        x, res, it, ok, detJ, psi, sig = _newton(s, present, uh, kxy, ratio, alpha, g, lengths, tol, maxit, Jc)
        total += it
        if ok:
            break
    return x, res, total, ok, detJ, psi, sig


@njit(cache=True, error_model="numpy")
def _multistart_search(s, present, uh, cs, cpresent, cuh, kxy, ratio, alpha, sig0, lengths, tol, maxit,
                       count):
    """Multistart search for other stable equilibria than the one at base torsions ``sig0``
    (n,) [1/m] on the grid ``s``: the first ``count`` of the guesses sig0 + pi / L_i, then
    sig0 - pi / L_i, of extra twist on each inner tube i (round-robin), each solved by damped
    Newton on the coarse grid ``cs`` (``cpresent``, ``cuh``: the predictor's grid) to the
    shooting tolerance ``tol``. A coarse solution with a positive shooting-Jacobian determinant
    whose base torsions differ from every equilibrium found so far by more than
    ``DISTINCT_EQUILIBRIUM_TWIST`` (in twist, |d sigma_i| L_i [rad]) is confirmed on the fine
    grid (one chord step with the coarse Jacobian, then Newton); only a fine solution that
    converges, is stable-looking (det > 0) and is distinct by the same test counts.

    The guesses are the ones the search has always used; only where they are solved changed: a coarse sweep costs about a quarter of a fine one, and a restart that returns
    to the known equilibrium, the usual case, needs no fine sweep at all. Measured against
    the all-fine search on the grids and trajectory of docs/mechanics.md, Sec. 2: the same
    configurations flagged.

    A restart whose coarse Newton iterate comes within ``_RETURN_TWIST`` (1e-2 rad) of an
    equilibrium found so far, at least halving its distance in one step, is abandoned
    (:func:`_newton_core`): it would converge there and be rejected as not distinct. This
    saves a third of the coarse iterations (one or two sweeps per restart); restarts that
    end at a distinct equilibrium came no closer than 0.124 rad to a known one on the 9638
    configurations of docs/mechanics.md, Sec. 2, and the same configurations are flagged.

    Returns (number of equilibria found, including the one at ``sig0``; Newton iterations).
    """
    n = sig0.shape[0]
    found = np.empty((1 + count, n))
    found[0] = sig0
    n_found = int(1)   # int(...): a run-time int64 from the start, so numba types the call below once
    its = 0
    Jc = np.empty((n, n))
    Jf = np.empty((n, n))
    for q in range(min(count, 2 * (n - 1))):
        i = 1 + q % (n - 1)
        g = sig0.copy()
        g[i] += (1.0 if q < n - 1 else -1.0) * np.pi / lengths[i]
        c_sig, _, c_it, c_ok, c_det, _, _, _ = _newton_core(cs, cpresent, cuh, kxy, ratio, alpha, g, lengths, tol,
                                                            maxit, Jc, found, n_found)
        its += c_it
        if not c_ok or not c_det > 0.0 or not _distinct(c_sig, found, n_found, lengths):
            continue
        x1 = _chord_step(s, present, uh, kxy, ratio, alpha, c_sig, Jc, lengths)
        its += 1
        f_sig, _, f_it, f_ok, f_det, _, _ = _newton(s, present, uh, kxy, ratio, alpha, x1, lengths, tol, maxit, Jf)
        its += f_it
        if f_ok and f_det > 0.0 and _distinct(f_sig, found, n_found, lengths):
            found[n_found] = f_sig
            n_found += 1
    return n_found, its


@njit(cache=True, error_model="numpy", inline="always")
def _nearest_twist(sig, found, n_found, lengths):
    """Twist distance [rad] from base torsions ``sig`` (n,) [1/m] to the nearest of the first
    ``n_found`` rows of ``found`` (m, n): min over rows of max_i |d sigma_i| L_i."""
    near = np.inf
    for f in range(n_found):
        far = 0.0
        for j in range(sig.shape[0]):
            far = max(far, abs(sig[j] - found[f, j]) * lengths[j])
        near = min(near, far)
    return near


@njit(cache=True, inline="always")
def _distinct(sig, found, n_found, lengths):
    """Whether base torsions ``sig`` (n,) differ from each of the first ``n_found`` rows of
    ``found`` by more than ``DISTINCT_EQUILIBRIUM_TWIST`` in twist (max_i |d sigma_i| L_i)."""
    return _nearest_twist(sig, found, n_found, lengths) > _DISTINCT_TWIST


@njit(cache=True, error_model="numpy", inline="always")
def _mean_bending(angle, present, uh, j, kxy):
    """Shared bending curvature (u_x, u_y) [1/m] = sum_i k_i R_z(angle_i) uhat_i / sum_i k_i over
    the tubes present on interval ``j`` (angle (n,) [rad], present (G - 1, n), uh (G - 1, n, 2)
    [1/m], kxy (n,)). A tube without precurvature there adds its stiffness to the sum but no
    bending, so its angle's sine and cosine are not evaluated (the sums are the same, bit for
    bit: its terms were +-0)."""
    ks = 0.0
    bx = 0.0
    by = 0.0
    for i in range(angle.shape[0]):
        if present[j, i]:
            ks += kxy[i]
            u0 = uh[j, i, 0]
            u1 = uh[j, i, 1]
            if u0 != 0.0 or u1 != 0.0:
                c = np.cos(angle[i])
                sn = np.sin(angle[i])
                bx += kxy[i] * (c * u0 - sn * u1)
                by += kxy[i] * (sn * u0 + c * u1)
    ks = max(ks, 1e-300)
    return bx / ks, by / ks


@njit(cache=True, error_model="numpy")
def _centerline(s, present, uh, kxy, psi, sig):
    """Shared centerline of the standard model from the node angles and torsions (G, n).

    Per interval: Hermite midpoint angle (4th order) and torsion (3rd order), the bending
    curvature u_xy = sum_i k_i R_z(psi_i) uhat_i / sum_i k_i of the tubes present, then
    exponential-coordinates steps from R = I, p = (0, 0, s_0) (Eq. (57) of Ha et al. 2019).
    Returns psi_mid, sig_mid (G - 1, n), u_xy (G - 1, 2), R (G, 3, 3), p (G, 3), and the
    bending at the nodes (G, 2) (last interval's tubes at the last node).
    """
    G = s.shape[0]
    n = psi.shape[1]
    psi_mid = np.empty((G - 1, n))
    sig_mid = np.empty((G - 1, n))
    ub = np.empty((G - 1, 2))
    ucurv = np.zeros((G - 1, 3))
    h = np.empty(G - 1)
    bend = np.empty((G, 2))
    for j in range(G - 1):
        hj = s[j + 1] - s[j]
        h[j] = hj
        for i in range(n):
            psi_mid[j, i] = 0.5 * (psi[j, i] + psi[j + 1, i]) + hj * (sig[j, i] - sig[j + 1, i]) / 8.0
            sig_mid[j, i] = 1.5 * (psi[j + 1, i] - psi[j, i]) / hj - 0.25 * (sig[j, i] + sig[j + 1, i])
        ub[j, 0], ub[j, 1] = _mean_bending(psi_mid[j], present, uh, j, kxy)
        ucurv[j, 0] = ub[j, 0]
        ucurv[j, 1] = ub[j, 1]
    for q in range(G):
        j = min(q, G - 2)
        bend[q, 0], bend[q, 1] = _mean_bending(psi[q], present, uh, j, kxy)
    R = np.empty((G, 3, 3))
    p = np.empty((G, 3))
    node_off = np.array([0, G], dtype=np.int64)
    chain_kinematics(ucurv, h, np.zeros(1), np.array([s[0]]), node_off, R, p)
    return psi_mid, sig_mid, ub, R, p, bend


@njit(cache=True, error_model="numpy")
def _tip_frame(s, present, uh, kxy, psi, sig):
    """Tip position (3,) [m] and frame (3, 3) of :func:`_centerline`, with the same arithmetic
    (Hermite midpoint angles, shared bending, the step of ``chain_kinematics``) but without the
    per-node arrays and the bending at the nodes, which a batch of tips does not read: the same
    tip. Only the midpoint angles of tubes with precurvature on an interval are formed (the
    others do not bend it), and an interval without bending (no tube there has precurvature)
    moves the point along the tangent without the exponential: exp(0) = I and V(0) e_z = e_z,
    so the step of ``chain_kinematics`` gives the same numbers (up to the sign of exact zeros)."""
    G = s.shape[0]
    n = psi.shape[1]
    pm = np.zeros(n)
    R = np.eye(3)
    Rn = np.empty((3, 3))
    p = np.zeros(3)
    p[2] = s[0]
    pn = np.empty(3)
    E = np.empty((3, 3))
    vz = np.empty(3)
    for j in range(G - 1):
        hk = s[j + 1] - s[j]
        bends = False
        for i in range(n):
            if present[j, i] and (uh[j, i, 0] != 0.0 or uh[j, i, 1] != 0.0):
                pm[i] = 0.5 * (psi[j, i] + psi[j + 1, i]) + hk * (sig[j, i] - sig[j + 1, i]) / 8.0
                bends = True
        if not bends:
            p[0] += R[0, 2] * hk
            p[1] += R[1, 2] * hk
            p[2] += R[2, 2] * hk
            continue
        bx, by = _mean_bending(pm, present, uh, j, kxy)
        advance(R, p, bx * hk, by * hk, 0.0 * hk, hk, E, vz, Rn, pn)
        R, Rn = Rn, R
        p, pn = pn, p
    return p, R


def _assemble(problem, sig0, psi, sig, diag) -> StandardSolution:
    """The solution from the node angles and torsions (G, n) of the converged shooting."""
    g = problem.grid
    s = g.s
    psi_mid, sig_mid, ub, R, p, bend = _centerline(s, g.present, g.precurvature, problem.kxy, psi, sig)
    n = problem.robot.n_tubes
    psi_rep = psi.copy()
    sig_rep = sig.copy()
    for i in range(n):
        absent = np.ones(s.size, dtype=bool)
        absent[g.first[i]:g.last[i] + 1] = False
        psi_rep[absent, i] = np.nan
        sig_rep[absent, i] = np.nan
    ends = problem.robot.tube_ends(problem.beta)
    tip_tube = int(max(range(n), key=lambda i: (ends[i], i)))
    tip_rot = R[-1] @ rot_z(psi[-1, tip_tube])
    return StandardSolution(
        s=s, centerline=p, frames=R, psi=psi_rep, torsion=sig_rep, bending=bend,
        alpha=problem.alpha.copy(), beta=problem.beta.copy(), tip_position=p[-1].copy(),
        tip_tangent=R[-1][:, 2].copy(), tip_rotation=tip_rot, diagnostics=diag,
        base_torsion=np.asarray(sig0, dtype=float).copy(), psi_mid=psi_mid, torsion_mid=sig_mid,
        bending_mid=ub, grid=g)


def solve_standard(robot, alpha, beta, settings: ModelSettings | None = None, *,
                   initial_guess=None, check_stability: bool = True,
                   raise_on_failure: bool = False) -> StandardSolution:
    """Solve the standard zero-clearance, torsionally compliant model at one configuration.

    Parameters
    ----------
    robot : Robot
    alpha : array-like, shape (n,)
        Base rotations [rad] (the paper's theta_b).
    beta : array-like, shape (n,)
        Base translations [m] (the paper's l_b).
    settings : ModelSettings, optional
        Uses ``ds``, ``refine_ratio``, ``refine_length`` (the grid), ``shooting_tol``,
        ``max_shooting_iterations`` and ``multistart``.
    initial_guess : array-like, shape (n,), optional
        Base torsions [1/m] to start Newton from, e.g. ``previous.base_torsion`` to follow the
        branch the robot is on along a path. Default: no twist, solved first on a grid
        ``PREDICTOR_STEP_FACTOR`` (4) times coarser, whose base torsions start the Newton
        shooting on the ``ds`` grid (``constants``; it falls back to no twist if that fails,
        then restarts from plus and minus pi / L_i of twist on each inner tube i).
    check_stability : bool
        Run the multistart search for other equilibria (skipped when ``settings.multistart``
        is 0; restarts solved on the predictor's coarse grid, distinct candidates confirmed on
        the fine one: :func:`_multistart_search`). The Jacobian-determinant test always runs.
    raise_on_failure : bool
        Raise instead of flagging in ``diagnostics``.

    Returns
    -------
    StandardSolution
        ``diagnostics.unstable`` is True when the shooting Jacobian determinant is not
        positive (the equilibrium is past a bifurcation) or another equilibrium exists.

    Raises
    ------
    JointLimitError
        If the configuration is kinematically impossible (``Robot.check_configuration``).
    ConvergenceError
        If ``raise_on_failure`` and Newton shooting did not converge.
    ElasticInstabilityError
        If ``raise_on_failure`` and the configuration has more than one equilibrium.

    Notes
    -----
    Equations: Section II-A of Ha, Fagogenis & Dupont 2019 and its refs [10], [11]; torsion
    ODE as Eq. (11) of Rucker, Jones & Webster, IEEE T-RO 26(5) 2010 with no external load.
    """
    settings = settings or ModelSettings()
    robot.check_configuration(alpha, beta)
    problem = _Problem(robot, alpha, beta, settings)
    n = robot.n_tubes
    sig0 = np.zeros(n) if initial_guess is None else np.asarray(initial_guess, dtype=float)
    sig0, res, iters, ok, detJ, nodes = problem.newton(sig0, settings, predict=initial_guess is None)
    if not ok and initial_guess is not None:
        sig0, res, iters2, ok, detJ, nodes = problem.newton(np.zeros(n), settings)
        iters += iters2
    unstable = bool(ok and not detJ > 0.0)
    n_eq = 0  # not checked
    msg = "converged" if ok else f"shooting did not converge (tip torsion residual {res:.3g} 1/m)"
    if ok and check_stability and settings.multistart > 0:
        # equilibria are told apart by their base torsions (the shooting unknowns): two
        # solutions of the BVP with the same base torsions are the same solution
        g, c = problem.grid, problem._coarse_grid()
        n_eq, ms_it = _multistart_search(g.s, g.present, g.precurvature, c.s, c.present, c.precurvature,
                                         problem.kxy, problem.ratio, problem.alpha, np.asarray(sig0, dtype=float),
                                         problem.lengths, float(settings.shooting_tol),
                                         int(settings.max_shooting_iterations), int(settings.multistart))
        iters += ms_it
        if n_eq > 1:
            unstable = True
    if unstable:
        msg = (f"elastically unstable: {n_eq} equilibria found by the multistart search" if n_eq > 1
               else f"elastically unstable: shooting Jacobian determinant {detJ:.3g} <= 0")
    diag = Diagnostics(converged=ok, iterations=iters, unstable=unstable, n_equilibria=n_eq,
                       message=msg, residual=res)
    if raise_on_failure and not ok:
        raise ConvergenceError(f"standard model at alpha={np.round(alpha, 4)} rad, "
                               f"beta={np.round(np.asarray(beta) * 1e3, 3)} mm: {msg}")
    if raise_on_failure and unstable:
        raise ElasticInstabilityError(f"standard model at alpha={np.round(alpha, 4)} rad, "
                                      f"beta={np.round(np.asarray(beta) * 1e3, 3)} mm: {msg}")
    return _assemble(problem, sig0, *nodes, diag)
