"""The roadmap of a scenario (:func:`load_roadmap`): read from the cache, else built and stored.

Used by :class:`~ctrplan.pipeline.interactive.Planner` and by
:func:`~ctrplan.pipeline.routes.plan_routes` when a scenario's legs go through the roadmap
(:mod:`ctrplan.planning.roadmap`).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from .._log import progress_level

__all__ = ["load_roadmap"]

logger = logging.getLogger(__package__)


def load_roadmap(setup, field, checker, joint_space, *, n_nodes: int | None = None, neighbours: int | None = None,
                 seed: int | None = None, cache_dir: str | os.PathLike | None = None, store: bool = True,
                 n_jobs: int = 1):
    """The roadmap of a scenario's robot, map and obstacles: read from the cache, else built (and
    stored).

    Its key (:func:`ctrplan.planning.roadmap.roadmap_key`) covers the robot file's bytes, the map's
    key, the obstacles' geometry, the checker's model settings and resolution, the roadmap's size,
    neighbours and seed, and the mechanics version; not the goals, the start or the bound weight.

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
    checker : BatchValidityChecker
        The planning search's checker (:func:`ctrplan.planning.route_checks`).
    joint_space : JointStateSpace
    n_nodes, neighbours : int, optional, keyword-only
        Default :data:`~ctrplan.planning.roadmap.DEFAULT_NODES_PER_JOINT` states per joint and PRM*'s k.
    seed : int, optional, keyword-only
        Default the scenario's planner seed.
    cache_dir : path, optional, keyword-only
        Default ``roadmaps`` in :func:`ctrplan.cache.cache_dir`.
    store : bool, keyword-only
        Read and write the cache.
    n_jobs : int, keyword-only
        Processes that build it (:func:`~ctrplan.planning.roadmap.build_roadmap`).

    Returns
    -------
    (Roadmap, str, pathlib.Path or None)
        The roadmap, ``"cache"`` or ``"built"``, and its file.
    """
    from ..boundmap.identity import settings_dict
    from ..cache import cache_dir as cache_dir_default, file_hash, mechanics_version
    from ..planning.roadmap import (DEFAULT_NODES_PER_JOINT, Roadmap, build_roadmap,
                                    obstacles_digest, prm_star_neighbours, roadmap_key)

    sc = setup.scenario
    d = joint_space.n_joints
    n = DEFAULT_NODES_PER_JOINT * d if n_nodes is None else int(n_nodes)
    k = prm_star_neighbours(n, d) if neighbours is None else int(neighbours)
    seed = sc.planner.seed if seed is None else int(seed)
    key = roadmap_key(file_hash(sc.robot_file) if sc.robot_file else "", field.key, obstacles_digest(setup.obstacles),
                      {"settings": settings_dict(checker.settings), "resolution": checker.resolution},
                      {"n_nodes": n, "neighbours": k, "seed": seed}, mechanics_version())
    folder = Path(cache_dir) if cache_dir is not None else cache_dir_default("roadmaps")
    path = folder / f"{Path(sc.robot_file).stem if sc.robot_file else 'robot'}-{key[:12]}.npz" if store else None
    if path is not None and path.exists():
        try:
            roadmap = Roadmap.load(path)
            if roadmap.key == key:
                return roadmap, "cache", path
        except ValueError as exc:
            logger.warning(f"{exc}; building the roadmap again")
    logger.log(progress_level(), f"roadmap: {n} states, {k} neighbours each (built once for this robot, map and "
                                 f"obstacles)")
    roadmap = build_roadmap(checker, joint_space, field, n_nodes=n, neighbours=k, seed=seed, key=key, n_jobs=n_jobs)
    logger.log(progress_level(), f"roadmap: {roadmap.n_nodes} states, {roadmap.n_edges} motions in "
                                 f"{roadmap.build_seconds:.1f} s")
    if path is not None:
        roadmap.save(path)
    return roadmap, "built", path
