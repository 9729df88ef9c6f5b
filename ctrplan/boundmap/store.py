"""Chunked, resumable on-disk bound maps (zarr).

A bound map (:class:`~ctrplan.boundmap.field.BoundField`) is stored as one zarr v3 group (a
directory ``*.zarr``):

=====================  ==========================  =========================================
array                  shape                       content
=====================  ==========================  =========================================
``values``             ``(n_1, ..., n_d, 4)``      bound quantities (:data:`QUANTITIES`) [m, rad]
``valid``              ``(n_1, ..., n_d)``         False where the model failed or was unstable
``done``               ``(b_1, ..., b_d)``         True once a chunk is written (last write)
``chunk_seconds``      ``(b_1, ..., b_d)``         evaluation wall time of each chunk [s]
``chunk_cpu_seconds``  ``(b_1, ..., b_d)``         CPU time of the evaluating thread [s]
``chunk_cold``         ``(b_1, ..., b_d)``         first chunk of its process (time includes
                                                   imports and warm-up)
``chunk_run``          ``(b_1, ..., b_d)``         number of the run that computed the chunk
``axis_k``             ``(n_k,)``                  nodes of map coordinate k [rad or m]
``pilot_k_points``     ``(L, m, d)``               pilot samples of adaptive coordinate k
``pilot_k_values``     ``(L, m, 4)``               the exact bound there (NaN where it failed)
=====================  ==========================  =========================================

``values`` and ``valid`` are chunked on the grid with one zarr chunk per computation chunk, so
each finished chunk is one atomic file write per array; ``done`` is written last, so a run killed
at any moment resumes from the chunks whose ``done`` flag is set.

The group's attributes identify the map (:class:`~ctrplan.boundmap.identity.MapIdentity`: robot
file hash, model settings, grid spec, evaluator, mechanics version, key) and hold the map
coordinates (:class:`~ctrplan.coordinates.MapCoordinates`). Resuming into, or loading
with a key, a store made for anything else raises
:class:`~ctrplan.boundmap.identity.BoundMapMismatchError` naming the attribute and both values.
"""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import numpy as np

from ..errors import CtrplanError
from .field import QUANTITIES, UNITS, BoundField, coordinates_from_dict
from .identity import BoundMapMismatchError, MapIdentity

__all__ = ["STORE_FORMAT", "STORE_VERSION", "STORE_SUFFIX", "IncompleteBoundMapError", "BoundMapStore",
           "chunk_shape_for", "is_store_path", "load_bound_map"]

# Written to the group's attributes; a store of another format or version is refused.
STORE_FORMAT = "ctrplan-boundmap"
STORE_VERSION = 2
# Suffix that marks a path as a zarr store (a directory) rather than an .npz file.
STORE_SUFFIX = ".zarr"


class IncompleteBoundMapError(CtrplanError, ValueError):
    """A bound-map store is read as a field before all its chunks are computed."""


def is_store_path(path) -> bool:
    """True if ``path`` names a zarr store (suffix ``.zarr`` or an existing directory)."""
    p = Path(path)
    return p.suffix == STORE_SUFFIX or p.is_dir()


def _json_roundtrip(x):
    return json.loads(json.dumps(x, sort_keys=True, default=repr))


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def chunk_shape_for(resolution, chunk_size: int) -> tuple[int, ...]:
    """Chunk shape of about ``chunk_size`` nodes, filling the last coordinates first.

    Each axis is split into the fewest pieces that respect the budget, with ``ceil(n / pieces)``
    nodes per chunk (zarr chunks are regular; the last chunk of an axis may be shorter).

    Parameters
    ----------
    resolution : sequence of int, shape (d,)
        Grid nodes per map coordinate.
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


class BoundMapStore:
    """A bound map in a zarr group (see the module docstring for the layout).

    Use :meth:`create_or_resume` to compute into a store and :meth:`open` to read one.

    Attributes
    ----------
    path : str
        Location (``"<memory>"`` for an in-memory store).
    group : zarr.Group
    axes : list of ndarray, shape (n_k,)
    periodic : ndarray of bool, shape (d,)
    coordinates : MapCoordinates
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
        self.coordinates = coordinates_from_dict(attrs["coordinates"])
        self.periodic = np.asarray(attrs["periodic"], dtype=bool)
        d = self.periodic.size
        self.axes = [np.asarray(group[f"axis_{j}"][...], dtype=float) for j in range(d)]
        self.resolution = tuple(a.size for a in self.axes)
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
        BoundMapMismatchError
            A store of another format version (made by older code).
        """
        import zarr

        if not Path(path).exists():
            raise FileNotFoundError(f"no bound map store at {path}")
        return cls(zarr.open_group(str(path), mode="r"), str(path))

    @classmethod
    def resume(cls, path, identity: MapIdentity) -> "BoundMapStore | None":
        """The store at ``path`` opened for writing if it was made for ``identity``; None if there
        is none (or ``path`` is None).

        Raises
        ------
        BoundMapMismatchError
            The store there was made for another map.
        IncompleteBoundMapError
            ``path`` holds a zarr group that is not a ctrplan bound map.
        """
        import zarr

        if path is None or not Path(path).exists():
            return None
        store = cls(zarr.open_group(str(path), mode="r+"), str(path))
        store.check(identity)
        return store

    def check(self, identity: MapIdentity) -> None:
        """Raise :class:`BoundMapMismatchError` unless this store was made for ``identity``."""
        identity.check(self.attrs, self.path)

    @classmethod
    def create_or_resume(cls, path, identity: MapIdentity, axes, periodic, chunks, coordinates, *,
                         metadata: dict | None = None, pilots: dict | None = None) -> "BoundMapStore":
        """Create a store for ``identity``, or reopen the existing one if it was made for it.

        Parameters
        ----------
        path : str, Path or None
            Store directory (``*.zarr``); None keeps the store in memory.
        identity : MapIdentity
        axes : list of ndarray, shape (n_k,)
            Grid nodes [rad or m].
        periodic : sequence of bool, shape (d,)
        chunks : tuple of int, shape (d,)
            Nodes per chunk along each coordinate, for a new store (an existing store keeps its own).
        coordinates : MapCoordinates
        metadata : dict, optional, keyword-only
            Extra JSON metadata for a new store (robot file name, ...).
        pilots : dict, optional, keyword-only
            ``{k: (points (L, m, d), values (L, m, 4))}`` pilot samples of adaptive coordinates.

        Returns
        -------
        BoundMapStore

        Raises
        ------
        BoundMapMismatchError
            The existing store was made for another map.
        IncompleteBoundMapError
            ``path`` holds a zarr group that is not a ctrplan bound map.
        """
        import zarr

        existing = cls.resume(path, identity)
        if existing is not None:
            return existing
        if path is None:
            group, where = zarr.open_group(zarr.storage.MemoryStore(), mode="w"), "<memory>"
        else:
            where = str(path)
            group = zarr.open_group(where, mode="w-")
        res = tuple(len(a) for a in axes)
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
        for k, (pts, vals) in (pilots or {}).items():
            for name, arr in (("points", pts), ("values", vals)):
                a = np.asarray(arr, dtype=float)
                z = group.create_array(f"pilot_{k}_{name}", shape=a.shape, dtype="float64", fill_value=np.nan)
                z[...] = a
        meta = {"quantities": list(QUANTITIES), "units": [UNITS[q] for q in QUANTITIES], "created_utc": _now(),
                "pilot_coordinates": sorted(int(k) for k in (pilots or {})), **_json_roundtrip(metadata or {})}
        # identity last: a store whose creation was interrupted has no identity and is refused
        group.attrs.update({"periodic": [bool(p) for p in periodic], "coordinates": coordinates.as_dict(),
                            "metadata": meta, "runs": [], "format": STORE_FORMAT, "format_version": STORE_VERSION,
                            **identity.as_attrs()})
        return cls(group, where)

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
        """Grid nodes of chunk ``flat`` in C order, shape (m, d) [map coordinates]."""
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
        """CPU time of the thread that evaluated each chunk, shape (n_chunks,) [s]."""
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

    def pilots(self) -> dict:
        """Pilot samples of the adaptive coordinates: ``{k: (points (L, m, d), values (L, m, 4))}``."""
        out = {}
        for k in self.attrs.get("metadata", {}).get("pilot_coordinates", []):
            out[int(k)] = (np.asarray(self.group[f"pilot_{k}_points"][...]),
                           np.asarray(self.group[f"pilot_{k}_values"][...]))
        return out

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
        """Field metadata: robot, joint and coordinate names, spec, evaluator, settings, mechanics
        version, units, hashes."""
        a = self.attrs
        meta = dict(a.get("metadata", {}))
        meta.update({k: a.get(k) for k in ("robot", "joint_names", "coordinate_names", "spec", "evaluator",
                                           "settings", "mechanics_version", "robot_sha256", "robot_hash_of")})
        meta["store"] = self.path
        return meta

    def to_field(self, key: str | None = None, **kwargs) -> BoundField:
        """The complete map as a :class:`BoundField`.

        Parameters
        ----------
        key : str, optional
            Expected key; a mismatch raises.
        **kwargs
            Passed to :class:`BoundField` (``invalid_value``).

        Raises
        ------
        BoundMapMismatchError
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
        return BoundField(self.axes, self.periodic, values, valid, self.key, meta, coordinates=self.coordinates,
                          **kwargs)


def load_bound_map(path, key: str | None = None, **kwargs) -> BoundField:
    """Read a bound map from an ``.npz`` file (:meth:`BoundField.save`) or a complete zarr store.

    Parameters
    ----------
    path : str or Path
    key : str, optional
        Expected key; a mismatch raises.
    **kwargs
        Passed to :class:`BoundField` (``invalid_value``).

    Returns
    -------
    BoundField

    Raises
    ------
    BoundMapMismatchError
        The key differs, or the map is of an older format.
    IncompleteBoundMapError
        The store still misses chunks.
    FileNotFoundError
    """
    if is_store_path(path):
        return BoundMapStore.open(path).to_field(key=key, **kwargs)
    return BoundField.load(path, key=key, **kwargs)
