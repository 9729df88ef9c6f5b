"""Friction-bounded motion planning in the joint space of a concentric tube robot.

Building blocks (each usable on its own in an OMPL setup, see ``docs/planning.md``):

- :class:`JointStateSpace`: OMPL compound space (SO2 per periodic rotation, bounded reals for
  translations) with numpy conversions; :func:`unwrap_path`.
- :class:`CollisionChecker`: robot body (capsule chain) versus the obstacles of
  :mod:`ctrplan.obstacles` (spheres, capsules, boxes, meshes and any registered type) with
  python-fcl.
- :class:`BoundField` (from :mod:`ctrplan.boundmap`): the friction bound of Ha, Fagogenis &
  Dupont 2019 (doi:10.1109/TRO.2018.2878906) precomputed on a grid and interpolated.
- :class:`BoundCostObjective`: ``ob.OptimizationObjective`` = length + weight x integral of bound.
- :func:`plan_leg` with :data:`PLANNERS`, :class:`ValidityChecker`, :class:`SearchSettings`, :class:`SearchResult`.
- :func:`order_path` (rotate, then translate) and :func:`bounds_given_last_motion`.
- :func:`resolve_goal` for joint or tip-position goals; :func:`compensate_goal` aims a tip-position
  goal with the tip predicted for the motion that reaches it (compensated targeting).
- :func:`path_history`, :func:`approach_history`, :func:`end_with`, :func:`goal_indices`: the
  friction-relevant motion history of a path (direction of each pair's last relative rotation,
  translation-last) and the scenario's final motion (:data:`FINAL_MOTIONS`).
- :class:`~ctrplan.planning.validity.BatchValidityChecker` (states and motions in compiled
  batches, an OMPL motion validator), :class:`~ctrplan.planning.verify.MotionVerifier` (the
  final check of ordered phases) and :func:`plan_route` (plan, order, check, repair).
"""

from ..boundmap import (QUANTITIES, BoundField, BoundFieldKeyError, InterpolationError, field_key,
                        interpolation_error)
from .collision import CollisionChecker, CollisionReport
from .goals import (CompensatedGoal, GoalSolution, IKSearch, JointGoal, TaskGoal, as_goal, compensate_goal,
                    resolve_goal)
from .history import DEFAULT_FINAL_MOTION, FINAL_MOTIONS, approach_history, end_with, goal_indices, path_history
from .objective import DEFAULT_BOUND_WEIGHT, BoundCostObjective
from .ordering import LastMotionBounds, OrderedPath, OrderedWaypoint, bounds_given_last_motion, order_path
from .planners import PLANNERS, SearchResult, SearchSettings, ValidityChecker, plan_leg
from .route import CheckResolution, Route, RouteChecks, plan_route, route_checks
from .space import DEFAULT_METERS_PER_RADIAN, JointStateSpace, unwrap_path, wrap_angle
from .validity import BatchMotionValidator, BatchValidityChecker, use_motion_validator
from .verify import MotionCheck, MotionVerifier

__all__ = [
    "JointStateSpace", "DEFAULT_METERS_PER_RADIAN", "unwrap_path", "wrap_angle",
    "CollisionChecker", "CollisionReport",
    "BoundField", "BoundFieldKeyError", "InterpolationError", "QUANTITIES", "field_key", "interpolation_error",
    "BoundCostObjective", "DEFAULT_BOUND_WEIGHT",
    "PLANNERS", "SearchResult", "SearchSettings", "ValidityChecker", "plan_leg",
    "OrderedPath", "OrderedWaypoint", "LastMotionBounds", "order_path", "bounds_given_last_motion",
    "JointGoal", "TaskGoal", "as_goal", "GoalSolution", "IKSearch", "resolve_goal", "CompensatedGoal",
    "compensate_goal",
    "path_history", "approach_history", "end_with", "goal_indices", "FINAL_MOTIONS",
    "DEFAULT_FINAL_MOTION",
    "BatchValidityChecker", "BatchMotionValidator", "use_motion_validator", "MotionVerifier", "MotionCheck",
    "Route", "RouteChecks", "CheckResolution", "plan_route", "route_checks",
]

# Names this package had before each concept got one name: PlanResult (now SearchResult, distinct
# from the user-facing ctrplan.PlanResult), TaskSpaceGoal (now TaskGoal, the scenario's type) and
# plan (now plan_leg, distinct from ctrplan.plan, the plan of a scenario).
_DEPRECATED = {"PlanResult": ("SearchResult", "SearchResult"),
               "TaskSpaceGoal": ("TaskGoal(tip_position, tolerance)", "_task_space_goal"),
               "plan": ("plan_leg", "plan_leg")}


def __getattr__(name):
    if name in _DEPRECATED:
        import warnings

        from . import goals, planners

        use, attr = _DEPRECATED[name]
        warnings.warn(f"ctrplan.planning.{name} is deprecated: use ctrplan.planning.{use}", DeprecationWarning,
                      stacklevel=2)
        return getattr(planners, attr, None) or getattr(goals, attr)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
