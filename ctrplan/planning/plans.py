"""Stage 5 of a plan: every leg planned bound-aware (and bound-blind), ordered, checked, with the
exact bound and the prediction at its waypoints (:mod:`~ctrplan.planning.path_bounds`;
:class:`RoutePlan`, :class:`Plans`)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from .._log import deprecated_echo, progress_level
from ..errors import CtrplanError
from .aiming import AimedGoals
from .approach import end_with, goal_indices
from .objective import BoundCostObjective
from .path_bounds import PathBounds, WaypointPredictions, bounds_along_path, predict_waypoints
from .planners import SearchSettings
from .route import plan_route
from .setup import PlanSetup

__all__ = ["RoutePlan", "Plans", "plan_routes", "effective_bound_weight"]

logger = logging.getLogger(__package__)


@dataclass(frozen=True, eq=False)
class RoutePlan:
    """Stage 5, one plan (bound-aware or bound-blind): search, ordering, final check and report.

    Attributes
    ----------
    legs : list of ctrplan.planning.planners.SearchResult
        One planner result per leg (start -> goal 1 -> goal 2 ...).
    ordered : OrderedPath
        The ordered path (pure rotation and pure translation phases) [rad or m].
    bounds : PathBounds
        Bounds along it and at its waypoints [m, rad].
    plan_time_s, exact_time_s : float
        Search and ordering time; exact-bound time [s].
    checks : dict
        The checkers' counters (``RouteChecks.counters``).
    max_body_step_m : float
        The final check's largest body displacement between checked states [m].
    prediction : WaypointPredictions
        Predicted tip at the ordered waypoints.
    goal_indices : list of int
        Waypoint index of each goal.
    final_motion_status : list of str
        Per goal: how the motion reaching it ends (:func:`ctrplan.planning.approach.end_with`).
    """

    legs: list
    ordered: Any
    bounds: PathBounds
    plan_time_s: float
    exact_time_s: float
    checks: dict
    max_body_step_m: float
    prediction: WaypointPredictions
    goal_indices: list
    final_motion_status: list


@dataclass(frozen=True, eq=False)
class Plans:
    """Stage 5: the plans of a run.

    Attributes
    ----------
    routes : mapping of str to RoutePlan
        ``"bound_aware"``, then ``"bound_blind"`` when compared.
    in_parallel : bool
        Whether the two plans ran in two processes.
    time_s : float
        Wall time of all plans [s] (the roadmap's reading or building included).
    roadmap : dict or None
        With legs planned through a roadmap: its ``states``, ``motions``, ``source`` (``"cache"``
        or ``"built"``), ``file`` and ``time_s`` (reading or building) [s]; else None.
    """

    routes: Mapping[str, RoutePlan]
    in_parallel: bool
    time_s: float
    roadmap: dict | None = None

    @property
    def aware(self) -> RoutePlan:
        """The bound-aware plan (the one that is executed)."""
        return self.routes["bound_aware"]

    @property
    def blind(self) -> RoutePlan | None:
        """The bound-blind plan (length only, same planner and seed); None when not planned."""
        return self.routes.get("bound_blind")


@dataclass(frozen=True, eq=False)
class _PlanJob:
    """Inputs of one plan (:func:`_plan_mode`); picklable, to run in another process (the setup
    arrives there without its checkers and joint space, which that process builds once)."""

    setup: PlanSetup
    field: Any
    goals: list
    weight: float
    iterations: int
    final_motion: str
    roadmap: Any = None


def _plan_mode(job: _PlanJob) -> RoutePlan:
    """One plan of a scenario (bound-aware or bound-blind): search, ordering, final check and the
    report, with the setup's checkers of the map (``PlanSetup.route_checks``) and its joint space.
    Takes and returns only picklable data, so that it can run in another process."""
    setup, field = job.setup, job.field
    robot, joint_space = setup.robot, setup.joint_space
    checks = setup.route_checks(field)
    before = checks.counters()
    p = setup.scenario.planner
    roadmap = None
    if job.roadmap is not None:
        from .roadmap import motion_terms

        roadmap = (job.roadmap, motion_terms(joint_space, field), job.weight)
    t0 = time.perf_counter()
    route = plan_route(robot, setup.scenario.start, job.goals, checks,
                       BoundCostObjective.factory(field, bound_weight=job.weight),
                       SearchSettings.from_scenario(p, iterations=job.iterations), joint_space=joint_space,
                       roadmap=roadmap)
    ordered = route.ordered
    # the motion reaching each goal ends as the scenario asks (swap its last two phases if needed
    # and if the swapped phases pass the final check)
    idx = goal_indices(ordered, job.goals, robot)
    final_status = []
    for gi in idx:
        ordered, status = end_with(ordered, gi, job.final_motion, checks.final.check)
        final_status.append(status)
    plan_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    bounds = bounds_along_path(ordered, robot, field, setup.settings, joint_space)
    exact_time = time.perf_counter() - t0
    pred = predict_waypoints(ordered, robot, setup.settings, bounds.exact)
    return RoutePlan(legs=route.legs, ordered=ordered, bounds=bounds, plan_time_s=plan_time,
                     exact_time_s=exact_time, checks=checks.counters(since=before),
                     max_body_step_m=checks.final.max_body_step, prediction=pred, goal_indices=idx,
                     final_motion_status=final_status)


def _compile_before_fork(job) -> None:
    """The standard-model kernels both plans need (the robot bodies of the validity checks, the
    shooting with its multistart search of the exact checks), compiled or loaded here before the
    fork: the forked process inherits them, where on a cold start each process would compile
    them again side by side. Milliseconds when they are cached: two solves at the start."""
    from ..mechanics import solve_standard, solve_standard_bodies

    try:
        setup = job.setup
        alpha, beta = setup.robot.configuration(setup.scenario.start)
        solve_standard_bodies(setup.robot, np.atleast_2d(alpha), np.atleast_2d(beta), setup.check_settings)
        solve_standard(setup.robot, alpha, beta, setup.settings)
    except (CtrplanError, ValueError):   # only a warm-up: the plans report a bad start themselves
        pass


def _plan_modes(jobs: dict, n_jobs: int) -> tuple[dict, bool]:
    """Run the plans of ``jobs`` ({mode: _PlanJob}); with ``n_jobs`` >= 2 and more than one plan,
    the bound-blind plan runs in a forked worker while this process plans bound-aware
    (:class:`ctrplan.parallel.Executor`; the plans are independent and seeded, so the result is
    the same as in series; a plan whose worker died is planned again here). Returns
    ({mode: RoutePlan}, whether they ran in parallel)."""
    from concurrent.futures.process import BrokenProcessPool

    from ..parallel import Executor

    modes = list(jobs)
    if n_jobs < 2 or len(modes) < 2:
        return {m: _plan_mode(jobs[m]) for m in modes}, False
    _compile_before_fork(jobs[modes[0]])
    out = {}
    try:
        with Executor(min(n_jobs, len(modes)), fork=True) as ex:
            for m, plan in ex.run(_plan_mode, [(m, (jobs[m],)) for m in modes], first_here=True):
                out[m] = plan
    except BrokenProcessPool:
        pass
    for m in modes:
        if m not in out:
            out[m] = _plan_mode(jobs[m])
    return {m: out[m] for m in modes}, True


@deprecated_echo
def plan_routes(setup: PlanSetup, field, aimed: AimedGoals, *, iterations: int | None = None,
                compare_blind: bool = True, n_jobs: int = 1, use_roadmap: bool = False, echo=None) -> Plans:
    """Stage 5: plan start -> goals bound-aware (and bound-blind), order, check and evaluate.

    Each plan runs the scenario's planner and seed on every leg with the cost length + weight x
    integral of the bound (weight ``[planner] bound_weight`` [1/m] bound-aware, 0 bound-blind),
    orders the path into pure rotation and pure translation phases, checks every phase, ends the
    motion reaching each goal as ``aimed.final_motion`` asks, and re-runs the exact model at the
    ordered waypoints (Section V-B of Ha, Fagogenis & Dupont 2019).

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
    aimed : AimedGoals
        The joint goals planned to, shape (n_joints,) each [rad or m].
    iterations : int, optional, keyword-only
        Planner iterations per leg; default ``[planner] iterations``.
    compare_blind : bool, keyword-only
        Also plan bound-blind.
    n_jobs : int, keyword-only
        With 2 or more, the bound-blind plan runs in a forked process beside the bound-aware one
        (same result as in series).
    use_roadmap : bool, keyword-only
        Plan the legs of both plans through the scenario's roadmap
        (:func:`~ctrplan.planning.roadmap.load_roadmap`, read from the cache or built here
        first on ``n_jobs`` processes; the bound-aware legs with the bound weight, the bound-blind
        ones with weight 0).
    echo : callable, optional, keyword-only
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    Plans

    Raises
    ------
    UnreachableGoalError
        No valid path within the planner's budget.
    """
    sc = setup.scenario
    iters = iterations or sc.planner.iterations
    modes = ([("bound_aware", effective_bound_weight(sc.calibration.bound, sc.planner.bound_weight))]
             + ([("bound_blind", 0.0)] if compare_blind else []))
    jobs = {mode: _PlanJob(setup=setup, field=field, goals=list(aimed.q), weight=weight, iterations=iters,
                           final_motion=aimed.final_motion)
            for mode, weight in modes}
    t0 = time.perf_counter()
    info = None
    if use_roadmap:
        from .roadmap import load_roadmap

        roadmap, source, path = load_roadmap(setup, field, setup.route_checks(field).search, setup.joint_space,
                                             n_jobs=n_jobs)
        info = {"states": roadmap.n_nodes, "motions": roadmap.n_edges, "source": source,
                "file": None if path is None else str(path), "time_s": time.perf_counter() - t0}
        jobs = {m: replace(job, roadmap=roadmap) for m, job in jobs.items()}
    routes, in_parallel = _plan_modes(jobs, n_jobs)
    seconds = time.perf_counter() - t0
    for mode, r in routes.items():
        lm = r.bounds.exact
        ordered = r.ordered
        logger.log(progress_level(),
                   f"{mode}: {len(ordered)} ordered waypoints, planning {r.plan_time_s:.1f} s "
                   f"({r.checks['validity_calls']} states checked, {r.checks['search_states_evaluated']} not cached, "
                   f"final check {r.checks['final_check_states']} states, "
                   f"{ordered.n_subdivisions} bisections, {ordered.n_repairs} repairs); exact bound at waypoints: "
                   f"max {np.nanmax(lm.position) * 1e3:.2f} mm, final {lm.position[-1] * 1e3:.2f} mm")
    return Plans(routes=MappingProxyType(routes), in_parallel=in_parallel, time_s=seconds, roadmap=info)


def effective_bound_weight(calibration, weight: float) -> float:
    """The bound weight that ranks paths by the calibrated bound.

    Planning minimises ``L + w integral(b) ds``; with the calibrated bound ``c (b + m)`` in place
    of ``b`` the cost is ``(1 + w c m) L + w c integral(b) ds``, which has the same minimiser as
    ``L + w' integral(b) ds`` with ``w' = w c / (1 + w c m)``. Without a calibration, ``w``.

    Parameters
    ----------
    calibration : CalibratedBound or None
        ``Scenario.calibration.bound``.
    weight : float
        ``[planner] bound_weight`` [1/m].

    Returns
    -------
    float
        [1/m] (:meth:`ctrplan.calibration.CalibratedBound.effective_weight`).
    """
    if calibration is None:
        return float(weight)
    return calibration.effective_weight(weight)
