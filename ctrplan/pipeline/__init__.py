"""The stages of a bound-aware plan, each a function that returns a frozen result in SI units (m,
rad, s); :func:`ctrplan.plan` composes them and returns them all in its
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
   2019) instead of the standard model's tip (:func:`ctrplan.planning.goals.compensate_goal`),
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
:mod:`ctrplan.pipeline.outputs`, the only one with millimetres, degrees and dicts:
:func:`plan_summary` (``summary.json``), :func:`write_plan_report` (path.csv, trajectory.csv,
figures, plan.html and summary.json, written atomically) and :func:`log_summary`, with the
readers beside the writers (:func:`read_plan_record`,
:func:`ctrplan.pipeline.outputs.read_plan_folder`).

The stages print nothing: they log to ``ctrplan.pipeline`` (:mod:`logging`) the lines ``ctrplan
plan`` shows (scenario, bound map, goals, plans, then the summary) at INFO, the files written at
DEBUG, and a goal planned without its compensation at WARNING. Their ``echo`` parameters are
deprecated, and so is :func:`run_plan` (use :func:`ctrplan.plan`).

:class:`Planner` (:mod:`~ctrplan.pipeline.interactive`) plans one goal after another from the
current configuration on a roadmap built once per robot, map and obstacles (stages 3 to 6 for
one goal, in a fraction of a second) -> :class:`GoalPlan`.
"""

from .bound_map import GIVEN, BoundMapStage, complete_bound_map, given_bound_map, prepare_bound_map
from .drive import drive_trajectory
from .evaluation import GoalOutcome, PlanComparison, RouteMetrics, compare_plans, goal_outcomes, route_metrics
from .goals import (AimDecision, AimReason, AimedGoals, GoalCheckCounts, ResolvedGoals, aim_decision, aim_goals, check_start,
                    resolve_goals)
from .interactive import GoalPlan, Planner
from .path_bounds import PATH_SAMPLE_SPACING, PathBounds, bounds_along_path
from .prediction import WaypointPredictions, predict_waypoints
from .refine import ExactBound, MapRefinement, Refinement, RefinementRound, refine_plans, start_refinement
from .routes import Plans, RoutePlan, effective_bound_weight, plan_routes
from .run import PlanRun, run_plan, run_stages
from .setup import PlanSetup, default_out_dir, load_setup, map_spec, setup_plan
from .outputs import COMPARED, PlanRecord, log_summary, path_rows, plan_summary, read_plan_record, write_plan_report
from .waypoints import WaypointTable, calibrated_bound, waypoint_table

__all__ = [
    # stage 1
    "PlanSetup", "setup_plan", "load_setup", "map_spec", "default_out_dir",
    # stage 2
    "BoundMapStage", "prepare_bound_map", "complete_bound_map", "given_bound_map", "GIVEN",
    # stages 3 and 4
    "check_start", "GoalCheckCounts", "ResolvedGoals", "resolve_goals", "AimDecision", "AimReason", "aim_decision", "AimedGoals",
    "aim_goals",
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
    # the report
    "plan_summary", "COMPARED", "write_plan_report", "path_rows", "log_summary", "PlanRecord", "read_plan_record",
    # deprecated
    "run_plan",
]

# The stages' names before each public name had one meaning: ctrplan.boundmap.load_bound_map reads a
# map file, ctrplan.trajectory.time_parameterize times waypoints and the discrepancy workflow has
# its own write_report.
_RENAMED = {"load_bound_map": "prepare_bound_map", "time_parameterize": "drive_trajectory",
            "write_report": "write_plan_report"}


def __getattr__(name):
    if name in _RENAMED:
        import warnings

        warnings.warn(f"ctrplan.pipeline.{name} is deprecated: use ctrplan.pipeline.{_RENAMED[name]}",
                      DeprecationWarning, stacklevel=2)
        return globals()[_RENAMED[name]]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
