"""Clearance model (Section II) and maximal torsional Coulomb friction model (Section III).

Linearized problem (Eqs. (10)-(25) of Ha, Fagogenis & Dupont 2019). About a linearization
point u* (first the standard zero-clearance solution), with segment curvatures u = u* + du,

    min_du  1/2 du^T K du + g^T du,   g = K (u* - uhat)                        (12), (13)
    s.t.    |d_k(du)| <= c_k,  d_k = B_k^T S_k (p* + J_p du)                      (19)-(24)

where S_k picks p_i - p_(i+1) at constraint k and B_k = [x_i, y_i] spans the outer tube's
cross section (B_k B_k^T = P_k of Eq. (22)). We keep the paper's multipliers lambda_k >= 0 of
the constraints 1/2 (|d_k|^2 - c_k^2) <= 0 (Eq. (26)-(27)), whose stationarity gives the
equilibrium (34)-(36):

    K (u - uhat) = sum_k A_k^T phi_k + sum_k lambda_k z_k,   phi_k = -lambda_k M_k d_k

with A_k = B_k^T S_k J_p, the contact force on the outer tube B_k phi_k (|f_k| = c_k lambda_k
at an active contact, Eq. (33)), and, for friction (Eqs. (37)-(43)):

- M_k = I + eta_k mu_k J (J the +90 deg in-plane rotation): the circumferential friction force
  eta_k mu_k [t_k]x f_normal,k of Eq. (38) acting on the centerlines (Eq. (40));
- z_k = eta_k mu_k c_k (r_(i,in) J_omega,i^T e_z - r_(i+1,out) J_omega,i+1^T e_z): the friction
  torques about each tube's axis of Eq. (41) (see the errata note on Eq. (42)).

Instead of the paper's fixed-step projected gradient ascent on the dual (Section II-E), the
multipliers are found by a semismooth Newton method on the complementarity conditions
lambda_k >= 0, c_k^2 - |d_k|^2 >= 0, lambda_k (c_k^2 - |d_k|^2) = 0 (natural residual min(a, b)
on loaded contacts, Fischer-Burmeister on the others and as the fallback), with the
Woodbury-type reduction of Appendix A (Eqs. (50)-(56)) restricted to active contacts: all that
is needed is the contact compliance W = A K^-1 A^T. Without friction this is exactly the
optimum of the convex dual (26); with friction, where Q(lambda) of Eq. (45) is not symmetric,
it solves the equilibrium of Eq. (44) directly. The outer loop re-linearizes about the new
solution (Section II-E, alpha = 1) until the centerlines stop moving.

The work is done by compiled kernels (``_contact_kernels``, driven by ``_contact_fast``) that
never form the dense constraint Jacobian: the compliance blocks W_ce come from per-node prefix
sums of the chain Jacobian factors, only for the contacts the Newton method touches, and the
generalized forces A^T phi from suffix sums. The slow original is kept as
tests/ctrplan_reference/contact_reference.py, and the fast path is tested against it.
"""

from __future__ import annotations

import numpy as np

from ..constants import OUTER_STAGNATION_WINDOW
from ..errors import ConvergenceError
from ._contact_fast import FlatProblem, run_outer_loop
from .results import ContactSolution, Diagnostics, ModelSettings
from . import warmup
from .standard import solve_standard

__all__ = ["solve_clearance", "solve_friction", "solve_contact"]


def solve_contact(robot, alpha, beta, settings: ModelSettings | None = None, *, eta=None,
                  mu=None, standard=None, warm_start: ContactSolution | None = None,
                  raise_on_failure: bool = False) -> ContactSolution:
    """Solve the clearance model (``eta=None``) or one friction solution (``eta`` given).

    Parameters
    ----------
    robot : Robot
        Clearances from tube diameters (Eq. (15)) or the robot's override.
    alpha, beta : array-like, shape (n,)
        Base rotations [rad] and translations [m].
    settings : ModelSettings, optional
    eta : array-like of int, shape (n - 1,), optional
        Direction of the last relative rotation of each pair (+1 CCW, -1 CW; Eq. (39)).
        ``None``: frictionless clearance model.
    mu : array-like, shape (n - 1,), optional
        Friction coefficients; default the robot's when ``eta`` is given, else zero.
    standard : StandardSolution, optional
        Standard-model solution at the same configuration (first linearization point).
    warm_start : ContactSolution, optional
        Start from this solution's curvatures and multipliers (same configuration and grid).
        Any object with ``curvatures`` (list of n arrays (S_i, 3) [1/m]) and ``multipliers``
        ((M,) or None) will do, e.g. the mirrored start of ``evaluate_bound``.
    raise_on_failure : bool
        Raise ConvergenceError instead of flagging ``diagnostics.converged = False``.

    Returns
    -------
    ContactSolution
        Centerlines, frames, curvatures, contact forces f_k = c_i lambda_k [N] (Eq. (33)) with
        arc lengths and directions, and diagnostics (outer and Newton iteration counts,
        largest constraint violation relative to the clearance in ``residual``).

    Raises
    ------
    JointLimitError
        Kinematically impossible configuration.
    ConvergenceError
        If ``raise_on_failure`` and the solve did not converge.
    PhysicalParameterError
        Non-positive clearance, or friction without tube diameters.

    Notes
    -----
    Eqs. (10)-(36) (clearance) and (37)-(47) (friction) of Ha, Fagogenis & Dupont 2019, with the
    Woodbury reduction of Appendix A and the Jacobians of Appendix B; see the module docstring
    for the differences from the paper's gradient ascent.
    """
    settings = settings or ModelSettings()
    if standard is None:
        warmup.start()   # on a cold start, the contact kernels compile beside the standard model's
    n = robot.n_tubes
    if eta is not None:
        eta = friction_directions(eta, n)
        mu = np.asarray(robot.friction_coefficients if mu is None else mu, dtype=float)
    else:
        mu = np.zeros(n - 1) if mu is None else np.asarray(mu, dtype=float)
    if standard is None:
        standard = solve_standard(robot, alpha, beta, settings, check_stability=False)
    warmup.wait()   # a cold start's contact kernels, compiled in another process (warmup.start)
    prob = _flat_problem(robot, standard, eta, mu)
    if warm_start is not None and len(warm_start.curvatures) == n and all(
            w.shape == u.shape for w, u in zip(warm_start.curvatures, prob.split_segments(prob.u0))):
        u = np.concatenate(warm_start.curvatures).astype(float)
        lam = (np.array(warm_start.multipliers, dtype=float) if warm_start.multipliers is not None
               else np.zeros(prob.M))
    else:
        u = prob.u0.copy()
        lam = np.zeros(prob.M)
    u, R, p, lam, converged, outer, inner_total, inner_ok, change = run_outer_loop(prob, u, lam, settings)
    # final contact state from the converged kinematics
    forces = prob.c * lam
    rel = p[prob.jo] - p[prob.ji]
    t_out = R[prob.jo][:, :, 2]
    rel = rel - t_out * np.sum(t_out * rel, axis=1)[:, None]
    gaps = np.linalg.norm(rel, axis=1)
    safe = np.where(gaps > 0, gaps, 1.0)
    dirs = np.where(gaps[:, None] > 0, -rel / safe[:, None], 0.0)
    viol = float(np.max(gaps / prob.c - 1.0)) if prob.M else 0.0
    ends = robot.tube_ends(np.asarray(beta, dtype=float))
    tip_tube = int(max(range(n), key=lambda i: (ends[i], i)))
    frames = [x.copy() for x in prob.split_nodes(R)]
    lines = [x.copy() for x in prob.split_nodes(p)]
    Rt, pt = frames[tip_tube], lines[tip_tube]
    model = "clearance" if eta is None else f"friction eta={eta.astype(int).tolist()}"
    if converged:
        msg = f"{model}: converged in {outer} outer iterations"
    else:
        why = ""
        if inner_ok and outer < settings.max_outer_iterations:
            why = (f"; stopped: no new smallest centerline change in {OUTER_STAGNATION_WINDOW} "
                   f"iterations")
        msg = (f"{model}: not converged after {outer} outer iterations (centerline change "
               f"{change:.3g} m, complementarity {'ok' if inner_ok else 'failed'}{why})")
    diag = Diagnostics(converged=converged, iterations=outer, inner_iterations=inner_total,
                       unstable=standard.diagnostics.unstable, n_equilibria=standard.diagnostics.n_equilibria,
                       message=msg, residual=viol)
    if raise_on_failure and not converged:
        raise ConvergenceError(f"at alpha={np.round(alpha, 4)} rad, beta={np.round(np.asarray(beta) * 1e3, 3)} mm: {msg}")
    return ContactSolution(
        s=[x.copy() for x in prob.s], centerlines=lines, frames=frames,
        curvatures=[x.copy() for x in prob.split_segments(u)], contact_s=prob.s_contact,
        contact_pair=prob.pair.astype(int), contact_force=forces, contact_direction=dirs,
        contact_gap=gaps, eta=np.zeros(n - 1, dtype=int) if eta is None else eta.astype(int), mu=mu,
        tip_position=pt[-1].copy(), tip_tangent=Rt[-1][:, 2].copy(), tip_rotation=Rt[-1].copy(),
        diagnostics=diag, multipliers=lam)


def friction_directions(eta, n_tubes: int) -> np.ndarray:
    """``eta`` as a float array of shape (n_tubes - 1,) of +1 (CCW) and -1 (CW) (Eq. (39) of Ha
    et al. 2019).

    Raises
    ------
    ValueError
        ``eta`` does not hold n_tubes - 1 values of +1 or -1.
    """
    eta = np.asarray(eta, dtype=float).reshape(-1)
    if eta.size != n_tubes - 1 or not np.all(np.isin(eta, (-1.0, 1.0))):
        raise ValueError(f"eta must hold {n_tubes - 1} values of +1 or -1, got {eta}")
    return eta


# The last problem built, with the robot and standard solution it was built from: the clearance
# and friction solves of one bound share a configuration, and building the flat arrays again cost
# 4 % of the bound. Identity, not equality: both objects are kept alive here, so an
# ``is`` match cannot be a recycled id.
_LAST_PROBLEM = [None]


def _flat_problem(robot, standard, eta, mu):
    """FlatProblem of this robot and standard solution with directions ``eta``: derived from the
    last one built when robot and standard solution are the same objects."""
    last = _LAST_PROBLEM[0]
    if last is not None and last[0] is robot and last[1] is standard:
        return last[2].with_directions(robot, eta, mu)
    prob = FlatProblem(robot, standard, eta, mu)
    _LAST_PROBLEM[0] = (robot, standard, prob)
    return prob


def solve_clearance(robot, alpha, beta, settings=None, **kwargs) -> ContactSolution:
    """Frictionless clearance model (Section II of Ha et al. 2019). See :func:`solve_contact`."""
    return solve_contact(robot, alpha, beta, settings, eta=None, **kwargs)


def solve_friction(robot, alpha, beta, eta, settings=None, **kwargs) -> ContactSolution:
    """One maximal-torsional-friction solution for directions ``eta`` (Section III, Eqs. (37)-(47)
    of Ha et al. 2019). See :func:`solve_contact`."""
    return solve_contact(robot, alpha, beta, settings, eta=eta, **kwargs)
