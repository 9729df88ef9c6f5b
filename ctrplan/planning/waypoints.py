"""The ordered waypoints of a plan with their bounds and predictions, one array per quantity
(:class:`WaypointTable`: what ``path.csv`` holds, in SI units), and stage 6, the drive trajectory
along them (:func:`drive_trajectory`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calibration import CalibratedBound
from ..choices import BoundKind, MotionKind
from ..errors import JointLimitError
from .plans import RoutePlan
from .setup import PlanSetup

__all__ = ["WaypointTable", "waypoint_table", "calibrated_bound", "drive_trajectory"]


def _frozen(a, dtype=None) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class WaypointTable:
    """The K ordered waypoints of one plan (the rows of ``path.csv``), as read-only arrays in SI
    units.

    Attributes
    ----------
    motion : ndarray of str, shape (K,)
        The phase that ends at each waypoint: ``"start"``, ``"rotation"`` or ``"translation"``.
    q : ndarray, shape (K, n_joints)
        Joint values [rad or m], in the robot's joint order.
    tip : ndarray, shape (K, 3)
        Standard-model tip position [m]; NaN where the exact bound failed.
    bound_position_m : ndarray, shape (K,)
        Exact tip-error bound given the last motion [m]: the friction bound after the start and a
        rotation, the translation-last bound after a translation (Section V-B of Ha, Fagogenis &
        Dupont 2019); NaN where it failed.
    calibrated_bound_m : ndarray, shape (K,)
        The robot file's calibrated bound ``factor (bound + noise margin)`` [m]; NaN without a
        ``[bound_calibration]``.
    planned_bound_m : ndarray, shape (K,)
        The same quantity as the planner's bound map gives it [m].
    bound_angle_rad : ndarray, shape (K,)
        Exact tip-angle bound given the last motion [rad].
    bound_kind : ndarray of str, shape (K,)
        ``"friction"`` or ``"translation_last"``.
    predicted_tip : ndarray, shape (K, 3)
        Tip predicted for the motion history the ordered plan creates [m]; NaN where the
        prediction failed.
    predicted_offset_m : ndarray, shape (K,)
        Its distance from the standard-model tip [m]; NaN where it failed.
    prediction_eta : ndarray of int, shape (K, n_tubes - 1)
        Friction direction the prediction applied per pair (0: frictionless there).
    prediction_cases : tuple of str, length K
        Per-pair cases of the prediction (``friction``, ``translation_last``, ``no_history`` or
        ``frictionless``) joined by ``;``.
    """

    motion: np.ndarray
    q: np.ndarray
    tip: np.ndarray
    bound_position_m: np.ndarray
    calibrated_bound_m: np.ndarray
    planned_bound_m: np.ndarray
    bound_angle_rad: np.ndarray
    bound_kind: np.ndarray
    predicted_tip: np.ndarray
    predicted_offset_m: np.ndarray
    prediction_eta: np.ndarray
    prediction_cases: tuple

    def __len__(self) -> int:
        return len(self.motion)


def calibrated_bound(calibration: CalibratedBound | None, bound) -> np.ndarray:
    """The calibrated bound ``factor (bound + noise_margin_m)`` of the robot file's
    ``[bound_calibration]`` (:mod:`ctrplan.discrepancy.verdict.coverage`) [m]; NaN without one.

    Parameters
    ----------
    calibration : CalibratedBound or None
        ``Scenario.calibration.bound``.
    bound : array-like
        The model's bound [m].

    Returns
    -------
    ndarray
        Same shape as ``bound``.
    """
    b = np.asarray(bound, float)
    if calibration is None:
        return np.full_like(b, np.nan)
    return calibration.apply(b)


def waypoint_table(plan: RoutePlan, calibration: CalibratedBound | None = None) -> WaypointTable:
    """The ordered waypoints of a plan with their bounds and predictions.

    Parameters
    ----------
    plan : RoutePlan
    calibration : CalibratedBound, optional
        The robot file's ``[bound_calibration]``; without one ``calibrated_bound_m`` is NaN.

    Returns
    -------
    WaypointTable
    """
    exact, pred = plan.bounds.exact, plan.prediction
    motions = list(plan.ordered.motions)
    tips = [np.full(3, np.nan) if res is None else np.asarray(res.standard.tip_position, float)
            for res in exact.results]
    return WaypointTable(
        motion=_frozen(motions), q=_frozen(plan.ordered.q, float),
        tip=_frozen(np.reshape(tips, (-1, 3)), float),
        bound_position_m=_frozen(exact.position, float),
        calibrated_bound_m=_frozen(calibrated_bound(calibration, exact.position)),
        planned_bound_m=_frozen(plan.bounds.planned, float), bound_angle_rad=_frozen(exact.angle, float),
        bound_kind=_frozen([BoundKind.TRANSLATION_LAST if m == MotionKind.TRANSLATION else BoundKind.FRICTION
                            for m in motions]),
        predicted_tip=_frozen(np.reshape(pred.tip, (-1, 3)), float),
        predicted_offset_m=_frozen(pred.offset, float), prediction_eta=_frozen(pred.eta_used, int),
        prediction_cases=tuple(pred.cases))


def drive_trajectory(setup: PlanSetup, ordered):
    """Stage 6: the drive trajectory along an ordered path, checked against the drive limits.

    Parameters
    ----------
    setup : PlanSetup
        Its scenario's ``[drive]`` limits [rad or m per s, s^2, s^3] and control rate [Hz].
    ordered : OrderedPath
        Waypoints shape (K, n_joints) [rad or m] with their motions.

    Returns
    -------
    Trajectory or None
        Rest-to-rest ruckig segments, stopping between phases
        (:func:`ctrplan.trajectory.time_parameterize_robot`); None when the scenario has no
        ``[drive]`` table.

    Raises
    ------
    JointLimitError
        The sampled trajectory violates a drive limit (the first five violations are named).
    """
    from ..trajectory import check_trajectory, time_parameterize_robot

    sc = setup.scenario
    traj = time_parameterize_robot(setup.robot, ordered.q, ordered.motions, sc.drive) \
        if sc.drive is not None else None
    violations = check_trajectory(traj) if traj is not None else []
    if violations:
        raise JointLimitError(f"{sc.file}: the time-parameterized trajectory violates the drive limits: "
                              + "; ".join(str(v) for v in violations[:5]))
    return traj
