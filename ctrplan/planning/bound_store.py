"""Chunked, resumable on-disk bound maps (zarr) computed locally or on a Dask cluster.

A bound map (the grid of :class:`~ctrplan.planning.BoundField`: the friction bound of Ha,
Fagogenis & Dupont 2019, Section III, doi:10.1109/TRO.2018.2878906, and its translation-last
variant, Section V-B) is stored as one zarr v3 group (a directory ``*.zarr``):

===================  ==========================  =========================================
array                shape                       content
===================  ==========================  =========================================
``values``           ``(n_1, ..., n_d, 4)``      bound quantities (:data:`QUANTITIES`) [m, rad]
``valid``            ``(n_1, ..., n_d)``         False where the model failed or was unstable
``done``             ``(b_1, ..., b_d)``         True once a chunk is written (last write)
``chunk_seconds``    ``(b_1, ..., b_d)``         evaluation wall time of each chunk [s]
``chunk_cpu_seconds`` ``(b_1, ..., b_d)``        CPU time of the evaluating thread [s]
``chunk_cold``       ``(b_1, ..., b_d)``         the chunk was the first one of its process
                                                 (its time includes imports and warm-up)
``chunk_run``        ``(b_1, ..., b_d)``         number of the run that computed the chunk
``axis_j``           ``(n_j,)``                  node coordinates of joint j [rad or m]
===================  ==========================  =========================================

``values`` and ``valid`` are chunked on the grid with one zarr chunk per computation chunk
(``b_j = ceil(n_j / c_j)`` chunks of ``c_j`` nodes along joint j), so each finished chunk is one
atomic file write per array; ``done`` is written last, so a run killed at any moment resumes
from the chunks whose ``done`` flag is set and recomputes only the others.

The group's attributes identify the map: the sha256 of the robot file (or, for a robot built in
code, of its canonical description), the model settings, the resolution, the evaluator and the
combined :func:`~ctrplan.planning.field_key`. Resuming into a store made for anything else raises
:class:`BoundMapMismatchError` naming the store, the attribute and both values.

Chunks are evaluated in this process (``n_jobs=1``), on a ``distributed.LocalCluster`` of
``n_jobs`` single-threaded worker processes, or on an existing Dask cluster given by its
scheduler address (``tcp://host:8786``) or a ``distributed.Client``. Only this process (the
client) writes to the store, as results arrive, so the workers need no shared file system.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import time
import uuid
from dataclasses import dataclass, field as dc_field
from pathlib import Path

import numpy as np

from ..errors import CtrplanError
from .bound_field import (DEFAULT_CHUNK_SIZE, QUANTITIES, UNITS, BoundField, BoundFieldKeyError,
                          _canonical_robot, _evaluate_node, _resolution, _settings_dict, evaluator_name, field_key,
                          grid_axes)

__all__ = ["STORE_FORMAT", "STORE_VERSION", "BoundMapMismatchError", "IncompleteBoundMapError",
           "SchedulerUnreachableError", "BoundMapStore",
           "BoundMapRun", "MapIdentity", "map_identity", "chunk_shape_for", "compute_bound_map_store",
           "is_store_path", "start_local_cluster"]

# Written to the group's attributes; a store of another format or version is refused.
STORE_FORMAT = "ctrplan-boundmap"
STORE_VERSION = 1
# Suffix that marks a path as a zarr store (a directory) rather than an .npz file.
STORE_SUFFIX = ".zarr"

# How long to try to reach a Dask scheduler given by its address [s].
SCHEDULER_TIMEOUT_S = 30.0

# Set in each process that evaluates chunks: the first chunk of a process carries the imports
# and numba warm-up, which a benchmark must not count as steady-state cost.
_CHUNKS_IN_THIS_PROCESS = 0


class BoundMapMismatchError(BoundFieldKeyError):
    """A store holds a map of another robot file, model settings, resolution or evaluator.

    Attributes
    ----------
    store : str
        Path of the store.
    key : str
        Attribute that differs (``robot_sha256``, ``resolution``, ``settings.ds``, ...).
    stored, requested
        The store's value and this run's value.
    """

    def __init__(self, store, key, stored, requested):
        self.store, self.key, self.stored, self.requested = str(store), str(key), stored, requested
        super().__init__(
            f"{self.store}: key '{self.key}' is {stored!r} in the store but {requested!r} for this run; "
            "the store holds a bound map of another robot file, model settings, resolution or evaluator "
            "and maps are never mixed: use another output path or delete the store")


class SchedulerUnreachableError(CtrplanError, RuntimeError):
    """No Dask scheduler answers at the given address."""


class IncompleteBoundMapError(CtrplanError, ValueError):
    """A bound-map store is read as a field before all its chunks are computed."""


def is_store_path(path) -> bool:
    """True if ``path`` names a zarr store (suffix ``.zarr`` or an existing directory)."""
    p = Path(path)
    return p.suffix == STORE_SUFFIX or p.is_dir()


def _json_roundtrip(x):
    return json.loads(json.dumps(x, sort_keys=True, default=repr))


@dataclass(frozen=True)
class MapIdentity:
    """What a bound map was computed for; stored in the map and compared before resuming.

    Attributes
    ----------
    key : str
        :func:`~ctrplan.planning.field_key` (64 hex digits): hash of all the fields below.
    robot_sha256 : str
        sha256 of the robot file's text, or of the canonical robot description when
        ``robot_hash_of == "robot description"``.
    robot_hash_of : str
        ``"robot file"`` or ``"robot description"``.
    resolution : tuple of int, shape (n_joints,)
    settings : dict
        Model settings (:meth:`ModelSettings.as_dict`).
    evaluator : str
        :func:`~ctrplan.planning.bound_field.evaluator_name`.
    joint_names : tuple of str
    robot_name : str
        Informative only (not compared).
    """

    key: str
    robot_sha256: str
    robot_hash_of: str
    resolution: tuple
    settings: dict
    evaluator: str
    joint_names: tuple
    robot_name: str = ""

    def as_attrs(self) -> dict:
        """JSON attributes of the store."""
        return _json_roundtrip({
            "format": STORE_FORMAT, "format_version": STORE_VERSION, "key": self.key,
            "robot_sha256": self.robot_sha256, "robot_hash_of": self.robot_hash_of,
            "resolution": list(self.resolution), "settings": self.settings, "evaluator": self.evaluator,
            "joint_names": list(self.joint_names), "robot": self.robot_name,
        })


def map_identity(robot, settings, resolution, evaluator, robot_file_text: str | None = None) -> MapIdentity:
    """Identity of the bound map of ``robot`` (see :class:`MapIdentity`).

    Parameters
    ----------
    robot : Robot
    settings : ModelSettings, dict or None
    resolution : int or sequence of int, shape (n_joints,)
    evaluator : callable or str
    robot_file_text : str, optional
        Content of the robot file; hashed instead of the canonical robot description.

    Returns
    -------
    MapIdentity

    Raises
    ------
    ValueError
        Bad resolution (see :func:`~ctrplan.planning.grid_axes`).
    """
    res = _resolution(robot, resolution)
    if robot_file_text is not None:
        digest, of = hashlib.sha256(robot_file_text.encode()).hexdigest(), "robot file"
    else:
        digest, of = hashlib.sha256(_canonical_robot(robot).encode()).hexdigest(), "robot description"
    return MapIdentity(
        key=field_key(robot, settings, res, evaluator, robot_file_text), robot_sha256=digest, robot_hash_of=of,
        resolution=res, settings=_json_roundtrip(_settings_dict(settings)),
        evaluator=evaluator if isinstance(evaluator, str) else evaluator_name(evaluator),
        joint_names=tuple(robot.joint_names), robot_name=robot.name)


def chunk_shape_for(resolution, chunk_size: int) -> tuple[int, ...]:
    """Chunk shape of about ``chunk_size`` nodes, filling the last joints first.

    Each axis is split into the fewest pieces that respect the budget, with ``ceil(n / pieces)``
    nodes per chunk (zarr chunks are regular; the last chunk of an axis may be shorter).

    Parameters
    ----------
    resolution : sequence of int, shape (d,)
        Grid nodes per joint.
    chunk_size : int
        Target nodes per chunk (>= 1); the result has at most this many.

    Returns
    -------
    tuple of int, shape (d,)

    Raises
    ------
    ValueError
        If ``chunk_size < 1``.
    """
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size must be >= 1 node, got {chunk_size!r}")
    res = [int(n) for n in resolution]
    chunks = [1] * len(res)
    remaining = int(chunk_size)
    for j in reversed(range(len(res))):
        c = min(res[j], max(1, remaining))
        pieces = -(-res[j] // c)
        c = -(-res[j] // pieces)
        chunks[j] = c
        remaining //= c
    return tuple(chunks)


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


class BoundMapStore:
    """A bound map in a zarr group (see the module docstring for the layout).

    Use :meth:`create_or_resume` to compute into a store and :meth:`open` to read one.

    Attributes
    ----------
    path : str
        Location (``"<memory>"`` for an in-memory store).
    group : zarr.Group
    axes : list of ndarray, shape (n_j,)
    periodic : ndarray of bool, shape (d,)
    resolution, chunks, n_chunks_per_axis : tuple of int, shape (d,)
    """

    def __init__(self, group, path: str):
        self.group = group
        self.path = str(path)
        attrs = dict(group.attrs)
        if attrs.get("format") != STORE_FORMAT:
            raise IncompleteBoundMapError(
                f"{self.path}: key 'format' is {attrs.get('format')!r}, not {STORE_FORMAT!r}: not a ctrplan bound "
                "map, or its creation was interrupted before it was identified (delete it and rerun)")
        if attrs.get("format_version") != STORE_VERSION:
            raise BoundMapMismatchError(self.path, "format_version", attrs.get("format_version"), STORE_VERSION)
        self.attrs = attrs
        self.resolution = tuple(int(n) for n in attrs["resolution"])
        self.periodic = np.asarray(attrs["periodic"], dtype=bool)
        self.axes = [np.asarray(group[f"axis_{j}"][...], dtype=float) for j in range(len(self.resolution))]
        self.chunks = tuple(int(c) for c in group["valid"].chunks)
        self.n_chunks_per_axis = tuple(-(-n // c) for n, c in zip(self.resolution, self.chunks))

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path) -> "BoundMapStore":
        """Open an existing store read-only.

        Raises
        ------
        FileNotFoundError
            No store at ``path``.
        IncompleteBoundMapError
            ``path`` is a zarr group but not a ctrplan bound map.
        """
        import zarr

        return cls(zarr.open_group(str(path), mode="r"), str(path))

    @classmethod
    def create_or_resume(cls, path, identity: MapIdentity, axes, periodic, chunks,
                         metadata: dict | None = None) -> "BoundMapStore":
        """Create a store for ``identity``, or reopen the existing one if it was made for it.

        Parameters
        ----------
        path : str, Path or None
            Store directory (``*.zarr``); None keeps the store in memory.
        identity : MapIdentity
        axes : list of ndarray, shape (n_j,)
            Grid node coordinates (:func:`~ctrplan.planning.grid_axes`) [rad or m].
        periodic : sequence of bool, shape (d,)
        chunks : tuple of int, shape (d,)
            Nodes per chunk along each joint, for a new store; an existing store keeps its own.
        metadata : dict, optional
            Extra JSON metadata for a new store (robot file name, ...).

        Returns
        -------
        BoundMapStore

        Raises
        ------
        BoundMapMismatchError
            The existing store was made for another robot file, settings, resolution or
            evaluator (the error names the differing attribute and both values).
        IncompleteBoundMapError
            ``path`` holds a zarr group that is not a ctrplan bound map.
        """
        import zarr

        want = identity.as_attrs()
        if path is None:
            group, where = zarr.open_group(zarr.storage.MemoryStore(), mode="w"), "<memory>"
        else:
            where = str(path)
            if Path(path).exists():
                group = zarr.open_group(where, mode="r+")
                store = cls(group, where)
                store._check_identity(want)
                return store
            group = zarr.open_group(where, mode="w-")
        res = tuple(int(n) for n in identity.resolution)
        chunks = tuple(int(c) for c in chunks)
        nb = tuple(-(-n // c) for n, c in zip(res, chunks))
        group.create_array("values", shape=res + (len(QUANTITIES),), chunks=chunks + (len(QUANTITIES),),
                           dtype="float64", fill_value=np.nan)
        group.create_array("valid", shape=res, chunks=chunks, dtype="bool", fill_value=False)
        group.create_array("done", shape=nb, chunks=(1,) * len(nb), dtype="bool", fill_value=False)
        group.create_array("chunk_seconds", shape=nb, chunks=(1,) * len(nb), dtype="float64", fill_value=np.nan)
        group.create_array("chunk_cpu_seconds", shape=nb, chunks=(1,) * len(nb), dtype="float64",
                           fill_value=np.nan)
        group.create_array("chunk_cold", shape=nb, chunks=(1,) * len(nb), dtype="bool", fill_value=False)
        group.create_array("chunk_run", shape=nb, chunks=(1,) * len(nb), dtype="int32", fill_value=0)
        for j, a in enumerate(axes):
            arr = group.create_array(f"axis_{j}", shape=(len(a),), dtype="float64", fill_value=np.nan)
            arr[...] = np.asarray(a, dtype=float)
        meta = {
            "quantities": list(QUANTITIES), "units": [UNITS[q] for q in QUANTITIES],
            "created_utc": _now(), **_json_roundtrip(metadata or {}),
        }
        # identity last: a store whose creation was interrupted has no identity and is refused
        group.attrs.update({"periodic": [bool(p) for p in periodic], "metadata": meta, "runs": [], **want})
        return cls(group, where)

    def _check_identity(self, want: dict) -> None:
        for name in ("resolution", "robot_sha256", "robot_hash_of", "evaluator", "joint_names"):
            if self.attrs.get(name) != want[name]:
                raise BoundMapMismatchError(self.path, name, self.attrs.get(name), want[name])
        stored_s, want_s = self.attrs.get("settings", {}), want["settings"]
        for name in sorted(set(stored_s) | set(want_s)):
            if stored_s.get(name) != want_s.get(name):
                raise BoundMapMismatchError(self.path, f"settings.{name}", stored_s.get(name), want_s.get(name))
        if self.attrs.get("key") != want["key"]:
            raise BoundMapMismatchError(self.path, "key", self.attrs.get("key"), want["key"])

    # ------------------------------------------------------------------ chunks
    @property
    def key(self) -> str:
        return str(self.attrs["key"])

    @property
    def n_chunks(self) -> int:
        return int(np.prod(self.n_chunks_per_axis))

    def chunk_index(self, flat: int) -> tuple[int, ...]:
        """Chunk grid index of flat chunk number ``flat`` (C order)."""
        return tuple(int(i) for i in np.unravel_index(int(flat), self.n_chunks_per_axis))

    def chunk_slices(self, flat: int) -> tuple[slice, ...]:
        """Grid slices of chunk ``flat``."""
        return tuple(slice(i * c, min((i + 1) * c, n))
                     for i, c, n in zip(self.chunk_index(flat), self.chunks, self.resolution))

    def chunk_nodes(self, flat: int) -> np.ndarray:
        """Grid nodes of chunk ``flat`` in C order, shape (m, d) [rad or m]."""
        sl = self.chunk_slices(flat)
        mesh = np.meshgrid(*[a[s] for a, s in zip(self.axes, sl)], indexing="ij")
        return np.stack([g.reshape(-1) for g in mesh], axis=1)

    def done(self) -> np.ndarray:
        """Finished-chunk flags, shape (n_chunks,) (flat C order)."""
        return np.asarray(self.group["done"][...], dtype=bool).reshape(-1)

    def missing_chunks(self) -> list[int]:
        """Flat numbers of the chunks not yet written."""
        return [int(c) for c in np.flatnonzero(~self.done())]

    def chunk_seconds(self) -> np.ndarray:
        """Evaluation wall time of each chunk, shape (n_chunks,) [s] (NaN if missing)."""
        return np.asarray(self.group["chunk_seconds"][...], dtype=float).reshape(-1)

    def chunk_cpu_seconds(self) -> np.ndarray:
        """CPU time of the thread that evaluated each chunk, shape (n_chunks,) [s]; below the wall
        time when the worker shared its core."""
        return np.asarray(self.group["chunk_cpu_seconds"][...], dtype=float).reshape(-1)

    def chunk_cold(self) -> np.ndarray:
        """First chunk of its process (time includes warm-up), shape (n_chunks,)."""
        return np.asarray(self.group["chunk_cold"][...], dtype=bool).reshape(-1)

    def chunk_run(self) -> np.ndarray:
        """Run number that computed each chunk (0: none yet), shape (n_chunks,)."""
        return np.asarray(self.group["chunk_run"][...], dtype=np.int64).reshape(-1)

    def chunk_sizes(self) -> np.ndarray:
        """Nodes in each chunk, shape (n_chunks,)."""
        return np.array([int(np.prod([s.stop - s.start for s in self.chunk_slices(c)]))
                         for c in range(self.n_chunks)])

    def begin_run(self, info: dict) -> int:
        """Record the start of a computing run; returns its number (1, 2, ...)."""
        runs = list(self.group.attrs.get("runs", []))
        runs.append(_json_roundtrip({"started_utc": _now(), **info}))
        self.group.attrs.update({"runs": runs})
        self.attrs["runs"] = runs
        return len(runs)

    def end_run(self, run: int, info: dict) -> None:
        """Add ``info`` (end time, wall time, chunks computed, ...) to the record of run ``run``."""
        runs = list(self.group.attrs.get("runs", []))
        runs[run - 1] = _json_roundtrip({**runs[run - 1], "finished_utc": _now(), **info})
        self.group.attrs.update({"runs": runs})
        self.attrs["runs"] = runs

    def runs(self) -> list[dict]:
        """Records of the computing runs: start and end time, executor, wall time [s], chunks."""
        return list(self.group.attrs.get("runs", []))

    def write_chunk(self, flat: int, values, valid, seconds: float, cold: bool, run: int,
                    cpu_seconds: float = float("nan")) -> None:
        """Write one finished chunk; the ``done`` flag is written last.

        Parameters
        ----------
        flat : int
            Chunk number.
        values : ndarray, shape (m, 4)
            Per node in C order: the quantities of :data:`QUANTITIES` [m, rad].
        valid : ndarray of bool, shape (m,)
        seconds : float
            Evaluation wall time [s].
        cold : bool
            First chunk of its process.
        run : int
            Run number (:meth:`begin_run`).
        cpu_seconds : float
            CPU time of the evaluating thread [s].
        """
        sl = self.chunk_slices(flat)
        shape = tuple(s.stop - s.start for s in sl)
        idx = self.chunk_index(flat)
        self.group["values"][sl + (slice(None),)] = np.asarray(values, dtype=float).reshape(shape + (len(QUANTITIES),))
        self.group["valid"][sl] = np.asarray(valid, dtype=bool).reshape(shape)
        self.group["chunk_seconds"][idx] = float(seconds)
        self.group["chunk_cpu_seconds"][idx] = float(cpu_seconds)
        self.group["chunk_cold"][idx] = bool(cold)
        self.group["chunk_run"][idx] = int(run)
        self.group["done"][idx] = True

    # ------------------------------------------------------------------ reading
    def metadata(self) -> dict:
        """Field metadata: robot, joint names, resolution, evaluator, settings, units, hashes."""
        a = self.attrs
        meta = dict(a.get("metadata", {}))
        meta.update({"robot": a.get("robot"), "joint_names": a.get("joint_names"), "resolution": a.get("resolution"),
                     "evaluator": a.get("evaluator"), "settings": a.get("settings"),
                     "robot_sha256": a.get("robot_sha256"), "robot_hash_of": a.get("robot_hash_of"),
                     "store": self.path})
        return meta

    def to_field(self, key: str | None = None, **kwargs) -> BoundField:
        """The complete map as a :class:`BoundField`.

        Parameters
        ----------
        key : str, optional
            Expected :func:`~ctrplan.planning.field_key`; a mismatch raises.
        **kwargs
            Passed to :class:`BoundField` (``invalid_value``).

        Raises
        ------
        BoundFieldKeyError
            ``key`` differs from the store's key.
        IncompleteBoundMapError
            Some chunks are not computed yet.
        """
        if key is not None and key != self.key:
            raise BoundMapMismatchError(self.path, "key", self.key, key)
        missing = self.missing_chunks()
        if missing:
            raise IncompleteBoundMapError(
                f"{self.path}: bound map incomplete: {len(missing)} of {self.n_chunks} chunks not computed yet; "
                f"resume it with `ctrplan boundmap --robot <robot file> --out {self.path}` and the same settings")
        values = np.asarray(self.group["values"][...], dtype=float)
        valid = np.asarray(self.group["valid"][...], dtype=bool)
        meta = self.metadata()
        meta["n_invalid"] = int(np.count_nonzero(~valid))
        return BoundField(self.axes, self.periodic, values, valid, self.key, meta, **kwargs)


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
        Wall time of the run [s], including cluster start-up.
    executor : str
        ``"serial"``, ``"local cluster (k workers)"`` or ``"dask scheduler <address>"``.
    chunk_seconds : list of float
        Evaluation time of each chunk computed by this run [s].
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


def _compute_chunk(robot, evaluator, settings, q_nodes):
    """Evaluate one chunk (runs on a worker).

    Returns (values (m, 4), valid (m,), wall seconds, thread CPU seconds, first chunk of the process).
    """
    global _CHUNKS_IN_THIS_PROCESS
    t0, c0 = time.perf_counter(), time.thread_time()
    values = np.empty((len(q_nodes), len(QUANTITIES)))
    valid = np.empty(len(q_nodes), dtype=bool)
    for m, q in enumerate(q_nodes):
        values[m], valid[m] = _evaluate_node(robot, evaluator, q, settings)
    _CHUNKS_IN_THIS_PROCESS += 1
    return values, valid, time.perf_counter() - t0, time.thread_time() - c0, _CHUNKS_IN_THIS_PROCESS == 1


class _Progress:
    """tqdm bar over nodes, or nothing (tqdm imported lazily)."""

    def __init__(self, total, initial, enable, desc):
        self._bar = None
        if enable:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=total, initial=initial, unit="node", desc=desc)

    def update(self, n):
        if self._bar is not None:
            self._bar.update(n)

    def close(self):
        if self._bar is not None:
            self._bar.close()


def start_local_cluster(n_workers: int):
    """A ``distributed.LocalCluster`` of ``n_workers`` single-threaded worker processes.

    No dashboard; the scheduler's HTTP endpoint listens on a free localhost port (not 8787, which
    another cluster on the machine may hold). Workers inherit this process's environment (set
    ``OPENBLAS_NUM_THREADS=1`` before, as the CLI does). Close it (or use it as a context
    manager) when done.
    """
    from distributed import LocalCluster

    return LocalCluster(n_workers=int(n_workers), threads_per_worker=1, processes=True, dashboard_address=None,
                        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})


def _open_client(scheduler, n_jobs):
    """(client, cluster or None, close_client, description) for the dask executors."""
    from distributed import Client

    if scheduler is None:
        cluster = start_local_cluster(n_jobs)
        return Client(cluster), cluster, True, f"local cluster ({int(n_jobs)} workers)"
    if isinstance(scheduler, str):
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SchedulerUnreachableError(
                f"dask scheduler {scheduler!r}: cannot connect within {SCHEDULER_TIMEOUT_S:g} s ({exc}); start it "
                "with `dask scheduler` and workers with `dask worker ADDRESS --nthreads 1`") from None
        return client, None, True, f"dask scheduler {scheduler}"
    return scheduler, None, False, f"dask client of {scheduler.scheduler.address}"


def compute_bound_map_store(robot, evaluator, resolution, settings=None, store=None, n_jobs: int = 1, *,
                            scheduler=None, chunk_size: int = DEFAULT_CHUNK_SIZE, progress: bool = True,
                            robot_file_text: str | None = None, metadata: dict | None = None,
                            max_chunks: int | None = None, on_chunk=None) -> BoundMapRun:
    """Evaluate the bound map chunk by chunk into a zarr store, resuming finished chunks.

    Parameters
    ----------
    robot : Robot
    evaluator : callable
        ``evaluator(robot, alpha (n,) [rad], beta (n,) [m], settings) -> BoundResult`` (normally
        :func:`ctrplan.mechanics.evaluate_bound`). On a cluster it must be importable by the
        workers (a module-level function of an installed package).
    resolution : int or sequence of int, shape (n_joints,)
        Nodes per joint (>= 2).
    settings : ModelSettings, optional
    store : str or Path, optional
        Store directory (``*.zarr``). Finished chunks found there are reused when the store was
        made for the same robot, settings, resolution and evaluator. None: in memory.
    n_jobs : int
        Without ``scheduler``: 1 evaluates in this process, k > 1 starts a
        ``distributed.LocalCluster`` of k single-threaded worker processes.
    scheduler : str or distributed.Client, optional, keyword-only
        Dask scheduler address (``"tcp://host:8786"``) or a connected client (left open).
    chunk_size : int, keyword-only
        Nodes per chunk for a new store (an existing store keeps its chunks).
    progress : bool, keyword-only
        tqdm bar over nodes.
    robot_file_text : str, optional, keyword-only
        Robot file content: its sha256 identifies the robot in the store and the key.
    metadata : dict, optional, keyword-only
        Extra JSON metadata for a new store.
    max_chunks : int, optional, keyword-only
        Compute at most this many missing chunks, then stop (the field is None unless complete).
    on_chunk : callable, optional, keyword-only
        ``on_chunk(n_written, chunk)`` after each chunk is written (n_written counts this run's
        chunks); an exception raised there stops the run like an interruption.

    Returns
    -------
    BoundMapRun

    Raises
    ------
    BoundMapMismatchError
        ``store`` holds a map of another robot file, settings, resolution or evaluator.
    SchedulerUnreachableError
        No scheduler answers at the address ``scheduler`` within :data:`SCHEDULER_TIMEOUT_S`.
    ValueError
        Bad resolution or chunk size.
    """
    t_start = time.perf_counter()
    ident = map_identity(robot, settings, resolution, evaluator, robot_file_text)
    res = ident.resolution
    axes = grid_axes(robot, res)
    periodic = [j.periodic for j in robot.joints]
    st = BoundMapStore.create_or_resume(store, ident, axes, periodic, chunk_shape_for(res, chunk_size),
                                        metadata=metadata)
    todo = st.missing_chunks()
    n_reused = st.n_chunks - len(todo)
    if max_chunks is not None:
        todo = todo[:max(0, int(max_chunks))]
    use_dask = scheduler is not None or int(n_jobs) > 1
    executor = "serial"
    computed: list[float] = []
    run = 0
    if todo:
        sizes = st.chunk_sizes()
        n_nodes = int(np.prod(res))
        done_nodes = int(sizes[st.done()].sum())
        client = cluster = None
        close_client = False
        if use_dask:
            client, cluster, close_client, executor = _open_client(scheduler, n_jobs)
        run = st.begin_run({"executor": executor, "pid": os.getpid(), "chunks_to_compute": len(todo)})
        bar = _Progress(n_nodes, done_nodes, progress, f"bound map {robot.name}")

        def finish(c, result):
            values, valid, secs, cpu, cold = result
            st.write_chunk(c, values, valid, secs, cold, run, cpu)
            computed.append(float(secs))
            bar.update(int(sizes[c]))
            if on_chunk is not None:
                on_chunk(len(computed), c)

        try:
            if not use_dask:
                for c in todo:
                    finish(c, _compute_chunk(robot, evaluator, settings, st.chunk_nodes(c)))
            else:
                from distributed import as_completed

                tag = uuid.uuid4().hex[:8]
                futures = {}
                for c in todo:
                    fut = client.submit(_compute_chunk, robot, evaluator, settings, st.chunk_nodes(c),
                                        key=f"ctrplan-boundmap-{ident.key[:12]}-{tag}-chunk-{c}", pure=False)
                    futures[fut] = c
                try:
                    for fut in as_completed(list(futures)):
                        c = futures.pop(fut)
                        finish(c, fut.result())
                finally:
                    if futures:
                        client.cancel(list(futures))
        finally:
            bar.close()
            if close_client:
                client.close()
            if cluster is not None:
                cluster.close()
            st.end_run(run, {"wall_seconds": time.perf_counter() - t_start, "chunks_computed": len(computed),
                             "stopped_early": len(computed) < len(todo)})
    complete = not st.missing_chunks()
    field = st.to_field() if complete else None
    return BoundMapRun(field=field, store=st, n_chunks=st.n_chunks, n_reused=n_reused, n_computed=len(computed),
                       run=run, wall_seconds=time.perf_counter() - t_start, executor=executor,
                       chunk_seconds=computed)
