"""Bound maps of robot files on disk: where they live, finding a shipped or cached one, computing
one (``ctrplan boundmap``, and ``ctrplan plan`` when no map matches).

A map of robot file ``model/<robot>.toml`` with key ``<key>`` is looked for as

- ``model/boundmaps/<robot>-<key[:12]>.npz`` or ``.zarr`` (shipped with the repository), then
- ``<cache>/boundmaps/<robot>-<key[:12]>.zarr`` or ``.npz`` (computed earlier on this machine;
  :func:`cache_folder`, in :func:`ctrplan.cache.cache_dir`).

The key (:func:`~ctrplan.boundmap.identity.field_key`) covers the robot file's text, the model
settings, the grid spec, the evaluator and the mechanics version, so an edited robot file, other
settings or newer mechanics never pick up an old map; a map of the same robot that no longer
matches is named with the attribute that differs.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from ..choices import JointKind, MapSource
from .._log import deprecated_echo, progress_level
from ..cache import cache_dir
from .axes import MapSpec
from .compute import ComputeOptions, compute_bound_map_store
from ..coordinates import map_coordinates
from .identity import BoundFieldKeyError, BoundMapMismatchError, map_identity
from .store import STORE_SUFFIX, IncompleteBoundMapError, load_bound_map

__all__ = ["DEFAULT_ROTATION_NODES", "DEFAULT_TRANSLATION_NODES", "default_spec", "map_paths", "map_file",
           "compute_bound_map", "find_bound_map", "load_or_compute_bound_map", "cache_folder"]

# Default grid nodes per periodic rotation and per translation coordinate (uniform): the
# original default of ctrplan (median interpolation error 0.08 mm on the Table VII robot, but
# 1.3 mm at the 95th percentile; shipped maps use adaptive placement, docs/boundmaps.md).
DEFAULT_ROTATION_NODES = 16
DEFAULT_TRANSLATION_NODES = 6

logger = logging.getLogger(__name__)


def cache_folder() -> Path:
    """Where ``ctrplan plan`` keeps the maps it computed for robots without a shipped map:
    ``boundmaps`` in :func:`ctrplan.cache.cache_dir` (read at call time)."""
    return cache_dir("boundmaps")


def default_spec(robot) -> MapSpec:
    """Uniform grid, 16 nodes per rotation coordinate and 6 per translation coordinate.

    Parameters
    ----------
    robot : Robot

    Returns
    -------
    MapSpec
        Resolution of shape (d,), one entry per map coordinate (:func:`map_coordinates`).

    Raises
    ------
    ValueError
        The robot has no joints.
    """
    coords = map_coordinates(robot)
    return MapSpec(tuple(DEFAULT_ROTATION_NODES if k == JointKind.ROTATION else DEFAULT_TRANSLATION_NODES
                         for k in coords.kinds))


def map_paths(robot_path, key: str) -> tuple[Path, Path]:
    """Where the map of a robot file with key ``key`` is shipped and cached.

    Parameters
    ----------
    robot_path : path
        Robot model file.
    key : str
        :func:`~ctrplan.boundmap.identity.field_key` (its first 12 hex digits name the files).

    Returns
    -------
    shipped, cached : Path
        ``<robot dir>/boundmaps/<robot>-<key12>`` and ``<cache>/boundmaps/<robot>-<key12>``
        (:func:`cache_folder`), without suffix (``.npz`` or ``.zarr`` is added by the caller).
    """
    robot_path = Path(robot_path)
    shipped = robot_path.parent / "boundmaps" / f"{robot_path.stem}-{key[:12]}"
    cache = cache_folder() / f"{robot_path.stem}-{key[:12]}"
    return shipped, cache


def map_file(base, suffix: str) -> Path:
    """A map's file: ``base`` with ``suffix`` appended.

    Not ``Path.with_suffix``: a robot file's name may hold a dot (``tube-x1.1.toml``), which would
    make the key the suffix and drop it (every map of that robot in one store).

    Parameters
    ----------
    base : path
        ``<folder>/<robot>-<key12>``, from :func:`map_paths`.
    suffix : str
        ``".npz"`` or ``".zarr"``.

    Returns
    -------
    Path
        ``<folder>/<robot>-<key12><suffix>``.
    """
    base = Path(base)
    return base.with_name(base.name + suffix)


def compute_bound_map(robot_path, spec, settings, evaluator=None, *, out_path=None, store_path=None,
                      options: ComputeOptions = ComputeOptions()):
    """Compute (or resume) the bound map of a robot file into a zarr store.

    Parameters
    ----------
    robot_path : path
        Robot model file; its sha256 is recorded in the map and is part of the map's key.
    spec : MapSpec or sequence of int
        Grid spec, or nodes per map coordinate (uniform).
    settings : ModelSettings
    evaluator : callable, optional
        Default :func:`ctrplan.mechanics.evaluate_bound`.
    out_path : path, optional, keyword-only
        The map: a zarr store ``*.zarr`` (default ``<robot dir>/boundmaps/<robot>-<key12>.zarr``)
        or an ``.npz`` file, written once the store ``store_path`` is complete.
    store_path : path, optional, keyword-only
        Chunk store of an ``.npz`` output (default: ``out_path`` with suffix ``.zarr``); must be
        None or equal to ``out_path`` for a ``.zarr`` output.
    options : ComputeOptions, keyword-only
        Workers or a Dask scheduler, chunk size, progress, a stop after some chunks, a callback
        per chunk (:class:`~ctrplan.boundmap.compute.ComputeOptions`).

    Returns
    -------
    run : BoundMapRun
    path : Path
        The map written (the store, or the ``.npz``).

    Raises
    ------
    ModelFileError
        Malformed robot file.
    BoundMapMismatchError
        The store holds another map.
    ValueError
        A spec that does not fit the robot, ``store_path`` given with a ``.zarr`` output, or an
        output suffix other than ``.zarr`` or ``.npz``.
    """
    from ..io.robot_file import load_robot

    if evaluator is None:
        from ..mechanics import evaluate_bound as evaluator
    robot_path = Path(robot_path)
    robot = load_robot(robot_path)
    text = robot_path.read_text()
    ident = map_identity(robot, settings, spec, evaluator, text)
    shipped, _ = map_paths(robot_path, ident.key)
    out = Path(out_path) if out_path else map_file(shipped, STORE_SUFFIX)
    if out.suffix == STORE_SUFFIX:
        if store_path is not None and Path(store_path) != out:
            raise ValueError(f"--store {store_path} cannot differ from a .zarr output {out} (the store is the map)")
        store = out
    elif out.suffix == ".npz":
        store = Path(store_path) if store_path else out.with_suffix(STORE_SUFFIX)
    else:
        raise ValueError(f"bound map output {out} must end in {STORE_SUFFIX} (chunked store) or .npz")
    store.parent.mkdir(parents=True, exist_ok=True)
    run = compute_bound_map_store(robot, evaluator, spec, settings, store, options=options, robot_file_text=text,
                                  metadata={"robot_file": robot_path.name})
    if run.field is not None and out.suffix == ".npz":
        run.field.save(out)
    return run, out


def _identity_of(path) -> dict:
    """Identity attributes of a map file or store (empty if unreadable)."""
    try:
        if Path(path).suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["metadata"])) if "metadata" in z else {}
                meta["key"] = str(z["key"])
                return meta
        from .store import BoundMapStore

        return dict(BoundMapStore.open(path).attrs)
    except Exception:  # noqa: BLE001 - any unreadable map is just not explained
        return {}


def _stale_maps(robot_path, ident) -> list[str]:
    """Why other maps of the same robot file do not match this run (one line each)."""
    robot_path = Path(robot_path)
    lines = []
    for folder in (robot_path.parent / "boundmaps", cache_folder()):
        for path in sorted(folder.glob(f"{robot_path.stem}-*")):
            if path.suffix not in (".npz", STORE_SUFFIX) or path.name.endswith(f"{ident.key[:12]}{path.suffix}"):
                continue
            stored = _identity_of(path)
            try:
                ident.check(stored, str(path))
            except BoundMapMismatchError as exc:
                lines.append(f"{path} is not used: '{exc.key}' is {exc.stored!r} there, {exc.requested!r} now")
    return lines


def _read_existing(robot_path: Path, ident) -> tuple | None:
    """The complete shipped or cached map of ``ident`` as (field, source), else None."""
    shipped, cache = map_paths(robot_path, ident.key)
    for path, source in ((map_file(shipped, ".npz"), MapSource.SHIPPED),
                         (map_file(shipped, STORE_SUFFIX), MapSource.SHIPPED),
                         (map_file(cache, STORE_SUFFIX), MapSource.CACHE), (map_file(cache, ".npz"), MapSource.CACHE)):
        if path.exists():
            try:
                field = load_bound_map(path, key=ident.key)
            except IncompleteBoundMapError:
                logger.debug(f"{path}: incomplete (an interrupted computation), not read")
                continue
            except BoundFieldKeyError as exc:
                logger.warning(f"ignoring {path}: {exc}")
                continue
            logger.debug(f"bound map read from {path} ({source})")
            return field, source
    return None


def find_bound_map(robot_path, robot, spec, settings, *, evaluator=None) -> tuple | None:
    """The shipped or cached map of a robot file with the right key, without computing one.

    Parameters
    ----------
    robot_path : path
        Robot model file (its content is part of the key).
    robot : Robot
        The robot loaded from ``robot_path``.
    spec : MapSpec or sequence of int
    settings : ModelSettings
    evaluator : callable, optional, keyword-only
        Default :func:`ctrplan.mechanics.evaluate_bound`.

    Returns
    -------
    tuple or None
        ``(field, source)`` with source :class:`~ctrplan.choices.MapSource` ``SHIPPED`` or
        ``CACHE``; None when there is no complete map (an interrupted computation is not one).
    """
    if evaluator is None:
        from ..mechanics import evaluate_bound as evaluator
    robot_path = Path(robot_path)
    return _read_existing(robot_path, map_identity(robot, settings, spec, evaluator, robot_path.read_text()))


@deprecated_echo
def load_or_compute_bound_map(robot_path, robot, spec, settings, n_jobs: int = 1, echo=None, *,
                              scheduler=None, evaluator=None, progress: bool = False):
    """Shipped or cached map with the right key, else compute it (resumable zarr store).

    Logs (logger ``ctrplan.boundmap.files``) that a map is computed (INFO), which file was read
    (DEBUG), and each map of this robot that is stale or unreadable, and why (WARNING).

    Parameters
    ----------
    robot_path : path
        Robot model file (its content is part of the key).
    robot : Robot
        The robot loaded from ``robot_path``.
    spec : MapSpec or sequence of int
    settings : ModelSettings
    n_jobs : int
        Local worker processes when computing.
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the INFO and higher messages of this call;
        configure :mod:`logging` instead.
    scheduler : str or distributed.Client, optional, keyword-only
        Dask scheduler address for computing.
    evaluator : callable, optional, keyword-only
        Default :func:`ctrplan.mechanics.evaluate_bound`.
    progress : bool, keyword-only
        tqdm bars while computing (default none).

    Returns
    -------
    field : BoundField
    source : MapSource
        A :class:`~ctrplan.choices.MapSource`: ``"shipped"``, ``"cache"`` or ``"computed"``.
    seconds : float
        Wall time spent loading or computing [s].

    Raises
    ------
    BoundMapMismatchError
        The cache store holds a map computed for another identity under the same key prefix.
    """
    if evaluator is None:
        from ..mechanics import evaluate_bound as evaluator
    t0 = time.perf_counter()
    robot_path = Path(robot_path)
    text = robot_path.read_text()
    ident = map_identity(robot, settings, spec, evaluator, text)
    found = _read_existing(robot_path, ident)
    if found is not None:
        return found[0], found[1], time.perf_counter() - t0
    shipped, cache = map_paths(robot_path, ident.key)
    for line in _stale_maps(robot_path, ident):
        logger.warning(line)
    store = map_file(cache, STORE_SUFFIX)
    logger.log(progress_level(), f"computing the bound map of {robot_path.name} "
               f"({', '.join(map_coordinates(robot).names)}; {ident.spec}) into {store}; interrupt and rerun to resume")
    store.parent.mkdir(parents=True, exist_ok=True)
    run = compute_bound_map_store(robot, evaluator, spec, settings, store,
                                  options=ComputeOptions(n_jobs=n_jobs, scheduler=scheduler, progress=progress),
                                  robot_file_text=text, metadata={"robot_file": robot_path.name})
    return run.field, MapSource.COMPUTED, time.perf_counter() - t0
