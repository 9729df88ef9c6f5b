"""How ctrplan runs independent tasks: one executor for every parallel job of the library.

:class:`Executor` runs a function over tasks and yields each result, with its tag, as it
finishes:

- ``n_jobs == 1`` and no scheduler: in this process, in order;
- ``n_jobs > 1``: on ``n_jobs`` local worker processes (``joblib.Parallel`` on its loky backend:
  processes started once per Python process and reused, shared with every other joblib user of the
  process);
- ``scheduler`` given (an address such as ``"tcp://host:8786"`` or a connected
  ``distributed.Client``): on the workers of that Dask cluster, which may span several machines.

The bound map, the batch evaluation of configurations, studies over many scenarios and the
bound-aware and bound-blind plans of one scenario all run through it; a caller picks where the
work runs with the same two arguments (``n_jobs``, ``scheduler``) everywhere.

Tasks are pickled to the workers: their function must be importable (module level), and every
argument picklable. An exception raised by a task is raised again where the results are read,
and the tasks not yet started are cancelled.
"""

from __future__ import annotations

from typing import Any, Callable, Hashable, Iterable, Iterator

from .errors import CtrplanError

__all__ = ["SCHEDULER_TIMEOUT_S", "SchedulerUnreachableError", "Executor", "start_local_cluster"]


#: How long to try to reach a Dask scheduler given by its address [s].
SCHEDULER_TIMEOUT_S = 30.0


class SchedulerUnreachableError(CtrplanError, RuntimeError):
    """No Dask scheduler answers at the given address."""


def start_local_cluster(n_workers: int):
    """A ``distributed.LocalCluster`` of ``n_workers`` single-threaded worker processes, to pass
    (or its address) as an :class:`Executor`'s ``scheduler``.

    No dashboard; the scheduler's HTTP endpoint listens on a free localhost port (not 8787, which
    another cluster on the machine may hold). Workers inherit this process's environment (set
    ``OPENBLAS_NUM_THREADS=1`` before, as the CLI does). Close it (or use it as a context
    manager) when done.
    """
    from distributed import LocalCluster

    return LocalCluster(n_workers=int(n_workers), threads_per_worker=1, processes=True, dashboard_address=None,
                        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})


class Executor:
    """Runs independent tasks in this process, on local worker processes or on a Dask cluster.

    Parameters
    ----------
    n_jobs : int
        Without ``scheduler``: 1 runs the tasks in this process, k > 1 on k local worker processes.
        With ``scheduler``: ignored (the cluster's workers take the tasks).
    scheduler : str or distributed.Client, optional
        Address of a running Dask scheduler (``"tcp://host:8786"``), connected on first use and
        closed on exit, or a connected client (left open).
    fork : bool, keyword-only
        Local workers forked from this process for each :meth:`run` (where the platform can fork;
        else the reusable workers): they start in milliseconds with this process's imported
        modules and compiled kernels, where a new reusable worker imports them again (about a
        second). For a few long tasks whose arguments this process already holds; forking a
        process that runs threads is unsafe in general, so only where the caller knows it is not.

    Raises
    ------
    ValueError
        ``n_jobs`` below 1.
    SchedulerUnreachableError
        (On first use.) No scheduler answers at ``scheduler`` within :data:`SCHEDULER_TIMEOUT_S`.

    Examples
    --------
    >>> with Executor(n_jobs=2) as ex:                                  # doctest: +SKIP
    ...     squares = dict(ex.run(pow, [(k, (k, 2)) for k in range(4)]))
    >>> squares                                                         # doctest: +SKIP
    {0: 0, 1: 1, 2: 4, 3: 9}
    """

    def __init__(self, n_jobs: int = 1, scheduler=None, *, fork: bool = False):
        n_jobs = int(n_jobs)
        if n_jobs < 1:
            raise ValueError(f"n_jobs must be at least 1, got {n_jobs}")
        self.n_jobs = n_jobs
        self.scheduler = scheduler
        self.fork = bool(fork)
        self._client = None
        self._close_client = False

    @property
    def kind(self) -> str:
        """``"serial"``, ``"processes"`` (local workers) or ``"dask"``."""
        if self.scheduler is not None:
            return "dask"
        return "processes" if self.n_jobs > 1 else "serial"

    @property
    def description(self) -> str:
        """Where the tasks run, for logs and run records: ``"serial"``, ``"k local processes"``,
        ``"dask scheduler <address>"`` or ``"dask client of <address>"``."""
        if self.kind == "serial":
            return "serial"
        if self.kind == "processes":
            return f"{self.n_jobs} local processes"
        if isinstance(self.scheduler, str):
            return f"dask scheduler {self.scheduler}"
        return f"dask client of {self.scheduler.scheduler.address}"

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def open(self) -> "Executor":
        """Connect to the Dask scheduler now (else on the first :meth:`run`); nothing to do for
        the other kinds. Raises :class:`SchedulerUnreachableError`."""
        if self.kind != "dask" or self._client is not None:
            return self
        if not isinstance(self.scheduler, str):
            self._client, self._close_client = self.scheduler, False
            return self
        from distributed import Client

        try:
            self._client = Client(self.scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SchedulerUnreachableError(
                f"dask scheduler {self.scheduler!r}: cannot connect within {SCHEDULER_TIMEOUT_S:g} s ({exc}); start "
                "it with `dask scheduler` and workers with `dask worker ADDRESS --nthreads 1`") from None
        self._close_client = True
        return self

    def close(self) -> None:
        """Close the client this executor connected (a client passed in stays open)."""
        if self._close_client and self._client is not None:
            self._client.close()
        self._client, self._close_client = None, False

    def run(self, fn: Callable, tasks: Iterable[tuple[Hashable, tuple]], *,
            first_here: bool = False) -> Iterator[tuple[Any, Any]]:
        """Run ``fn(*args)`` for each ``(tag, args)`` of ``tasks``; yield ``(tag, result)`` as each
        finishes (in order in this process; in order of completion on workers).

        Parameters
        ----------
        fn : callable
            A module-level function (pickled by reference to the workers).
        tasks : iterable of (tag, tuple)
            The tag names the task's result; ``args`` are passed to ``fn``.
        first_here : bool
            Run the first task in this process while the workers run the others (its result
            comes first). For a caller whose own process would otherwise wait idle: with
            ``n_jobs`` = 2 and two tasks, one runs here and one on a worker.

        Yields
        ------
        tuple
            ``(tag, fn(*args))``.

        Raises
        ------
        Exception
            The first exception of a task, where its result is read; the tasks not yet started
            are cancelled when the generator is closed.
        """
        tasks = list(tasks)
        head, rest = (tasks[:1], tasks[1:]) if first_here else ([], tasks)
        if self.kind == "serial" or not rest:
            for tag, args in tasks:
                yield tag, fn(*args)
            return
        results = self._start(fn, rest, reserve=len(head))
        for tag, args in head:
            yield tag, fn(*args)
        yield from results

    def _start(self, fn, tasks, reserve: int):
        """Submit ``tasks`` to the workers now; the generator of their tagged results."""
        if self.kind == "dask":
            from distributed import as_completed

            self.open()
            futures = {self._client.submit(fn, *args, pure=False): tag for tag, args in tasks}
            return _as_completed(futures, as_completed, self._client.cancel)
        import multiprocessing

        workers = max(1, min(self.n_jobs - reserve, len(tasks)))
        if self.fork and "fork" in multiprocessing.get_all_start_methods():
            from concurrent.futures import ProcessPoolExecutor, as_completed

            pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"))
            futures = {pool.submit(fn, *args): tag for tag, args in tasks}
            return _as_completed(futures, as_completed, lambda fs: [f.cancel() for f in fs], pool.shutdown)
        # joblib's own pool (not loky's reusable executor taken directly: joblib assumes that
        # executor is its own and fails on one created elsewhere). joblib runs a single worker in
        # this process; one worker beside a task run here is a pool of two given one task at a time.
        from joblib import Parallel, delayed

        n, ahead = (workers, 2 * workers) if workers > 1 or not reserve else (2, 1)
        return Parallel(n_jobs=n, pre_dispatch=ahead, batch_size=1, return_as="generator_unordered")(
            delayed(_tagged)(fn, tag, args) for tag, args in tasks)


def _tagged(fn, tag, args):
    """``(tag, fn(*args))``: a task of the local backend."""
    return tag, fn(*args)


def _as_completed(futures: dict, as_completed, cancel, shutdown=None):
    """Yield ``(tag, result)`` of ``futures`` ({future: tag}) as they finish; cancel the others when
    the generator is closed or a result raises; then ``shutdown()`` (a pool of this run only)."""
    try:
        for fut in as_completed(list(futures)):
            tag = futures.pop(fut)
            yield tag, fut.result()
    finally:
        if futures:
            cancel(list(futures))
        if shutdown is not None:
            shutdown(wait=True, cancel_futures=True)
