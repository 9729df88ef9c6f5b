"""Stage 4 of a plan: task-space goals aimed with the tip *predicted* after the final approach
instead of the standard model's tip (compensated targeting), where the robot file's
``[prediction_validation]`` shows the prediction beat the standard model.

:func:`compensate_goal` moves an inverse-kinematics solution so that the tip predicted for the
motion history that reaches it (:func:`ctrplan.mechanics.predict_tip`: clearance model after a final
translation, friction model after a final rotation, Section V-B of Ha, Fagogenis & Dupont 2019)
is on the target; :func:`aim_decision` decides which model goals are aimed with
(:class:`AimDecision`, worded by :func:`aim_reason`) and :func:`aim_goals` aims a plan's goals
(:class:`AimedGoals`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from enum import Enum
from types import MappingProxyType
from typing import Mapping

import numpy as np

from .._log import deprecated_echo, progress_level
from ..calibration import PredictionValidation
from ..choices import AimWith, JointKind
from ..errors import CtrplanError
from ..io.scenario import TaskGoal
from .approach import approach_history, approach_rows
from .goals import ResolvedGoals
from .setup import PlanSetup
from .space import wrap_angle

__all__ = ["CompensatedGoal", "compensate_goal", "AimReason", "AimDecision", "aim_decision", "aim_reason",
           "AimedGoals", "aim_goals"]

logger = logging.getLogger(__package__)


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
        PairState`` for a goal ``q`` (e.g. :func:`ctrplan.planning.approach.approach_history` of
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


# ----------------------------------------------------------------------------- stage 4
class AimReason(str, Enum):
    """Why task-space goals are aimed with the model :class:`AimDecision` names (its value is
    what ``summary.json`` records as ``aiming.why``; :func:`aim_reason`
    words it)."""

    #: ``[planner] aim_with = "history"``.
    ASKED_HISTORY = "asked_history"
    #: ``[planner] aim_with = "standard"``.
    ASKED_STANDARD = "asked_standard"
    #: ``"auto"`` and the robot file has no ``[prediction_validation]``.
    NOT_VALIDATED = "not_validated"
    #: ``"auto"`` and the history-aware prediction beat the standard model on measurements.
    BEATS_STANDARD = "beats_standard"
    #: ``"auto"`` and it did not.
    DOES_NOT_BEAT_STANDARD = "does_not_beat_standard"


@dataclass(frozen=True)
class AimDecision:
    """Which model task-space goals are aimed with, and why (:func:`aim_decision`).

    Attributes
    ----------
    model : str
        ``"history-aware prediction"`` or ``"standard model"``.
    use_history : bool
        Whether task-space goals are compensated with the history-aware prediction.
    why : AimReason
        Why; the numbers behind it are in ``validation``.
    measured_mean_m, measured_max_m : float or None
        Mean and largest measured tip error of the model aimed with [m]; None when not measured.
    validation : PredictionValidation or None
        The robot file's ``[prediction_validation]``.
    """

    model: str
    use_history: bool
    why: AimReason
    measured_mean_m: float | None = None
    measured_max_m: float | None = None
    validation: PredictionValidation | None = None


def aim_decision(validation: PredictionValidation | None, aim_with: str = "auto") -> AimDecision:
    """Which model task-space goals are aimed with, and why.

    With ``aim_with = "auto"`` the history-aware prediction is used only when the robot file's
    ``[prediction_validation]`` (written by ``ctrplan discrepancy``) records that it beat the
    standard model on measurements (the interval of the per-unit paired difference of their mean
    test-split tip errors lies below zero); otherwise the standard model. ``"history"`` and
    ``"standard"`` force one.

    Parameters
    ----------
    validation : PredictionValidation or None
        The robot file's ``[prediction_validation]`` (``Scenario.calibration.prediction``).
    aim_with : AimWith or str
        ``"auto"``, ``"history"`` or ``"standard"``.

    Returns
    -------
    AimDecision

    Raises
    ------
    ValueError
        ``aim_with`` not one of the three.
    """
    if aim_with not in tuple(AimWith):
        raise ValueError(f"aim_with must be one of {', '.join(AimWith)}, got {aim_with!r}")
    pv = validation
    if aim_with == AimWith.HISTORY:
        use, why = True, AimReason.ASKED_HISTORY
    elif aim_with == AimWith.STANDARD:
        use, why = False, AimReason.ASKED_STANDARD
    elif pv is None:
        use, why = False, AimReason.NOT_VALIDATED
    else:
        use = bool(pv.history_beats_standard)
        why = AimReason.BEATS_STANDARD if use else AimReason.DOES_NOT_BEAT_STANDARD
    side = "history" if use else "standard"
    return AimDecision(model="history-aware prediction" if use else "standard model", use_history=use, why=why,
                       measured_mean_m=None if pv is None else getattr(pv, f"{side}_mean_m"),
                       measured_max_m=None if pv is None else getattr(pv, f"{side}_max_m"), validation=pv)


@dataclass(frozen=True, eq=False)
class AimedGoals:
    """Stage 4: the joint vectors the planner goes to.

    Attributes
    ----------
    final_motion : str
        ``"translation-last"`` or ``"rotation-last"`` (``[planner] final_motion``).
    q : tuple of ndarray, shape (n_joints,) each
        Planned goal per scenario goal [rad or m]: the compensated joint vector of a task-space
        goal, else the resolved one.
    compensations : tuple of (CompensatedGoal or None)
        Per goal; None for joint goals and where the compensation raised.
    errors : mapping of int to str
        Goal index -> why it was not compensated (the exception, as text).
    time_s : float
        Compensation time [s].
    aim : AimDecision
        The model goals are aimed with and why, with its measured error.
    """

    final_motion: str
    q: tuple
    compensations: tuple
    errors: Mapping[int, str]
    time_s: float
    aim: AimDecision


@deprecated_echo
def aim_goals(setup: PlanSetup, resolved: ResolvedGoals, validity, echo=None) -> AimedGoals:
    """Stage 4: aim task-space goals with the tip predicted after the final approach.

    The approach to goal k is assumed to be one straight segment from the previous planned goal
    (or the start), ordered as ``[planner] final_motion`` asks (relative rotations the short way,
    :func:`ctrplan.planning.approach.approach_history`); the joint vector whose predicted tip is on
    the target is found by :func:`ctrplan.planning.aiming.compensate_goal` (Section V-B of Ha,
    Fagogenis & Dupont 2019). A goal whose compensation raises is planned to its standard-model
    solution, and the reason is kept. Joint goals are planned as resolved. Where
    :func:`aim_decision` chooses the standard model (``[planner] aim_with``), task-space goals are
    planned to their standard-model solutions.

    Parameters
    ----------
    setup : PlanSetup
    resolved : ResolvedGoals
    validity : callable
        State validity (:func:`check_start`'s checker).
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    AimedGoals
    """
    sc, robot = setup.scenario, setup.robot
    final_motion = sc.planner.final_motion
    t0 = time.perf_counter()
    compensations, goal_q = [], []
    motion = [np.asarray(sc.start, dtype=float)]      # the assumed motion so far (approaches to the goals)
    errors = {}
    aim = aim_decision(sc.calibration.prediction, sc.planner.aim_with)
    if any(isinstance(doc, TaskGoal) for doc in sc.goals):
        logger.log(progress_level(), f"aiming task-space goals with the {aim.model}: {aim_reason(aim)}")
    for k, (doc, g) in enumerate(zip(sc.goals, resolved.goals)):
        c = None
        if isinstance(doc, TaskGoal) and aim.use_history:
            before = np.array(motion)

            def state_at(q, before=before):
                return approach_history(robot, before[-1], q, final_motion, before=before)

            try:
                c = compensate_goal(doc.tip_position, robot, g.q, state_at, setup.settings, tolerance=doc.tolerance,
                                    validity_fn=validity)
            except CtrplanError as exc:   # no prediction at the standard solution: plan to it, say why
                errors[k] = f"{type(exc).__name__}: {exc}"
                logger.warning(f"goal {k + 1}: no compensation ({errors[k]}); planning to the standard-model goal")
        if c is not None:
            logger.log(progress_level(),
                       f"goal {k + 1} ({final_motion}, {c.model} model, eta {_eta_text(c.eta)}): predicted miss of "
                       f"standard-model IK {c.predicted_miss_standard * 1e3:.3f} mm, compensated "
                       f"{c.predicted_miss * 1e3:.3f} mm ({'used' if c.accepted else 'not used: ' + c.message}); "
                       f"q = {np.round(c.q, 4).tolist()}")
        compensations.append(c)
        goal_q.append(c.q if c is not None else g.q)
        motion += list(approach_rows(robot, motion[-1], goal_q[-1], final_motion)[1:])
    return AimedGoals(final_motion=final_motion, q=tuple(goal_q), compensations=tuple(compensations),
                      errors=MappingProxyType(errors), time_s=time.perf_counter() - t0, aim=aim)


def _eta_text(eta) -> str:
    """Per-pair directions as text, e.g. ``+1;-1`` (0: no friction on that pair)."""
    return ";".join(f"{int(e):+d}" if e else "0" for e in eta)


def aim_reason(decision) -> str:
    """Why task-space goals are aimed with ``decision.model``, in one sentence.

    Parameters
    ----------
    decision : AimDecision
        Its ``why`` (:class:`~ctrplan.planning.aiming.AimReason`) and ``validation`` (the robot
        file's ``[prediction_validation]``: data file, test samples, mean and largest tip errors
        of both models and the paired difference's interval [m]).

    Returns
    -------
    str
        E.g. ``on measurements (run.csv, 200 test samples) the history-aware prediction's tip
        error is mean 0.91 / max 2.10 mm against the standard model's 1.52 / 3.40 mm (mean
        difference -0.61 mm, 95 % interval -0.80..-0.42 mm)``.
    """
    why = getattr(decision.why, "value", decision.why)
    pv = decision.validation
    figures = ""
    if pv is not None:
        figures = (f"on measurements ({pv.data_file or 'unnamed data'}, {pv.test_samples} test samples) "
                   f"the history-aware prediction's tip error is mean {pv.history_mean_m * 1e3:.2f} / max "
                   f"{pv.history_max_m * 1e3:.2f} mm against the standard model's {pv.standard_mean_m * 1e3:.2f}"
                   f" / {pv.standard_max_m * 1e3:.2f} mm")
        if pv.difference_low_m is not None:
            figures += (f" (mean difference {pv.difference_mean_m * 1e3:+.2f} mm, 95 % interval "
                        f"{pv.difference_low_m * 1e3:+.2f}..{pv.difference_high_m * 1e3:+.2f} mm)")
    if why == "asked_history":
        return "[planner] aim_with = \"history\"" + (f"; {figures}" if figures else "; not validated on measurements")
    if why == "asked_standard":
        return "[planner] aim_with = \"standard\""
    if why == "not_validated":
        return ("the robot file has no [prediction_validation]: the history-aware prediction is not validated on "
                "measurements (ctrplan discrepancy writes it)")
    if why == "beats_standard":
        return figures
    return figures + ": it does not beat the standard model"
