"""Motions an experiment is built from: primitives the effects respond to, their feasibility, and
the time-parameterized, jerk-limited trajectory (ruckig, :mod:`ctrplan.trajectory`) they make.

A primitive starts and ends at rest at joint waypoints; each of its segments moves one joint group
(rotations or translations), as the drive and :func:`ctrplan.trajectory.check_trajectory` require.
The kinds (the history each effect shows in):

- ``move``: one joint to a new value (explores the workspace);
- ``reversal``: one joint out and back (drive backlash, torsional friction's switch, Eq. (38));
- ``slow``: a move at a quarter of the drive limits (a tracker lag scales with speed, gradual
  friction does not);
- ``turn``: every tube rotated together (the same relative configuration at another absolute angle:
  an off-plane precurvature turns with the tubes, a tracker frame does not);
- ``release``: a rotation followed by a translation (a translation after the last rotation releases
  friction-induced twist, Section V-B of Ha et al. 2019);
- ``shifted reversal`` (with ``compound=True``): a move of one joint by its larger step, then a
  reversal of that joint about the new value: two steps a search that adds one primitive at a time
  would take only if the move alone paid, where a reversal repeated about one value gives less and
  less (the same history seen again).

Every primitive ends with a rest (the sensor's noise and any settling are seen there).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..choices import MotionKind
from ..history import MotionRecord, motion_state
from ..robot import ROTATION, TRANSLATION
from ..drive import JointLimits
from ..trajectory import Trajectory, time_parameterize

#: Speed factor of a ``slow`` primitive: the drive limits are scaled by f, f^2, f^3 [-].
SLOW_FACTOR = 0.25
#: Rotation amplitudes of moves and reversals [rad].
ROTATION_STEPS = (0.5, 1.5)
#: Translation amplitudes as fractions of the joint's range [-].
TRANSLATION_STEPS = (0.25, 0.6)
#: Most out-and-back cycles of one reversal primitive.
MAX_CYCLES = 8


@dataclass(frozen=True)
class Primitive:
    """A motion from rest to rest through joint waypoints.

    Attributes
    ----------
    kind : str
        ``"move"``, ``"reversal"``, ``"slow"``, ``"turn"`` or ``"release"``.
    waypoints : ndarray, shape (k + 1, n_joints)
        Start, then the end of each segment [rad or m], in the robot's joint order.
    motions : tuple of str
        ``"rotation"`` or ``"translation"`` per segment.
    speed : float
        Fraction of the drive limits (velocity; acceleration and jerk by its square and cube).
    rest : float
        Rest at the end [s].
    """

    kind: str
    waypoints: np.ndarray
    motions: tuple
    speed: float = 1.0
    rest: float = 1.0

    @property
    def end(self) -> np.ndarray:
        return self.waypoints[-1]

    def describe(self, joint_names) -> str:
        """E.g. ``"reversal alpha_2 0 -> 0.5 -> 0 rad"``."""
        moved = np.flatnonzero(np.any(np.abs(np.diff(self.waypoints, axis=0)) > 0, axis=0))
        parts = []
        for i in moved:
            unit = "m" if joint_names[i].startswith("beta") else "rad"
            parts.append(f"{joint_names[i]} " + " -> ".join(f"{v:.4g}" for v in self.waypoints[:, i]) + f" {unit}")
            if self.kind == "reversal":
                parts[-1] = (f"{joint_names[i]} {self.waypoints[0, i]:.4g} -> {self.waypoints[1, i]:.4g} -> "
                             f"{self.waypoints[2, i]:.4g} {unit}")
            elif self.kind == "shifted reversal":
                parts[-1] = (f"{joint_names[i]} {self.waypoints[0, i]:.4g} -> {self.waypoints[1, i]:.4g}, then "
                             f"{self.waypoints[1, i]:.4g} -> {self.waypoints[2, i]:.4g} -> "
                             f"{self.waypoints[3, i]:.4g} {unit}")
        speed = "" if self.speed == 1.0 else f" at {self.speed:g} of the drive limits"
        cycles = (len(self.motions) // 2 if self.kind == "reversal" else
                  (len(self.motions) - 1) // 2 if self.kind == "shifted reversal" else 1)
        return f"{self.kind} " + ", ".join(parts) + (f", {cycles} cycles" if cycles > 1 else "") + speed


def _inside(robot, q) -> bool:
    for j, v in zip(robot.joints, q):
        if not j.periodic and not (j.lower - 1e-12 <= v <= j.upper + 1e-12):
            return False
    return True


def primitives(robot, q, rest: float = 1.0, *, drive=None, min_duration: float = 0.0,
               compound: bool = False) -> list[Primitive]:
    """The primitives that start at ``q`` and stay inside the joint limits.

    Parameters
    ----------
    robot : Robot
    q : array-like, shape (n_joints,)
        Current joint values [rad or m].
    rest : float
        Rest at the end of each [s].
    drive : DriveLimits, optional
        With ``min_duration``: a reversal is cycled (out and back, again) as often as fits in
        ``min_duration`` (at most :data:`MAX_CYCLES`), with one rest at the end.
    min_duration : float
        [s]
    compound : bool
        Also the ``shifted reversal`` of every joint: a move by its larger step either way, then
        its smaller step out and back either way, cycled as a reversal is.

    Returns
    -------
    list of Primitive
        Not yet checked for stability or collisions (:func:`feasible`).
    """
    q = np.asarray(q, float)
    out = []
    joints = robot.joints
    kinds = [j.kind for j in joints]

    def add(kind, points, motions, speed=1.0, lead=()):
        lead = [np.asarray(p, float) for p in lead]
        W = np.vstack([q] + lead + [np.asarray(p, float) for p in points])
        head = tuple(motions[:len(lead)])
        if all(_inside(robot, w) for w in W) and np.any(np.abs(np.diff(W, axis=0)) > 0):
            prim = Primitive(kind, W, tuple(motions), speed, rest)
            if kind in ("reversal", "shifted reversal") and drive is not None and min_duration > 0:
                # cycles of the same reversal up to min_duration (a replicated support point)
                one = trajectory(robot, [prim], drive).duration
                cycles = int(min(MAX_CYCLES, max(1, min_duration // one)))
                if cycles > 1:
                    W = np.vstack([q] + lead + [np.asarray(p, float) for p in points] * cycles)
                    prim = Primitive(kind, W, head + tuple(motions[len(lead):]) * cycles, speed, rest)
            out.append(prim)

    for i, j in enumerate(joints):
        if j.kind == ROTATION:
            steps = ROTATION_STEPS
        else:
            steps = tuple(f * (j.upper - j.lower) for f in TRANSLATION_STEPS)
        for a in steps:
            for sign in (1.0, -1.0):
                p = q.copy()
                p[i] += sign * a
                add("move", [p], [j.kind])
                add("reversal", [p, q], [j.kind, j.kind])
            p = q.copy()
            p[i] += a if _inside(robot, q + a * np.eye(len(q))[i]) else -a
            add("slow", [p], [j.kind], SLOW_FACTOR)
        if compound:
            small, large = steps[0], steps[-1]
            for sign in (1.0, -1.0):
                shifted = q.copy()
                shifted[i] += sign * large
                for back in (1.0, -1.0):
                    out_p = shifted.copy()
                    out_p[i] += back * small
                    add("shifted reversal", [out_p, shifted], [j.kind, j.kind, j.kind], lead=[shifted])
    rot = [i for i, k in enumerate(kinds) if k == ROTATION]
    tubes_rotated = {joints[i].tube for i in rot}
    if rot and tubes_rotated == set(range(robot.n_tubes)):
        for a in ROTATION_STEPS:
            for sign in (1.0, -1.0):
                p = q.copy()
                p[rot] += sign * a
                add("turn", [p], [ROTATION])
    trans = [i for i, k in enumerate(kinds) if k == TRANSLATION]
    for i in rot:
        for k in trans:
            j = joints[k]
            for sign in (1.0, -1.0):
                p = q.copy()
                p[i] += sign * ROTATION_STEPS[0]
                p2 = p.copy()
                span = TRANSLATION_STEPS[0] * (j.upper - j.lower)
                p2[k] += span if _inside(robot, p + span * np.eye(len(q))[k]) else -span
                add("release", [p, p2], [ROTATION, TRANSLATION])
    return out


def feasible(checker, prim: Primitive) -> bool:
    """Every segment of ``prim`` valid for ``checker`` (a
    :class:`ctrplan.planning.validity.BatchValidityChecker`: joint limits, a converged and stable
    standard model, no collision, checked along the straight joint-space segment)."""
    return all(checker.check_motion(a, b) for a, b in zip(prim.waypoints[:-1], prim.waypoints[1:]))


def trajectory(robot, prims, drive) -> Trajectory:
    """The jerk-limited trajectory of a sequence of primitives.

    Each segment is one ruckig rest-to-rest motion along its straight joint-space segment
    (:func:`ctrplan.trajectory.time_parameterize`) at the primitive's share of the drive limits;
    the rests are held samples between segments.

    Parameters
    ----------
    robot : Robot
    prims : sequence of Primitive
        Consecutive (each starts where the previous ended).
    drive : DriveLimits
        The drive's limits and control rate (:class:`ctrplan.drive.DriveLimits`).

    Returns
    -------
    Trajectory
        With the full drive limits recorded (slow segments stay within them).

    Raises
    ------
    ValueError
        Primitives that do not join, or empty.
    """
    if not prims:
        raise ValueError("no primitives")
    joints = JointLimits.of_robot(robot)
    names, kinds = joints.names, joints.kinds
    # each piece is validated on its straight segment, unwrapped or not: no joint taken as periodic
    pieces = JointLimits(names, kinds, joints.lower, joints.upper, np.zeros(len(names), bool))
    drive = drive.in_order(names)
    dt = 1.0 / drive.control_rate_hz
    n = len(names)
    q = np.asarray(prims[0].waypoints[0], float)
    p_chunks, v_chunks, a_chunks = [q[None, :]], [np.zeros((1, n))], [np.zeros((1, n))]
    segments, waypoints = [], [q]
    i0 = 0
    for prim in prims:
        if np.max(np.abs(prim.waypoints[0] - waypoints[-1])) > 1e-12:
            raise ValueError("primitives do not join: one starts where the previous did not end")
        f = prim.speed
        for a, b, motion in zip(prim.waypoints[:-1], prim.waypoints[1:], prim.motions):
            piece = time_parameterize(np.vstack([a, b]), [MotionKind.START, motion], pieces, drive.scaled(f))
            s = piece.segments[0]
            m = len(piece.t) - 1
            segments.append(replace(s, index=len(segments), t_start=i0 * dt, t_end=(i0 + m) * dt, i_start=i0,
                                    i_end=i0 + m))
            p_chunks.append(piece.position[1:])
            v_chunks.append(piece.velocity[1:])
            a_chunks.append(piece.acceleration[1:])
            waypoints.append(np.asarray(b, float))
            i0 += m
        hold = int(round(prim.rest / dt))
        if hold:
            p_chunks.append(np.repeat(p_chunks[-1][-1:], hold, axis=0))
            v_chunks.append(np.zeros((hold, n)))
            a_chunks.append(np.zeros((hold, n)))
            i0 += hold
    position = np.concatenate(p_chunks)
    return Trajectory(t=np.arange(position.shape[0]) * dt, position=position, velocity=np.concatenate(v_chunks),
                      acceleration=np.concatenate(a_chunks), segments=tuple(segments), waypoints=np.array(waypoints),
                      joint_names=names, joint_kinds=kinds, control_rate_hz=drive.control_rate_hz,
                      max_velocity=np.asarray(drive.max_velocity, float),
                      max_acceleration=np.asarray(drive.max_acceleration, float),
                      max_jerk=np.asarray(drive.max_jerk, float), lower=joints.lower, upper=joints.upper,
                      periodic=joints.periodic)


def sample(traj: Trajectory, period: float, t0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory's joint values at the sensor's sample times ``t0, t0 + period, ...``
    (linear interpolation of the control-rate samples).

    Returns
    -------
    t : ndarray, shape (K,) [s]
    q : ndarray, shape (K, n_joints) [rad or m]
    """
    t = np.arange(t0, traj.t[-1] + 1e-9, period)
    q = np.column_stack([np.interp(t, traj.t, traj.position[:, i]) for i in range(traj.n_joints)])
    return t, q


def joint_configurations(robot, q) -> tuple[np.ndarray, np.ndarray]:
    """Base rotations and translations, shape (K, n) each [rad, m], of joint vectors ``q`` shape
    (K, n_joints) (:meth:`ctrplan.robot.Robot.configuration` row by row, limits not checked)."""
    q = np.asarray(q, float)
    alpha = np.empty((q.shape[0], robot.n_tubes))
    beta = np.empty_like(alpha)
    for k in range(q.shape[0]):
        alpha[k], beta[k] = robot.configuration(q[k], check_limits=False)
    return alpha, beta


def motion_data(robot, t, q, *, frame: str = "robot", file: str = "<designed motion>", rows=None,
                configurations=None, history: bool = True):
    """A :class:`ctrplan.discrepancy.MeasuredData` of a planned motion (one continuous sequence;
    tips NaN: nothing measured yet), with the motion history the workflow derives from it.

    Parameters
    ----------
    robot : Robot
    t : array-like, shape (K,)
        Sample times [s], increasing.
    q : array-like, shape (K, n_joints), or None
        Joint values [rad or m]; None with ``configurations``.
    frame : PoseFrame or str
        ``"robot"`` or ``"tracker"``: the frame the predictions are given in (a tracker frame
        applies the hypotheses' registration).
    file : str
        Name for messages.
    rows : array-like of int, optional
        The samples to keep (the whole motion stays their history); default all.
    configurations : tuple of ndarray, optional
        ``(alpha, beta)``, shape (K, n) each [rad, m], instead of ``q``.
    history : bool
        Fill ``eta`` and ``translation_last`` from the motion (:func:`ctrplan.history.motion_state`);
        False leaves them 0 and False, for a caller that needs only the record and the samples
        (:func:`ctrplan.discrepancy.predict` derives the state from the record itself).

    Returns
    -------
    MeasuredData
    """
    from ..discrepancy.measured.data import MeasuredData

    alpha, beta = configurations if configurations is not None else joint_configurations(robot, q)
    K, n = alpha.shape
    t = np.asarray(t, float)
    sequence = np.zeros(K, dtype=int)
    record = MotionRecord(alpha, beta, t, sequence)
    given = np.zeros((K, n - 1), dtype=int)
    if history:
        hist = motion_state(record, given_eta=given)
        eta, released = hist.eta.astype(int), np.asarray(hist.released, bool)
    else:
        eta, released = given.copy(), np.zeros((K, n - 1), bool)
    data = MeasuredData(alpha=alpha, beta=beta, tip=np.full((K, 3), np.nan), tangent=None, eta=eta,
                        translation_last=released, sequence=sequence, config_id=np.arange(K), subset=None,
                        time=t, file=file, frame=frame, record=record, rows=np.arange(K), given_eta=given)
    return data if rows is None else data.take(rows)
