"""Part of stage 5: the bound map refined where the plan goes (:func:`start_refinement`,
:func:`refine_plans`).

The planner reads the bound map; the plan's waypoints then get the exact bound (Section V-B of
Ha, Fagogenis & Dupont 2019). Where the map is off there, by its interpolation error (a coarse
preview map for a robot whose map is not computed yet, or the full map between its nodes), the
plan was chosen with the wrong cost. Refinement plans on the map subdivided
(:func:`ctrplan.boundmap.subdivided`: twice for a preview map, so that its grid is twice as fine
as the full map's; once for another); after each plan it evaluates the exact bound at every node
of the cells the plan's path crosses, corrects the map to the waypoints' exact bounds
(:mod:`ctrplan.boundmap.refine`) and plans again, until the map is within the tolerance of the
exact bound at every waypoint of the last plan, a plan adds no waypoint, or the rounds run out.
Task-space goals are resolved with the exact bound (:class:`ExactBound`): among the inverse
kinematics' solutions the one with the smallest exact bound, not the smallest map bound, which
would favour where the map is too low.
The bound-blind plan (which does not read the bound) is kept, with its interpolated bounds read
from the refined map.

What was evaluated is kept beside the map in the map cache (``<map>-refined.npz``, written after
every round), so the next plan of the same robot, spec and settings starts from it.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

from .._log import progress_level
from ..boundmap import (BoundField, ExactSamples, cell_nodes, evaluate_nodes, map_paths, refined_field, subdivided,
                        with_nodes)
from ..io.atomic import atomic_savez
from .aiming import AimedGoals
from .bound_map import GIVEN, BoundMapStage
from .path_bounds import bounds_along_path
from .plans import Plans, RoutePlan, plan_routes
from .setup import PlanSetup

__all__ = ["RefinementRound", "MapRefinement", "Refinement", "ExactBound", "start_refinement", "refine_plans",
           "DEFAULT_PREVIEW_ROUNDS"]

logger = logging.getLogger(__package__)

#: Most re-plans with a preview map when the scenario does not say.
DEFAULT_PREVIEW_ROUNDS = 4
#: Subdivisions of a preview map for its refinement: its grid then has twice the full map's
#: nodes per coordinate (the full map's once); the exact nodes of a waypoint's cell are a
#: quarter of the preview's spacing apart.
PREVIEW_LEVELS = 2
#: Format of the ``-refined.npz`` files beside cached maps.
_FORMAT = 1


@dataclass(frozen=True)
class RefinementRound:
    """One bound-aware plan of the refinement.

    Attributes
    ----------
    max_error, median_error : float
        Largest and median ``|map - exact|`` of the bound given the last motion at the plan's
        waypoints where the exact model converged [m] (NaN without one).
    n_waypoints : int
        Those waypoints.
    n_samples, n_nodes : int
        Exact samples and exact nodes of the map this plan read.
    time_s : float
        The plan's search, ordering, final check and exact bound [s].
    """

    max_error: float
    median_error: float
    n_waypoints: int
    n_samples: int
    n_nodes: int
    time_s: float


@dataclass(frozen=True, eq=False)
class MapRefinement:
    """The refinement of a run (:func:`refine_plans`).

    Attributes
    ----------
    rounds : tuple of RefinementRound
        Every bound-aware plan, the first one included.
    samples : ExactSamples
        The waypoints' exact bounds, of every plan [m, rad].
    field : BoundField
        The map the final plan read: the loaded map subdivided, exact at the nodes of the cells
        the earlier plans' paths crossed, and corrected to their waypoints' exact bounds.
    n_nodes : int
        Nodes of ``field`` where the exact bound was evaluated (this run or an earlier one).
    node_evaluations : int
        Of those, evaluated in this run.
    node_time_s : float
        Time of those evaluations [s].
    cache : Path or None
        Where they are kept (None for a map handed in).
    tolerance : float
        [m].
    converged : bool
        The last plan's map is within ``tolerance`` of the exact bound at all its waypoints.
    time_s : float
        Wall time of the re-plans and evaluations [s].
    """

    rounds: tuple
    samples: ExactSamples
    field: BoundField
    n_nodes: int
    node_evaluations: int
    node_time_s: float
    cache: Path | None
    tolerance: float
    converged: bool
    time_s: float


class Refinement:
    """The state of a refinement: the subdivided map, its exact nodes and samples (mutable; one
    run's). Made by :func:`start_refinement`."""

    def __init__(self, setup: PlanSetup, base: BoundField, cache: Path | None, n_jobs: int):
        self.setup = setup
        self.base = base
        self.cache = cache
        self.n_jobs = int(n_jobs)
        self.node_index = np.zeros(0, np.int64)
        self.node_values = np.zeros((0, 4))
        self.node_ok = np.zeros(0, bool)
        self.samples = ExactSamples.empty(base.n_coordinates)
        self.node_evaluations = 0
        self.node_time_s = 0.0
        self._field = base
        if cache is not None and cache.exists():
            self._load(cache)

    # ------------------------------------------------------------------ cache
    def _load(self, path: Path) -> None:
        try:
            with np.load(path, allow_pickle=False) as z:
                if int(z["format"]) != _FORMAT or tuple(z["shape"]) != self.base.shape:
                    raise ValueError("another format or grid")
                self.node_index, self.node_values, self.node_ok = z["node_index"], z["node_values"], z["node_ok"]
                self.samples = ExactSamples(z["sample_u"], z["sample_values"], z["sample_ok"])
        except (OSError, KeyError, ValueError) as exc:
            logger.warning(f"ignoring {path}: {exc}")
            return
        self._field = refined_field(with_nodes(self.base, self.node_index, self.node_values, self.node_ok),
                                    self.samples)
        logger.log(progress_level(), f"map refinement: {self.node_index.size} exact nodes and {self.samples.n} "
                   f"exact samples read from {path}")

    def _save(self) -> None:
        if self.cache is None:
            return
        self.cache.parent.mkdir(parents=True, exist_ok=True)
        atomic_savez(self.cache, format=np.array(_FORMAT), shape=np.array(self.base.shape),
                     node_index=self.node_index, node_values=self.node_values, node_ok=self.node_ok,
                     sample_u=self.samples.u, sample_values=self.samples.values, sample_ok=self.samples.ok)

    # ------------------------------------------------------------------ rounds
    @property
    def field(self) -> BoundField:
        """The map as refined so far [m, rad]."""
        return self._field

    def add(self, route: RoutePlan) -> int:
        """The exact bounds of a plan's waypoints, and of the nodes of the cells its path crosses
        (the samples of its :class:`~ctrplan.planning.path_bounds.PathBounds`, at most
        :data:`~ctrplan.planning.path_bounds.PATH_SAMPLE_SPACING` apart, and the waypoints),
        into the map. Returns the number of waypoints not seen before."""
        new = ExactSamples.from_results(self.base, route.ordered.q, route.bounds.exact.results)
        before = self.samples.n
        self.samples = self.samples.merged(new)
        added = self.samples.n - before
        path = self.base.to_map(route.bounds.dense_q)
        need = np.setdiff1d(cell_nodes(self.base, np.concatenate([new.u, path])), self.node_index)
        if need.size:
            t0 = time.perf_counter()
            values, ok = evaluate_nodes(self.setup.robot, self.base, need, self.setup.settings, self.n_jobs)
            self.node_time_s += time.perf_counter() - t0
            self.node_evaluations += int(need.size)
            order = np.argsort(np.concatenate([self.node_index, need]))
            self.node_index = np.concatenate([self.node_index, need])[order]
            self.node_values = np.concatenate([self.node_values, values])[order]
            self.node_ok = np.concatenate([self.node_ok, ok])[order]
        self._field = refined_field(with_nodes(self.base, self.node_index, self.node_values, self.node_ok),
                                    self.samples)
        self._save()
        return added


class ExactBound:
    """The exact bound as a map is called: ``bound(q, quantity="position")`` (for choosing among
    inverse-kinematics solutions where the map is a refinement's, :func:`ctrplan.planning.resolve_goal`).

    Parameters
    ----------
    robot : Robot
    settings : ModelSettings
        Of the exact model.
    """

    def __init__(self, robot, settings):
        self.robot = robot
        self.settings = settings

    def __call__(self, q, quantity: str = "position"):
        """The exact ``quantity`` (:data:`~ctrplan.boundmap.field.QUANTITIES`) at joint vectors ``q``
        (n_joints,) or (m, n_joints) [m or rad]; inf where the model fails or is unstable."""
        from ..boundmap import QUANTITIES, sample_exact
        from ..mechanics import evaluate_bound

        single = np.ndim(q) == 1
        values, ok = sample_exact(self.robot, evaluate_bound, np.atleast_2d(np.asarray(q, float)), self.settings)
        out = np.where(ok, values[:, QUANTITIES.index(quantity)], np.inf)
        return float(out[0]) if single else out


def start_refinement(setup: PlanSetup, bound_map: BoundMapStage, n_jobs: int = 1) -> Refinement:
    """The refinement of a run's map: the map subdivided, with what earlier runs evaluated for
    the same map (its cache file) applied.

    Parameters
    ----------
    setup : PlanSetup
    bound_map : BoundMapStage
        Stage 2 (a map handed in is refined without a cache file).
    n_jobs : int
        Worker processes for the exact nodes.

    Returns
    -------
    Refinement
    """
    cache = None
    if bound_map.source != GIVEN:
        base = map_paths(setup.scenario.robot_file, bound_map.field.key)[1]
        cache = base.with_name(base.name + "-refined.npz")
    return Refinement(setup, subdivided(bound_map.field, PREVIEW_LEVELS if bound_map.preview else 1), cache, n_jobs)


def _round(route: RoutePlan, state: Refinement) -> RefinementRound:
    b = route.bounds
    ok = np.asarray(b.exact.valid, bool) & np.isfinite(b.exact.position) & np.isfinite(b.planned)
    err = np.abs(np.asarray(b.planned) - np.asarray(b.exact.position))[ok]
    return RefinementRound(max_error=float(err.max()) if err.size else float("nan"),
                           median_error=float(np.median(err)) if err.size else float("nan"),
                           n_waypoints=int(err.size), n_samples=state.samples.n, n_nodes=int(state.node_index.size),
                           time_s=route.plan_time_s + route.exact_time_s)


def refine_plans(setup: PlanSetup, state: Refinement, aimed: AimedGoals, plans: Plans, *, rounds: int,
                 tolerance: float, iterations: int | None = None) -> tuple[Plans, MapRefinement]:
    """Refine the map where the plans go and plan bound-aware again (module docstring).

    Parameters
    ----------
    setup : PlanSetup
    state : Refinement
        :func:`start_refinement`; ``plans`` read ``state.field``.
    aimed : AimedGoals
        The joint goals planned to.
    plans : Plans
        The plans with ``state.field`` (:func:`~ctrplan.planning.plans.plan_routes`).
    rounds : int
        Most re-plans (>= 0).
    tolerance : float
        Stop when ``|map - exact| <= tolerance`` at every waypoint of the last plan [m] (> 0).
    iterations : int, optional
        Planner iterations per leg; default ``[planner] iterations``.

    Returns
    -------
    plans : Plans
        The last bound-aware plan, and the bound-blind plan with its interpolated bounds read
        from the final map.
    refinement : MapRefinement

    Raises
    ------
    ValueError
        ``rounds`` < 0 or ``tolerance`` <= 0.
    UnreachableGoalError
        A re-plan finds no valid path within the planner's budget.
    """
    if rounds < 0 or not tolerance > 0:
        raise ValueError(f"need rounds >= 0 and tolerance > 0, got {rounds!r} and {tolerance!r}")
    t0 = time.perf_counter()
    aware = plans.aware
    history = [_round(aware, state)]
    read = state.field
    while not history[-1].max_error <= tolerance and len(history) <= rounds:
        if not state.add(aware):
            break                      # every waypoint was seen before: a new plan would be the same
        read = state.field
        aware = plan_routes(setup, read, aimed, iterations=iterations, compare_blind=False).aware
        history.append(_round(aware, state))
    if not history[-1].max_error <= tolerance:
        state.add(aware)               # the last plan's waypoints too, for the next run
    for k, r in enumerate(history):
        logger.log(progress_level(), f"map refinement, plan {k + 1}: map within {r.max_error * 1e3:.3f} mm of the "
                   f"exact bound at its {r.n_waypoints} waypoints (median {r.median_error * 1e3:.3f} mm); the map "
                   f"it read had {r.n_nodes} exact nodes and {r.n_samples} exact samples; {r.time_s:.1f} s")
    routes = {"bound_aware": aware}
    if plans.blind is not None:
        blind = plans.blind
        routes["bound_blind"] = replace(blind, bounds=bounds_along_path(
            blind.ordered, setup.robot, read, setup.settings, setup.joint_space,
            exact=blind.bounds.exact))
    seconds = time.perf_counter() - t0
    refinement = MapRefinement(rounds=tuple(history), samples=state.samples, field=read,
                               n_nodes=int(state.node_index.size), node_evaluations=state.node_evaluations,
                               node_time_s=state.node_time_s, cache=state.cache, tolerance=float(tolerance),
                               converged=bool(history[-1].max_error <= tolerance), time_s=seconds)
    return Plans(routes=MappingProxyType(routes), in_parallel=plans.in_parallel, time_s=plans.time_s + seconds), \
        refinement
