"""Stages 3 and 4 of a plan: the start checked (:func:`check_start`), each goal as a joint vector
(:class:`ResolvedGoals`), the model goals are aimed with (:class:`AimDecision`) and task-space goals
aimed with the tip predicted after the final approach (:class:`AimedGoals`)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from enum import Enum
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ..choices import AimWith
from .._log import deprecated_echo, progress_level
from ..calibration import PredictionValidation
from ..errors import CtrplanError, UnreachableGoalError
from ..io.scenario import TaskGoal
from ..planning import IKSearch, resolve_goal
from ..planning.goals import compensate_goal
from ..planning.history import approach_history, approach_rows
from .setup import PlanSetup
from .wording import aim_reason

__all__ = ["ResolvedGoals", "AimReason", "AimDecision", "AimedGoals", "GoalCheckCounts", "check_start", "resolve_goals",
           "aim_decision", "aim_goals"]

logger = logging.getLogger(__package__)


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


class AimReason(str, Enum):
    """Why task-space goals are aimed with the model :class:`AimDecision` names (its value is
    what ``summary.json`` records as ``aiming.why``; :func:`ctrplan.pipeline.wording.aim_reason`
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


@deprecated_echo
def aim_goals(setup: PlanSetup, resolved: ResolvedGoals, validity, echo=None) -> AimedGoals:
    """Stage 4: aim task-space goals with the tip predicted after the final approach.

    The approach to goal k is assumed to be one straight segment from the previous planned goal
    (or the start), ordered as ``[planner] final_motion`` asks (relative rotations the short way,
    :func:`ctrplan.planning.history.approach_history`); the joint vector whose predicted tip is on
    the target is found by :func:`ctrplan.planning.goals.compensate_goal` (Section V-B of Ha,
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
