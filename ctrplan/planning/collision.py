"""Collision checking of the robot body against scenario obstacles with python-fcl.

The robot body is the shared centerline of the standard model distal to the most distal tube
base (:meth:`ctrplan.mechanics.results.StandardSolution.body`), swept as a chain of capsules:
one capsule per centerline segment, with the larger of the two endpoint radii (the outer radius
of the outermost tube present), so the swept volume contains the tubes. Obstacles are the types
of :mod:`ctrplan.obstacles` (each gives its python-fcl object and its axis-aligned box), or dicts
naming a registered type. Geometry queries are FCL's
(Pan, Chitta & Manocha, "FCL: A general purpose library for collision and proximity queries",
ICRA 2012, doi:10.1109/ICRA.2012.6225337); nothing is hand-rolled here.

:meth:`CollisionChecker.collides_batch` checks many bodies at once: the capsule chains are built
in compiled code, a conservative broad phase keeps only the capsule-obstacle pairs whose
axis-aligned boxes overlap, and FCL's narrow phase (``fcl.collide``) decides each kept pair.
"""

from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np
from numba import njit

from ..obstacles import as_obstacle, rotation_z_to
# the tolerance of rotation_z_to, so that _capsule_poses builds the same poses as it does
from ..obstacles import AXIS_PARALLEL_TOL

__all__ = ["CollisionChecker", "CollisionReport", "AABB_MARGIN"]

# Centerline points closer than this along the body are merged into one capsule [m]: the
# standard model's grid is ~1 mm, and 2 mm capsules keep a query near 1 ms while the sagitta
# error of a 2 mm chord at the tightest curvature of clinical tubes (radius >= 20 mm) is 25 um.
DEFAULT_SEGMENT_LENGTH = 2e-3

# Margin by which each obstacle's world axis-aligned box is inflated in the broad phase of
# CollisionChecker.collides_batch [m]: ten times FCL's default GJK/EPA collision tolerance
# (1e-6 m, absolute), so a pair that FCL could still call touching is never culled; 10 um is
# negligible against the 2-5 mm capsules, so the culling loses nothing measurable.
AABB_MARGIN = 1e-5



def _capsule_object(a, b, radius) -> fcl.CollisionObject:
    d = b - a
    length = float(np.linalg.norm(d))
    rot = rotation_z_to(d) if length > 0.0 else np.eye(3)
    return fcl.CollisionObject(fcl.Capsule(float(radius), length),
                               fcl.Transform(rot, 0.5 * (a + b)))


def _obstacle_aabb(obstacle, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned box of one obstacle (:meth:`ctrplan.obstacles.Obstacle.aabb`), inflated
    by ``margin`` [m]; unbounded (never culled) for a duck-typed obstacle without ``aabb``.

    Returns
    -------
    lo, hi : ndarray, shape (3,)
        Box corners [m].
    """
    aabb = getattr(obstacle, "aabb", None)
    if aabb is None:
        return np.full(3, -np.inf), np.full(3, np.inf)
    lo, hi = aabb()
    return np.asarray(lo, dtype=float).reshape(3) - margin, np.asarray(hi, dtype=float).reshape(3) + margin


@njit(cache=True)
def _capsule_chains(points, radii, counts, seg, pad, cap_a, cap_b, cap_r, ncap):
    """Decimate each body into the capsule chain of ``CollisionChecker._body_manager``.

    Body k is ``points[k, :counts[k]]`` (P, 3) [m] with ``radii[k, :counts[k]]`` [m]. A point is
    kept when it is at least ``seg`` [m] from the last kept point, or is the last point; each
    pair of consecutive kept points a, b gives a capsule of radius
    max(radii[a..b]) + ``pad`` (skipped if not positive); a single-point body gives one
    zero-length capsule. Writes the capsule ends ``cap_a``, ``cap_b`` (K, C, 3) [m], radii
    ``cap_r`` (K, C) [m] and counts ``ncap`` (K,).
    """
    for k in range(points.shape[0]):
        m = counts[k]
        c = 0
        prev = 0
        for j in range(1, m):
            dx = points[k, j, 0] - points[k, prev, 0]
            dy = points[k, j, 1] - points[k, prev, 1]
            dz = points[k, j, 2] - points[k, prev, 2]
            if np.sqrt(dx * dx + dy * dy + dz * dz) >= seg or j == m - 1:
                r = radii[k, prev]
                for q in range(prev + 1, j + 1):
                    r = max(r, radii[k, q])
                r += pad
                if r > 0.0:
                    cap_a[k, c] = points[k, prev]
                    cap_b[k, c] = points[k, j]
                    cap_r[k, c] = r
                    c += 1
                prev = j
        if m == 1 and radii[k, 0] + pad > 0.0:
            cap_a[k, c] = points[k, 0]
            cap_b[k, c] = points[k, 0]
            cap_r[k, c] = radii[k, 0] + pad
            c += 1
        ncap[k] = c


@njit(cache=True)
def _candidate_pairs(cap_a, cap_b, cap_r, ncap, lo, hi):
    """Conservative broad phase: the (body k, capsule c, obstacle o) triples, shape (M, 3), whose
    capsule box (segment box inflated by the radius) overlaps obstacle o's box ``lo[o]``,
    ``hi[o]`` (O, 3) [m]; ordered by k, then c, then o."""
    n_obs = lo.shape[0]
    total = 0
    for k in range(cap_a.shape[0]):
        total += ncap[k] * n_obs
    pairs = np.empty((total, 3), dtype=np.int64)
    m = 0
    for k in range(cap_a.shape[0]):
        for c in range(ncap[k]):
            r = cap_r[k, c]
            for o in range(n_obs):
                overlap = True
                for d in range(3):
                    a = cap_a[k, c, d]
                    b = cap_b[k, c, d]
                    if min(a, b) - r > hi[o, d] or max(a, b) + r < lo[o, d]:
                        overlap = False
                        break
                if overlap:
                    pairs[m, 0] = k
                    pairs[m, 1] = c
                    pairs[m, 2] = o
                    m += 1
    return pairs[:m]


@njit(cache=True)
def _capsule_poses(cap_a, cap_b, ncap, length, rot, center):
    """FCL poses of the capsules from ``cap_a`` to ``cap_b`` (K, C, 3) [m], as
    ``_capsule_object`` builds them: ``length`` (K, C) = |b - a| [m], ``rot`` (K, C, 3, 3)
    taking +z onto d = (b - a) / |b - a| with the operations of ``rotation_z_to``
    (I + [v]x + [v]x^2 / (1 + c), v = z x d, c = z . d; identity for a zero length) and
    ``center`` (K, C, 3) = (a + b) / 2 [m]; filled in place for the first ``ncap[k]`` capsules."""
    for k in range(cap_a.shape[0]):
        for j in range(ncap[k]):
            a = cap_a[k, j]
            b = cap_b[k, j]
            d0 = b[0] - a[0]
            d1 = b[1] - a[1]
            d2 = b[2] - a[2]
            L = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            length[k, j] = L
            for r in range(3):
                center[k, j, r] = 0.5 * (a[r] + b[r])
                for q in range(3):
                    rot[k, j, r, q] = 1.0 if r == q else 0.0
            if not L > 0.0:
                continue
            u0 = d0 / L
            u1 = d1 / L
            c = d2 / L
            if c > 1.0 - AXIS_PARALLEL_TOL:
                continue
            if c < -1.0 + AXIS_PARALLEL_TOL:
                rot[k, j, 1, 1] = -1.0
                rot[k, j, 2, 2] = -1.0
                continue
            w = 1.0 + c
            rot[k, j, 0, 0] = 1.0 + (-u0 * u0) / w
            rot[k, j, 0, 1] = (-u0 * u1) / w
            rot[k, j, 0, 2] = u0
            rot[k, j, 1, 0] = (-u0 * u1) / w
            rot[k, j, 1, 1] = 1.0 + (-u1 * u1) / w
            rot[k, j, 1, 2] = u1
            rot[k, j, 2, 0] = -u0
            rot[k, j, 2, 1] = -u1
            rot[k, j, 2, 2] = 1.0 + (-(u0 * u0 + u1 * u1)) / w


@dataclass(frozen=True)
class CollisionReport:
    """Result of one body query.

    Attributes
    ----------
    collides : bool
    min_distance : float
        Smallest body-obstacle distance [m]; 0 (or FCL's negative penetration estimate) when
        colliding, NaN when not computed, +inf without obstacles.
    """

    collides: bool
    min_distance: float = float("nan")


class CollisionChecker:
    """Robot-body versus obstacles queries; the obstacle broad phase is built once.

    Parameters
    ----------
    obstacles : sequence of Obstacle or dict
        :class:`ctrplan.obstacles.Obstacle` instances, or dicts with a registered ``type``
        (:func:`ctrplan.obstacles.obstacle_from_dict`).
    segment_length : float, keyword-only
        Centerline points are decimated to about this spacing before building capsules [m]
        (the last point is always kept).
    padding : float, keyword-only
        Safety margin added to every capsule radius [m].

    Attributes
    ----------
    n_batch_bodies, n_batch_narrow_bodies, n_batch_narrow_calls : int
        Work of :meth:`collides_batch` since construction: bodies checked, bodies with at
        least one capsule-obstacle pair left by the broad phase, and ``fcl.collide`` calls.
    obstacles : list of Obstacle
        The obstacles, dicts converted.

    Raises
    ------
    ValueError
        A dict of an unknown type or with a bad key (:func:`ctrplan.obstacles.obstacle_from_dict`),
        or a mesh file without triangles.
    TypeError
        An obstacle that is neither an :class:`~ctrplan.obstacles.Obstacle` nor a dict.
    """

    def __init__(self, obstacles=(), *, segment_length: float = DEFAULT_SEGMENT_LENGTH, padding: float = 0.0):
        self.obstacles = [as_obstacle(o) for o in obstacles]
        self.segment_length = float(segment_length)
        self.padding = float(padding)
        self._objects = [o.collision_object() for o in self.obstacles]
        self._manager = fcl.DynamicAABBTreeCollisionManager()
        if self._objects:
            self._manager.registerObjects(self._objects)
        self._manager.setup()
        self._aabb = None   # obstacle boxes of collides_batch, (lo, hi) each (O, 3) [m], built on first use
        self.n_batch_bodies = 0
        self.n_batch_narrow_bodies = 0
        self.n_batch_narrow_calls = 0

    def _body_manager(self, points, radii):
        points = np.asarray(points, dtype=float)
        radii = np.asarray(radii, dtype=float).reshape(-1)
        if points.ndim != 2 or points.shape[1] != 3 or radii.shape != (points.shape[0],):
            raise ValueError(f"body needs points (K, 3) and radii (K,), got {points.shape} and {radii.shape}")
        keep = [0]
        for k in range(1, len(points)):
            if np.linalg.norm(points[k] - points[keep[-1]]) >= self.segment_length or k == len(points) - 1:
                keep.append(k)
        objs = []
        for a, b in zip(keep[:-1], keep[1:]):
            r = float(np.max(radii[a:b + 1])) + self.padding
            if r > 0.0:
                objs.append(_capsule_object(points[a], points[b], r))
        if len(keep) == 1 and radii[0] + self.padding > 0.0:
            objs.append(_capsule_object(points[0], points[0], radii[0] + self.padding))
        mgr = fcl.DynamicAABBTreeCollisionManager()
        mgr.registerObjects(objs)
        mgr.setup()
        return mgr, objs

    def check_body(self, points, radii, *, distance: bool = False) -> CollisionReport:
        """Check a body given as centerline points and radii.

        Parameters
        ----------
        points : array-like, shape (K, 3)
            Centerline [m].
        radii : array-like, shape (K,)
            Outer radius at each point [m].
        distance : bool
            Also compute the minimum distance (a few times slower than the boolean query).

        Returns
        -------
        CollisionReport
        """
        if not self._objects:
            return CollisionReport(False, float("inf"))
        mgr, _objs = self._body_manager(points, radii)
        data = fcl.CollisionData()
        self._manager.collide(mgr, data, fcl.defaultCollisionCallback)
        hit = bool(data.result.is_collision)
        dmin = float("nan")
        if distance:
            if hit:
                dmin = 0.0
            else:
                ddata = fcl.DistanceData()
                self._manager.distance(mgr, ddata, fcl.defaultDistanceCallback)
                dmin = float(ddata.result.min_distance)
        return CollisionReport(hit, dmin)

    def collides(self, solution, robot) -> bool:
        """True if the body of a standard-model solution touches an obstacle.

        Parameters
        ----------
        solution : StandardSolution
            Provides ``body(robot) -> (points (K, 3) [m], radii (K,) [m])``.
        robot : Robot
        """
        points, radii = solution.body(robot)
        return self.check_body(points, radii).collides

    def obstacle_aabbs(self) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned boxes of the obstacles used by :meth:`collides_batch`, inflated by
        :data:`AABB_MARGIN` (computed once).

        Returns
        -------
        lo, hi : ndarray, shape (O, 3)
            Box corners [m], in the order of :attr:`obstacles`; +-inf for a duck-typed obstacle
            without ``aabb()``.
        """
        if self._aabb is None:
            boxes = [_obstacle_aabb(o, AABB_MARGIN) for o in self.obstacles]
            lo = np.array([b[0] for b in boxes], dtype=float).reshape(-1, 3)
            hi = np.array([b[1] for b in boxes], dtype=float).reshape(-1, 3)
            self._aabb = (lo, hi)
        return self._aabb

    def collides_batch(self, points, radii, counts) -> np.ndarray:
        """Which of K bodies touch an obstacle; the same answer as :meth:`check_body` per body.

        Compiled broad phase, FCL narrow phase: each body is decimated into the capsule chain
        of :meth:`check_body` (same keep rule with ``segment_length``, radius = largest radius
        over the merged points + ``padding``, single-point bodies as one sphere-like capsule);
        a capsule can touch an obstacle only if its axis-aligned box (segment box inflated by
        the radius) overlaps the obstacle's box (:meth:`obstacle_aabbs`); FCL capsules are
        built only for those pairs and ``fcl.collide`` decides, stopping at a body's first hit.

        Parameters
        ----------
        points : array-like, shape (K, P, 3)
            Centerline points of each body [m] (padded; e.g. ``StandardBodies.points``).
        radii : array-like, shape (K, P)
            Outer radius at each point [m].
        counts : array-like of int, shape (K,)
            Points of body k: ``points[k, :counts[k]]``; 0 for no body (never colliding).

        Returns
        -------
        ndarray of bool, shape (K,)
            True where the body touches an obstacle.

        Raises
        ------
        ValueError
            If the shapes do not match or a count is outside [0, P].
        """
        points = np.ascontiguousarray(points, dtype=float)
        radii = np.ascontiguousarray(radii, dtype=float)
        counts = np.ascontiguousarray(counts, dtype=np.int64).reshape(-1)
        if points.ndim != 3 or points.shape[2] != 3 or radii.shape != points.shape[:2] \
                or counts.shape != (points.shape[0],):
            raise ValueError(f"bodies need points (K, P, 3), radii (K, P) and counts (K,), got "
                             f"{points.shape}, {radii.shape} and {counts.shape}")
        K, P = radii.shape
        if np.any(counts < 0) or np.any(counts > P):
            raise ValueError(f"counts must lie in [0, {P}], got {counts.min()} to {counts.max()}")
        hit = np.zeros(K, dtype=bool)
        self.n_batch_bodies += K
        if not self._objects or K == 0 or P == 0:
            return hit
        lo, hi = self.obstacle_aabbs()
        cap_a = np.empty((K, P, 3))
        cap_b = np.empty((K, P, 3))
        cap_r = np.empty((K, P))
        ncap = np.zeros(K, dtype=np.int64)
        _capsule_chains(points, radii, counts, self.segment_length, self.padding, cap_a, cap_b, cap_r, ncap)
        pairs = _candidate_pairs(cap_a, cap_b, cap_r, ncap, lo, hi)
        if pairs.shape[0] == 0:
            return hit
        length = np.empty((K, P))
        rot = np.empty((K, P, 3, 3))
        center = np.empty((K, P, 3))
        _capsule_poses(cap_a, cap_b, ncap, length, rot, center)
        self.n_batch_narrow_bodies += int(np.unique(pairs[:, 0]).size)
        request = fcl.CollisionRequest()
        built = {}
        calls = 0
        for k, c, o in pairs.tolist():
            if hit[k]:
                continue
            obj = built.get((k, c))
            if obj is None:
                obj = fcl.CollisionObject(fcl.Capsule(float(cap_r[k, c]), float(length[k, c])),
                                          fcl.Transform(rot[k, c], center[k, c]))
                built[(k, c)] = obj
            result = fcl.CollisionResult()
            fcl.collide(self._objects[o], obj, request, result)
            calls += 1
            if result.is_collision:
                hit[k] = True
        self.n_batch_narrow_calls += calls
        return hit

    def min_distance(self, solution, robot) -> float:
        """Minimum body-obstacle distance [m] (0 when colliding, +inf without obstacles)."""
        points, radii = solution.body(robot)
        return self.check_body(points, radii, distance=True).min_distance
