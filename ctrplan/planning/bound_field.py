"""Precomputed friction-bound map over the joint space with multilinear interpolation.

The friction bound of Ha, Fagogenis & Dupont 2019 (largest tip deviation of the 2^(n-1) bounding
friction solutions of Section III from the standard model, as computed by
:func:`ctrplan.mechanics.evaluate_bound`;
doi:10.1109/TRO.2018.2878906) costs 0.2-2 s per configuration, far too slow inside a sampling
planner that queries ~10^5 states. :class:`BoundField` evaluates it once on a regular grid of the
joint space and interpolates multilinearly:

- rotation joints whose limits span 2 pi are periodic: ``n`` nodes ``lower + 2 pi k / n``,
  ``k = 0..n-1`` (no duplicated endpoint), interpolation wraps round;
- other joints: ``n`` nodes from ``lower`` to ``upper`` inclusive; queries are clamped to the
  limits.

Each node stores the friction bound (tip position [m], tip angle [rad]), the translation-last
bound (the clearance-only solution, Section V-B) and a validity flag. Nodes where the evaluator
raised, did not converge, or reported an elastically unstable standard model are invalid: an
interpolated value that draws on an invalid node is ``invalid_value`` (default +inf) and
:meth:`BoundField.is_valid` is False there.

Computing runs the nodes in chunks, in this process, on a local Dask cluster or on a Dask
cluster given by its scheduler address, and writes each finished chunk to a zarr store as it
arrives, so an interrupted run resumes with only the missing chunks
(:mod:`ctrplan.planning.bound_store`). A finished field is read from the store or from one
``.npz`` file (:meth:`BoundField.save`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CtrplanError

__all__ = ["QUANTITIES", "BoundField", "BoundFieldKeyError", "InterpolationError", "field_key",
           "evaluator_name", "interpolation_error", "grid_axes"]

# Stored per-node quantities, in this order, with units.
QUANTITIES = ("position", "angle", "translation_last_position", "translation_last_angle")
UNITS = {"position": "m", "angle": "rad", "translation_last_position": "m", "translation_last_angle": "rad"}

# Grid nodes evaluated per chunk file: ~64 nodes x 0.2-2 s keeps a chunk between 10 s and 2 min,
# so an interruption loses little work while the number of files stays small.
DEFAULT_CHUNK_SIZE = 64

# Interpolation weights at or below this are ignored when deciding whether an invalid node
# contaminates a query (a query exactly on a valid node is valid).
_WEIGHT_EPS = 1e-12

FORMAT_VERSION = 1


class BoundFieldKeyError(CtrplanError, ValueError):
    """A cached chunk or saved field belongs to another robot, model setting, grid or evaluator."""


def evaluator_name(evaluator) -> str:
    """Stable name of an evaluator for the cache key: its ``name`` attribute, else
    ``module.qualname``."""
    name = getattr(evaluator, "name", None)
    if isinstance(name, str):
        return name
    mod = getattr(evaluator, "__module__", "") or ""
    qual = getattr(evaluator, "__qualname__", None) or type(evaluator).__qualname__
    return f"{mod}.{qual}"


def _canonical_robot(robot) -> str:
    d = dataclasses.asdict(robot)
    d.pop("metadata", None)
    return json.dumps(d, sort_keys=True, default=repr)


def _settings_dict(settings) -> dict:
    if settings is None:
        from ..mechanics.results import ModelSettings
        settings = ModelSettings()
    return settings.as_dict() if hasattr(settings, "as_dict") else dict(settings)


def _resolution(robot, resolution) -> tuple[int, ...]:
    n = len(robot.joints)
    res = np.broadcast_to(np.asarray(resolution, dtype=int), (n,)) if np.ndim(resolution) == 0 \
        else np.asarray(resolution, dtype=int)
    if res.shape != (n,):
        raise ValueError(f"resolution needs 1 or {n} integers ({', '.join(robot.joint_names)}), got {resolution!r}")
    if np.any(res < 2):
        raise ValueError(f"resolution must be >= 2 nodes per joint, got {resolution!r}")
    return tuple(int(r) for r in res)


def field_key(robot, settings, resolution, evaluator, robot_file_text: str | None = None) -> str:
    """Cache key of a bound field: sha256 over robot, model settings, grid and evaluator.

    Parameters
    ----------
    robot : Robot
        Used through a canonical JSON dump of its dataclass fields (metadata excluded) unless
        ``robot_file_text`` is given.
    settings : ModelSettings, dict or None
        None means default :class:`~ctrplan.mechanics.results.ModelSettings`.
    resolution : int or sequence of int, shape (n_joints,)
    evaluator : callable or str
        Name from :func:`evaluator_name` (or the name itself).
    robot_file_text : str, optional
        Content of the robot file, hashed instead of the canonical repr.

    Returns
    -------
    str
        64 hex digits.
    """
    payload = {
        "format": FORMAT_VERSION,
        "robot": robot_file_text if robot_file_text is not None else _canonical_robot(robot),
        "settings": _settings_dict(settings),
        "resolution": list(_resolution(robot, resolution)),
        "evaluator": evaluator if isinstance(evaluator, str) else evaluator_name(evaluator),
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=repr).encode()).hexdigest()


def grid_axes(robot, resolution) -> list[np.ndarray]:
    """Grid node coordinates of each joint.

    Parameters
    ----------
    robot : Robot
    resolution : int or sequence of int, shape (n_joints,)
        Nodes per joint (>= 2).

    Returns
    -------
    list of ndarray, shape (resolution[j],)
        Periodic rotations: ``lower + 2 pi k / n`` (no duplicated endpoint) [rad]; other joints:
        ``linspace(lower, upper, n)`` including both limits [rad or m].
    """
    res = _resolution(robot, resolution)
    axes = []
    for joint, n in zip(robot.joints, res):
        if joint.periodic:
            axes.append(joint.lower + 2.0 * np.pi * np.arange(n) / n)
        else:
            axes.append(np.linspace(joint.lower, joint.upper, n))
    return axes


def _atomic_savez(path: Path, **arrays) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _evaluate_node(robot, evaluator, q, settings):
    """Values (4,) and validity of one node; exceptions from the model mark it invalid."""
    try:
        alpha, beta = robot.configuration(q)
        robot.check_configuration(alpha, beta)
        res = evaluator(robot, alpha, beta, settings)
    except (CtrplanError, np.linalg.LinAlgError, FloatingPointError):
        # model failures mark the node invalid; programming errors propagate
        return np.full(len(QUANTITIES), np.nan), False
    vals = np.array([float(getattr(res, name)) for name in QUANTITIES])
    diag = getattr(res, "diagnostics", None)
    ok = bool(np.all(np.isfinite(vals)))
    if diag is not None:
        ok = ok and bool(diag.converged) and not bool(diag.unstable)
    return vals, ok


@dataclass
class InterpolationError:
    """Interpolated versus exact bound at random configurations.

    Attributes
    ----------
    q : ndarray, shape (m, n_joints)
        Configurations where both the field and the exact model are valid [rad or m].
    exact, interpolated : ndarray, shape (m,)
        Bound of ``quantity`` [m or rad].
    errors : ndarray, shape (m,)
        ``|interpolated - exact|`` [m or rad].
    n_invalid : int
        Sampled configurations skipped because the field or the exact model was invalid there.
    quantity : str
    """

    q: np.ndarray
    exact: np.ndarray
    interpolated: np.ndarray
    errors: np.ndarray
    n_invalid: int
    quantity: str

    @property
    def median(self) -> float:
        """Median absolute error [m or rad]."""
        return float(np.median(self.errors)) if self.errors.size else float("nan")

    @property
    def p95(self) -> float:
        """95th-percentile absolute error [m or rad]."""
        return float(np.percentile(self.errors, 95)) if self.errors.size else float("nan")


class BoundField:
    """Friction bound on a regular joint-space grid, interpolated multilinearly.

    Parameters
    ----------
    axes : list of ndarray, shape (n_i,)
        Node coordinates of each joint (from :func:`grid_axes`) [rad or m].
    periodic : sequence of bool, shape (n_joints,)
        Periodic rotation joints (period 2 pi).
    values : ndarray, shape (n_1, ..., n_d, 4)
        Per node: friction bound position [m], angle [rad], translation-last position [m],
        translation-last angle [rad] (order of :data:`QUANTITIES`). NaN at invalid nodes.
    valid : ndarray of bool, shape (n_1, ..., n_d)
        False where the model did not converge, was elastically unstable, or raised.
    key : str
        Cache key (:func:`field_key`).
    metadata : dict
        joint names, evaluator, settings, robot name, creation time ...
    invalid_value : float, keyword-only
        Returned by :meth:`__call__` where an invalid node contributes (default +inf).
    """

    def __init__(self, axes, periodic, values, valid, key: str, metadata: dict | None = None, *,
                 invalid_value: float = float("inf")):
        self.axes = [np.asarray(a, dtype=float) for a in axes]
        self.periodic = np.asarray(periodic, dtype=bool)
        self.shape = tuple(len(a) for a in self.axes)
        self.values = np.asarray(values, dtype=float)
        self.valid = np.asarray(valid, dtype=bool)
        if self.values.shape != self.shape + (len(QUANTITIES),) or self.valid.shape != self.shape:
            raise ValueError(f"values need shape {self.shape + (len(QUANTITIES),)} and valid {self.shape}, "
                             f"got {self.values.shape} and {self.valid.shape}")
        if self.periodic.shape != (len(self.axes),):
            raise ValueError(f"periodic needs {len(self.axes)} flags, got {self.periodic.shape}")
        self.key = str(key)
        self.metadata = dict(metadata or {})
        self.invalid_value = float(invalid_value)
        self._lo = np.array([a[0] for a in self.axes])
        self._hi = np.array([a[-1] for a in self.axes])
        self._h = np.array([(a[1] - a[0]) if len(a) > 1 else 1.0 for a in self.axes])
        # flat-index tables of the vectorized interpolation
        d = len(self.axes)
        self._n_int = np.array(self.shape, dtype=np.int64)
        self._n = self._n_int.astype(float)
        self._max_lo = np.where(self.periodic, self._n - 1, self._n - 2)
        self._strides = np.array([int(np.prod(self.shape[j + 1:])) for j in range(d)], dtype=np.int64)
        self._corner_bits = np.array([[(c >> j) & 1 for j in range(d)] for c in range(1 << d)], dtype=np.int64)
        self._flat_valid = self.valid.reshape(-1)
        flat = self.values.reshape(-1, len(QUANTITIES))
        self._flat_values = [np.where(self._flat_valid, np.nan_to_num(flat[:, k]), 0.0)
                             for k in range(len(QUANTITIES))]

    @property
    def n_joints(self) -> int:
        return len(self.axes)

    # ------------------------------------------------------------------ interpolation
    def _interp(self, q, column):
        """Multilinear interpolation of one quantity; returns (single, values (m,), ok (m,))."""
        q = np.asarray(q, dtype=float)
        single = q.ndim == 1
        q = np.atleast_2d(q)
        if q.shape[1] != self.n_joints:
            raise ValueError(f"queries need shape (m, {self.n_joints}), got {q.shape}")
        n = self._n
        u = (q - self._lo) / self._h
        u = np.where(self.periodic, np.mod(u, n), np.clip(u, 0.0, n - 1))
        lo = np.minimum(np.floor(u), self._max_lo)  # mod can round up to n
        t = u - lo
        lo = lo.astype(np.int64)
        hi = np.where(self.periodic, (lo + 1) % self._n_int, lo + 1)
        base = lo @ self._strides
        step = (hi - lo) * self._strides  # (m, d)
        flat = base[:, None] + step @ self._corner_bits.T  # (m, 2^d)
        tt = t[:, None, :]
        w = np.prod(np.where(self._corner_bits[None, :, :], tt, 1.0 - tt), axis=2)  # (m, 2^d)
        ok_node = self._flat_valid[flat]
        bad = np.any((w > _WEIGHT_EPS) & ~ok_node, axis=1)
        out = np.sum(w * self._flat_values[column][flat], axis=1)
        return single, out, ~bad

    def __call__(self, q, quantity: str = "position"):
        """Interpolated bound.

        Parameters
        ----------
        q : array-like, shape (n_joints,) or (m, n_joints)
            Joint vectors [rad or m]; periodic angles may be unwrapped, others are clamped to
            the grid.
        quantity : str
            One of :data:`QUANTITIES`.

        Returns
        -------
        float or ndarray, shape (m,)
            [m] or [rad]; ``invalid_value`` where an invalid node contributes.

        Raises
        ------
        ValueError
            Unknown quantity or wrong query shape.
        """
        if quantity not in QUANTITIES:
            raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
        single, out, ok = self._interp(q, QUANTITIES.index(quantity))
        res = np.where(ok, out, self.invalid_value)
        return float(res[0]) if single else res

    def is_valid(self, q):
        """False where an invalid node contributes to the interpolation.

        Parameters
        ----------
        q : array-like, shape (n_joints,) or (m, n_joints)

        Returns
        -------
        bool or ndarray of bool, shape (m,)
        """
        single, _, ok = self._interp(q, 0)
        return bool(ok[0]) if single else ok

    def nodes(self) -> np.ndarray:
        """All grid nodes in C order, shape (prod(shape), n_joints) [rad or m]."""
        mesh = np.meshgrid(*self.axes, indexing="ij")
        return np.stack([g.reshape(-1) for g in mesh], axis=1)

    # ------------------------------------------------------------------ persistence
    def save(self, path) -> Path:
        """Write the field to one ``.npz`` (atomically) with its key and metadata (JSON).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        path = Path(path)
        arrays = {f"axis_{j}": a for j, a in enumerate(self.axes)}
        _atomic_savez(path, key=np.array(self.key), periodic=self.periodic, values=self.values,
                      valid=self.valid, metadata=np.array(json.dumps(self.metadata, default=repr)),
                      format_version=np.array(FORMAT_VERSION), **arrays)
        return path

    @classmethod
    def load(cls, path, key: str | None = None, **kwargs) -> "BoundField":
        """Read a field from an ``.npz`` written by :meth:`save` or a complete zarr store.

        Parameters
        ----------
        path : str or Path
            ``*.npz`` file, or ``*.zarr`` store directory written by :meth:`compute` /
            ``ctrplan boundmap``.
        key : str, optional
            Expected key (:func:`field_key`); a mismatch raises.
        **kwargs
            Passed to the constructor (``invalid_value``).

        Raises
        ------
        BoundFieldKeyError
            If ``key`` is given and differs from the stored key.
        IncompleteBoundMapError
            The zarr store still misses chunks (``ctrplan.planning.bound_store``).
        FileNotFoundError
        """
        from .bound_store import BoundMapStore, is_store_path

        if is_store_path(path):
            return BoundMapStore.open(path).to_field(key=key, **kwargs)
        with np.load(Path(path), allow_pickle=False) as z:
            stored = str(z["key"])
            if key is not None and stored != key:
                raise BoundFieldKeyError(
                    f"{path}: bound field key {stored[:12]}... does not match the expected {key[:12]}...: "
                    "it was computed for another robot, model settings, resolution or evaluator")
            d = int(z["periodic"].shape[0])
            axes = [z[f"axis_{j}"] for j in range(d)]
            return cls(axes, z["periodic"], z["values"], z["valid"], stored,
                       json.loads(str(z["metadata"])), **kwargs)

    # ------------------------------------------------------------------ computing
    @classmethod
    def compute(cls, robot, evaluator, resolution, settings=None, store=None, n_jobs: int = 1,
                *, scheduler=None, chunk_size: int = DEFAULT_CHUNK_SIZE, progress: bool = True,
                robot_file_text: str | None = None, max_chunks: int | None = None,
                on_chunk=None) -> "BoundField | None":
        """Evaluate the bound at every grid node (in parallel, resumable) and build the field.

        A thin wrapper of :func:`ctrplan.planning.bound_store.compute_bound_map_store`, which
        also reports how many chunks were reused and computed.

        Parameters
        ----------
        robot : Robot
        evaluator : callable
            ``evaluator(robot, alpha (n,) [rad], beta (n,) [m], settings) -> BoundResult`` (e.g.
            :func:`ctrplan.mechanics.evaluate_bound`); must be importable by the workers (a
            module-level function of an installed package) when ``n_jobs != 1`` or
            ``scheduler`` is given.
        resolution : int or sequence of int, shape (n_joints,)
            Nodes per joint (>= 2).
        settings : ModelSettings, optional
        store : str or Path, optional
            zarr store directory (``*.zarr``) written chunk by chunk as chunks finish; a rerun
            with the same arguments after an interruption computes only the missing chunks.
            None computes in memory.
        n_jobs : int
            Without ``scheduler``: 1 runs in this process, k > 1 on a local Dask cluster of k
            single-threaded worker processes.
        scheduler : str or distributed.Client, optional, keyword-only
            Dask scheduler address (``"tcp://host:8786"``) or a connected client.
        chunk_size : int, keyword-only
            Nodes per chunk of a new store.
        progress : bool, keyword-only
            Show a tqdm progress bar (counts nodes).
        robot_file_text : str, optional
            Robot file content for the key (see :func:`field_key`) and the store's robot hash.
        max_chunks : int, optional
            Compute at most this many missing chunks and return None if the grid is still
            incomplete (for batch jobs and tests of resumption).
        on_chunk : callable, optional, keyword-only
            ``on_chunk(n_written, chunk)`` after each written chunk.

        Returns
        -------
        BoundField or None
            None only when ``max_chunks`` stopped the run early.

        Raises
        ------
        BoundFieldKeyError
            ``store`` holds a map of another robot, settings, resolution or evaluator
            (:class:`~ctrplan.planning.bound_store.BoundMapMismatchError`).
        """
        from .bound_store import compute_bound_map_store

        return compute_bound_map_store(robot, evaluator, resolution, settings, store, n_jobs, scheduler=scheduler,
                                       chunk_size=chunk_size, progress=progress, robot_file_text=robot_file_text,
                                       max_chunks=max_chunks, on_chunk=on_chunk).field


def interpolation_error(field: BoundField, robot, evaluator, n: int = 100, seed: int = 0, settings=None,
                        quantity: str = "position") -> InterpolationError:
    """Compare the field with the exact model at uniformly random configurations.

    Parameters
    ----------
    field : BoundField
    robot : Robot
    evaluator : callable
        Exact model, same signature as for :meth:`BoundField.compute`.
    n : int
        Number of random configurations (uniform within the joint limits).
    seed : int
        numpy Generator seed.
    settings : ModelSettings, optional
    quantity : str
        One of :data:`QUANTITIES`.

    Returns
    -------
    InterpolationError
        Errors at configurations valid in both; report ``.median`` and ``.p95``.
    """
    rng = np.random.default_rng(seed)
    lo, hi = robot.joint_lower, robot.joint_upper
    qs = lo + rng.random((n, len(lo))) * (hi - lo)
    col = QUANTITIES.index(quantity)
    interp = field(qs, quantity)
    fvalid = field.is_valid(qs)
    keep, exact = [], []
    for k, q in enumerate(qs):
        if not fvalid[k]:
            continue
        vals, ok = _evaluate_node(robot, evaluator, q, settings)
        if ok:
            keep.append(k)
            exact.append(vals[col])
    keep = np.asarray(keep, dtype=int)
    exact = np.asarray(exact, dtype=float)
    return InterpolationError(qs[keep], exact, interp[keep], np.abs(interp[keep] - exact), n - keep.size, quantity)
