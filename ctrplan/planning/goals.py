"""Planning goals: a joint vector, or a tip position with a tolerance solved by inverse kinematics.

Inverse kinematics minimizes ``|p_tip(q) - p_target|^2`` with ``scipy.optimize.least_squares``
(trust-region reflective, translation limits as bounds, periodic rotations unbounded) on the
standard model's tip position, started from every node of a coarse grid of the joint space
(plus a seeded jitter) or, when that grid would exceed ``max_starts`` (six joints: 3^6 = 729
starts), from ``max_starts`` seeded Latin-hypercube points of the joint box. All converged
solutions within tolerance that pass the validity function are kept; the one with the smallest
friction bound (from a :class:`~ctrplan.boundmap.BoundField`, or the smallest tip error without
one) is chosen. A redundant robot (more than three joints) has a manifold of solutions, and
more starts find lower bounds on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import CtrplanError, UnreachableGoalError
from .space import wrap_angle

__all__ = ["JointGoal", "TaskSpaceGoal", "GoalSolution", "resolve_goal", "DEFAULT_IK_STARTS_PER_JOINT",
           "DEFAULT_IK_MAX_STARTS"]

# Coarse start grid: nodes per joint (3 joints -> 27 starts, ~1-3 s with a ~1 ms model).
DEFAULT_IK_STARTS_PER_JOINT = 3
# Largest number of starts; a bigger grid is replaced by this many Latin-hypercube points
# (six joints: 64 starts of ~0.1 s each instead of 729).
DEFAULT_IK_MAX_STARTS = 64

# Residual returned where the model fails, so least_squares steers away [m].
_FAILED_RESIDUAL = 1.0

# Two IK solutions closer than this in every joint are the same [rad or m].
_DUPLICATE_TOL = 1e-4


@dataclass(frozen=True)
class JointGoal:
    """Goal given directly as a joint vector ``q`` (shape (n_joints,)) [rad or m]."""

    q: tuple


@dataclass(frozen=True)
class TaskSpaceGoal:
    """Goal given as a tip position ``tip_position_m`` (shape (3,)) [m] within ``tolerance_m`` [m]."""

    tip_position_m: tuple
    tolerance_m: float = 1e-3


@dataclass
class GoalSolution:
    """Resolved goal.

    Attributes
    ----------
    q : ndarray, shape (n_joints,)
        Chosen joint vector [rad or m]; periodic angles in [-pi, pi).
    tip_error : float
        Distance of the standard-model tip from the target [m] (0 for a joint goal).
    bound : float
        Field bound at ``q`` [m] (NaN without field).
    candidates : ndarray, shape (m, n_joints)
        All valid solutions within tolerance [rad or m].
    candidate_errors, candidate_bounds : ndarray, shape (m,)
        [m]
    n_model_evaluations : int
    """

    q: np.ndarray
    tip_error: float
    bound: float
    candidates: np.ndarray
    candidate_errors: np.ndarray
    candidate_bounds: np.ndarray
    n_model_evaluations: int = 0


def _starts(robot, n_per_joint, max_starts, rng):
    """The start grid, or ``max_starts`` seeded Latin-hypercube points when the grid is larger."""
    n = len(robot.joints)
    if n_per_joint ** n <= max_starts:
        return _start_grid(robot, n_per_joint, rng)
    from scipy.stats import qmc

    u = qmc.LatinHypercube(d=n, seed=rng).random(int(max_starts))
    return robot.joint_lower + u * (robot.joint_upper - robot.joint_lower)


def _start_grid(robot, n_per_joint, rng):
    axes = []
    for j in robot.joints:
        if j.periodic:
            axes.append(j.lower + 2.0 * np.pi * (np.arange(n_per_joint) + 0.5) / n_per_joint)
        else:
            axes.append(j.lower + (j.upper - j.lower) * (np.arange(n_per_joint) + 0.5) / n_per_joint)
    mesh = np.meshgrid(*axes, indexing="ij")
    starts = np.stack([g.reshape(-1) for g in mesh], axis=1)
    span = robot.joint_upper - robot.joint_lower
    step = span / n_per_joint
    jitter = (rng.random(starts.shape) - 0.5) * 0.5 * step
    return np.clip(starts + jitter, robot.joint_lower, robot.joint_upper)


def resolve_goal(goal, robot, validity_fn=None, field=None, solve_standard=None, settings=None, *,
                 starts_per_joint: int = DEFAULT_IK_STARTS_PER_JOINT, seed: int = 0,
                 max_nfev: int = 60, max_starts: int = DEFAULT_IK_MAX_STARTS) -> GoalSolution:
    """Turn a goal into one joint vector.

    Parameters
    ----------
    goal : JointGoal, TaskSpaceGoal, array-like of shape (n_joints,), dict, or scenario goal
        Dicts: ``{"q": [...]}`` or ``{"tip_position_m": [...], "tolerance_m": ...}``; objects
        with ``tip_position`` [m] and ``tolerance`` [m] (``ctrplan.io.scenario.TaskGoal``) or
        with ``q`` (``ctrplan.io.scenario.JointGoal``) are accepted too.
    robot : Robot
    validity_fn : callable, optional
        ``validity_fn(q) -> bool``; invalid IK solutions are discarded.
    field : BoundField, optional
        Chooses among solutions by the smallest ``position`` bound.
    solve_standard : callable, optional
        ``(robot, alpha, beta, settings) -> StandardSolution``; default
        :func:`ctrplan.mechanics.solve_standard`.
    settings : ModelSettings, optional
    starts_per_joint : int, keyword-only
        Multi-start grid nodes per joint.
    max_starts : int, keyword-only
        Largest number of starts: a bigger grid is replaced by this many seeded Latin-hypercube
        points of the joint box.
    seed : int, keyword-only
        Seed of the start jitter.
    max_nfev : int, keyword-only
        Model evaluations per least-squares run.

    Returns
    -------
    GoalSolution

    Raises
    ------
    UnreachableGoalError
        A joint goal is invalid, or no valid IK solution lies within tolerance (message names
        the target and the best distance reached, in mm).
    ValueError
        Malformed goal.
    """
    if isinstance(goal, dict):
        goal = TaskSpaceGoal(**goal) if "tip_position_m" in goal else JointGoal(**goal)
    elif hasattr(goal, "tip_position") and hasattr(goal, "tolerance"):  # ctrplan.io.scenario.TaskGoal
        goal = TaskSpaceGoal(tuple(np.asarray(goal.tip_position, dtype=float)), float(goal.tolerance))
    elif not isinstance(goal, JointGoal) and hasattr(goal, "q"):  # ctrplan.io.scenario.JointGoal
        goal = JointGoal(tuple(np.asarray(goal.q, dtype=float)))
    if not isinstance(goal, (JointGoal, TaskSpaceGoal)):
        goal = JointGoal(tuple(np.asarray(goal, dtype=float).reshape(-1)))
    if isinstance(goal, JointGoal):
        q = np.asarray(goal.q, dtype=float).reshape(-1)
        if q.shape != (len(robot.joints),):
            raise ValueError(f"joint goal needs {len(robot.joints)} values ({', '.join(robot.joint_names)}), got {q.shape}")
        if validity_fn is not None and not bool(validity_fn(q)):
            raise UnreachableGoalError(f"goal configuration {q} is invalid (limits, stability or collision)")
        b = float(field(q)) if field is not None else float("nan")
        return GoalSolution(q, 0.0, b, q[None, :], np.zeros(1), np.array([b]))

    target = np.asarray(goal.tip_position_m, dtype=float).reshape(-1)
    if target.shape != (3,) or not np.all(np.isfinite(target)):
        raise ValueError(f"tip_position_m must be 3 finite numbers [m], got {goal.tip_position_m!r}")
    tol = float(goal.tolerance_m)
    if not np.isfinite(tol) or tol <= 0.0:
        raise ValueError(f"tolerance_m must be > 0 m, got {goal.tolerance_m!r}")
    if solve_standard is None:
        from ..mechanics import solve_standard  # noqa: PLC0415
    periodic = np.array([j.periodic for j in robot.joints])
    lo = np.where(periodic, -np.inf, robot.joint_lower)
    hi = np.where(periodic, np.inf, robot.joint_upper)
    n_eval = 0

    def residual(q):
        nonlocal n_eval
        n_eval += 1
        try:
            alpha, beta = robot.configuration(np.where(periodic, wrap_angle(q), q))
            sol = solve_standard(robot, alpha, beta, settings)
        except (CtrplanError, np.linalg.LinAlgError, FloatingPointError):
            return np.full(3, _FAILED_RESIDUAL)
        if not sol.diagnostics.converged:
            return np.full(3, _FAILED_RESIDUAL)
        return np.asarray(sol.tip_position, dtype=float) - target

    rng = np.random.default_rng(seed)
    best_err, best_q = np.inf, None
    sols, errs = [], []
    starts = _starts(robot, int(starts_per_joint), int(max_starts), rng)
    for q0 in starts:
        res = least_squares(residual, q0, bounds=(lo, hi), method="trf", max_nfev=max_nfev,
                            x_scale=np.where([j.kind == "rotation" for j in robot.joints], 1.0, 0.01))
        q = np.where(periodic, wrap_angle(res.x), res.x)
        err = float(np.linalg.norm(residual(q)))
        if err < best_err:
            best_err, best_q = err, q
        if err > tol:
            continue
        if validity_fn is not None and not bool(validity_fn(q)):
            continue
        diffs = [np.abs(np.where(periodic, wrap_angle(q - s), q - s)) for s in sols]
        if any(np.all(d < _DUPLICATE_TOL) for d in diffs):
            continue
        sols.append(q)
        errs.append(err)
    if not sols:
        where = "" if best_q is None else f" at q = {np.array2string(best_q, precision=4)}"
        raise UnreachableGoalError(
            f"no valid inverse-kinematics solution within {tol * 1e3:.3g} mm of the tip target "
            f"({', '.join(f'{v * 1e3:.2f}' for v in target)}) mm; best distance reached "
            f"{best_err * 1e3:.3g} mm{where} from {len(starts)} starts")
    cand = np.array(sols)
    errs = np.array(errs)
    if field is not None:
        bounds = np.asarray(field(cand), dtype=float).reshape(-1)
        order = np.lexsort((errs, np.where(np.isfinite(bounds), bounds, np.inf)))
    else:
        bounds = np.full(len(cand), np.nan)
        order = np.argsort(errs)
    i = int(order[0])
    return GoalSolution(cand[i], float(errs[i]), float(bounds[i]), cand, errs, bounds, n_eval)
