"""The stages of a plan in order (:func:`run_stages`), and every stage's result (:class:`PlanRun`).

:func:`ctrplan.plan` is the entry point: it sets the run up from a scenario, hands it the bound
map or looks it up, runs the stages and, when asked, writes the report. :func:`run_plan` is the
earlier entry point, kept for one release.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

from .._log import deprecated_echo
from ..trajectory import Trajectory
from .aiming import AimedGoals, aim_goals
from .bound_map import BoundMapStage, prepare_bound_map
from .comparison import PlanComparison, compare_plans, goal_outcomes
from .goals import GoalCheckCounts, ResolvedGoals, check_start, resolve_goals
from .map_refinement import DEFAULT_PREVIEW_ROUNDS, ExactBound, MapRefinement, refine_plans, start_refinement
from .outputs.summary import plan_summary
from .outputs.writer import log_summary, write_plan_report
from .plans import Plans, plan_routes
from .setup import PlanSetup, load_setup
from .waypoints import WaypointTable, drive_trajectory, waypoint_table

__all__ = ["PlanRun", "run_stages", "run_plan"]


@dataclass(frozen=True, eq=False)
class PlanRun:
    """Every stage's result of one plan, in SI units (:func:`run_stages`).

    Attributes
    ----------
    setup : PlanSetup
        Stage 1: the scenario, its robot and calibration, model settings, map spec.
    bound_map : BoundMapStage
        Stage 2: the bound map and where it came from.
    goal_checks : GoalCheckCounts
        Work of the validity checker of the start and the goals.
    resolved : ResolvedGoals
        Stage 3: each goal as a joint vector.
    aimed : AimedGoals
        Stage 4: the joint vectors planned to, and how task-space goals were aimed.
    plans : Plans
        Stage 5: the bound-aware plan (and the bound-blind one), ordered and checked, with the
        exact bound and the prediction at their waypoints.
    trajectory : Trajectory or None
        Stage 6: the drive trajectory of the bound-aware plan; None without a ``[drive]`` table.
    waypoints : WaypointTable
        The bound-aware plan's K ordered waypoints with their bounds and predictions.
    comparison : PlanComparison
        Stage 7: the headline numbers of the bound-aware plan beside the bound-blind plan's.
    goals : tuple of GoalOutcome
        Stage 7: per scenario goal, where the bound-aware plan reaches it and what is predicted
        there.
    time_s : float
        Time from the start of the run to the end of the last stage [s].
    refinement : MapRefinement or None
        Stage 5: the map refined where the plan goes and the plans it took; None without
        refinement.
    """

    setup: PlanSetup
    bound_map: BoundMapStage
    goal_checks: GoalCheckCounts
    resolved: ResolvedGoals
    aimed: AimedGoals
    plans: Plans
    trajectory: Trajectory | None
    waypoints: WaypointTable
    comparison: PlanComparison
    goals: tuple
    time_s: float
    refinement: MapRefinement | None = None

    @property
    def field(self):
        """The map the bound-aware plan read: the refined one after a refinement [m, rad]."""
        return self.bound_map.field if self.refinement is None else self.refinement.field

    @property
    def timings_s(self) -> dict:
        """Stage times [s]: ``bound_map``, ``inverse_kinematics``, ``compensation``,
        ``prediction_at_waypoints``, ``plans_wall`` (the refinement included), ``refinement``
        (its exact nodes and re-plans), ``plans_in_parallel`` (bool) and ``total``."""
        return {"bound_map": self.bound_map.time_s, "inverse_kinematics": self.resolved.time_s,
                "compensation": self.aimed.time_s, "prediction_at_waypoints": self.plans.aware.prediction.time_s,
                "plans_wall": self.plans.time_s,
                "refinement": 0.0 if self.refinement is None else self.refinement.time_s,
                "plans_in_parallel": self.plans.in_parallel, "total": self.time_s}


def run_stages(setup: PlanSetup, bound_map: BoundMapStage, *, iterations: int | None = None,
               compare_blind: bool = True, n_jobs: int = 1, started: float | None = None) -> PlanRun:
    """Stages 3 to 7 of a plan: check the start, resolve and aim the goals, plan bound-aware (and
    bound-blind; through the roadmap of :class:`~ctrplan.planning.interactive.Planner` with
    ``[planner] roadmap``, by default with two goals or more and a complete map), refine the map
    where the plan goes and plan again (``[bound_field]
    refine_rounds``; by default with a preview map only, :mod:`ctrplan.planning.map_refinement`; task
    goals are then resolved with the exact bound), time-parameterize, evaluate. Writes nothing;
    logs the progress lines.

    Parameters
    ----------
    setup : PlanSetup
        Stage 1 (:func:`~ctrplan.planning.setup.setup_plan`).
    bound_map : BoundMapStage
        Stage 2 (:func:`~ctrplan.planning.bound_map.prepare_bound_map` or
        :func:`~ctrplan.planning.bound_map.given_bound_map`).
    iterations : int, optional, keyword-only
        Planner iterations per leg; default ``[planner] iterations``.
    compare_blind : bool, keyword-only
        Also plan bound-blind (length only, same planner and seed).
    n_jobs : int, keyword-only
        With 2 or more, the bound-blind plan runs in a forked process beside the bound-aware one
        (same result as in series).
    started : float, optional, keyword-only
        ``time.perf_counter()`` at the start of the run (default: now), for ``PlanRun.time_s``.

    Returns
    -------
    PlanRun

    Raises
    ------
    UnreachableGoalError
        Invalid start, unreachable goal, or no valid path within the budget.
    JointLimitError
        The time-parameterized trajectory violates the drive limits.
    """
    t0 = time.perf_counter() if started is None else started
    bf = setup.scenario.bound_field
    rounds = bf.refine_rounds if bf.refine_rounds is not None else DEFAULT_PREVIEW_ROUNDS if bound_map.preview else 0
    state = start_refinement(setup, bound_map, n_jobs) if rounds else None
    field = bound_map.field if state is None else state.field
    validity = check_start(setup, field)
    resolved = resolve_goals(setup, field if state is None else ExactBound(setup.robot, setup.settings), validity)
    aimed = aim_goals(setup, resolved, validity)
    goal_checks = GoalCheckCounts.of(validity)
    roadmap = setup.scenario.planner.roadmap
    plans = plan_routes(setup, field, aimed, iterations=iterations, compare_blind=compare_blind, n_jobs=n_jobs,
                        use_roadmap=roadmap if roadmap is not None else (len(aimed.q) >= 2 and state is None))
    refinement = None
    if state is not None:
        plans, refinement = refine_plans(setup, state, aimed, plans, rounds=rounds, tolerance=bf.refine_tolerance,
                                         iterations=iterations)
        field = refinement.field
    trajectory = drive_trajectory(setup, plans.aware.ordered)
    return PlanRun(setup=setup, bound_map=bound_map, goal_checks=goal_checks, resolved=resolved, aimed=aimed,
                   plans=plans, trajectory=trajectory,
                   waypoints=waypoint_table(plans.aware, setup.calibration.bound), comparison=compare_plans(plans),
                   goals=goal_outcomes(setup.robot, field, aimed, plans.aware), time_s=time.perf_counter() - t0,
                   refinement=refinement)


@deprecated_echo
def run_plan(scenario_path, out_dir=None, n_jobs: int = 1, iterations: int | None = None,
             compare_blind: bool = True, echo=None, *, progress: bool = False) -> dict:
    """Deprecated: use :func:`ctrplan.plan` (typed result) or :func:`ctrplan.plan_scenario`.

    Plans, orders, time-parameterizes and reports one scenario as ``ctrplan plan`` does.

    Parameters
    ----------
    scenario_path : path
        Scenario TOML file.
    out_dir : path, optional
        Output folder (default: the scenario's ``[output] dir``, else ``out/<scenario name>``).
    n_jobs : int
        Worker processes: for a bound map that must be computed, and, with 2 or more, the
        bound-blind plan runs beside the bound-aware one (same results as in series).
    iterations : int, optional
        Overrides the scenario's planner iterations.
    compare_blind : bool
        Also plan bound-blind (length only, same planner and seed) and compare.
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).
    progress : bool, keyword-only
        tqdm bars while a bound map is computed (default none).

    Returns
    -------
    dict
        The summary written to ``summary.json`` (report units), plus ``output_dir``.

    Raises
    ------
    ModelFileError
        Malformed scenario or robot file.
    UnreachableGoalError
        Invalid start, unreachable goal, or no valid path within the budget.
    JointLimitError
        The time-parameterized trajectory violates the drive limits.

    Warns
    -----
    DeprecationWarning
        Always.
    """
    warnings.warn("ctrplan.planning.run_plan is deprecated: use ctrplan.plan (a typed PlanResult; out_dir= writes "
                  "the files) or ctrplan.plan_scenario", DeprecationWarning, stacklevel=3)
    t0 = time.perf_counter()
    setup = load_setup(scenario_path, out_dir)
    run = run_stages(setup, prepare_bound_map(setup, n_jobs, progress=progress), iterations=iterations,
                     compare_blind=compare_blind, n_jobs=n_jobs, started=t0)
    summary = plan_summary(run)
    write_plan_report(run, setup.out_dir, summary=summary)
    log_summary(summary)
    return {**summary, "output_dir": str(setup.out_dir)}
