"""The motion history that a planned, ordered path creates, and the choice of its final motion.

Ha, Fagogenis & Dupont 2019 (Section V-B, doi:10.1109/TRO.2018.2878906): the friction state of a
tube pair is set by the direction eta_k of its last relative rotation (Eqs. (38)-(39)), and a
translation after that rotation releases the friction-induced twist ("translation-last"). This
module reads both from a sequence of joint waypoints, for
:func:`ctrplan.mechanics.predict_tip`:

- :func:`path_history`: eta and the translation-last flag of every pair at every waypoint;
- :func:`approach_history`: the history at a goal reached by one straight segment from a given
  configuration, executed rotation-then-translation or translation-then-rotation (what the
  compensated inverse kinematics assumes before the plan exists);
- :func:`end_with`: reorder the two phases before a waypoint so that the motion reaching it ends
  with the requested kind (``"translation-last"`` or ``"rotation-last"``), if the reordered
  phases pass a motion check.

Rules (the same as :func:`ctrplan.discrepancy.simulate.motion_history` except that the
translation-last flag is kept **per pair**):

- eta_k follows the relative angle ``alpha_(k+1) - alpha_k`` with the hysteresis of
  :func:`ctrplan.io.tables.rotation_directions` (0 until the pair has rotated);
- a step that changes rotations and translations together is executed as its rotation, then its
  translation (the order of :func:`~ctrplan.planning.order_path`);
- pair k is translation-last at a waypoint when some base translation changed by more than
  ``translation_tol`` after the pair's last relative rotation. Any base counts, as in
  ``motion_history`` and the translation-last bound of the bound map (clearance model for the
  whole robot after a final translation); a rotation of another pair afterwards does not
  restore the released pair's friction (``motion_history`` keeps one flag per sample, which a
  later rotation of any pair clears).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import HISTORY_ROTATION_TOL, HISTORY_TRANSLATION_TOL
from ..errors import UnreachableGoalError
from ..io.tables import rotation_directions
from .ordering import OrderedPath, OrderedWaypoint
from .space import wrap_angle

__all__ = ["PathHistory", "path_history", "approach_history", "end_with", "goal_indices", "FINAL_MOTIONS",
           "DEFAULT_FINAL_MOTION"]

# Final motions a scenario may ask for ([planner] final_motion) and the motion kind each ends with.
FINAL_MOTIONS = {"translation-last": "translation", "rotation-last": "rotation"}
DEFAULT_FINAL_MOTION = "translation-last"

# Default hysteresis of a relative rotation [rad] and threshold of a translation [m], shared with
# ctrplan.discrepancy.simulate.motion_history (constants).
DEFAULT_ROTATION_TOL = HISTORY_ROTATION_TOL
DEFAULT_TRANSLATION_TOL = HISTORY_TRANSLATION_TOL


@dataclass(frozen=True, eq=False)
class PathHistory:
    """Friction-relevant history at each waypoint of a path.

    Attributes
    ----------
    eta : ndarray of int, shape (K, n - 1)
        Direction of the last relative rotation of tube k+1 with respect to tube k: +1 CCW
        (``alpha_(k+1) - alpha_k`` increasing), -1 CW, 0 none yet (Eq. (39)).
    translation_last : ndarray of bool, shape (K, n - 1)
        A base translation came after the pair's last relative rotation (Section V-B).
    """

    eta: np.ndarray
    translation_last: np.ndarray

    def at(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(eta (n - 1,), translation_last (n - 1,)) at waypoint ``k``."""
        return self.eta[k].copy(), self.translation_last[k].copy()


def path_history(robot, q, *, rotation_tol: float = DEFAULT_ROTATION_TOL,
                 translation_tol: float = DEFAULT_TRANSLATION_TOL) -> PathHistory:
    """Motion history at every waypoint of a joint-space path.

    Parameters
    ----------
    robot : Robot
    q : array-like, shape (K, n_joints)
        Waypoints in path order [rad or m], periodic angles **continuous** (as
        :class:`~ctrplan.planning.OrderedPath` holds them; see
        :func:`~ctrplan.planning.unwrap_path`). The robot moves in a straight line between
        consecutive waypoints; a step changing rotations and translations is executed rotation
        first. The first waypoint has no history.
    rotation_tol : float, keyword-only
        Hysteresis of a relative rotation [rad], > 0.
    translation_tol : float, keyword-only
        Smallest base translation that releases friction [m], > 0.

    Returns
    -------
    PathHistory
        ``eta`` (K, n - 1) and ``translation_last`` (K, n - 1).

    Raises
    ------
    ValueError
        ``q`` not of shape (K, n_joints) or not finite; tolerances <= 0.
    JointLimitError
        A waypoint the robot cannot take (``Robot.configuration``).
    """
    q = np.asarray(q, dtype=float)
    nj = len(robot.joints)
    if q.ndim != 2 or q.shape[1] != nj or q.shape[0] < 1:
        raise ValueError(f"q must have shape (K, {nj}) ({', '.join(robot.joint_names)}), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q must be finite")
    if not rotation_tol > 0 or not translation_tol > 0:
        raise ValueError(f"tolerances must be > 0, got rotation_tol={rotation_tol!r} rad, "
                         f"translation_tol={translation_tol!r} m")
    conf = [robot.configuration(qk, check_limits=False) for qk in q]
    alpha = np.array([c[0] for c in conf])
    beta = np.array([c[1] for c in conf])
    K, n = alpha.shape
    eta = rotation_directions(alpha, tol=rotation_tol) if n > 1 else np.zeros((K, 0), dtype=int)
    rel = np.diff(alpha, axis=1)
    tlast = np.zeros((K, n - 1), dtype=bool)
    rel_ref = rel[0].copy()
    beta_ref = np.repeat(beta[:1], n - 1, axis=0)        # (n - 1, n): base translations at each pair's last rotation
    translated = np.zeros(n - 1, dtype=bool)
    for k in range(1, K):
        rotated = np.abs(rel[k] - rel_ref) > rotation_tol
        # the rotation of this step happens first, with the translations still at beta[k - 1]
        rel_ref[rotated] = rel[k][rotated]
        beta_ref[rotated] = beta[k - 1]
        translated[rotated] = False
        translated |= np.max(np.abs(beta[k][None, :] - beta_ref), axis=1) > translation_tol
        tlast[k] = translated
    return PathHistory(eta=eta.astype(int), translation_last=tlast)


def approach_history(robot, q_from, q_to, final_motion: str = DEFAULT_FINAL_MOTION, *,
                     rotation_tol: float = DEFAULT_ROTATION_TOL,
                     translation_tol: float = DEFAULT_TRANSLATION_TOL) -> tuple[np.ndarray, np.ndarray]:
    """History at ``q_to`` reached from ``q_from`` by one straight segment, ordered as asked.

    Periodic rotations turn the short way (as :class:`~ctrplan.planning.JointStateSpace`
    interpolates); ``q_from`` is taken without earlier history, so a pair that does not rotate
    on the segment has eta 0.

    Parameters
    ----------
    robot : Robot
    q_from, q_to : array-like, shape (n_joints,)
        [rad or m].
    final_motion : {"translation-last", "rotation-last"}
        ``"translation-last"``: rotations, then translations (the order of
        :func:`~ctrplan.planning.order_path`); ``"rotation-last"``: translations, then rotations.
    rotation_tol, translation_tol : float, keyword-only
        As :func:`path_history` [rad], [m].

    Returns
    -------
    eta : ndarray of int, shape (n - 1,)
    translation_last : ndarray of bool, shape (n - 1,)

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
    rot = np.array([j.kind == "rotation" for j in robot.joints])
    d = np.where(periodic, wrap_angle(b - a), b - a)
    end = a + d
    mid = a + np.where(rot, d, 0.0) if final_motion == "translation-last" else a + np.where(rot, 0.0, d)
    h = path_history(robot, np.array([a, mid, end]), rotation_tol=rotation_tol, translation_tol=translation_tol)
    return h.at(2)


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
    other = "rotation" if want == "translation" else "translation"
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
