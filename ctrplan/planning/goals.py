"""Planning goals and stage 3 of a plan: a joint vector, or a tip position with a tolerance solved
by inverse kinematics; the scenario's start checked (:func:`check_start`) and each goal resolved to
one joint vector (:func:`resolve_goals` -> :class:`ResolvedGoals`).

Inverse kinematics minimizes ``|p_tip(q) - p_target|^2`` with ``scipy.optimize.least_squares``
(trust-region reflective, translation limits as bounds, periodic rotations unbounded) on the
standard model's tip position, started from every node of a coarse grid of the joint space
(plus a seeded jitter) or, when that grid would exceed ``max_starts`` (six joints: 3^6 = 729
starts), from ``max_starts`` seeded Latin-hypercube points of the joint box. All converged
solutions within tolerance that pass the validity function are kept; the one with the smallest
friction bound (from a :class:`~ctrplan.boundmap.BoundField`, or the smallest tip error without
one) is chosen. A redundant robot (more than three joints) has a manifold of solutions, and
more starts find lower bounds on it. Such a solution is then aimed (:mod:`~ctrplan.planning.aiming`).
"""

from __future__ import annotations

import logging
import time

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .._log import deprecated_echo, progress_level
from ..choices import JointKind
from ..errors import CtrplanError, UnreachableGoalError
from ..io.scenario import JointGoal, TaskGoal
from .setup import PlanSetup
from .space import wrap_angle

__all__ = ["JointGoal", "TaskGoal", "GoalSolution", "IKSearch", "resolve_goal", "DEFAULT_IK_STARTS_PER_JOINT",
           "DEFAULT_IK_MAX_STARTS", "ResolvedGoals", "GoalCheckCounts", "check_start", "resolve_goals"]

logger = logging.getLogger(__package__)

# Coarse start grid: nodes per joint (3 joints -> 27 starts, ~1-3 s with a ~1 ms model).
DEFAULT_IK_STARTS_PER_JOINT = 3
# Largest number of starts; a bigger grid is replaced by this many Latin-hypercube points
# (six joints: 64 starts of ~0.1 s each instead of 729).
DEFAULT_IK_MAX_STARTS = 64

# Residual returned where the model fails, so least_squares steers away [m].
_FAILED_RESIDUAL = 1.0

# Two IK solutions closer than this in every joint are the same [rad or m].
_DUPLICATE_TOL = 1e-4

# Resolutions at which IK candidates are ranked: friction bounds closer than _BOUND_RESOLUTION [m]
# and tip residuals closer than _RESIDUAL_RESOLUTION times the goal tolerance count as equal, so a
# tie (a flat bound map, two solutions both converged far inside the tolerance) goes to the
# solution found first from the seeded starts rather than to floating-point rounding.
_BOUND_RESOLUTION = 1e-9
_RESIDUAL_RESOLUTION = 1e-3


def _task_space_goal(tip_position_m, tolerance_m: float = 1e-3) -> TaskGoal:
    """``TaskGoal(tip_position_m, tolerance_m)``: what the deprecated name
    ``ctrplan.planning.TaskSpaceGoal`` makes (its keywords were ``tip_position_m`` and
    ``tolerance_m``) [m]."""
    return TaskGoal(tip_position_m, tolerance_m)


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


def as_goal(goal) -> JointGoal | TaskGoal:
    """A goal as a :class:`JointGoal` or a :class:`TaskGoal`.

    Parameters
    ----------
    goal : JointGoal, TaskGoal, mapping, object, or array-like of shape (n_joints,)
        Mappings as a scenario file's goal tables: ``{"q": [...]}`` [rad or m], or
        ``{"tip_position_m": [x, y, z], "tolerance_m": t}`` [m] (tolerance default 1 mm);
        another object with ``tip_position`` and ``tolerance``, or with ``q``, as those fields.

    Returns
    -------
    JointGoal or TaskGoal

    Raises
    ------
    ValueError
        A mapping with neither ``q`` nor ``tip_position_m``, or values the goal types refuse.
    """
    if isinstance(goal, (JointGoal, TaskGoal)):
        return goal
    if isinstance(goal, Mapping):
        if "tip_position_m" in goal:
            return TaskGoal(goal["tip_position_m"], goal.get("tolerance_m", 1e-3))
        if "q" in goal:
            return JointGoal(goal["q"])
        raise ValueError(f"a goal mapping needs 'q' [rad or m] or 'tip_position_m' [m], got keys {sorted(goal)}")
    if hasattr(goal, "tip_position") and hasattr(goal, "tolerance"):
        return TaskGoal(goal.tip_position, goal.tolerance)
    if hasattr(goal, "q"):
        return JointGoal(goal.q)
    return JointGoal(goal)


@dataclass(frozen=True)
class IKSearch:
    """The multi-start inverse kinematics of :func:`resolve_goal` for a task-space goal.

    Attributes
    ----------
    starts_per_joint : int
        Multi-start grid nodes per joint.
    max_starts : int
        Largest number of starts: a bigger grid is replaced by this many seeded Latin-hypercube
        points of the joint box.
    seed : int
        Seed of the start jitter.
    max_nfev : int
        Model evaluations per least-squares run.
    """

    starts_per_joint: int = DEFAULT_IK_STARTS_PER_JOINT
    max_starts: int = DEFAULT_IK_MAX_STARTS
    seed: int = 0
    max_nfev: int = 60


def resolve_goal(goal, robot, validity_fn=None, field=None, solve_standard=None, settings=None, *,
                 search: IKSearch = IKSearch()) -> GoalSolution:
    """Turn a goal into one joint vector.

    Parameters
    ----------
    goal : JointGoal, TaskGoal, array-like of shape (n_joints,), dict or object
        As :func:`as_goal`: a joint vector [rad or m] is a :class:`JointGoal`; dicts as in a
        scenario file: ``{"q": [...]}`` or ``{"tip_position_m": [...], "tolerance_m": ...}`` [m].
    robot : Robot
    validity_fn : callable, optional
        ``validity_fn(q) -> bool``; invalid IK solutions are discarded.
    field : BoundField, optional
        Chooses among solutions by the smallest ``position`` bound (bounds within 1 nm are
        equal), then by the smallest tip residual (residuals within 1e-3 of the tolerance are
        equal), then by the order the seeded starts found them. Without a field, by residual
        and order found.
    solve_standard : callable, optional
        ``(robot, alpha, beta, settings) -> StandardSolution``; default
        :func:`ctrplan.mechanics.solve_standard`.
    settings : ModelSettings, optional
    search : IKSearch, keyword-only
        Starts, their seed and the evaluations of each least-squares run of a task-space goal.

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
    goal = as_goal(goal)
    if isinstance(goal, JointGoal):
        q = np.asarray(goal.q, dtype=float).reshape(-1)
        if q.shape != (len(robot.joints),):
            raise ValueError(f"joint goal needs {len(robot.joints)} values ({', '.join(robot.joint_names)}), got {q.shape}")
        if validity_fn is not None and not bool(validity_fn(q)):
            raise UnreachableGoalError(f"goal configuration {q} is invalid (limits, stability or collision)")
        b = float(field(q)) if field is not None else float("nan")
        return GoalSolution(q, 0.0, b, q[None, :], np.zeros(1), np.array([b]))

    target, tol = np.asarray(goal.tip_position, dtype=float), float(goal.tolerance)
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

    rng = np.random.default_rng(search.seed)
    best_err, best_q = np.inf, None
    sols, errs = [], []
    starts = _starts(robot, int(search.starts_per_joint), int(search.max_starts), rng)
    for q0 in starts:
        res = least_squares(residual, q0, bounds=(lo, hi), method="trf", max_nfev=search.max_nfev,
                            x_scale=np.where([j.kind == JointKind.ROTATION for j in robot.joints], 1.0, 0.01))
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
    found = np.arange(len(cand))
    err_rank = np.floor(errs / (_RESIDUAL_RESOLUTION * tol))
    if field is not None:
        bounds = np.asarray(field(cand), dtype=float).reshape(-1)
        bound_rank = np.where(np.isfinite(bounds), np.round(bounds / _BOUND_RESOLUTION), np.inf)
        order = np.lexsort((found, err_rank, bound_rank))
    else:
        bounds = np.full(len(cand), np.nan)
        order = np.lexsort((found, err_rank))
    i = int(order[0])
    return GoalSolution(cand[i], float(errs[i]), float(bounds[i]), cand, errs, bounds, n_eval)


# ----------------------------------------------------------------------------- stage 3
@dataclass(frozen=True, eq=False)
class ResolvedGoals:
    """Stage 3: each scenario goal as a joint vector.

    Attributes
    ----------
    goals : tuple of GoalSolution
        One per scenario goal, in order: ``q`` shape (n_joints,) [rad or m], ``tip_error`` [m],
        ``bound`` (the map's friction bound there) [m], the IK ``candidates`` and
        ``n_model_evaluations``.
    time_s : float
        Inverse-kinematics time [s].
    """

    goals: tuple
    time_s: float


@dataclass(frozen=True)
class GoalCheckCounts:
    """Work of the validity checker that checked the start and the goals (inverse kinematics and
    compensation included), as the summary reports it.

    Attributes
    ----------
    n_calls : int
        States checked.
    n_model : int
        Standard-model solves.
    collision_time_s : float
        Time in collision checks [s].
    """

    n_calls: int
    n_model: int
    collision_time_s: float

    @classmethod
    def of(cls, validity) -> "GoalCheckCounts":
        """The counters of a checker (:func:`check_start`'s) as they stand.

        Parameters
        ----------
        validity : BatchValidityChecker

        Returns
        -------
        GoalCheckCounts
        """
        return cls(n_calls=int(validity.n_calls), n_model=int(validity.n_model),
                   collision_time_s=float(validity.seconds_collision))


def check_start(setup: PlanSetup, field):
    """Stage 3a: the search's validity checker, after checking the scenario's start with it.

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
        Its validity flags reject states near unstable or failed map nodes.

    Returns
    -------
    BatchValidityChecker
        The planning search's checker (``setup.route_checks(field).search``: collision with
        ``setup.obstacles``, elastic stability, the map's valid region;
        ``setup.check_settings``), which the plans then search with. It counts its calls
        (``n_calls``, ``n_model``, ``seconds_collision``); taken after the goals are aimed, they are
        the goal stages' work, which the summary reports.

    Raises
    ------
    UnreachableGoalError
        The start is in collision, elastically unstable or outside the map's valid region.
    """
    sc = setup.scenario
    validity = setup.route_checks(field).search
    if not validity(sc.start):
        raise UnreachableGoalError(f"{sc.file}: start configuration {sc.joint_dict(sc.start)} is invalid "
                                   "(collision, elastic instability or outside the bound map's valid region)")
    return validity


@deprecated_echo
def resolve_goals(setup: PlanSetup, field, validity, echo=None) -> ResolvedGoals:
    """Stage 3b: each scenario goal as one joint vector.

    Joint goals are checked; task-space goals are solved by inverse kinematics with the standard
    model, keeping every valid solution within the goal's tolerance and taking the one with the
    smallest friction bound in ``field`` (:func:`ctrplan.planning.resolve_goal`, IK seed k + 1
    for goal k).

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
    validity : callable
        State validity (:func:`check_start`'s checker).
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    ResolvedGoals

    Raises
    ------
    UnreachableGoalError
        A joint goal is invalid, or no valid IK solution reaches a task goal within its tolerance.
    """
    t0 = time.perf_counter()
    goals = tuple(resolve_goal(g, setup.robot, validity_fn=validity, field=field, settings=setup.check_settings,
                               search=IKSearch(seed=k + 1))
                  for k, g in enumerate(setup.scenario.goals))
    seconds = time.perf_counter() - t0
    for k, g in enumerate(goals):
        logger.log(progress_level(), f"goal {k + 1}: q = {np.round(g.q, 4).tolist()}, tip error "
                   f"{g.tip_error * 1e3:.3f} mm, field bound {g.bound * 1e3:.2f} mm ({len(g.candidates)} candidates)")
    return ResolvedGoals(goals=goals, time_s=seconds)
