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

:func:`compensate_goal` then moves such a solution so that the tip *predicted* for the motion
history that reaches it (:func:`ctrplan.mechanics.predict_tip`: clearance model after a final
translation, friction model after a final rotation, Section V-B of Ha, Fagogenis & Dupont 2019)
is on the target, instead of the standard model's tip.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..choices import JointKind
from ..errors import CtrplanError, UnreachableGoalError
from ..io.scenario import JointGoal, TaskGoal
from .space import wrap_angle

__all__ = ["JointGoal", "TaskGoal", "GoalSolution", "IKSearch", "resolve_goal", "DEFAULT_IK_STARTS_PER_JOINT",
           "DEFAULT_IK_MAX_STARTS", "CompensatedGoal", "compensate_goal"]

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


# ----------------------------------------------------------------------------- compensation
# Compensated IK: stop when the predicted tip is this close to the target [m] (well below any
# goal tolerance, above the contact solver's tip accuracy, ~1 um for outer_tol 1e-7 m).
COMPENSATION_TIP_TOL = 1e-5
# Quasi-Newton iterations before giving up.
COMPENSATION_MAX_ITERATIONS = 15
# Finite-difference steps of the standard-model Jacobian [rad] and [m].
_FD_STEP_ROTATION = 1e-5
_FD_STEP_TRANSLATION = 1e-6
# Scale of a translation against a rotation in the minimum-norm step of a redundant robot [m/rad]
# (the same 0.01 as the x_scale of resolve_goal's least squares).
_TRANSLATION_SCALE = 0.01
# Step halvings of the backtracking line search.
_MAX_HALVINGS = 5


@dataclass(frozen=True, eq=False)
class CompensatedGoal:
    """A task-space goal aimed with the predicted tip instead of the standard model's.

    Attributes
    ----------
    q : ndarray, shape (n_joints,)
        The goal to plan to [rad or m]: ``q_compensated`` when ``accepted``, else ``q_standard``.
    q_compensated : ndarray, shape (n_joints,)
        Where the compensation ended (periodic angles in [-pi, pi)).
    q_standard : ndarray, shape (n_joints,)
        The standard-model IK solution it started from.
    target : ndarray, shape (3,)
        Target tip position [m].
    eta : ndarray of int, shape (n - 1,)
        Friction direction per pair of the assumed final approach (Eq. (39)), at the compensated goal.
    translation_last : ndarray of bool, shape (n - 1,)
        Per pair: a translation follows the pair's last rotation in the assumed approach.
    state : PairState
        The assumed history at the compensated goal (:mod:`ctrplan.history`): offsets of the
        configuration the tubes reach (drive backlash) [rad, m], directions, release and
        friction state per pair.
    predicted_tip_standard : ndarray, shape (3,)
        Predicted tip at ``q_standard`` with that history [m].
    predicted_miss_standard : float
        Its distance from the target [m]: the miss of standard-model IK.
    predicted_tip : ndarray, shape (3,)
        Predicted tip at ``q_compensated`` [m].
    predicted_miss : float
        Its distance from the target [m]: the compensated miss.
    standard_tip_error : float
        Distance of the standard model's tip at ``q_compensated`` from the target [m] (about
        the predicted offset: the standard model now misses by design).
    model : str
        ``"clearance"`` or ``"friction"``: the model of the prediction.
    converged : bool
        ``predicted_miss`` reached the iteration's tolerance.
    accepted : bool
        The compensated ``q`` is used: it converged to within the goal tolerance and passed the
        validity function.
    iterations : int
        Quasi-Newton iterations.
    n_predictions : int
        Contact-model solves (predictions).
    message : str
        What happened, for the report.
    """

    q: np.ndarray
    q_compensated: np.ndarray
    q_standard: np.ndarray
    target: np.ndarray
    eta: np.ndarray
    translation_last: np.ndarray
    state: object
    predicted_tip_standard: np.ndarray
    predicted_miss_standard: float
    predicted_tip: np.ndarray
    predicted_miss: float
    standard_tip_error: float
    model: str
    converged: bool
    accepted: bool
    iterations: int
    n_predictions: int
    message: str


def compensate_goal(target, robot, q_standard, state, settings=None, *, tolerance: float,
                    validity_fn=None, predict=None, tip_tol: float = COMPENSATION_TIP_TOL,
                    max_iterations: int = COMPENSATION_MAX_ITERATIONS) -> CompensatedGoal:
    """Joint vector whose predicted tip is on the target, for the history of its final approach.

    Quasi-Newton on the residual ``r(q) = p_pred(q; history(q)) - target``:
    ``q <- q - D (J D)^+ r(q)`` with ``D = diag(1, 0.01 m/rad)`` (minimum-norm step of a
    redundant robot), a backtracking line search on ``|r|`` and translations kept in their
    limits. ``J`` starts as the standard model's tip Jacobian at ``q_standard`` (finite
    differences, cheap: the prediction differs from the standard tip by a slowly varying offset,
    the friction and clearance deviation of a few mm) and is corrected by Broyden's update after
    every step. One contact solve per iteration (warm-started from the previous one).

    Parameters
    ----------
    target : array-like, shape (3,)
        Target tip position [m].
    robot : Robot
    q_standard : array-like, shape (n_joints,)
        Standard-model IK solution to start from (:func:`resolve_goal`) [rad or m].
    state : PairState or callable
        The history at the goal (:class:`ctrplan.history.PairState`), or ``state(q) ->
        PairState`` for a goal ``q`` (e.g. :func:`ctrplan.planning.history.approach_history` of
        the approach to ``q``, so that the lag of a drive with backlash and the friction state
        follow the goal as it moves).
    settings : ModelSettings, optional
    tolerance : float, keyword-only
        Goal tolerance [m], > 0: the compensated solution is accepted only within it.
    validity_fn : callable, optional, keyword-only
        ``validity_fn(q) -> bool`` (limits, stability, collisions); an invalid compensated
        configuration is not accepted.
    predict : callable, optional, keyword-only
        ``predict(robot, alpha, beta, settings=..., state=..., warm_start=...) -> Prediction``;
        default :func:`ctrplan.mechanics.predict_tip`.
    tip_tol : float, keyword-only
        Stop when the predicted miss is below this [m] (default 10 um).
    max_iterations : int, keyword-only

    Returns
    -------
    CompensatedGoal
        With the predicted miss of ``q_standard`` and of ``q_compensated``. When the iteration
        does not reach ``tolerance`` or the result is invalid, ``accepted`` is False, ``q`` is
        ``q_standard`` and ``message`` says why.

    Raises
    ------
    ValueError
        ``target`` not 3 finite numbers, ``tolerance`` <= 0, a state that does not fit the robot
        (see :func:`ctrplan.mechanics.predict_tip`), ``q_standard`` of the wrong length.
    CtrplanError
        The prediction fails at ``q_standard`` itself (e.g. ``ConvergenceError`` of the standard
        model, ``PhysicalParameterError`` without clearances).

    Notes
    -----
    Prediction: Section V-B with Sections II (clearance model) and III (friction model, Eqs.
    (37)-(47)) of Ha, Fagogenis & Dupont, IEEE T-RO 35(2):353-370, 2019,
    doi:10.1109/TRO.2018.2878906. A fixed ``state`` is held while q moves (a small change of the
    goal does not change the direction of the final rotations); a callable one is re-read at
    every trial goal.
    """
    from ..mechanics import ModelSettings, predict_tip, solve_standard  # noqa: PLC0415

    settings = settings or ModelSettings()
    predict = predict or predict_tip
    target = np.asarray(target, dtype=float).reshape(-1)
    if target.shape != (3,) or not np.all(np.isfinite(target)):
        raise ValueError(f"target must be 3 finite numbers [m], got {target!r}")
    if not np.isfinite(tolerance) or tolerance <= 0.0:
        raise ValueError(f"tolerance must be > 0 m, got {tolerance!r}")
    q0 = np.asarray(q_standard, dtype=float).reshape(-1)
    nj = len(robot.joints)
    if q0.shape != (nj,):
        raise ValueError(f"q_standard needs {nj} values ({', '.join(robot.joint_names)}), got {q0.shape}")
    periodic = np.array([j.periodic for j in robot.joints])
    rot = np.array([j.kind == JointKind.ROTATION for j in robot.joints])
    lo = np.where(periodic, -np.inf, robot.joint_lower)
    hi = np.where(periodic, np.inf, robot.joint_upper)
    scale = np.where(rot, 1.0, _TRANSLATION_SCALE)
    fd = np.where(rot, _FD_STEP_ROTATION, _FD_STEP_TRANSLATION)
    n_pred = 0
    last = {"sol": None, "state": None}
    state_at = state if callable(state) else (lambda q: state)

    def prediction(q):
        nonlocal n_pred
        alpha, beta = robot.configuration(q)
        n_pred += 1
        s = state_at(q)
        p = predict(robot, alpha, beta, settings=settings, state=s, warm_start=last["sol"])
        last["sol"], last["state"] = p.solution, s
        return p

    def std_tip(q):
        alpha, beta = robot.configuration(q)
        sol = solve_standard(robot, alpha, beta, settings, check_stability=False)
        if not sol.diagnostics.converged:
            raise ValueError("standard model did not converge")
        return np.asarray(sol.tip_position, dtype=float)

    def jacobian(q):
        # the standard model's tip Jacobian at the commanded q (the prediction's own standard
        # solution may sit at another configuration, e.g. behind a drive's dead band)
        p0 = std_tip(q)
        J = np.empty((3, nj))
        for j in range(nj):
            h = fd[j] if q[j] + fd[j] <= hi[j] else -fd[j]
            dq = np.zeros(nj)
            dq[j] = h
            J[:, j] = (std_tip(q + dq) - p0) / h
        return J

    first = prediction(q0)
    tip0 = first.tip_position.copy()
    miss0 = float(np.linalg.norm(tip0 - target))
    q, p, miss = q0.copy(), first, miss0
    it, message = 0, ""
    try:
        J = jacobian(q) if miss > tip_tol else None
        while miss > tip_tol and it < max_iterations:
            it += 1
            r = p.tip_position - target
            step = -scale * (np.linalg.pinv(J * scale[None, :]) @ r)
            t = 1.0
            for _ in range(_MAX_HALVINGS + 1):
                q_new = np.clip(q + t * step, lo, hi)
                try:
                    p_new = prediction(q_new)
                    miss_new = float(np.linalg.norm(p_new.tip_position - target))
                except (CtrplanError, ValueError, np.linalg.LinAlgError, FloatingPointError):
                    miss_new = np.inf
                if miss_new < miss:
                    break
                t *= 0.5
            if not miss_new < miss:
                message = f"no descent after {it} iterations"
                break
            # Broyden's update of the Jacobian with the step taken (the standard model's Jacobian
            # is only the first guess of the prediction's: alone it contracts the miss by as
            # little as 0.86 per iteration near the task-target goal)
            dq, dr = q_new - q, (p_new.tip_position - target) - r
            if float(dq @ dq) > 0.0:
                J = J + np.outer(dr - J @ dq, dq) / float(dq @ dq)
            q, p, miss = q_new, p_new, miss_new
    except (CtrplanError, ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
        message = f"stopped after {it} iterations: {type(exc).__name__}: {exc}"
    p_state = state_at(q)
    q = np.where(periodic, wrap_angle(q), q)
    converged = miss <= tip_tol
    std_err = float(np.linalg.norm(p.standard.tip_position - target))
    accepted = miss <= tolerance and bool(p.ok)
    if not p.ok:
        message = message or f"the prediction at the compensated goal did not converge: {p.solution.diagnostics.message}"
    if accepted and validity_fn is not None and not bool(validity_fn(q)):
        accepted, message = False, "the compensated configuration is invalid (limits, stability, map or collision)"
    if not accepted and not message:
        message = f"predicted miss {miss * 1e3:.3g} mm is outside the tolerance {tolerance * 1e3:.3g} mm"
    if accepted:
        message = (f"converged in {it} iterations" if converged else
                   f"within tolerance after {it} iterations ({message or 'iteration limit'})")
    return CompensatedGoal(
        q=q if accepted else q0.copy(), q_compensated=q, q_standard=q0.copy(), target=target,
        eta=np.asarray(p_state.eta, dtype=int).copy(), translation_last=np.asarray(p_state.released, bool).copy(),
        state=p_state,
        predicted_tip_standard=tip0, predicted_miss_standard=miss0, predicted_tip=p.tip_position.copy(),
        predicted_miss=miss, standard_tip_error=std_err, model=p.model, converged=converged, accepted=accepted,
        iterations=it, n_predictions=n_pred, message=message)
