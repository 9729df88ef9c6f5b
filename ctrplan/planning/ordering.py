"""Rotate-then-translate ordering of a planned path and the bound given the last motion.

Ha, Fagogenis & Dupont 2019 (Section V-B, doi:10.1109/TRO.2018.2878906) show that a final
*translation* leaves only the clearance-induced tip error (the translation-last bound), while a
final *rotation* can leave the full friction bound. :func:`order_path` therefore splits every
straight segment ``q_a -> q_b`` of a planned path into

1. a rotation phase: rotation joints move from ``q_a`` to ``q_b``, translations held at ``q_a``;
2. a translation phase: translation joints move, rotations held at ``q_b``.

Both phases are checked, by a validity function sampled at a given resolution or by a motion
check such as :class:`~ctrplan.planning.verify.MotionVerifier` (the final check of the
pipeline). If a phase is invalid and the straight segment itself is valid, the segment is
bisected and each half ordered again (the L-shaped detour shrinks toward the straight
segment), up to ``max_subdivisions`` times. If the straight segment is invalid too (a search
that checked it coarsely or lazily was wrong about it), a ``repair`` function, when given,
re-plans from one end to the other and the new sub-path is ordered in turn (at most
``max_repairs`` nested repairs); otherwise, or if that fails, the ordering raises
:class:`~ctrplan.errors.UnreachableGoalError`. Phases with no change are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..choices import MotionKind
from ..errors import UnreachableGoalError
from .space import JointStateSpace, unwrap_path

__all__ = ["OrderedWaypoint", "OrderedPath", "LastMotionBounds", "order_path", "bounds_given_last_motion",
           "MOTIONS"]

MOTIONS = tuple(MotionKind)

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
    n_repairs : int
        Segments re-planned because the straight segment itself failed the check.
    n_phase_checks : int
        Phases (and straight segments) checked.
    failures : list of str
        What failed, for each bisection or repair.
    """

    waypoints: list
    n_subdivisions: int = 0
    n_repairs: int = 0
    n_phase_checks: int = 0
    failures: list = field(default_factory=list)

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


# Nested repairs (a repaired sub-path whose own segment fails again) before giving up.
DEFAULT_MAX_REPAIRS = 2


def _phase_valid(js, validity_fn, q0, q1, resolution) -> bool:
    length = float(js.distance(q0, q1))
    m = max(1, int(np.ceil(length / resolution)))
    for q in js.interpolate(q0, q1, np.arange(1, m + 1) / m):
        if not bool(validity_fn(q)):
            return False
    return True


def _fmt(q) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in np.asarray(q, dtype=float)) + "]"


def order_path(waypoints, robot, validity_fn=None, *, joint_space: JointStateSpace | None = None,
               resolution: float = DEFAULT_ORDERING_RESOLUTION,
               max_subdivisions: int = DEFAULT_MAX_SUBDIVISIONS, motion_check=None, repair=None,
               max_repairs: int = DEFAULT_MAX_REPAIRS) -> OrderedPath:
    """Split each segment into a rotation phase followed by a translation phase.

    Parameters
    ----------
    waypoints : array-like, shape (K, n_joints)
        Planned path [rad or m] (periodic angles may be wrapped; they are unwrapped first).
    robot : Robot
    validity_fn : callable, optional
        ``validity_fn(q (n_joints,)) -> bool``, sampled every ``resolution`` along a phase;
        required without ``motion_check``.
    joint_space : JointStateSpace, optional
        Metric for the sampling resolution (default ``JointStateSpace(robot)``).
    resolution : float, keyword-only
        Largest spacing of validity samples along a phase [m of the weighted metric].
    max_subdivisions : int, keyword-only
        Bisections allowed per planned segment when a phase is invalid.
    motion_check : callable, optional, keyword-only
        ``motion_check(q0, q1)`` -> bool, or an object with ``valid`` and ``reason`` (e.g.
        :meth:`MotionVerifier.check`); replaces the sampled ``validity_fn``.
    repair : callable, optional, keyword-only
        ``repair(q_a, q_b) -> ndarray (K, n_joints)``: a new path from ``q_a`` to ``q_b``
        (first and last rows those states), called when the straight segment between them
        fails; may raise :class:`UnreachableGoalError`.
    max_repairs : int, keyword-only
        Nested repairs allowed.

    Returns
    -------
    OrderedPath
        First waypoint ``"start"``; then rotation / translation waypoints; within each planned
        segment rotations precede translations.

    Raises
    ------
    UnreachableGoalError
        A segment cannot be ordered validly within ``max_subdivisions`` bisections and
        ``max_repairs`` repairs (the message names the segment and what failed).
    ValueError
        Bad waypoint shape, or neither ``validity_fn`` nor ``motion_check``.
    """
    if validity_fn is None and motion_check is None:
        raise ValueError("order_path needs a validity_fn or a motion_check")
    js = joint_space if joint_space is not None else JointStateSpace(robot)
    w = unwrap_path(np.atleast_2d(np.asarray(waypoints, dtype=float)), robot)
    rot = js.is_rotation
    out = [OrderedWaypoint(MotionKind.START, w[0].copy())]
    result = OrderedPath(out)

    def check(p, q):
        """(valid, reason) of the motion p -> q."""
        result.n_phase_checks += 1
        if motion_check is not None:
            r = motion_check(p, q)
            if isinstance(r, (bool, np.bool_)):
                return bool(r), "invalid"
            return bool(r.valid), str(getattr(r, "reason", ""))
        ok = _phase_valid(js, validity_fn, p, q, resolution)
        return ok, "" if ok else f"an invalid state (checked every {resolution * 1e3:.3g} mm)"

    def emit(a, b, depth, n_rep):
        d = b - a
        mid = a + np.where(rot, d, 0.0)
        phases = []
        if np.any(np.abs(d[rot]) > NO_MOTION_TOL):
            phases.append((MotionKind.ROTATION, a, mid))
        if np.any(np.abs(d[~rot]) > NO_MOTION_TOL):
            phases.append((MotionKind.TRANSLATION, mid, b))
        reason = ""
        for kind, p, q in phases:
            ok, reason = check(p, q)
            if not ok:
                reason = f"{kind} phase {_fmt(p)} -> {_fmt(q)}: {reason}"
                break
        else:
            out.extend(OrderedWaypoint(kind, q.copy()) for kind, _, q in phases)
            return
        if len(phases) == 1:   # a pure rotation or translation is its own straight segment
            straight_ok, straight_reason = False, reason
        else:
            straight_ok, straight_reason = check(a, b)
        if straight_ok and depth < max_subdivisions:
            result.n_subdivisions += 1
            result.failures.append(f"bisected: {reason}")
            c = a + 0.5 * d
            emit(a, c, depth + 1, n_rep)
            emit(c, b, depth + 1, n_rep)
            return
        why = straight_reason if not straight_ok else reason
        if repair is None or n_rep >= max_repairs:
            raise UnreachableGoalError(
                f"cannot order the segment {_fmt(a)} -> {_fmt(b)} into valid rotation and translation phases "
                f"({result.n_subdivisions} bisections, {n_rep} repairs): {why}")
        result.n_repairs += 1
        result.failures.append(f"repaired: {why}")
        sub = unwrap_path(np.atleast_2d(np.asarray(repair(a, b), dtype=float)), robot)
        sub = sub - sub[0] + a                       # continuous angles from a
        if not np.allclose(js.difference(sub[-1], b), 0.0, atol=1e-9):
            raise UnreachableGoalError(f"the repair of {_fmt(a)} -> {_fmt(b)} ended at {_fmt(sub[-1])}")
        sub[-1] = b
        for p, q in zip(sub[:-1], sub[1:]):
            emit(p, q, 0, n_rep + 1)

    for a, b in zip(w[:-1], w[1:]):
        emit(a, b, 0, 0)
    return result


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
        if wp.motion == MotionKind.TRANSLATION:
            pos[i], ang[i] = res.translation_last_position, res.translation_last_angle
        else:
            pos[i], ang[i] = res.position, res.angle
        diag = getattr(res, "diagnostics", None)
        valid[i] = diag is None or (bool(diag.converged) and not bool(diag.unstable))
    return LastMotionBounds(ordered.motions, pos, ang, valid, results)
