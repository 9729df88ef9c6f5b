"""Computing a bound map: pilot lines, then the grid's nodes in chunks, in this process or on a
Dask cluster, written to a zarr store as they finish (resumable).

Steps of :func:`compute_bound_map_store`:

1. the map's identity and key from the robot, settings, spec, evaluator and mechanics version;
2. if the store does not exist yet: the axes. Periodic and uniform axes follow from the spec;
   adaptive ones from pilot lines of the exact bound (:mod:`ctrplan.boundmap.axes`), evaluated
   like the chunks (locally or on the cluster). The pilots are written into the new store with
   the axes (an interruption during the pilots repeats them; they are a few percent of a map);
3. the missing chunks, each a block of nodes evaluated at their representative configurations
   (:meth:`~ctrplan.coordinates.MapCoordinates.configuration`); only this process (the
   client) writes the store, as results arrive, so the workers need no shared file system.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field as dc_field

import numpy as np

from ..errors import CtrplanError
from ..parallel import SCHEDULER_TIMEOUT_S, Executor, SchedulerUnreachableError, start_local_cluster
from .axes import pilot_design, place_nodes, uniform_axis
from ..coordinates import map_coordinates
from .field import QUANTITIES, BoundField
from .identity import as_spec, map_identity
from .store import BoundMapStore, chunk_shape_for

__all__ = ["DEFAULT_CHUNK_SIZE", "SCHEDULER_TIMEOUT_S", "SchedulerUnreachableError", "BoundMapRun", "ComputeOptions",
           "node_values", "compute_bound_map_store", "compute_field", "start_local_cluster"]

logger = logging.getLogger(__name__)

# Grid nodes evaluated per chunk: ~64 nodes x 0.05-0.3 s keeps a chunk between a few seconds
# and a minute, so an interruption loses little work while the number of files stays small.
DEFAULT_CHUNK_SIZE = 64

# Set in each process that evaluates chunks: the first chunk of a process carries the imports
# and numba warm-up, which a benchmark must not count as steady-state cost.
_CHUNKS_IN_THIS_PROCESS = 0


def node_values(robot, evaluator, alpha, beta, settings):
    """The four map quantities and the validity of one configuration.

    Parameters
    ----------
    robot : Robot
    evaluator : callable
        ``evaluator(robot, alpha, beta, settings) -> BoundResult``.
    alpha, beta : ndarray, shape (n,)
        Base rotations [rad] and translations [m].
    settings : ModelSettings or None

    Returns
    -------
    values : ndarray, shape (4,)
        :data:`QUANTITIES` [m, rad]; NaN where the model failed.
    ok : bool
        The model converged and the standard model is stable (unique equilibrium).

    Notes
    -----
    Model failures (a ``CtrplanError``, a singular or non-finite linear algebra step) mark the
    configuration invalid; programming errors propagate.
    """
    try:
        robot.check_configuration(alpha, beta)
        res = evaluator(robot, alpha, beta, settings)
    except (CtrplanError, np.linalg.LinAlgError, FloatingPointError):
        return np.full(len(QUANTITIES), np.nan), False
    vals = np.array([float(getattr(res, name)) for name in QUANTITIES])
    diag = getattr(res, "diagnostics", None)
    ok = bool(np.all(np.isfinite(vals)))
    if diag is not None:
        ok = ok and bool(diag.converged) and not bool(diag.unstable)
    return vals, ok


def _compute_chunk(robot, evaluator, settings, alpha, beta):
    """Evaluate configurations (runs on a worker): alpha, beta (m, n).

    Returns (values (m, 4), valid (m,), wall seconds, thread CPU seconds, first chunk of the process).
    """
    global _CHUNKS_IN_THIS_PROCESS
    t0, c0 = time.perf_counter(), time.thread_time()
    values = np.empty((len(alpha), len(QUANTITIES)))
    valid = np.empty(len(alpha), dtype=bool)
    for m in range(len(alpha)):
        values[m], valid[m] = node_values(robot, evaluator, alpha[m], beta[m], settings)
    _CHUNKS_IN_THIS_PROCESS += 1
    return values, valid, time.perf_counter() - t0, time.thread_time() - c0, _CHUNKS_IN_THIS_PROCESS == 1


def _run_chunks(executor, tasks, robot, evaluator, settings):
    """Evaluate ``tasks`` = [(tag, alpha (m, n), beta (m, n))] with :func:`_compute_chunk` on
    ``executor`` (:class:`ctrplan.parallel.Executor`); yields (tag, result) as each finishes."""
    return executor.run(_compute_chunk, [(tag, (robot, evaluator, settings, alpha, beta)) for tag, alpha, beta in tasks])


class _Progress:
    """tqdm bar, or nothing (tqdm imported lazily)."""

    def __init__(self, total, initial, enable, desc, unit="node"):
        self._bar = None
        if enable:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=total, initial=initial, unit=unit, desc=desc)

    def update(self, n):
        if self._bar is not None:
            self._bar.update(n)

    def close(self):
        if self._bar is not None:
            self._bar.close()


@dataclass
class BoundMapRun:
    """What one call of :func:`compute_bound_map_store` did.

    Attributes
    ----------
    field : BoundField or None
        The complete map, or None if the run stopped early (``max_chunks``).
    store : BoundMapStore
    n_chunks : int
        Chunks of the map.
    n_reused : int
        Chunks found finished in the store at the start.
    n_computed : int
        Chunks evaluated and written by this run.
    run : int
        Run number recorded in the store (``chunk_run == run`` marks this run's chunks).
    wall_seconds : float
        Wall time of the run [s], including cluster start-up and pilots.
    executor : str
        Where the chunks ran (:attr:`ctrplan.parallel.Executor.description`): ``"serial"``,
        ``"k local processes"`` or ``"dask scheduler <address>"``.
    chunk_seconds : list of float
        Evaluation time of each chunk computed by this run [s].
    pilot_evaluations : int
        Exact-model evaluations of pilot lines in this run (0 when the store existed).
    pilot_seconds : float
        Wall time of the pilots [s].
    """

    field: BoundField | None
    store: BoundMapStore
    n_chunks: int
    n_reused: int
    n_computed: int
    run: int
    wall_seconds: float
    executor: str
    chunk_seconds: list = dc_field(default_factory=list)
    pilot_evaluations: int = 0
    pilot_seconds: float = 0.0


def _axes_and_pilots(robot, coords, spec, executor, evaluator, settings, progress):
    """Axes of a new map; pilot samples of its adaptive coordinates ({k: (points, values)})."""
    axes = [uniform_axis(coords.lower[k], coords.upper[k], spec.resolution[k], coords.periodic[k])
            for k in range(coords.dim)]
    pilots = {}
    adaptive = spec.adaptive(coords)
    if not adaptive:
        return axes, pilots
    designs = {k: pilot_design(coords, robot, spec, k) for k in adaptive}
    tasks = []
    for k, (x, points) in designs.items():
        for line in range(points.shape[0]):
            alpha, beta = coords.configuration(points[line])
            tasks.append(((k, line), alpha, beta))
    total = sum(p.shape[0] * p.shape[1] for _, p in designs.values())
    bar = _Progress(total, 0, progress, f"bound map {robot.name}: pilot lines", unit="point")
    values = {k: np.full(p.shape[:2] + (len(QUANTITIES),), np.nan) for k, (_, p) in designs.items()}
    try:
        for (k, line), (vals, ok, *_rest) in _run_chunks(executor, tasks, robot, evaluator, settings):
            values[k][line] = np.where(ok[:, None], vals, np.nan)
            bar.update(len(vals))
    finally:
        bar.close()
    for k, (x, points) in designs.items():
        n = min(spec.resolution[k], x.size)
        axes[k] = place_nodes(x, values[k][:, :, QUANTITIES.index("position")], n)
        pilots[k] = (points, values[k])
    return axes, pilots


@dataclass(frozen=True)
class ComputeOptions:
    """How a bound map's computation runs: where, in what pieces, how far, and what it shows.
    None of these enters the map's identity (the same map comes out however it is computed).

    Attributes
    ----------
    n_jobs : int
        Without ``scheduler``: 1 evaluates in this process, k > 1 on k local worker processes
        (:class:`ctrplan.parallel.Executor`).
    scheduler : str or distributed.Client, optional
        Dask scheduler address (``"tcp://host:8786"``) or a connected client (left open).
    chunk_size : int
        Nodes per chunk for a new store (an existing store keeps its chunks).
    progress : bool
        tqdm bars (pilot points, then nodes); default none.
    max_chunks : int, optional
        Compute at most this many missing chunks, then stop (the field is None unless complete).
    on_chunk : callable, optional
        ``on_chunk(n_written, chunk)`` after each chunk is written; an exception raised there
        stops the run like an interruption.
    """

    n_jobs: int = 1
    scheduler: object = None
    chunk_size: int = DEFAULT_CHUNK_SIZE
    progress: bool = False
    max_chunks: int | None = None
    on_chunk: object = None


def compute_bound_map_store(robot, evaluator, spec, settings=None, store=None, *,
                            options: ComputeOptions = ComputeOptions(), robot_file_text: str | None = None,
                            metadata: dict | None = None) -> BoundMapRun:
    """Evaluate a bound map chunk by chunk into a zarr store, resuming finished chunks.

    Parameters
    ----------
    robot : Robot
    evaluator : callable
        ``evaluator(robot, alpha (n,) [rad], beta (n,) [m], settings) -> BoundResult`` (normally
        :func:`ctrplan.mechanics.evaluate_bound`). On a cluster it must be importable by the
        workers (a module-level function of an installed package).
    spec : MapSpec, int or sequence of int
        Grid spec, or nodes per map coordinate (uniform placement).
    settings : ModelSettings, optional
    store : str or Path, optional
        Store directory (``*.zarr``). Finished chunks found there are reused when the store was
        made for the same map (identity). None: in memory.
    options : ComputeOptions, keyword-only
        Workers or a Dask scheduler, chunk size, progress bars, a stop after some chunks, a
        callback per chunk.
    robot_file_text : str, optional, keyword-only
        Robot file content: its sha256 identifies the robot in the store and the key.
    metadata : dict, optional, keyword-only
        Extra JSON metadata for a new store.

    Returns
    -------
    BoundMapRun

    Raises
    ------
    BoundMapMismatchError
        ``store`` holds a map of another robot file, settings, spec, evaluator or mechanics version.
    SchedulerUnreachableError
        No scheduler answers at ``scheduler`` within :data:`SCHEDULER_TIMEOUT_S`.
    ValueError
        A spec that does not fit the robot's map coordinates, or a bad chunk size.
    """
    t_start = time.perf_counter()
    n_jobs, scheduler, chunk_size, progress = options.n_jobs, options.scheduler, options.chunk_size, options.progress
    max_chunks, on_chunk = options.max_chunks, options.on_chunk
    ident = map_identity(robot, settings, spec, evaluator, robot_file_text)
    spec = as_spec(robot, spec)
    coords = map_coordinates(robot)
    chunk_shape_for(spec.resolution, chunk_size)     # checks chunk_size before any work
    computed: list[float] = []
    pilot_evals, pilot_secs = 0, 0.0
    run = 0
    with Executor(n_jobs, scheduler) as ex:
        st = BoundMapStore.resume(store, ident)
        if st is None:
            t0 = time.perf_counter()
            axes, pilots = _axes_and_pilots(robot, coords, spec, ex, evaluator, settings, progress)
            pilot_secs = time.perf_counter() - t0
            pilot_evals = int(sum(p.shape[0] * p.shape[1] for p, _ in pilots.values()))
            st = BoundMapStore.create_or_resume(
                store, ident, axes, coords.periodic, chunk_shape_for([len(a) for a in axes], chunk_size), coords,
                metadata={**(metadata or {}), "pilot_seconds": pilot_secs}, pilots=pilots)
        todo = st.missing_chunks()
        n_reused = st.n_chunks - len(todo)
        logger.debug(f"bound map store {store or '(in memory)'}: {n_reused} of {st.n_chunks} chunks finished earlier, "
                     f"{len(todo)} to compute")
        if max_chunks is not None:
            todo = todo[:max(0, int(max_chunks))]
        if todo:
            sizes = st.chunk_sizes()
            n_nodes = int(np.prod(st.resolution))
            done_nodes = int(sizes[st.done()].sum())
            ex.open()
            run = st.begin_run({"executor": ex.description, "pid": os.getpid(), "chunks_to_compute": len(todo)})
            bar = _Progress(n_nodes, done_nodes, progress, f"bound map {robot.name}")
            tasks = []
            for c in todo:
                alpha, beta = coords.configuration(st.chunk_nodes(c))
                tasks.append((c, alpha, beta))
            try:
                for c, (values, valid, secs, cpu, cold) in _run_chunks(ex, tasks, robot, evaluator, settings):
                    st.write_chunk(c, values, valid, secs, cold, run, cpu)
                    computed.append(float(secs))
                    bar.update(int(sizes[c]))
                    if on_chunk is not None:
                        on_chunk(len(computed), c)
            finally:
                bar.close()
                st.end_run(run, {"wall_seconds": time.perf_counter() - t_start, "chunks_computed": len(computed),
                                 "stopped_early": len(computed) < len(todo)})
        executor = ex.description
    complete = not st.missing_chunks()
    field = st.to_field() if complete else None
    return BoundMapRun(field=field, store=st, n_chunks=st.n_chunks, n_reused=n_reused, n_computed=len(computed),
                       run=run, wall_seconds=time.perf_counter() - t_start, executor=executor,
                       chunk_seconds=computed, pilot_evaluations=pilot_evals, pilot_seconds=pilot_secs)


def compute_field(robot, evaluator, spec, settings=None, store=None, **kwargs) -> BoundField | None:
    """The bound map as a :class:`BoundField` (:func:`compute_bound_map_store`'s ``field``).

    Parameters and errors as :func:`compute_bound_map_store`; returns None only when
    ``options.max_chunks`` stopped the run early.
    """
    return compute_bound_map_store(robot, evaluator, spec, settings, store, **kwargs).field
