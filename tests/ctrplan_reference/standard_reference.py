"""FROZEN REFERENCE COPY of ctrplan/mechanics/standard.py as of commit d2d3ee6 (before the
speed work). Slow and simple on purpose: tests/test_mechanics_fast_vs_reference.py
holds the fast path in ctrplan.mechanics to it. Do not optimise; only imports were changed:
the arc-length grid (ctrplan.mechanics.grid) is shared, not copied, and since the grid became
graded it is built with the settings' refine_ratio and refine_length, like the fast path.

Original module docstring follows.

Standard zero-clearance, torsionally compliant CTR kinematics.

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

from ctrplan.constants import DISTINCT_EQUILIBRIUM_TWIST
from ctrplan.errors import ConvergenceError, ElasticInstabilityError
from ctrplan.mechanics._lie import exp_so3, left_jacobian_so3, rot_z
from ctrplan.mechanics.grid import build_grid
from ctrplan.mechanics.results import Diagnostics, ModelSettings, StandardSolution

__all__ = ["solve_standard"]


@njit(cache=True)
def _rhs(psi, sig, Sp, Ss, present, uh, kxy, ratio, dpsi, dsig, dSp, dSs):
    """Torsion ODE and its variational equations on one interval (in-place outputs)."""
    n = psi.shape[0]
    ksum = 0.0
    ucx = 0.0
    ucy = 0.0
    ax = np.empty(n)
    ay = np.empty(n)
    for i in range(n):
        c = np.cos(psi[i])
        s = np.sin(psi[i])
        ax[i] = c * uh[i, 0] - s * uh[i, 1]
        ay[i] = s * uh[i, 0] + c * uh[i, 1]
        if present[i]:
            ksum += kxy[i]
            ucx += kxy[i] * ax[i]
            ucy += kxy[i] * ay[i]
    if ksum > 0.0:
        ucx /= ksum
        ucy /= ksum
    m = Sp.shape[1]
    # d u_c / d psi_j = k_j rot90(a_j) / ksum, rot90(a) = (-a_y, a_x)
    ducx = np.zeros(m)
    ducy = np.zeros(m)
    for j in range(n):
        if present[j]:
            w = kxy[j] / ksum
            for q in range(m):
                ducx[q] += w * (-ay[j]) * Sp[j, q]
                ducy[q] += w * ax[j] * Sp[j, q]
    for i in range(n):
        if present[i]:
            dpsi[i] = sig[i]
            dsig[i] = ratio[i] * (ucx * ay[i] - ucy * ax[i])
            for q in range(m):
                dSp[i, q] = Ss[i, q]
                dax = -ay[i] * Sp[i, q]
                day = ax[i] * Sp[i, q]
                dSs[i, q] = ratio[i] * (ducx[q] * ay[i] - ducy[q] * ax[i] + ucx * day - ucy * dax)
        else:
            dpsi[i] = 0.0
            dsig[i] = 0.0
            for q in range(m):
                dSp[i, q] = 0.0
                dSs[i, q] = 0.0


@njit(cache=True)
def _integrate(s, present, uh, kxy, ratio, psi0, sig0, record, with_sens):
    """Classical RK4 over the grid intervals, one step per interval.

    Returns final psi, sigma, sensitivities d(psi, sigma)/d sigma0, and, when ``record``,
    psi, sigma and sigma' at every node.
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
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        pr = present[j]
        u = uh[j]
        _rhs(psi, sig, Sp, Ss, pr, u, kxy, ratio, k1p, k1s, K1p, K1s)
        if record:
            rec_psi[j] = psi
            rec_sig[j] = sig
            rec_dsig[j] = k1s
        _rhs(psi + 0.5 * h * k1p, sig + 0.5 * h * k1s, Sp + 0.5 * h * K1p, Ss + 0.5 * h * K1s,
             pr, u, kxy, ratio, k2p, k2s, K2p, K2s)
        _rhs(psi + 0.5 * h * k2p, sig + 0.5 * h * k2s, Sp + 0.5 * h * K2p, Ss + 0.5 * h * K2s,
             pr, u, kxy, ratio, k3p, k3s, K3p, K3s)
        _rhs(psi + h * k3p, sig + h * k3s, Sp + h * K3p, Ss + h * K3s,
             pr, u, kxy, ratio, k4p, k4s, K4p, K4s)
        psi = psi + h / 6.0 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
        sig = sig + h / 6.0 * (k1s + 2.0 * k2s + 2.0 * k3s + k4s)
        Sp = Sp + h / 6.0 * (K1p + 2.0 * K2p + 2.0 * K3p + K4p)
        Ss = Ss + h / 6.0 * (K1s + 2.0 * K2s + 2.0 * K3s + K4s)
        if record and j == G - 2:
            # derivative at the last node, evaluated with the last interval's data
            _rhs(psi, sig, Sp, Ss, pr, u, kxy, ratio, k1p, k1s, K1p, K1s)
            rec_psi[G - 1] = psi
            rec_sig[G - 1] = sig
            rec_dsig[G - 1] = k1s
    return psi, sig, Sp, Ss, rec_psi, rec_sig, rec_dsig


class _Problem:
    """Pre-processed data of one configuration for the shooting method."""

    def __init__(self, robot, alpha, beta, settings):
        self.robot = robot
        self.alpha = np.asarray(alpha, dtype=float)
        self.beta = np.asarray(beta, dtype=float)
        self.grid = build_grid(robot, self.beta, settings.ds, settings.refine_ratio, settings.refine_length)
        self.kxy = np.array([t.k_xy for t in robot.tubes])
        self.ratio = np.array([t.k_xy / t.k_z for t in robot.tubes])
        self.lengths = np.array([t.length for t in robot.tubes])

    def shoot(self, sig0, record=False, with_sens=True):
        g = self.grid
        return _integrate(g.s, g.present, g.precurvature, self.kxy, self.ratio,
                          self.alpha.copy(), np.asarray(sig0, dtype=float).copy(), record, with_sens)

    def newton(self, sig0, settings):
        """Newton shooting on the base torsions; returns (sig0, residual norm, iterations, ok, detJ)."""
        sig0 = np.asarray(sig0, dtype=float).copy()
        n = sig0.size
        res_norm = np.inf
        detJ = np.nan
        for it in range(1, settings.max_shooting_iterations + 1):
            _, sig, _, Ss, _, _, _ = self.shoot(sig0)
            r = sig  # torsion at each tube's free end must vanish
            res_norm = float(np.max(np.abs(r)))
            J = Ss[:, :n]
            detJ = float(np.linalg.det(J))
            if not np.all(np.isfinite(r)):
                return sig0, np.inf, it, False, detJ
            if res_norm < settings.shooting_tol:
                return sig0, res_norm, it, True, detJ
            try:
                step = np.linalg.solve(J, r)
            except np.linalg.LinAlgError:
                step = np.linalg.lstsq(J, r, rcond=None)[0]
            # damped step: never change a base torsion by more than pi over the tube length
            lim = np.pi / self.lengths
            scale = min(1.0, float(np.min(lim / np.maximum(np.abs(step), 1e-300))))
            t = scale
            accepted = False
            for _ in range(20):
                trial = sig0 - t * step
                _, sig_t, _, _, _, _, _ = self.shoot(trial, with_sens=False)
                if np.all(np.isfinite(sig_t)) and np.max(np.abs(sig_t)) < (1.0 - 1e-4 * t) * res_norm:
                    accepted = True
                    break
                t *= 0.5
            sig0 = trial if accepted else sig0 - scale * step
        _, sig, _, Ss, _, _, _ = self.shoot(sig0)
        res_norm = float(np.max(np.abs(sig)))
        return sig0, res_norm, settings.max_shooting_iterations, res_norm < settings.shooting_tol, float(np.linalg.det(Ss))


def _assemble(problem, sig0, diag) -> StandardSolution:
    g = problem.grid
    s = g.s
    h = np.diff(s)
    _, _, _, _, psi, sig, dsig = problem.shoot(sig0, record=True, with_sens=False)
    # Hermite midpoints (4th-order psi, 3rd-order sigma) for the per-interval curvature
    psi_mid = 0.5 * (psi[:-1] + psi[1:]) + h[:, None] * (sig[:-1] - sig[1:]) / 8.0
    sig_mid = 1.5 * (psi[1:] - psi[:-1]) / h[:, None] - 0.25 * (sig[:-1] + sig[1:])
    c, sn = np.cos(psi_mid), np.sin(psi_mid)
    uh = g.precurvature
    ax = c * uh[..., 0] - sn * uh[..., 1]
    ay = sn * uh[..., 0] + c * uh[..., 1]
    k = problem.kxy[None, :] * g.present
    ksum = np.maximum(k.sum(axis=1), 1e-300)
    ub = np.stack([(k * ax).sum(axis=1) / ksum, (k * ay).sum(axis=1) / ksum], axis=1)
    phi = np.zeros((h.size, 3))
    phi[:, :2] = ub * h[:, None]
    E = exp_so3(phi)
    Vz = left_jacobian_so3(phi)[:, :, 2] * h[:, None]
    R = np.empty((s.size, 3, 3))
    p = np.empty((s.size, 3))
    R[0] = np.eye(3)
    p[0] = (0.0, 0.0, s[0])
    for j in range(h.size):
        p[j + 1] = p[j] + R[j] @ Vz[j]
        R[j + 1] = R[j] @ E[j]
    # bending at nodes (for reporting): from node angles
    cN, sN = np.cos(psi), np.sin(psi)
    presN = np.vstack([g.present, g.present[-1:]])
    uhN = np.vstack([uh, uh[-1:]])
    kN = problem.kxy[None, :] * presN
    kNs = np.maximum(kN.sum(axis=1), 1e-300)
    bend = np.stack([(kN * (cN * uhN[..., 0] - sN * uhN[..., 1])).sum(axis=1) / kNs,
                     (kN * (sN * uhN[..., 0] + cN * uhN[..., 1])).sum(axis=1) / kNs], axis=1)
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


def _multistart_guesses(problem, sig0, count):
    """Initial base torsions that put about +pi, then -pi, of extra twist on each inner tube
    (round-robin over the tubes, so every inner tube gets a guess once ``count >= n - 1``)."""
    guesses = []
    n = problem.robot.n_tubes
    for sign in (1.0, -1.0):
        for i in range(1, n):
            g = np.array(sig0, dtype=float)
            g[i] += sign * np.pi / problem.lengths[i]
            guesses.append(g)
    return guesses[:count]


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
        Uses ``ds``, ``shooting_tol``, ``max_shooting_iterations`` and ``multistart``.
    initial_guess : array-like, shape (n,), optional
        Base torsions [1/m] to start Newton from, e.g. ``previous.base_torsion`` to follow the
        branch the robot is on along a path. Default: no twist.
    check_stability : bool
        Run the multistart search for other equilibria (skipped when ``settings.multistart``
        is 0). The Jacobian-determinant test always runs.
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
    sig0, res, iters, ok, detJ = problem.newton(sig0, settings)
    if not ok and initial_guess is not None:
        sig0, res, iters2, ok, detJ = problem.newton(np.zeros(n), settings)
        iters += iters2
    unstable = bool(ok and not detJ > 0.0)
    n_eq = 0  # not checked
    msg = "converged" if ok else f"shooting did not converge (tip torsion residual {res:.3g} 1/m)"
    if ok and check_stability and settings.multistart > 0:
        # equilibria are told apart by their base torsions (the shooting unknowns): two
        # solutions of the BVP with the same base torsions are the same solution
        found = [sig0]
        for guess in _multistart_guesses(problem, sig0, settings.multistart):
            g_sig, g_res, g_it, g_ok, g_det = problem.newton(guess, settings)
            iters += g_it
            if not g_ok or not g_det > 0.0:
                continue
            if all(np.max(np.abs(g_sig - f) * problem.lengths) > DISTINCT_EQUILIBRIUM_TWIST for f in found):
                found.append(g_sig)
        n_eq = len(found)
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
    return _assemble(problem, sig0, diag)
