"""The main job: a bound-aware plan for a scenario, ordered, time-parameterized and reported.

``run_plan(scenario)`` composes these stages; each returns a frozen result in SI units (m, rad,
s), and millimetres and degrees appear only in the report stage and in progress messages:

1. :func:`load_setup` -> :class:`PlanSetup`: the scenario, its robot, the model settings, the
   bound map's spec and the output folder;
2. :func:`load_bound_map` -> :class:`BoundMapStage`: the robot's bound map (shipped in
   ``<robot dir>/boundmaps/`` as ``.npz`` or ``.zarr``, or cached) or computed into a zarr store
   (local cores or a Dask cluster; an interrupted computation resumes from its finished chunks);
3. :func:`check_start` -> the search's validity checker, after checking the start;
   :func:`resolve_goals` -> :class:`ResolvedGoals`: each goal as a joint vector (task-space goals
   by inverse kinematics preferring the smallest bound);
4. :func:`aim_goals` -> :class:`AimedGoals`: task-space goals aimed with the tip *predicted*
   after the final approach (``[planner] final_motion``: translation-last, the default, or
   rotation-last; Section V-B of Ha et al. 2019) instead of the standard model's tip
   (:func:`ctrplan.planning.goals.compensate_goal`);
5. :func:`plan_routes` -> :class:`Plans`: every leg planned with the same planner and seed,
   bound-aware (length + weight x integral of the bound) and bound-blind (length only); each
   plan (:class:`RoutePlan`) is ordered into rotations then translations (Section V-B) and both
   phases checked, the phases reaching each goal swapped if the final motion asks for it; the
   exact model re-run at the ordered waypoints gives the bound given the last motion and the tip
   predicted for the history the ordered plan creates (one contact solve at most per waypoint,
   usually none: the bound's own solutions are reused);
6. :func:`time_parameterize` -> the drive trajectory (ruckig, rest-to-rest, stop between
   phases), its samples checked;
7. :func:`path_rows`, :func:`plan_summary` and :func:`write_report`: path.csv, trajectory.csv,
   figures and summary.json, written atomically (mm and degrees only here).

The stages print nothing: they log to ``ctrplan.pipeline`` (:mod:`logging`) the lines ``ctrplan
plan`` shows (scenario, bound map, goals, plans, then the summary) at INFO, the files written at
DEBUG, and a goal planned without its compensation at WARNING. Their ``echo`` parameters are
deprecated.
"""

from .bound_map import BoundMapStage, load_bound_map
from .drive import time_parameterize
from .goals import AimedGoals, ResolvedGoals, aim_decision, aim_goals, check_start, resolve_goals
from .path_bounds import PATH_SAMPLE_SPACING, PathBounds
from .prediction import WaypointPredictions
from .report import calibrated_bound, path_rows, write_report
from .routes import Plans, RoutePlan, effective_bound_weight, plan_routes
from .run import PlanRun, plan_stages, run_plan
from .setup import PlanSetup, load_setup, map_spec
from .summary import plan_summary

__all__ = ["run_plan", "plan_stages", "PlanRun", "map_spec", "PlanSetup", "BoundMapStage", "ResolvedGoals",
           "AimedGoals", "PathBounds", "PATH_SAMPLE_SPACING", "WaypointPredictions", "RoutePlan", "Plans", "load_setup",
           "load_bound_map", "check_start", "resolve_goals", "aim_decision", "aim_goals", "plan_routes",
           "effective_bound_weight", "time_parameterize", "calibrated_bound", "path_rows", "plan_summary",
           "write_report"]
