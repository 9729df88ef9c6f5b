"""Friction-bounded motion planning of a concentric tube robot: the building blocks of a search
in its joint space, and the stages of a scenario's plan that compose them.

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
- :class:`~ctrplan.planning.roadmap.Roadmap`: PRM* with the bound in its edge costs, built once
  per robot, map and obstacles.

The stages of a plan, each a function that returns a frozen result in SI units (m, rad, s);
:func:`ctrplan.plan` composes them and returns them all in its
:class:`~ctrplan.api.PlanResult` (``result.run``, a :class:`PlanRun`):

1. :func:`setup_plan` (or :func:`load_setup` from a file) -> :class:`PlanSetup`: the scenario,
   its robot and the robot file's calibration (``Scenario.calibration``), the model settings and
   the bound map's spec;
2. :func:`prepare_bound_map` -> :class:`BoundMapStage`: the robot's bound map (shipped in
   ``<robot dir>/boundmaps/`` as ``.npz`` or ``.zarr``, or cached) or computed into a zarr store
   (local cores or a Dask cluster; an interrupted computation resumes from its finished chunks);
   or :func:`given_bound_map`, a map handed in;
3. :func:`check_start` -> the search's validity checker, after checking the start;
   :func:`resolve_goals` -> :class:`ResolvedGoals`: each goal as a joint vector (task-space goals
   by inverse kinematics preferring the smallest bound);
4. :func:`aim_decision` -> :class:`AimDecision` and :func:`aim_goals` -> :class:`AimedGoals`:
   task-space goals aimed with the tip *predicted* after the final approach (``[planner]
   final_motion``: translation-last, the default, or rotation-last; Section V-B of Ha et al.
   2019) instead of the standard model's tip (:func:`compensate_goal`),
   where the robot file's ``[prediction_validation]`` shows the prediction beat the standard
   model;
5. :func:`plan_routes` -> :class:`Plans`: every leg planned with the same planner and seed,
   bound-aware (length + weight x integral of the bound) and bound-blind (length only); each
   plan (:class:`RoutePlan`) is ordered into rotations then translations (Section V-B) and both
   phases checked, the phases reaching each goal swapped if the final motion asks for it; the
   exact model re-run at the ordered waypoints gives the bound given the last motion
   (:func:`bounds_along_path` -> :class:`PathBounds`) and the tip predicted for the history the
   ordered plan creates (:func:`predict_waypoints` -> :class:`WaypointPredictions`; one contact
   solve at most per waypoint, usually none: the bound's own solutions are reused); the
   bound-aware plan's waypoints as arrays: :func:`waypoint_table` -> :class:`WaypointTable`;
6. :func:`drive_trajectory` -> the drive trajectory (ruckig, rest-to-rest, stop between
   phases), its samples checked;
7. :func:`compare_plans` -> :class:`PlanComparison` (:class:`RouteMetrics` of both plans) and
   :func:`goal_outcomes` -> :class:`GoalOutcome` per goal.

:func:`run_stages` runs stages 3 to 7 -> :class:`PlanRun`. The outputs are a package of their own,
:mod:`ctrplan.planning.outputs`, the only one with millimetres, degrees and dicts:
:func:`plan_summary` (``summary.json``), :func:`write_plan_report` (path.csv, trajectory.csv,
figures, plan.html and summary.json, written atomically) and :func:`log_summary`, with the
readers beside the writers (:func:`read_plan_record`,
:func:`ctrplan.planning.outputs.read_plan_folder`).

The stages print nothing: they log to ``ctrplan.planning`` (:mod:`logging`) the lines ``ctrplan
plan`` shows (scenario, bound map, goals, plans, then the summary) at INFO, the files written at
DEBUG, and a goal planned without its compensation at WARNING. Their ``echo`` parameters are
deprecated, and so is :func:`run_plan` (use :func:`ctrplan.plan`).

:class:`Planner` (:mod:`~ctrplan.planning.interactive`) plans one goal after another from the
current configuration on a roadmap built once per robot, map and obstacles (stages 3 to 6 for
one goal, in a fraction of a second) -> :class:`GoalPlan`.
"""

from ..boundmap import (QUANTITIES, BoundField, BoundFieldKeyError, InterpolationError, field_key,
                        interpolation_error)
from .aiming import (AimDecision, AimedGoals, AimReason, CompensatedGoal, aim_decision, aim_goals, aim_reason,
                     compensate_goal)
from .approach import DEFAULT_FINAL_MOTION, FINAL_MOTIONS, approach_history, end_with, goal_indices, path_history
from .bound_map import GIVEN, BoundMapStage, complete_bound_map, given_bound_map, prepare_bound_map
from .collision import CollisionChecker, CollisionReport
from .comparison import GoalOutcome, PlanComparison, RouteMetrics, compare_plans, goal_outcomes, route_metrics
from .goals import (GoalCheckCounts, GoalSolution, IKSearch, JointGoal, ResolvedGoals, TaskGoal, as_goal, check_start,
                    resolve_goal, resolve_goals)
from .interactive import GoalPlan, Planner
from .map_refinement import ExactBound, MapRefinement, Refinement, RefinementRound, refine_plans, start_refinement
from .objective import DEFAULT_BOUND_WEIGHT, BoundCostObjective
from .ordering import LastMotionBounds, OrderedPath, OrderedWaypoint, bounds_given_last_motion, order_path
from .outputs import COMPARED, PlanRecord, log_summary, path_rows, plan_summary, read_plan_record, write_plan_report
from .path_bounds import PATH_SAMPLE_SPACING, PathBounds, WaypointPredictions, bounds_along_path, predict_waypoints
from .planners import PLANNERS, SearchResult, SearchSettings, ValidityChecker, plan_leg
from .plans import Plans, RoutePlan, effective_bound_weight, plan_routes
from .roadmap import Roadmap, load_roadmap
from .route import CheckResolution, Route, RouteChecks, plan_route, route_checks
from .run import PlanRun, run_plan, run_stages
from .setup import PlanSetup, default_out_dir, load_setup, map_spec, setup_plan
from .space import DEFAULT_METERS_PER_RADIAN, JointStateSpace, unwrap_path, wrap_angle
from .validity import BatchMotionValidator, BatchValidityChecker, use_motion_validator
from .verify import MotionCheck, MotionVerifier
from .waypoints import WaypointTable, calibrated_bound, drive_trajectory, waypoint_table

__all__ = [
    # building blocks
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
    "Route", "RouteChecks", "CheckResolution", "plan_route", "route_checks", "Roadmap", "load_roadmap",
    # stage 1
    "PlanSetup", "setup_plan", "load_setup", "map_spec", "default_out_dir",
    # stage 2
    "BoundMapStage", "prepare_bound_map", "complete_bound_map", "given_bound_map", "GIVEN",
    # stages 3 and 4
    "check_start", "GoalCheckCounts", "ResolvedGoals", "resolve_goals", "AimDecision", "AimReason", "aim_decision",
    "aim_reason", "AimedGoals", "aim_goals",
    # stage 5
    "RoutePlan", "Plans", "plan_routes", "effective_bound_weight", "PathBounds", "bounds_along_path",
    "PATH_SAMPLE_SPACING", "WaypointPredictions", "predict_waypoints", "WaypointTable", "waypoint_table",
    "calibrated_bound", "MapRefinement", "RefinementRound", "Refinement", "ExactBound", "start_refinement",
    "refine_plans",
    # stage 6
    "drive_trajectory",
    # stage 7
    "RouteMetrics", "route_metrics", "PlanComparison", "compare_plans", "GoalOutcome", "goal_outcomes",
    # all stages
    "PlanRun", "run_stages",
    # one goal after another on a roadmap
    "Planner", "GoalPlan",
    # the outputs
    "plan_summary", "COMPARED", "write_plan_report", "path_rows", "log_summary", "PlanRecord", "read_plan_record",
    # deprecated
    "run_plan",
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
