"""A roadmap of the joint space with the friction bound in its edge costs, built once and queried
for many goals.

A single query with RRT* grows a new tree each time. For a fixed robot, bound map and obstacles,
the valid part of the joint space and the cost of moving through it do not change between
queries, so a probabilistic roadmap (PRM*: Karaman & Frazzoli 2011, "Sampling-based algorithms
for optimal motion planning", IJRR 30(7), doi:10.1177/0278364911406761) is built once:

1. ``n_nodes`` valid states, drawn uniformly from the joint box (seeded) and checked with the
   planning search's checker (:class:`~ctrplan.planning.validity.BatchValidityChecker`:
   joint limits, elastic stability, the map's valid region, collision);
2. each connected to its ``k`` nearest neighbours in the weighted joint metric
   (:class:`~ctrplan.planning.space.JointStateSpace`), PRM*'s
   ``k = ceil(e (1 + 1/d) ln n)`` by default, where the straight motion passes the same checker;
3. each edge stores its weighted length ``L`` and, in each direction, the integral ``I`` of the
   bound along the motion the drive executes for it: its rotations first (the friction bound of
   the map, Section III of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906), then its
   translations (the translation-last bound, Section V-B), by the trapezoid rule of
   :func:`~ctrplan.planning.objective._segment_cost`. One roadmap serves every bound weight
   ``w``: a query minimises ``sum L + w I`` (``w = 0``: the bound-blind plan). Where the RRT*
   search integrates the friction bound along the straight segment, the roadmap's cost is that of
   the executed motion, whose corner (rotated, not yet translated) the exact bound at the ordered
   waypoints sees.

A query (:meth:`Roadmap.query`) connects the start and the goal to their nearest roadmap states
(and to each other, when the straight motion is valid), finds the cheapest path with Dijkstra's
algorithm (``scipy.sparse.csgraph``) and shortcuts it where a straight motion is valid and
cheaper. Interactive-rate planning of concentric tube robots on a precomputed roadmap: Torres,
Baykal & Alterovitz, "Interactive-rate motion planning for concentric tube robots", ICRA 2014,
doi:10.1109/ICRA.2014.6907032.

A roadmap is stored in the cache under a key over the robot, the map, the obstacles' geometry,
the checker's settings and the roadmap's own (:func:`roadmap_key`), next to the bound maps; a
scenario's roadmap is read from there or built and stored (:func:`load_roadmap`), for
:class:`~ctrplan.planning.interactive.Planner` and for
:func:`~ctrplan.planning.plans.plan_routes` when a scenario's legs go through the roadmap.

Units: rotations in rad, translations in m, costs in m (of the weighted metric).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._log import progress_level
from ..errors import UnreachableGoalError
from .objective import DEFAULT_SAMPLE_SPACING, _segment_cost, motion_cost_kernel
from .space import wrap_angle

__all__ = ["Roadmap", "RoadmapPath", "build_roadmap", "roadmap_key", "obstacles_digest", "motion_terms",
           "prm_star_neighbours", "ROADMAP_FORMAT", "DEFAULT_NODES_PER_JOINT", "load_roadmap"]

logger = logging.getLogger(__package__)


#: Version of the stored roadmap layout (part of its key).
ROADMAP_FORMAT = 2

#: Default roadmap size: this many valid states per joint.
DEFAULT_NODES_PER_JOINT = 500


# States drawn per validity batch while sampling, and the most draws per requested state.
_SAMPLE_BATCH = 512
_MAX_DRAWS_PER_NODE = 200


def prm_star_neighbours(n_nodes: int, dimension: int) -> int:
    """PRM*'s neighbour count ``ceil(e (1 + 1/d) ln n)`` (Karaman & Frazzoli 2011).

    Parameters
    ----------
    n_nodes : int
        Roadmap states.
    dimension : int
        Joints.

    Returns
    -------
    int
        At least 1.
    """
    return max(1, int(math.ceil(math.e * (1.0 + 1.0 / dimension) * math.log(max(n_nodes, 2)))))


def roadmap_key(robot_text: str, field_key: str, obstacles_digest: str, checker_settings: dict,
                roadmap_settings: dict, mechanics_version: str) -> str:
    """Key of a stored roadmap: SHA-256 over everything its states, edges and costs depend on.

    Parameters
    ----------
    robot_text : str
        The robot file's text (or a canonical description of the robot).
    field_key : str
        The bound map's key (:func:`ctrplan.boundmap.field_key`).
    obstacles_digest : str
        :func:`obstacles_digest` of the obstacles.
    checker_settings : dict
        Model settings and resolution of the validity checker.
    roadmap_settings : dict
        ``n_nodes``, ``neighbours``, ``seed``, ``sample_spacing``.
    mechanics_version : str

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    from ..cache import content_key

    return content_key({"format": ROADMAP_FORMAT, "robot": robot_text, "map": field_key,
                        "obstacles": obstacles_digest, "checker": checker_settings, "roadmap": roadmap_settings,
                        "mechanics_version": mechanics_version})


def obstacles_digest(obstacles) -> str:
    """SHA-256 of the obstacles' geometry (type, bounding box and triangles of each, in order).

    Parameters
    ----------
    obstacles : sequence of Obstacle

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    h = hashlib.sha256()
    for ob in obstacles:
        lo, hi = ob.aabb()
        vertices, faces = ob.triangles()
        h.update(type(ob).__name__.encode() + b"\0")
        for arr in (lo, hi, vertices, faces):
            h.update(np.ascontiguousarray(arr, dtype=float).tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class RoadmapPath:
    """Outcome of :meth:`Roadmap.query`.

    Attributes
    ----------
    waypoints : ndarray, shape (K, n_joints)
        From the start to the goal [rad or m] (periodic angles wrapped to [-pi, pi)).
    cost : float
        Its cost, ``sum L + w I`` over its motions as executed (:func:`motion_terms`) [m].
    bound_weight : float
        ``w`` [1/m].
    cost_before_shortcut : float
        The cheapest roadmap path's cost [m].
    roadmap_states : int
        Roadmap states on the path before shortcutting.
    seconds : float
        Wall time of the query [s].
    motions_checked : int
        Straight motions checked during the query.
    """

    waypoints: np.ndarray
    cost: float
    bound_weight: float
    cost_before_shortcut: float
    roadmap_states: int
    seconds: float
    motions_checked: int


@dataclass(frozen=True, eq=False)
class Roadmap:
    """Valid states of the joint space joined by valid straight motions, with their costs.

    Attributes
    ----------
    nodes : ndarray, shape (N, n_joints)
        Valid states [rad or m] (periodic angles in [-pi, pi)).
    edges : ndarray of int, shape (E, 2)
        Node pairs ``i < j`` joined by a valid straight motion.
    length : ndarray, shape (E,)
        Weighted length of each edge's motion [m].
    integral : ndarray, shape (E,)
        Integral of the bound along the executed motion from ``edges[:, 0]`` to ``edges[:, 1]``
        (:func:`motion_terms`) [m^2].
    integral_reverse : ndarray, shape (E,)
        The same from ``edges[:, 1]`` to ``edges[:, 0]`` [m^2].
    neighbours : int
        Neighbours each state was connected to (k).
    settings : dict
        ``n_nodes``, ``neighbours``, ``seed``, ``sample_spacing``.
    key : str
        :func:`roadmap_key` (empty for a roadmap not meant to be stored).
    build_seconds : float
        Wall time of the build [s].
    draws : int
        States drawn to find the valid ones.
    """

    nodes: np.ndarray
    edges: np.ndarray
    length: np.ndarray
    integral: np.ndarray
    integral_reverse: np.ndarray
    neighbours: int
    settings: dict
    key: str = ""
    build_seconds: float = 0.0
    draws: int = 0

    @property
    def n_nodes(self) -> int:
        """Number of states, N."""
        return int(self.nodes.shape[0])

    @property
    def n_edges(self) -> int:
        """Number of motions, E (each usable both ways)."""
        return int(self.edges.shape[0])

    def cost(self, bound_weight: float, reverse: bool = False) -> np.ndarray:
        """Edge costs ``L + w I`` [m] for the bound weight ``w`` [1/m], shape (E,): from
        ``edges[:, 0]`` to ``edges[:, 1]``, or back with ``reverse``."""
        return self.length + float(bound_weight) * (self.integral_reverse if reverse else self.integral)

    def components(self) -> np.ndarray:
        """Connected-component label of each state, shape (N,)."""
        from scipy.sparse.csgraph import connected_components

        _, labels = connected_components(self._graph(self.n_nodes, self.length, self.length), directed=False)
        return labels

    def _graph(self, size: int, forward, backward, extra=()):
        """Directed sparse cost matrix of ``size`` states: the roadmap's edges at ``forward`` costs
        from ``edges[:, 0]`` to ``edges[:, 1]`` and ``backward`` costs back, and the directed
        ``extra`` ``(i, j, cost)`` edges. Zero costs get the smallest positive float (a stored zero
        would read as no edge)."""
        from scipy.sparse import coo_matrix

        ex = np.array([e[:2] for e in extra], dtype=np.int64).reshape(-1, 2)
        i = np.concatenate([self.edges[:, 0], self.edges[:, 1], ex[:, 0]])
        j = np.concatenate([self.edges[:, 1], self.edges[:, 0], ex[:, 1]])
        c = np.concatenate([np.asarray(forward, dtype=float), np.asarray(backward, dtype=float),
                            np.array([e[2] for e in extra], dtype=float)])
        return coo_matrix((np.maximum(c, np.finfo(float).tiny), (i, j)), shape=(size, size)).tocsr()

    # ------------------------------------------------------------------ query
    def query(self, start, goal, checker, terms, joint_space, *, bound_weight: float, connect: int | None = None,
              shortcut: bool = True) -> RoadmapPath:
        """The cheapest path from ``start`` to ``goal`` through the roadmap.

        Both ends are joined to their ``connect`` nearest roadmap states (default the roadmap's
        k; three times as many if that leaves them apart) where the straight motion passes
        ``checker``, and to each other when that motion does; Dijkstra's algorithm finds the
        cheapest path; with ``shortcut``, each waypoint is then joined straight to the furthest
        later one whose motion is valid and cheaper than the path between them.

        Parameters
        ----------
        start, goal : array-like, shape (n_joints,)
            Valid states [rad or m].
        checker : BatchValidityChecker
            The checker the roadmap was built with (its ``check_motion`` is used).
        terms : callable
            ``terms(q0, q1) -> (L [m], I [m^2])`` of the motion from ``q0`` to ``q1`` as executed
            (:func:`motion_terms` with the roadmap's map).
        joint_space : JointStateSpace
        bound_weight : float, keyword-only
            ``w`` [1/m] of the cost ``L + w I``.
        connect : int, optional, keyword-only
        shortcut : bool, keyword-only

        Returns
        -------
        RoadmapPath

        Raises
        ------
        UnreachableGoalError
            The start or the goal is invalid, or no path joins them through the roadmap.
        """
        from scipy.sparse.csgraph import dijkstra

        t0 = time.perf_counter()
        n0 = checker.n_motions
        w = float(bound_weight)

        def cost_fn(a, b):
            length, integral = terms(a, b)
            return length + w * integral

        start = np.asarray(start, dtype=float).reshape(-1)
        goal = np.asarray(goal, dtype=float).reshape(-1)
        for label, q in (("start", start), ("goal", goal)):
            if not checker(q):
                raise UnreachableGoalError(f"{label} configuration {np.round(q, 6).tolist()} is invalid (joint "
                                           "limits, elastic stability, the bound map's valid region or collision)")
        n = self.n_nodes
        k = self.neighbours if connect is None else int(connect)
        s_idx, g_idx = n, n + 1
        nodes = np.vstack([self.nodes, start[None, :], goal[None, :]])
        extra: list[tuple[int, int, float]] = []
        tried: dict[int, set] = {s_idx: set(), g_idx: set()}

        def join(idx, q, count):
            d = joint_space.distance(self.nodes, q)
            for i in np.argsort(d)[:count]:
                i = int(i)
                if i in tried[idx]:
                    continue
                tried[idx].add(i)
                if checker.check_motion(q, self.nodes[i]):
                    # out of the start, into the goal
                    extra.append((idx, i, float(cost_fn(q, self.nodes[i]))) if idx == s_idx
                                 else (i, idx, float(cost_fn(self.nodes[i], q))))

        if checker.check_motion(start, goal):
            extra.append((s_idx, g_idx, float(cost_fn(start, goal))))
        path = None
        for count in (k, 3 * k):
            join(s_idx, start, count)
            join(g_idx, goal, count)
            dist, pred = dijkstra(self._graph(n + 2, self.cost(w), self.cost(w, reverse=True), extra), directed=True,
                                  indices=s_idx, return_predecessors=True)
            if np.isfinite(dist[g_idx]):
                path = [g_idx]
                while path[-1] != s_idx:
                    path.append(int(pred[path[-1]]))
                path.reverse()
                best = float(dist[g_idx])
                break
        if path is None:
            raise UnreachableGoalError(
                f"no path through the roadmap ({n} states, {self.n_edges} motions) joins the start "
                f"{np.round(start, 6).tolist()} and the goal {np.round(goal, 6).tolist()}: "
                f"{sum(1 for e in extra if s_idx in e[:2])} valid motions from the start and "
                f"{sum(1 for e in extra if g_idx in e[:2])} to the goal among their {3 * k} nearest states")
        q = nodes[path]
        edge_cost = {(a, b): c for a, b, c in extra}
        costs = []
        for a, b in zip(path[:-1], path[1:]):
            c = edge_cost.get((a, b))
            costs.append(float(cost_fn(nodes[a], nodes[b])) if c is None else c)
        if shortcut and len(q) > 2:
            q, costs = _shortcut(q, np.array(costs), checker, cost_fn)
        q = q.copy()
        q[:, joint_space.periodic] = wrap_angle(q[:, joint_space.periodic])
        q[0], q[-1] = start, goal
        return RoadmapPath(waypoints=q, cost=float(np.sum(costs)), bound_weight=w, cost_before_shortcut=best,
                           roadmap_states=len(path) - 2, seconds=time.perf_counter() - t0,
                           motions_checked=checker.n_motions - n0)

    # ------------------------------------------------------------------ storage
    def save(self, path: str | Path) -> Path:
        """Write the roadmap to ``path`` (``.npz``, atomically).

        Returns
        -------
        pathlib.Path
        """
        from ..io.atomic import atomic_savez

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_savez(path, nodes=self.nodes, edges=self.edges, length=self.length, integral=self.integral,
                     integral_reverse=self.integral_reverse,
                     meta=np.array(json.dumps({"format": ROADMAP_FORMAT, "key": self.key,
                                               "neighbours": self.neighbours, "settings": self.settings,
                                               "build_seconds": self.build_seconds, "draws": self.draws})))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "Roadmap":
        """Read a roadmap written by :meth:`save`.

        Raises
        ------
        ValueError
            Not a roadmap file of this format (the message names the file).
        """
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                nodes, edges, length = z["nodes"], z["edges"], z["length"]
                integral, integral_reverse = z["integral"], z["integral_reverse"]
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{path}: not a readable roadmap file ({exc})") from None
        if meta.get("format") != ROADMAP_FORMAT:
            raise ValueError(f"{path}: roadmap format {meta.get('format')!r}, this code reads {ROADMAP_FORMAT}")
        return cls(nodes=nodes, edges=edges.astype(np.int64), length=length, integral=integral,
                   integral_reverse=integral_reverse,
                   neighbours=int(meta["neighbours"]),
                   settings=dict(meta["settings"]), key=str(meta["key"]),
                   build_seconds=float(meta["build_seconds"]), draws=int(meta["draws"]))


def _shortcut(q, costs, checker, cost_fn):
    """Greedy cost-aware shortcutting: from each kept waypoint, the furthest later waypoint whose
    straight motion is valid and cheaper than the path between them. Returns the waypoints and
    the cost of each motion."""
    keep, out_costs = [0], []
    i, last = 0, len(q) - 1
    cum = np.concatenate([[0.0], np.cumsum(costs)])
    while i < last:
        nxt, c_next = i + 1, costs[i]
        for j in range(last, i + 1, -1):
            c = float(cost_fn(q[i], q[j]))
            if c < cum[j] - cum[i] - 1e-12 and checker.check_motion(q[i], q[j]):
                nxt, c_next = j, c
                break
        keep.append(nxt)
        out_costs.append(c_next)
        i = nxt
    return q[keep], np.array(out_costs)


def motion_terms(joint_space, field, sample_spacing: float = DEFAULT_SAMPLE_SPACING):
    """``terms(q0, q1) -> (L, I)`` of the motion from ``q0`` to ``q1`` as the drive executes it:
    its rotations first, then its translations (:func:`~ctrplan.planning.order_path`).

    ``L`` is the weighted length [m] (that of the straight motion: the metric adds the rotations'
    and the translation's lengths); ``I`` [m^2] the integral of the map's friction bound along
    the rotation phase plus that of its translation-last bound along the translation phase (the
    bound given the last motion, Section V-B of Ha, Fagogenis & Dupont 2019), each by the trapezoid
    rule of the search's compiled motion cost (:func:`~ctrplan.planning.objective.motion_cost_kernel`).

    Parameters
    ----------
    joint_space : JointStateSpace
    field : BoundField
    sample_spacing : float
        Bound samples at most this far apart along a phase [m].

    Returns
    -------
    callable
    """
    friction = motion_cost_kernel(joint_space, field, 1.0, sample_spacing)
    last = motion_cost_kernel(joint_space, field, 1.0, sample_spacing, quantity="translation_last_position")
    if friction is None:
        raise ValueError("the roadmap's edge costs need a bound map (a BoundField)")
    rot = np.asarray(joint_space.is_rotation)

    def terms(q0, q1) -> tuple[float, float]:
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        corner = np.where(rot, q0 + joint_space.difference(q0, q1), q0)
        l_rot = float(joint_space.distance(q0, corner))
        l_tr = float(joint_space.distance(corner, q1))
        integral = float(_segment_cost(q0, corner, *friction)[0]) - l_rot
        integral += float(_segment_cost(corner, q1, *last)[0]) - l_tr
        return l_rot + l_tr, integral

    return terms


def _sample_valid(checker, joint_space, n_nodes: int, rng) -> tuple[np.ndarray, int]:
    """``n_nodes`` valid states drawn uniformly from the joint box, and the number drawn."""
    lo = np.where(joint_space.periodic, -np.pi, joint_space.lower)
    hi = np.where(joint_space.periodic, np.pi, joint_space.upper)
    found, draws = [], 0
    while sum(len(f) for f in found) < n_nodes and draws < _MAX_DRAWS_PER_NODE * n_nodes:
        Q = lo + rng.random((_SAMPLE_BATCH, len(lo))) * (hi - lo)
        draws += len(Q)
        found.append(Q[checker.check(Q)])
    nodes = np.concatenate(found)[:n_nodes] if found else np.zeros((0, len(lo)))
    return nodes, draws


# The checker, motion terms, states and candidate pairs of the build under way, read by the forked
# workers of :func:`_edges_of` (they inherit it; the checker's collision objects do not pickle).
_BUILD: dict = {}


def _edges_of(start: int, stop: int) -> list:
    """``(i, j, L, I, I_reverse)`` of the valid motions among candidate pairs ``start:stop`` of the
    build under way (:data:`_BUILD`)."""
    checker, terms, nodes, pairs = _BUILD["checker"], _BUILD["terms"], _BUILD["nodes"], _BUILD["pairs"]
    out = []
    for i, j in pairs[start:stop]:
        if checker.check_motion(nodes[i], nodes[j]):
            out.append((i, j) + terms(nodes[i], nodes[j]) + (terms(nodes[j], nodes[i])[1],))
    return out


def build_roadmap(checker, joint_space, field, *, n_nodes: int | None = None,
                  neighbours: int | None = None, seed: int = 1, sample_spacing: float = DEFAULT_SAMPLE_SPACING,
                  key: str = "", n_jobs: int = 1) -> Roadmap:
    """Build a roadmap (module docstring).

    Parameters
    ----------
    checker : BatchValidityChecker
        Validity of states and straight motions (the planning search's).
    joint_space : JointStateSpace
    field : BoundField
        The bound map of the edge costs.
    n_nodes : int, optional, keyword-only
        Valid states (default :data:`DEFAULT_NODES_PER_JOINT` per joint).
    neighbours : int, optional, keyword-only
        k (default :func:`prm_star_neighbours`).
    seed : int, keyword-only
    sample_spacing : float, keyword-only
        Bound samples along a motion at most this far apart [m].
    key : str, keyword-only
        :func:`roadmap_key`, stored with it.
    n_jobs : int, keyword-only
        Processes that check the candidate motions and integrate their bounds (this one and
        ``n_jobs - 1`` forked workers, :class:`ctrplan.parallel.Executor`); the roadmap does not
        depend on it.

    Returns
    -------
    Roadmap

    Raises
    ------
    UnreachableGoalError
        Fewer than two valid states found in ``200 n_nodes`` draws.
    """
    from ..parallel import Executor

    t0 = time.perf_counter()
    d = joint_space.n_joints
    n_nodes = DEFAULT_NODES_PER_JOINT * d if n_nodes is None else int(n_nodes)
    k = prm_star_neighbours(n_nodes, d) if neighbours is None else int(neighbours)
    terms = motion_terms(joint_space, field, sample_spacing)
    rng = np.random.default_rng(seed)
    nodes, draws = _sample_valid(checker, joint_space, n_nodes, rng)
    if len(nodes) < 2:
        raise UnreachableGoalError(f"only {len(nodes)} valid states in {draws} drawn from the joint box: the "
                                   "robot's valid region (limits, stability, map, obstacles) is too small for a roadmap")
    pairs = set()
    for a in range(0, len(nodes), 256):
        block = nodes[a:a + 256]
        dist = joint_space.distance(block[:, None, :], nodes[None, :, :])
        dist[np.arange(len(block)), a + np.arange(len(block))] = np.inf
        near = np.argpartition(dist, min(k, len(nodes) - 1) - 1, axis=1)[:, :k]
        for r, row in enumerate(near):
            i = a + r
            for j in row.tolist():
                pairs.add((min(i, j), max(i, j)))
    pairs = sorted(pairs)
    _BUILD.update(checker=checker, terms=terms, nodes=nodes, pairs=pairs)
    try:
        chunks = max(1, int(n_jobs))   # one here (first), one per worker
        bounds = np.linspace(0, len(pairs), chunks + 1).astype(int)
        found = {}
        with Executor(int(n_jobs), fork=True) as ex:
            for tag, rows in ex.run(_edges_of, [(c, (int(a), int(b))) for c, (a, b) in
                                                enumerate(zip(bounds[:-1], bounds[1:]))], first_here=True):
                found[tag] = rows
    finally:
        _BUILD.clear()
    rows = [r for c in sorted(found) for r in found[c]]
    edges = [r[:2] for r in rows]
    values = [r[2:] for r in rows]
    settings = {"n_nodes": int(n_nodes), "neighbours": int(k), "seed": int(seed), "sample_spacing": float(sample_spacing)}
    values = np.array(values, dtype=float).reshape(-1, 3)
    return Roadmap(nodes=nodes, edges=np.array(edges, dtype=np.int64).reshape(-1, 2), length=values[:, 0],
                   integral=values[:, 1], integral_reverse=values[:, 2],
                   neighbours=k, settings=settings, key=key, build_seconds=time.perf_counter() - t0, draws=draws)


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
