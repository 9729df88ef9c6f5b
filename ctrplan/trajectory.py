"""Time-parameterization of an ordered joint-space path with ruckig, and its checks.

The planner returns an ordered path: a start waypoint followed by waypoints each reached by a
pure rotation phase or a pure translation phase (the rotate-then-translate motions that keep the
friction-induced tip error bounded, Section IV of Ha, Fagogenis & Dupont 2019,
doi:10.1109/TRO.2018.2878906). The drive follows each straight joint-space segment from rest to
rest, so it stops between a rotation phase and the following translation phase.

ruckig (community edition, Berscheid & Kroeger 2021, "Jerk-limited real-time trajectory generation
with arbitrary target states", RSS, doi:10.15607/RSS.2021.XVII.015) computes one jerk-limited
rest-to-rest motion per segment. It moves the path parameter ``s`` of the straight segment
``q0 + s (q1 - q0)`` from 0 to 1, with each limit the tightest of the moving joints' limits divided
by their share of the segment, so that the joint-space path is the straight segment that the planner
validated, by construction, and the motion is the time-optimal straight one. Segment durations are
rounded up to whole control periods (ruckig's discrete duration discretization), so every waypoint
is a sample and is reached exactly, at rest.

Facts about ruckig used here (``shared/notes/ompl-ruckig.md``): intermediate waypoints are not
available offline (one calculation per segment instead); ``min_position``/``max_position`` are
ignored offline (position extrema are checked here instead); a calculation of all joints with Phase
synchronization gives the same motion only when ruckig finds a phase-synchronized profile: on short
segments of several joints it falls back to Time synchronization and leaves the straight segment by
up to 5e-4 rad (hence the one-parameter calculation).

Units: rotations in rad, translations in m, time in s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import ruckig

from .choices import MotionKind
from .drive import DriveLimits, JointLimits
from .errors import JointLimitError

__all__ = [
    "ROTATION",
    "TRANSLATION",
    "START",
    "TrajectorySegment",
    "Trajectory",
    "LimitViolation",
    "time_parameterize",
    "time_parameterize_robot",
    "check_trajectory",
]

#: Motion of a phase that changes rotations only (the ``motion`` column of ``path.csv``).
ROTATION = MotionKind.ROTATION
#: Motion of a phase that changes translations only.
TRANSLATION = MotionKind.TRANSLATION
#: Motion of the start waypoint, reached by no phase.
START = MotionKind.START
_UNITS = {ROTATION: "rad", TRANSLATION: "m"}

# A joint outside the moving group may differ between consecutive waypoints by at most this much
# [rad or m] (round-off of the planner); the value is then snapped to the previous waypoint's
# exactly. Larger changes are an error: the segment would move two joint groups.
GROUP_SNAP_TOL = 1e-9

# Relative tolerance on the velocity and acceleration limits of the samples [-] (ruckig's own
# profiles meet the limits to about 1e-12).
LIMIT_RTOL = 1e-6

# Relative tolerance on the jerk limit of finite differences of the sampled acceleration [-]
# (the difference quotient of a jerk-limited acceleration cannot exceed the limit, up to round-off
# amplified by 1 / dt).
JERK_RTOL = 0.05

# Absolute tolerance on "at rest", on joint limits and on "does not move" [rad or m, per s, per s^2].
ABS_TOL = 1e-9

# Largest deviation of a segment's samples from its straight joint-space segment, relative to the
# segment length [-]. The one-parameter motion keeps it at round-off level.
STRAIGHT_RTOL = 1e-6


@dataclass(frozen=True, eq=False)
class TrajectorySegment:
    """One rest-to-rest phase of a trajectory.

    Attributes
    ----------
    index : int
        Zero-based segment index; segment ``k`` goes from waypoint ``k`` to waypoint ``k + 1``.
    motion : {"rotation", "translation"}
        The joint group that moves.
    t_start, t_end : float
        Start and end time [s].
    i_start, i_end : int
        Indices of the samples at ``t_start`` and ``t_end`` (inclusive) in ``Trajectory.t``.
    q_start, q_end : ndarray, shape (n_joints,)
        Waypoints at both ends [rad or m] (periodic angles unwrapped).
    position_min, position_max : ndarray, shape (n_joints,)
        Position extrema of the continuous segment reported by ruckig [rad or m].
    """

    index: int
    motion: str
    t_start: float
    t_end: float
    i_start: int
    i_end: int
    q_start: np.ndarray
    q_end: np.ndarray
    position_min: np.ndarray
    position_max: np.ndarray

    @property
    def duration(self) -> float:
        """Segment duration [s]."""
        return self.t_end - self.t_start


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A sampled, jerk-limited trajectory through an ordered path.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Sample times [s], ``t[i] = i / control_rate_hz``; the last sample is at the end.
    position : ndarray, shape (T, n_joints)
        Joint positions [rad or m]; periodic rotations are unwrapped (continuous).
    velocity : ndarray, shape (T, n_joints)
        [rad/s or m/s]
    acceleration : ndarray, shape (T, n_joints)
        [rad/s^2 or m/s^2]
    segments : tuple of TrajectorySegment
        One per segment of the ordered path, in order.
    waypoints : ndarray, shape (K, n_joints)
        Waypoints as followed (periodic angles unwrapped) [rad or m].
    joint_names : tuple of str
        E.g. ``("alpha_2", "alpha_3", "beta_3")``.
    joint_kinds : tuple of str
        ``"rotation"`` or ``"translation"`` per joint.
    control_rate_hz : float
        Sample rate [Hz].
    max_velocity, max_acceleration, max_jerk : ndarray, shape (n_joints,)
        Limits the trajectory was computed with [unit/s, unit/s^2, unit/s^3].
    lower, upper : ndarray, shape (n_joints,)
        Joint limits [rad or m] (ignored for periodic joints).
    periodic : ndarray of bool, shape (n_joints,)
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    segments: tuple[TrajectorySegment, ...]
    waypoints: np.ndarray
    joint_names: tuple[str, ...]
    joint_kinds: tuple[str, ...]
    control_rate_hz: float
    max_velocity: np.ndarray
    max_acceleration: np.ndarray
    max_jerk: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    periodic: np.ndarray

    @property
    def duration(self) -> float:
        """Total duration [s]."""
        return float(self.t[-1] - self.t[0])

    @property
    def n_joints(self) -> int:
        return self.position.shape[1]

    @property
    def drive(self) -> DriveLimits:
        """The drive limits the trajectory was computed with (named by ``joint_names``)."""
        return DriveLimits(self.control_rate_hz, self.max_velocity, self.max_acceleration, self.max_jerk,
                           self.joint_names)

    @property
    def joints(self) -> JointLimits:
        """The joints' names, kinds and position limits the trajectory was computed with."""
        return JointLimits(self.joint_names, self.joint_kinds, self.lower, self.upper, self.periodic)


@dataclass(frozen=True)
class LimitViolation:
    """One failed check of :func:`check_trajectory`.

    Attributes
    ----------
    check : str
        ``"velocity"``, ``"acceleration"``, ``"jerk"``, ``"position"``, ``"group"``,
        ``"straight"``, ``"rest"``, ``"waypoint"`` or ``"sampling"``.
    joint : str or None
        Joint name, if the violation concerns one joint.
    segment : int or None
        Segment index, if the violation concerns one segment.
    time_s : float or None
        Time of the worst sample [s].
    value, limit : float
        Offending value and the limit it breaks, in ``unit``.
    unit : str
    message : str
        Human-readable description with units.
    """

    check: str
    joint: str | None
    segment: int | None
    time_s: float | None
    value: float
    limit: float
    unit: str
    message: str

    def __str__(self) -> str:
        return self.message


# ---------------------------------------------------------------------------------- parameterize
def time_parameterize(waypoints, motions: Sequence[str], joints: JointLimits, drive: DriveLimits) -> Trajectory:
    """Jerk-limited rest-to-rest trajectory through an ordered path, sampled at the control rate.

    Periodic rotations are first unwrapped along the path (``numpy.unwrap``) so that each segment
    turns the short way, as OMPL's SO2 state space interpolates. Each segment is then one ruckig
    calculation from rest to rest of its path parameter (:func:`_path_profile`; the joints stay on
    the straight joint-space segment by construction) with a duration rounded up to a whole number
    of control periods.

    Parameters
    ----------
    waypoints : array-like, shape (K, n_joints)
        Ordered path [rad or m], K >= 1.
    motions : sequence of str, length K
        ``motions[0] == "start"``; ``motions[k]`` (k >= 1) is ``"rotation"`` or
        ``"translation"``: the joint group that moves from waypoint k-1 to waypoint k.
    joints : JointLimits
        Names (used in messages), kinds and position limits of the n_joints joints
        (:meth:`~ctrplan.drive.JointLimits.of_robot`). The position limits are kept for
        :func:`check_trajectory` (ruckig ignores position limits offline). Periodic rotations
        (without limits) are the only ones unwrapped; bounded rotations are interpolated linearly
        between their waypoint values, as in a bounded real-vector space (a planner that models
        them as SO2, which may cross +-pi, would validate a different segment).
    drive : DriveLimits
        Control rate [Hz] and velocity, acceleration and jerk limits, > 0 [rad/s or m/s, per s^2,
        per s^3]; limits that name their joints are arranged in the joints' order.

    Returns
    -------
    Trajectory
        Starts and ends at rest; stops at rest at every waypoint.

    Raises
    ------
    ValueError
        Bad shapes, unknown motion, non-finite waypoint, a non-positive or non-finite limit
        (naming the joint), drive limits without a joint, or a segment that moves a joint outside
        its group by more than ``GROUP_SNAP_TOL``.
    ruckig.RuckigError
        If ruckig fails on a segment (re-raised with the segment and its waypoints).
    """
    q = np.array(waypoints, dtype=float)
    if q.ndim != 2 or q.shape[0] < 1:
        raise ValueError(f"waypoints must have shape (K, n_joints) with K >= 1, got {q.shape}")
    n_wp, n = q.shape
    kinds, names = joints.kinds, joints.names
    if joints.n_joints != n:
        raise ValueError(f"the joints need {n} entries (one per waypoint column), got {joints.n_joints}")
    motions = list(motions)
    if len(motions) != n_wp:
        raise ValueError(f"motions needs one entry per waypoint ({n_wp}), got {len(motions)}")
    if motions[0] != START:
        raise ValueError(f"motions[0] must be 'start', got {motions[0]!r}")
    for k, m in enumerate(motions[1:], start=1):
        if m not in _UNITS:
            raise ValueError(f"motions[{k}] must be 'rotation' or 'translation', got {m!r}")
    if not np.all(np.isfinite(q)):
        k, i = np.argwhere(~np.isfinite(q))[0]
        raise ValueError(f"waypoint {k}: joint {names[i]} = {float(q[k, i])!r} is not finite")
    drive = drive.in_order(names)
    vmax = _positive_limits(drive.max_velocity, n, names, kinds, "max_velocity", "/s")
    amax = _positive_limits(drive.max_acceleration, n, names, kinds, "max_acceleration", "/s^2")
    jmax = _positive_limits(drive.max_jerk, n, names, kinds, "max_jerk", "/s^3")
    rate = float(drive.control_rate_hz)
    if not np.isfinite(rate) or rate <= 0.0:
        raise ValueError(f"control_rate_hz must be > 0 Hz, got {drive.control_rate_hz!r}")
    lo, hi, per = joints.lower, joints.upper, joints.periodic

    if np.any(per):
        q[:, per] = np.unwrap(q[:, per], axis=0)
    _snap_groups(q, motions, kinds, names)

    dt = 1.0 / rate
    t_chunks = [np.zeros(1)]
    p_chunks, v_chunks, a_chunks = [q[:1].copy()], [np.zeros((1, n))], [np.zeros((1, n))]
    segments = []
    i0 = 0
    for k in range(n_wp - 1):
        q0, q1 = q[k], q[k + 1]
        try:
            s, sd, sdd, (s_lo, s_hi) = _path_profile(q1 - q0, vmax, amax, jmax, dt)
        except ruckig.RuckigError as exc:
            moved = ", ".join(f"{names[i]} {q0[i]:.6g} -> {q1[i]:.6g} {_UNITS[kinds[i]]}"
                              for i in range(n) if q0[i] != q1[i])
            raise ruckig.RuckigError(
                f"ruckig failed on segment {k} ({motions[k + 1]}: {moved or 'no motion'}): {exc}") from exc
        n_steps = len(s)
        d = q1 - q0
        # Samples strictly inside the segment lie on the straight segment by construction; both
        # ends are set exactly (at rest).
        p = q0 + s[:, None] * d
        v = sd[:, None] * d
        a = sdd[:, None] * d
        if n_steps > 0:
            p[-1] = q1
            v[-1] = 0.0
            a[-1] = 0.0
        ends = np.stack([q0 + s_lo * d, q0 + s_hi * d])
        segments.append(TrajectorySegment(
            index=k, motion=motions[k + 1], t_start=i0 * dt, t_end=(i0 + n_steps) * dt,
            i_start=i0, i_end=i0 + n_steps, q_start=q0.copy(), q_end=q1.copy(),
            position_min=np.minimum(ends.min(axis=0), np.minimum(q0, q1)),
            position_max=np.maximum(ends.max(axis=0), np.maximum(q0, q1))))
        t_chunks.append((i0 + np.arange(1, n_steps + 1)) * dt)
        p_chunks.append(p)
        v_chunks.append(v)
        a_chunks.append(a)
        i0 += n_steps

    return Trajectory(
        t=np.concatenate(t_chunks), position=np.concatenate(p_chunks),
        velocity=np.concatenate(v_chunks), acceleration=np.concatenate(a_chunks),
        segments=tuple(segments), waypoints=q, joint_names=names, joint_kinds=kinds,
        control_rate_hz=rate, max_velocity=vmax, max_acceleration=amax, max_jerk=jmax,
        lower=lo, upper=hi, periodic=per)


def time_parameterize_robot(robot, waypoints, motions: Sequence[str], drive: DriveLimits) -> Trajectory:
    """:func:`time_parameterize` with the joints' kinds, names and limits taken from a robot.

    Parameters
    ----------
    robot : ctrplan.robot.Robot
    waypoints : array-like, shape (K, n_joints)
        Ordered path in the order of ``robot.joints`` [rad or m].
    motions : sequence of str, length K
        As in :func:`time_parameterize`.
    drive : DriveLimits
        The drive's limits (e.g. a scenario file's ``[drive]``, ``Scenario.drive``, or
        :meth:`~ctrplan.drive.DriveLimits.by_joint` of ``{joint name: value}`` tables).

    Returns
    -------
    Trajectory

    Raises
    ------
    ValueError
        If the limits name joints and lack one of the robot's (naming it), or as
        :func:`time_parameterize`.
    """
    return time_parameterize(waypoints, motions, JointLimits.of_robot(robot), drive)


# ---------------------------------------------------------------------------------- checks
def check_trajectory(traj: Trajectory, drive: DriveLimits | None = None, joints: JointLimits | None = None, *,
                     strict: bool = False, limit_rtol: float = LIMIT_RTOL, jerk_rtol: float = JERK_RTOL,
                     abs_tol: float = ABS_TOL) -> list[LimitViolation]:
    """Check a sampled trajectory against drive and joint limits.

    Checks, per joint: sampled velocity and acceleration within the limits (relative tolerance
    ``limit_rtol``); jerk from finite differences of the sampled acceleration within the limit
    (loose tolerance ``jerk_rtol``); positions of non-periodic joints within their limits, on the
    samples and on ruckig's position extrema of each segment. Per segment: only the segment's joint
    group moves, the moving group stays on the straight segment, the end waypoint is reached, and
    the drive is at rest at both ends. Samples must be spaced by one control period.

    Parameters
    ----------
    traj : Trajectory
    drive : DriveLimits, optional
        Velocity, acceleration and jerk limits [unit/s, unit/s^2, unit/s^3]; default: those
        ``traj`` was computed with (``traj.drive``). Its control rate is not used: the samples
        are checked against ``traj.control_rate_hz``.
    joints : JointLimits, optional
        Position limits [rad or m] and periodic joints; default ``traj.joints``. Names and kinds
        are ``traj``'s.
    strict : bool
        Raise instead of returning violations.
    limit_rtol, jerk_rtol : float
        Relative tolerances on the velocity/acceleration and on the jerk limits [-].
    abs_tol : float
        Absolute tolerance on rest, position limits and non-moving joints [rad or m (per s^k)].

    Returns
    -------
    list of LimitViolation
        Empty when every check passes.

    Raises
    ------
    JointLimitError
        If ``strict`` and a check fails; the message lists every violation.
    """
    n = traj.n_joints
    names, kinds = traj.joint_names, traj.joint_kinds
    drive = traj.drive if drive is None else drive.in_order(names)
    joints = traj.joints if joints is None else joints
    vmax = _vector(drive.max_velocity, n, "max_velocity")
    amax = _vector(drive.max_acceleration, n, "max_acceleration")
    jmax = _vector(drive.max_jerk, n, "max_jerk")
    lo, hi = _vector(joints.lower, n, "lower"), _vector(joints.upper, n, "upper")
    per = np.asarray(joints.periodic, dtype=bool).reshape(n)
    units = [_UNITS[k] for k in kinds]
    t, p, v, a = traj.t, traj.position, traj.velocity, traj.acceleration
    out: list[LimitViolation] = []

    def add(check, i, seg, k, value, limit, unit, text):
        joint = None if i is None else names[i]
        time_s = None if k is None else float(t[k])
        out.append(LimitViolation(check, joint, seg, time_s, float(value), float(limit), unit, text))

    # Sampling at the control rate.
    dt = np.diff(t)
    period = 1.0 / traj.control_rate_hz
    if dt.size and np.max(np.abs(dt - period)) > 1e-9 * period:
        k = int(np.argmax(np.abs(dt - period)))
        add("sampling", None, None, k, dt[k], period, "s",
            f"sample spacing {dt[k]:.6g} s at t = {t[k]:.6g} s differs from the control period "
            f"{period:.6g} s")

    # Velocity, acceleration, jerk: worst sample per joint.
    jerk = np.diff(a, axis=0) / dt[:, None] if dt.size and np.all(dt > 0) else np.zeros((0, n))
    for check, values, limits, rtol, suffix in (("velocity", v, vmax, limit_rtol, "/s"),
                                                ("acceleration", a, amax, limit_rtol, "/s^2"),
                                                ("jerk", jerk, jmax, jerk_rtol, "/s^3")):
        if values.shape[0] == 0:
            continue
        for i in range(n):
            k = int(np.argmax(np.abs(values[:, i])))
            worst = abs(values[k, i])
            if worst > limits[i] * (1.0 + rtol) + abs_tol:
                add(check, i, None, k, worst, limits[i], units[i] + suffix,
                    f"{names[i]}: |{check}| {worst:.6g} {units[i]}{suffix} at t = {t[k]:.6g} s exceeds "
                    f"the limit {limits[i]:.6g} {units[i]}{suffix}")

    # Joint limits of non-periodic joints: samples and ruckig's extrema of each segment.
    for i in np.flatnonzero(~per):
        seg_min = [s.position_min[i] for s in traj.segments]
        seg_max = [s.position_max[i] for s in traj.segments]
        low = min([float(np.min(p[:, i]))] + seg_min)
        high = max([float(np.max(p[:, i]))] + seg_max)
        if low < lo[i] - abs_tol:
            add("position", i, None, int(np.argmin(p[:, i])), low, lo[i], units[i],
                f"{names[i]} reaches {low:.6g} {units[i]}, below its lower limit {lo[i]:.6g} {units[i]}")
        if high > hi[i] + abs_tol:
            add("position", i, None, int(np.argmax(p[:, i])), high, hi[i], units[i],
                f"{names[i]} reaches {high:.6g} {units[i]}, above its upper limit {hi[i]:.6g} {units[i]}")

    # Per segment: one joint group, straight, waypoint reached, at rest at both ends.
    kinds_arr = np.array(kinds)
    for seg in traj.segments:
        sl = slice(seg.i_start, seg.i_end + 1)
        moving = kinds_arr == seg.motion
        for i in np.flatnonzero(~moving):
            drift = max(float(np.max(np.abs(p[sl, i] - seg.q_start[i]))),
                        seg.position_max[i] - seg.q_start[i], seg.q_start[i] - seg.position_min[i])
            if drift > abs_tol:
                add("group", i, seg.index, None, drift, abs_tol, units[i],
                    f"segment {seg.index} ({seg.motion}) moves {kinds[i]} joint {names[i]} by "
                    f"{drift:.6g} {units[i]}")
        d = seg.q_end[moving] - seg.q_start[moving]
        length = float(np.linalg.norm(d))
        if length > 0.0:
            rel = p[sl][:, moving] - seg.q_start[moving]
            s = rel @ d / length**2
            dev = float(np.max(np.linalg.norm(rel - s[:, None] * d, axis=1)))
            unit = _UNITS[seg.motion]
            if dev > STRAIGHT_RTOL * length + abs_tol:
                add("straight", None, seg.index, None, dev, STRAIGHT_RTOL * length, unit,
                    f"segment {seg.index} ({seg.motion}) leaves its straight joint-space segment by "
                    f"{dev:.6g} {unit}")
        miss = np.abs(p[seg.i_end] - seg.q_end)
        if np.max(miss) > abs_tol:
            i = int(np.argmax(miss))
            add("waypoint", i, seg.index, seg.i_end, miss[i], abs_tol, units[i],
                f"segment {seg.index} ends {miss[i]:.6g} {units[i]} away from waypoint {seg.index + 1} "
                f"in {names[i]}")
    rest_idx = sorted({0, len(t) - 1} | {s.i_start for s in traj.segments} | {s.i_end for s in traj.segments})
    for k in rest_idx:
        for label, values, suffix in (("velocity", v, "/s"), ("acceleration", a, "/s^2")):
            i = int(np.argmax(np.abs(values[k])))
            if abs(values[k, i]) > abs_tol:
                add("rest", i, None, k, abs(values[k, i]), abs_tol, units[i] + suffix,
                    f"not at rest at t = {t[k]:.6g} s: {names[i]} {label} {values[k, i]:.6g} "
                    f"{units[i]}{suffix}")

    if strict and out:
        raise JointLimitError("trajectory violates its limits:\n" + "\n".join(f"- {x}" for x in out))
    return out


# ---------------------------------------------------------------------------------- helpers
def _path_profile(d: np.ndarray, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray, dt: float):
    """Rest-to-rest, jerk-limited, time-optimal motion along the straight segment ``q0 + s d``,
    ``s`` from 0 to 1, sampled every ``dt``.

    One ruckig calculation of the path parameter ``s`` alone, with each limit the tightest of the
    moving joints' limits divided by their share ``|d_i|`` (a joint's velocity is ``s' d_i``, and
    likewise its acceleration and jerk): the motion is the time-optimal straight one, and it stays
    on the segment by construction. (A calculation of all joints with Phase synchronization gives
    the same motion when ruckig finds it, but on short multi-joint segments it falls back to Time
    synchronization and leaves the segment.) The duration is rounded up to whole control periods.

    Parameters
    ----------
    d : ndarray, shape (n_joints,)
        ``q1 - q0`` [rad or m].
    vmax, amax, jmax : ndarray, shape (n_joints,)
        Drive limits [unit/s, unit/s^2, unit/s^3].
    dt : float
        Control period [s].

    Returns
    -------
    s, s_dot, s_ddot : ndarray, shape (n_steps,)
        The path parameter [-] and its first two time derivatives [1/s, 1/s^2] at ``t = j dt``,
        ``j = 1 .. n_steps``; ``s[-1] == 1``. Empty without motion.
    (s_min, s_max) : tuple of float
        Extrema of ``s`` over the continuous motion [-].

    Raises
    ------
    ruckig.RuckigError
        If ruckig fails.
    RuntimeError
        If ruckig's discrete duration is not a whole number of control periods.
    """
    moving = d != 0.0
    if not np.any(moving):
        return np.zeros(0), np.zeros(0), np.zeros(0), (0.0, 0.0)
    share = np.abs(d[moving])
    otg = ruckig.Ruckig(1, dt)
    inp = ruckig.InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [1.0], [0.0], [0.0]
    inp.max_velocity = [float(np.min(vmax[moving] / share))]
    inp.max_acceleration = [float(np.min(amax[moving] / share))]
    inp.max_jerk = [float(np.min(jmax[moving] / share))]
    inp.duration_discretization = ruckig.DurationDiscretization.Discrete
    out = ruckig.Trajectory(1)
    otg.calculate(inp, out)
    n_steps = int(round(out.duration / dt))
    if abs(n_steps - out.duration / dt) > 1e-6:  # discrete durations are whole periods
        raise RuntimeError(f"ruckig duration {out.duration!r} s is not a multiple of the control period {dt!r} s")
    s, sd, sdd = np.empty(n_steps), np.empty(n_steps), np.empty(n_steps)
    for j in range(n_steps - 1):
        (s[j],), (sd[j],), (sdd[j],) = out.at_time((j + 1) * dt)
    if n_steps:
        s[-1], sd[-1], sdd[-1] = 1.0, 0.0, 0.0
    ext = out.position_extrema[0]
    return s, sd, sdd, (float(ext.min), float(ext.max))


def _vector(values, n: int, label: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"{label} needs shape ({n},), got {np.shape(values)}")
    return arr


def _positive_limits(values, n, names, kinds, label, suffix) -> np.ndarray:
    arr = _vector(values, n, label)
    for i, x in enumerate(arr):
        if not np.isfinite(x) or x <= 0.0:
            raise ValueError(f"joint {names[i]}: {label} must be finite and > 0 {_UNITS[kinds[i]]}{suffix}, "
                             f"got {float(x)!r}")
    return arr


def _snap_groups(q: np.ndarray, motions: Sequence[str], kinds: Sequence[str], names: Sequence[str]) -> None:
    """In place: joints outside each segment's moving group keep the previous waypoint's value
    exactly; raise if one of them changes by more than ``GROUP_SNAP_TOL``."""
    kinds_arr = np.array(kinds)
    for k in range(1, q.shape[0]):
        still = kinds_arr != motions[k]
        step = np.abs(q[k, still] - q[k - 1, still])
        if step.size and np.max(step) > GROUP_SNAP_TOL:
            i = int(np.flatnonzero(still)[np.argmax(step)])
            raise ValueError(
                f"waypoint {k} is reached by a {motions[k]} phase but joint {names[i]} changes by "
                f"{q[k, i] - q[k - 1, i]:.6g} {_UNITS[kinds[i]]}")
        q[k, still] = q[k - 1, still]
