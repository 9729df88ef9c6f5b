"""The motion history that a planned, ordered path creates, and the choice of its final motion.

Ha, Fagogenis & Dupont 2019 (Section V-B, doi:10.1109/TRO.2018.2878906): the friction state of a
tube pair is set by the direction eta_k of its last relative rotation (Eqs. (38)-(39)), and a
translation after that rotation releases the friction-induced twist ("translation-last"). The
rule is :mod:`ctrplan.history`'s, the same for recorded motions; this module applies it to
joint-space paths, with the history effects of the robot file that act on the robot (drive
backlash, gradually developing friction; a tracker's time offset concerns measurements only),
for :func:`ctrplan.mechanics.predict_tip`:

- :func:`path_history`: the history state at every waypoint of a path;
- :func:`approach_history`: the state at a goal reached by one straight segment, executed
  rotation-then-translation or translation-then-rotation, after the motion so far (what the
  compensated inverse kinematics assumes before the plan exists);
- :func:`end_with`: reorder the two phases before a waypoint so that the motion reaching it ends
  with the requested kind (``"translation-last"`` or ``"rotation-last"``), if the reordered
  phases pass a motion check.

A planned path is ordered into pure rotation and pure translation phases
(:func:`~ctrplan.planning.order_path`); a step that changes rotations and translations together
counts as concurrent (:mod:`ctrplan.history`): order the path first.
"""

from __future__ import annotations

import numpy as np

from ..choices import FinalMotion, JointKind, MotionKind
from ..effects import history_state
from ..errors import UnreachableGoalError
from ..history import HistoryState, MotionRecord, PairState
from .ordering import OrderedPath, OrderedWaypoint
from .space import wrap_angle

__all__ = ["path_history", "approach_history", "approach_rows", "end_with", "goal_indices", "FINAL_MOTIONS", "DEFAULT_FINAL_MOTION"]

# Final motions a scenario may ask for ([planner] final_motion) and the motion kind each ends with.
FINAL_MOTIONS = {f: f.last for f in FinalMotion}
#: Final motion of a scenario that does not name one.
DEFAULT_FINAL_MOTION = FinalMotion.TRANSLATION_LAST


def _record(robot, q) -> MotionRecord:
    q = np.asarray(q, dtype=float)
    nj = len(robot.joints)
    if q.ndim != 2 or q.shape[1] != nj or q.shape[0] < 1:
        raise ValueError(f"q must have shape (K, {nj}) ({', '.join(robot.joint_names)}), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q must be finite")
    conf = [robot.configuration(qk, check_limits=False) for qk in q]
    return MotionRecord(np.array([c[0] for c in conf]), np.array([c[1] for c in conf]))


def path_history(robot, q) -> HistoryState:
    """The history state at every waypoint of a joint-space path.

    Parameters
    ----------
    robot : Robot
        Its file's history effects that act on the robot apply (:func:`ctrplan.effects.history_state`
        with ``tracker=False``).
    q : array-like, shape (K, n_joints)
        Waypoints in path order [rad or m], periodic angles **continuous** (as
        :class:`~ctrplan.planning.OrderedPath` holds them; see
        :func:`~ctrplan.planning.unwrap_path`), ordered into pure rotation and translation
        phases. The robot moves in a straight line between consecutive waypoints. The first
        waypoint has no history (its drives centred in their dead bands).

    Returns
    -------
    HistoryState
        Per waypoint: configuration the tubes reach (``alpha``, ``beta``) and offsets from the
        commanded one, eta, release (translation-last) and friction state per pair;
        ``state.at(k)`` is :func:`ctrplan.mechanics.predict_tip`'s ``state``.

    Raises
    ------
    ValueError
        ``q`` not of shape (K, n_joints) or not finite.
    """
    return history_state(robot, _record(robot, q), tracker=False)


def approach_rows(robot, q_from, q_to, final_motion: str = DEFAULT_FINAL_MOTION) -> np.ndarray:
    """The waypoints of one straight segment from ``q_from`` to ``q_to`` ordered as asked: start,
    end of the first phase, end; shape (3, n_joints) [rad or m], angles continuous from ``q_from``
    (periodic rotations turn the short way).

    Raises
    ------
    ValueError
        Unknown ``final_motion`` or wrong shapes.
    """
    if final_motion not in FINAL_MOTIONS:
        raise ValueError(f"final_motion must be one of {', '.join(FINAL_MOTIONS)}, got {final_motion!r}")
    a = np.asarray(q_from, dtype=float).reshape(-1)
    b = np.asarray(q_to, dtype=float).reshape(-1)
    nj = len(robot.joints)
    if a.shape != (nj,) or b.shape != (nj,):
        raise ValueError(f"q_from and q_to need {nj} values, got {a.shape} and {b.shape}")
    periodic = np.array([j.periodic for j in robot.joints])
    rot = np.array([j.kind == JointKind.ROTATION for j in robot.joints])
    d = np.where(periodic, wrap_angle(b - a), b - a)
    end = a + d
    mid = a + np.where(rot, d, 0.0) if final_motion == FinalMotion.TRANSLATION_LAST else a + np.where(rot, 0.0, d)
    return np.array([a, mid, end])


def approach_history(robot, q_from, q_to, final_motion: str = DEFAULT_FINAL_MOTION, *, before=None) -> PairState:
    """The state at ``q_to`` reached from ``q_from`` by one straight segment, ordered as asked.

    Periodic rotations turn the short way (as :class:`~ctrplan.planning.JointStateSpace`
    interpolates).

    Parameters
    ----------
    robot : Robot
        Its file's history effects that act on the robot apply.
    q_from, q_to : array-like, shape (n_joints,)
        [rad or m].
    final_motion : {"translation-last", "rotation-last"}
        ``"translation-last"``: rotations, then translations (the order of
        :func:`~ctrplan.planning.order_path`); ``"rotation-last"``: translations, then rotations.
    before : array-like, shape (B, n_joints), optional, keyword-only
        The motion before ``q_from`` (its last row is ``q_from`` or leads to it in a straight
        segment), continuous angles; without it ``q_from`` has no history, so a pair that does
        not rotate on the segment has eta 0 and every drive starts centred in its dead band.

    Returns
    -------
    PairState
        For :func:`ctrplan.mechanics.predict_tip` (``state=``).

    Raises
    ------
    ValueError
        Unknown ``final_motion`` or wrong shapes.
    """
    rows = list(approach_rows(robot, q_from, q_to, final_motion))
    if before is not None:
        nj = len(robot.joints)
        periodic = np.array([j.periodic for j in robot.joints])
        prior = np.asarray(before, dtype=float).reshape(-1, nj)
        # continue the angles of the motion before (the short way from its end to q_from)
        a = rows[0]
        shift = np.where(periodic, prior[-1] + wrap_angle(a - prior[-1]) - a, 0.0)
        rows = list(prior) + [r + shift for r in rows]
    return path_history(robot, np.array(rows)).at(len(rows) - 1)


def end_with(ordered: OrderedPath, index: int, final_motion: str, motion_check=None) -> tuple[OrderedPath, str]:
    """Make the motion that reaches waypoint ``index`` end with the requested kind.

    When the two phases before ``index`` are the other way round (rotation then translation for
    ``"rotation-last"``, or translation then rotation for ``"translation-last"``), they are
    replaced by the same joint changes in the opposite order, provided both new phases pass
    ``motion_check``.

    Parameters
    ----------
    ordered : OrderedPath
        Not modified.
    index : int
        Waypoint index (a goal), >= 1.
    final_motion : {"translation-last", "rotation-last"}
    motion_check : callable, optional
        ``motion_check(q0, q1)`` -> bool or an object with ``valid`` and ``reason`` (e.g.
        :meth:`~ctrplan.planning.MotionVerifier.check`). None accepts every phase.

    Returns
    -------
    OrderedPath
        The path, reordered or as it was (same number of waypoints either way).
    str
        What happened: ``"already"`` (the motion ends as asked), ``"reordered"``,
        ``"rejected: <reason>"`` (a reordered phase failed the check; path unchanged) or
        ``"impossible: <reason>"`` (the phases before ``index`` cannot be swapped, e.g. the last
        segment moves only one joint group).

    Raises
    ------
    ValueError
        Unknown ``final_motion`` or ``index`` out of range.
    """
    if final_motion not in FINAL_MOTIONS:
        raise ValueError(f"final_motion must be one of {', '.join(FINAL_MOTIONS)}, got {final_motion!r}")
    if not 1 <= index < len(ordered):
        raise ValueError(f"index must be in [1, {len(ordered) - 1}], got {index}")
    want = FINAL_MOTIONS[final_motion]
    other = MotionKind.ROTATION if want == MotionKind.TRANSLATION else MotionKind.TRANSLATION
    wps = ordered.waypoints
    if wps[index].motion == want:
        return ordered, "already"
    if index < 2 or wps[index - 1].motion != want:
        return ordered, (f"impossible: the {other} reaching waypoint {index} follows "
                         f"{'the start' if index < 2 else 'a ' + wps[index - 1].motion}, not a {want}")
    a, b = wps[index - 2].q, wps[index].q
    old_mid = wps[index - 1].q
    # the new middle: the joints of the current final phase (kind `other`) already at b, those
    # of the phase before it (kind `want`, now last) still at a
    moved_last = np.abs(b - old_mid) > 0.0
    mid = np.where(moved_last, b, a)
    for p, q in ((a, mid), (mid, b)):
        if motion_check is None:
            continue
        r = motion_check(p, q)
        ok = bool(r) if isinstance(r, (bool, np.bool_)) else bool(r.valid)
        if not ok:
            reason = "invalid" if isinstance(r, (bool, np.bool_)) else str(getattr(r, "reason", "invalid"))
            return ordered, f"rejected: {p.round(4).tolist()} -> {q.round(4).tolist()}: {reason}"
    new = list(wps[:index - 1]) + [OrderedWaypoint(other, mid.copy()), OrderedWaypoint(want, b.copy())] + \
        list(wps[index + 1:])
    out = OrderedPath(new, n_subdivisions=ordered.n_subdivisions, n_repairs=ordered.n_repairs,
                      n_phase_checks=ordered.n_phase_checks + (2 if motion_check is not None else 0),
                      failures=list(ordered.failures))
    return out, "reordered"


def goal_indices(ordered: OrderedPath, goals_q, robot, tol: float = 1e-9) -> list[int]:
    """Index of each goal's waypoint in an ordered route (goals in visiting order).

    Parameters
    ----------
    ordered : OrderedPath
    goals_q : sequence of array-like, shape (n_joints,)
        [rad or m]; periodic angles may be wrapped.
    robot : Robot
    tol : float
        Largest joint difference [rad or m] (periodic joints modulo 2 pi).

    Returns
    -------
    list of int

    Raises
    ------
    UnreachableGoalError
        A goal is not on the route after the previous one.
    """
    periodic = np.array([j.periodic for j in robot.joints])
    q = ordered.q
    out, start = [], 1
    for g in goals_q:
        g = np.asarray(g, dtype=float)
        d = np.abs(np.where(periodic, wrap_angle(q - g), q - g))
        hits = [k for k in range(start, len(q)) if np.all(d[k] <= tol)]
        if not hits:
            raise UnreachableGoalError(f"goal {np.round(g, 4).tolist()} is not on the ordered route")
        out.append(hits[0])
        start = hits[0] + 1
    return out
