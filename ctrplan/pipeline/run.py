"""The whole job: the stages of a plan in order, and its report."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from .._log import deprecated_echo
from .bound_map import BoundMapStage, load_bound_map
from .drive import time_parameterize
from .goals import AimedGoals, ResolvedGoals, aim_goals, check_start, resolve_goals
from .report import path_rows, write_report
from .routes import Plans, plan_routes
from .setup import PlanSetup, load_setup
from .summary import plan_summary

__all__ = ["run_plan", "PlanRun", "plan_stages"]


@deprecated_echo
def run_plan(scenario_path, out_dir=None, n_jobs: int = 1, iterations: int | None = None,
             compare_blind: bool = True, echo=None, *, progress: bool = False) -> dict:
    """Plan, order, time-parameterize and report one scenario (``ctrplan plan``).

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
        The summary written to ``summary.json`` (plus ``output_dir``).

    Raises
    ------
    ModelFileError
        Malformed scenario or robot file.
    UnreachableGoalError
        Invalid start, unreachable goal, or no valid path within the budget.
    JointLimitError
        The time-parameterized trajectory violates the drive limits.
    """
    return plan_stages(scenario_path, out_dir, n_jobs=n_jobs, iterations=iterations,
                       compare_blind=compare_blind, progress=progress).summary


@dataclass(frozen=True, eq=False)
class PlanRun:
    """What :func:`plan_stages` computed: every stage's result and the summary it wrote.

    Attributes
    ----------
    setup : PlanSetup
    bound_map : BoundMapStage
    resolved : ResolvedGoals
    aimed : AimedGoals
    plans : Plans
    trajectory : Trajectory or None
        Stage 6's drive trajectory (None without a ``[drive]`` table).
    rows : list of dict
        :func:`path_rows` of the bound-aware plan (SI units).
    summary : dict
        The summary written to ``summary.json`` (report units), plus ``output_dir``.
    """

    setup: PlanSetup
    bound_map: BoundMapStage
    resolved: ResolvedGoals
    aimed: AimedGoals
    plans: Plans
    trajectory: Any
    rows: list
    summary: dict


@deprecated_echo
def plan_stages(scenario_path, out_dir=None, *, n_jobs: int = 1, iterations: int | None = None,
                compare_blind: bool = True, echo=None, progress: bool = False) -> PlanRun:
    """:func:`run_plan` returning every stage's result as well as the summary.

    Parameters and exceptions as :func:`run_plan`; the same files are written.

    Returns
    -------
    PlanRun
    """
    t_start = time.perf_counter()
    setup = load_setup(scenario_path, out_dir)
    bound_map = load_bound_map(setup, n_jobs, progress=progress)
    validity = check_start(setup, bound_map.field)
    resolved = resolve_goals(setup, bound_map.field, validity)
    aimed = aim_goals(setup, resolved, validity)
    plans = plan_routes(setup, bound_map.field, aimed, iterations=iterations, compare_blind=compare_blind,
                        n_jobs=n_jobs)
    traj = time_parameterize(setup, plans.aware.ordered)
    rows = path_rows(plans.aware, setup.scenario.calibration.bound)
    summary = plan_summary(setup, bound_map, validity, resolved, aimed, plans, traj)
    summary["times_s"]["total"] = time.perf_counter() - t_start
    write_report(setup, plans, traj, rows, summary)
    summary["output_dir"] = str(setup.out_dir)
    return PlanRun(setup=setup, bound_map=bound_map, resolved=resolved, aimed=aimed, plans=plans, trajectory=traj,
                   rows=rows, summary=summary)
