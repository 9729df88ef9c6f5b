"""Stage 7 of a plan: what the plans achieved, in SI units.

- :class:`RouteMetrics` (:func:`route_metrics`): the headline numbers of one plan (cost, length,
  largest and final exact bound, bounds interpolated along the path, predicted offsets, the final
  check's repairs);
- :class:`PlanComparison` (:func:`compare_plans`): those of the bound-aware plan beside the
  bound-blind plan's;
- :class:`GoalOutcome` (:func:`goal_outcomes`): per scenario goal, where the bound-aware plan
  reaches it, the motion history and the tip predicted there, against the history its aiming
  assumed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..boundmap import BoundField
from ..history import pair_friction
from ..robot import Robot
from .aiming import AimedGoals
from .plans import Plans, RoutePlan

__all__ = ["RouteMetrics", "route_metrics", "PlanComparison", "compare_plans", "GoalOutcome", "goal_outcomes"]


@dataclass(frozen=True)
class RouteMetrics:
    """The headline numbers of one plan (:func:`route_metrics`).

    Bounds are those of the exact model given the last motion at the ordered waypoints (the
    friction bound after a rotation, the translation-last bound after a translation; Section V-B
    of Ha, Fagogenis & Dupont 2019) and those of the bound map interpolated along the path.

    Attributes
    ----------
    cost : float
        Sum of the legs' planning costs (length + weight x integral of the bound) [m].
    joint_path_length_m : float
        Length of the ordered path [m of the weighted joint metric].
    n_ordered_waypoints : int
    max_bound_at_waypoints_m, final_bound_m : float
        Largest and last exact bound at the waypoints [m] (NaN where it failed is skipped).
    final_bound_angle_rad : float
        Exact tip-angle bound at the last waypoint [rad].
    max_interpolated_friction_bound_m, mean_interpolated_friction_bound_m : float
        Largest and mean friction bound of the map along the path [m].
    max_interpolated_bound_given_last_motion_m : float
        Largest map bound given the last motion along the path [m].
    max_planned_bound_at_waypoints_m : float
        Largest map value, at the waypoints, of the quantity the exact bound gives [m].
    max_planned_minus_exact_bound_m : float
        Largest distance between that map value and the exact bound at the waypoints [m].
    max_predicted_offset_m : float
        Largest distance of the predicted tip from the standard-model tip at the waypoints [m];
        NaN when no prediction succeeded.
    final_predicted_offset_m : float
        That distance at the last waypoint [m]; NaN where the prediction failed.
    predictions_failed : int
        Waypoints whose prediction failed.
    repairs : int
        Phases the final check repaired.
    failures : tuple of str
        Phases the final check could not pass.
    """

    cost: float
    joint_path_length_m: float
    n_ordered_waypoints: int
    max_bound_at_waypoints_m: float
    final_bound_m: float
    final_bound_angle_rad: float
    max_interpolated_friction_bound_m: float
    mean_interpolated_friction_bound_m: float
    max_interpolated_bound_given_last_motion_m: float
    max_planned_bound_at_waypoints_m: float
    max_planned_minus_exact_bound_m: float
    max_predicted_offset_m: float
    final_predicted_offset_m: float
    predictions_failed: int
    repairs: int
    failures: tuple = ()


def route_metrics(plan: RoutePlan) -> RouteMetrics:
    """The headline numbers of one plan.

    Parameters
    ----------
    plan : RoutePlan

    Returns
    -------
    RouteMetrics
    """
    exact, b, pred = plan.bounds.exact, plan.bounds, plan.prediction
    offsets = np.asarray(pred.offset, float)
    return RouteMetrics(
        cost=float(sum(leg.cost for leg in plan.legs)), joint_path_length_m=float(b.dense_s[-1]),
        n_ordered_waypoints=len(plan.ordered),
        max_bound_at_waypoints_m=float(np.nanmax(exact.position)), final_bound_m=float(exact.position[-1]),
        final_bound_angle_rad=float(exact.angle[-1]),
        max_interpolated_friction_bound_m=float(np.nanmax(b.dense_friction)),
        mean_interpolated_friction_bound_m=float(np.nanmean(b.dense_friction)),
        max_interpolated_bound_given_last_motion_m=float(np.nanmax(b.dense_given_last)),
        max_planned_bound_at_waypoints_m=float(np.nanmax(b.planned)),
        max_planned_minus_exact_bound_m=float(np.nanmax(np.abs(b.planned - exact.position))),
        max_predicted_offset_m=float(np.nanmax(offsets)) if np.any(np.isfinite(offsets)) else math.nan,
        final_predicted_offset_m=float(offsets[-1]), predictions_failed=int(np.sum(~np.asarray(pred.ok))),
        repairs=int(plan.ordered.n_repairs), failures=tuple(plan.ordered.failures))


@dataclass(frozen=True)
class PlanComparison:
    """The bound-aware plan beside the bound-blind plan (same planner and seed, length only).

    Attributes
    ----------
    aware : RouteMetrics
        The bound-aware plan (the one executed).
    blind : RouteMetrics or None
        The bound-blind plan; None when it was not planned.
    """

    aware: RouteMetrics
    blind: RouteMetrics | None = None


def compare_plans(plans: Plans) -> PlanComparison:
    """The headline numbers of the bound-aware plan and of the bound-blind one.

    Parameters
    ----------
    plans : Plans

    Returns
    -------
    PlanComparison
    """
    blind = plans.blind
    return PlanComparison(aware=route_metrics(plans.aware), blind=None if blind is None else route_metrics(blind))


@dataclass(frozen=True, eq=False)
class GoalOutcome:
    """Where the bound-aware plan reaches one scenario goal, and what is predicted there.

    Attributes
    ----------
    waypoint : int
        Index of the ordered waypoint that reaches the goal.
    final_motion_status : str
        How the motion reaching it ends (:func:`ctrplan.planning.approach.end_with`).
    planned_field_bound_m : float
        The bound map's friction bound at the planned goal [m].
    planned_eta : ndarray of int, shape (n_tubes - 1,)
        Friction direction per pair of the history the plan creates at the goal (0: none).
    planned_cases : tuple of str, length n_tubes - 1
        Its case per pair (``friction``, ``translation_last``, ...).
    predicted_offset_m : float
        Distance of the predicted tip from the standard-model tip there [m]; NaN if it failed.
    assumed_eta : ndarray of int, shape (n_tubes - 1,), or None
        The same for the history the compensation assumed; None for a goal not compensated.
    assumed_cases : tuple of str or None
    planned_history_as_assumed : bool or None
        The plan creates the history the compensation assumed; None for a goal not compensated.
    predicted_miss_m : float or None
        Distance of the tip predicted at the goal's waypoint from the target [m]; None for a goal
        not compensated.
    """

    waypoint: int
    final_motion_status: str
    planned_field_bound_m: float
    planned_eta: np.ndarray
    planned_cases: tuple
    predicted_offset_m: float
    assumed_eta: np.ndarray | None = None
    assumed_cases: tuple | None = None
    planned_history_as_assumed: bool | None = None
    predicted_miss_m: float | None = None


def goal_outcomes(robot: Robot, field: BoundField, aimed: AimedGoals, plan: RoutePlan) -> tuple:
    """Per scenario goal: where the plan reaches it and what is predicted there.

    Parameters
    ----------
    robot : Robot
    field : BoundField
        The planner's bound map [m].
    aimed : AimedGoals
        The goals planned to, with their compensations.
    plan : RoutePlan
        The bound-aware plan.

    Returns
    -------
    tuple of GoalOutcome
        One per scenario goal, in order.
    """
    pred, mu = plan.prediction, robot.friction_coefficients
    out = []
    for k, (q, c, gi) in enumerate(zip(aimed.q, aimed.compensations, plan.goal_indices)):
        planned_eta, _, planned_cases = pair_friction(pred.state.at(gi), mu)
        extra = {}
        if c is not None:
            assumed_eta, _, assumed_cases = pair_friction(c.state, mu)
            extra = dict(assumed_eta=np.asarray(assumed_eta), assumed_cases=tuple(assumed_cases),
                         planned_history_as_assumed=bool(np.array_equal(assumed_eta, planned_eta)
                                                         and list(assumed_cases) == list(planned_cases)),
                         predicted_miss_m=float(np.linalg.norm(pred.tip[gi] - c.target)))
        out.append(GoalOutcome(waypoint=int(gi), final_motion_status=plan.final_motion_status[k],
                               planned_field_bound_m=float(field(np.asarray(q))),
                               planned_eta=np.asarray(planned_eta), planned_cases=tuple(planned_cases),
                               predicted_offset_m=float(pred.offset[gi]), **extra))
    return tuple(out)
