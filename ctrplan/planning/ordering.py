"""Rotate-then-translate ordering of a planned path and the bound given the last motion.

Ha, Fagogenis & Dupont 2019 (Section V-B, doi:10.1109/TRO.2018.2878906) show that a final
*translation* leaves only the clearance-induced tip error (the translation-last bound), while a
final *rotation* can leave the full friction bound. :func:`order_path` therefore splits every
straight segment ``q_a -> q_b`` of a planned path into

1. a rotation phase: rotation joints move from ``q_a`` to ``q_b``, translations held at ``q_a``;
2. a translation phase: translation joints move, rotations held at ``q_b``.

Both phases are checked for validity at a given resolution. If a phase is invalid, the segment
is bisected and each half ordered again (the L-shaped detour shrinks toward the validated
straight segment), up to ``max_subdivisions`` times. Phases with no change are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import UnreachableGoalError
from .space import JointStateSpace, unwrap_path

__all__ = ["OrderedWaypoint", "OrderedPath", "LastMotionBounds", "order_path", "bounds_given_last_motion",
           "MOTIONS"]

MOTIONS = ("start", "rotation", "translation")

# Joint changes at or below this are "no motion" [rad or m].
NO_MOTION_TOL = 1e-12

# Default spacing of validity samples along each phase [m of the weighted joint metric].
DEFAULT_ORDERING_RESOLUTION = 2e-3

# Bisections of one planned segment before giving up.
DEFAULT_MAX_SUBDIVISIONS = 6


@dataclass(frozen=True)
class OrderedWaypoint:
    """Joint vector reached by a motion.

    Attributes
    ----------
    motion : {"start", "rotation", "translation"}
        The phase that ends here.
    q : ndarray, shape (n_joints,)
        [rad or m]; periodic angles continuous along the path.
    """

    motion: str
    q: np.ndarray


@dataclass
class OrderedPath:
    """Waypoints of an ordered path.

    Attributes
    ----------
    waypoints : list of OrderedWaypoint
    n_subdivisions : int
        Bisections needed to make all phases valid.
    """

    waypoints: list
    n_subdivisions: int = 0

    @property
    def q(self) -> np.ndarray:
        """Joint vectors, shape (K, n_joints) [rad or m]."""
        return np.array([w.q for w in self.waypoints])

    @property
    def motions(self) -> list[str]:
        return [w.motion for w in self.waypoints]

    def __len__(self):
        return len(self.waypoints)


@dataclass
class LastMotionBounds:
    """Exact tip-error bound at each ordered waypoint, given the motion that reached it.

    Attributes
    ----------
    motions : list of str
    position : ndarray, shape (K,)
        Friction bound after "start" or "rotation"; translation-last bound after
        "translation" [m]. NaN where the evaluator failed.
    angle : ndarray, shape (K,)
        Same for the tip tangent [rad].
    valid : ndarray of bool, shape (K,)
        Evaluator converged and the configuration is stable.
    results : list
        The evaluator's results (None where it raised).
    """

    motions: list
    position: np.ndarray
    angle: np.ndarray
    valid: np.ndarray
    results: list = field(default_factory=list, repr=False)


def _phase_valid(js, validity_fn, q0, q1, resolution) -> bool:
    length = float(js.distance(q0, q1))
    m = max(1, int(np.ceil(length / resolution)))
    for q in js.interpolate(q0, q1, np.arange(1, m + 1) / m):
        if not bool(validity_fn(q)):
            return False
    return True


def order_path(waypoints, robot, validity_fn, *, joint_space: JointStateSpace | None = None,
               resolution: float = DEFAULT_ORDERING_RESOLUTION,
               max_subdivisions: int = DEFAULT_MAX_SUBDIVISIONS) -> OrderedPath:
    """Split each segment into a rotation phase followed by a translation phase.

    Parameters
    ----------
    waypoints : array-like, shape (K, n_joints)
        Planned path [rad or m] (periodic angles may be wrapped; they are unwrapped first).
    robot : Robot
    validity_fn : callable
        ``validity_fn(q (n_joints,)) -> bool``.
    joint_space : JointStateSpace, optional
        Metric for the sampling resolution (default ``JointStateSpace(robot)``).
    resolution : float, keyword-only
        Largest spacing of validity samples along a phase [m of the weighted metric].
    max_subdivisions : int, keyword-only
        Bisections allowed per planned segment when a phase is invalid.

    Returns
    -------
    OrderedPath
        First waypoint ``"start"``; then rotation / translation waypoints; within each planned
        segment rotations precede translations.

    Raises
    ------
    UnreachableGoalError
        A segment cannot be ordered validly within ``max_subdivisions`` bisections.
    ValueError
        Bad waypoint shape.
    """
    js = joint_space if joint_space is not None else JointStateSpace(robot)
    w = unwrap_path(np.atleast_2d(np.asarray(waypoints, dtype=float)), robot)
    rot = js.is_rotation
    out = [OrderedWaypoint("start", w[0].copy())]
    n_sub = 0

    def emit(a, b, depth):
        nonlocal n_sub
        d = b - a
        mid = a + np.where(rot, d, 0.0)
        phases = []
        if np.any(np.abs(d[rot]) > NO_MOTION_TOL):
            phases.append(("rotation", a, mid))
        if np.any(np.abs(d[~rot]) > NO_MOTION_TOL):
            phases.append(("translation", mid, b))
        if all(_phase_valid(js, validity_fn, p, q, resolution) for _, p, q in phases):
            out.extend(OrderedWaypoint(kind, q.copy()) for kind, _, q in phases)
            return
        if depth >= max_subdivisions:
            raise UnreachableGoalError(
                f"cannot order the segment from {a} to {b} into valid rotation and translation phases "
                f"after {max_subdivisions} bisections (resolution {resolution * 1e3:.3g} mm)")
        n_sub += 1
        c = a + 0.5 * d
        emit(a, c, depth + 1)
        emit(c, b, depth + 1)

    for a, b in zip(w[:-1], w[1:]):
        emit(a, b, 0)
    return OrderedPath(out, n_sub)


def bounds_given_last_motion(ordered: OrderedPath, robot, evaluator, settings=None) -> LastMotionBounds:
    """Run the exact bound model at every ordered waypoint and pick the bound that applies.

    After a rotation (and at the start, whose history is unknown) the friction bound applies;
    after a translation the translation-last bound (Section V-B of Ha et al. 2019).

    Parameters
    ----------
    ordered : OrderedPath
    robot : Robot
    evaluator : callable
        ``evaluator(robot, alpha (n,) [rad], beta (n,) [m], settings) -> BoundResult``, e.g.
        :func:`ctrplan.mechanics.evaluate_bound`.
    settings : ModelSettings, optional

    Returns
    -------
    LastMotionBounds
    """
    from ..errors import CtrplanError

    k = len(ordered.waypoints)
    pos = np.full(k, np.nan)
    ang = np.full(k, np.nan)
    valid = np.zeros(k, dtype=bool)
    results = []
    for i, wp in enumerate(ordered.waypoints):
        try:
            alpha, beta = robot.configuration(wp.q)
            res = evaluator(robot, alpha, beta, settings)
        except CtrplanError:
            results.append(None)
            continue
        results.append(res)
        if wp.motion == "translation":
            pos[i], ang[i] = res.translation_last_position, res.translation_last_angle
        else:
            pos[i], ang[i] = res.position, res.angle
        diag = getattr(res, "diagnostics", None)
        valid[i] = diag is None or (bool(diag.converged) and not bool(diag.unstable))
    return LastMotionBounds(ordered.motions, pos, ang, valid, results)
