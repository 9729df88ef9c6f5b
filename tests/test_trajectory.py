"""Time-parameterization with ruckig (ctrplan.trajectory): invariants on the samples, checks."""

import dataclasses

import numpy as np
import pytest
import ruckig
from _robots import table2_robot

from ctrplan.drive import DriveLimits, JointLimits
from ctrplan.errors import JointLimitError
from ctrplan.trajectory import (
    check_trajectory,
    time_parameterize,
    time_parameterize_robot,
)

KINDS = ["rotation", "rotation", "translation"]
NAMES = ["alpha_2", "alpha_3", "beta_3"]
VMAX = np.array([1.0, 1.5, 0.01])  # rad/s, rad/s, m/s
AMAX = np.array([2.0, 3.0, 0.05])  # per s^2
JMAX = np.array([20.0, 30.0, 1.0])  # per s^3
RATE = 250.0  # Hz
LOWER = np.array([-np.pi, -np.pi, -0.104])
UPPER = np.array([np.pi, np.pi, -0.034])
PERIODIC = np.array([True, True, False])

# alpha_2 crosses +-pi in the first phase: the short way is +0.283 rad, not -6 rad.
WAYPOINTS = np.array([[3.0, -1.0, -0.090],
                      [-3.0, 0.5, -0.090],
                      [-3.0, 0.5, -0.050],
                      [-2.0, 0.2, -0.050]])
MOTIONS = ["start", "rotation", "translation", "rotation"]


def _param(waypoints=WAYPOINTS, motions=MOTIONS, **kw):
    args = dict(max_velocity=VMAX, max_acceleration=AMAX, max_jerk=JMAX, control_rate_hz=RATE,
                lower=LOWER, upper=UPPER, periodic=PERIODIC)
    args.update(kw)
    joints = JointLimits(tuple(NAMES), tuple(KINDS), args["lower"], args["upper"], args["periodic"])
    drive = DriveLimits(args["control_rate_hz"], args["max_velocity"], args["max_acceleration"], args["max_jerk"])
    return time_parameterize(waypoints, motions, joints, drive)


@pytest.fixture(scope="module")
def traj():
    return _param()


def test_starts_and_ends_at_rest_and_stops_at_every_waypoint(traj):
    assert len(traj.segments) == 3
    for k in [0, len(traj.t) - 1] + [s.i_end for s in traj.segments]:
        assert np.all(traj.velocity[k] == 0.0)
        assert np.all(traj.acceleration[k] == 0.0)


def test_samples_respect_velocity_acceleration_and_joint_limits(traj):
    assert np.all(np.abs(traj.velocity) <= VMAX * (1 + 1e-9))
    assert np.all(np.abs(traj.acceleration) <= AMAX * (1 + 1e-9))
    assert np.all(traj.position[:, 2] >= LOWER[2]) and np.all(traj.position[:, 2] <= UPPER[2])
    # The drive actually uses its limits (not a trivially slow trajectory).
    assert np.max(np.abs(traj.velocity[:, 0])) > 0.1 * VMAX[0]


def test_each_phase_moves_only_its_joint_group(traj):
    kinds = np.array(KINDS)
    for seg in traj.segments:
        sl = slice(seg.i_start, seg.i_end + 1)
        still = kinds != seg.motion
        assert np.all(traj.position[sl][:, still] == seg.q_start[still])
        assert np.all(traj.velocity[sl][:, still] == 0.0)
        assert np.any(traj.position[sl][:, ~still] != seg.q_start[~still])
    assert [s.motion for s in traj.segments] == MOTIONS[1:]


def test_waypoints_reached_exactly_and_angles_take_the_short_way(traj):
    for k, seg in enumerate(traj.segments):
        assert np.array_equal(traj.position[seg.i_start], traj.waypoints[k])
        assert np.array_equal(traj.position[seg.i_end], traj.waypoints[k + 1])
    # Unwrapped waypoints equal the given ones modulo 2 pi; translations are untouched.
    wrapped = (traj.waypoints[:, :2] - WAYPOINTS[:, :2] + np.pi) % (2 * np.pi) - np.pi
    assert np.allclose(wrapped, 0.0, atol=1e-12)
    assert np.array_equal(traj.waypoints[:, 2], WAYPOINTS[:, 2])
    assert traj.waypoints[1, 0] - traj.waypoints[0, 0] == pytest.approx(2 * np.pi - 6.0)


def test_samples_at_the_control_rate_with_the_last_sample_at_the_end(traj):
    assert traj.t[0] == 0.0
    assert np.allclose(np.diff(traj.t), 1.0 / RATE, rtol=0, atol=1e-12)
    assert traj.t[-1] == pytest.approx(traj.duration) and traj.duration > 0
    assert traj.segments[-1].t_end == traj.t[-1]
    for seg in traj.segments:
        assert traj.t[seg.i_start] == seg.t_start and traj.t[seg.i_end] == seg.t_end


def test_two_rotations_stay_on_the_straight_joint_space_segment(traj):
    seg = traj.segments[0]
    p = traj.position[seg.i_start:seg.i_end + 1, :2]
    d = seg.q_end[:2] - seg.q_start[:2]
    s = (p - seg.q_start[:2]) @ d / (d @ d)
    assert np.max(np.abs(p - (seg.q_start[:2] + s[:, None] * d))) < 1e-12
    assert np.all(np.diff(s) >= -1e-12)  # monotonic: no overshoot, no return


def test_check_trajectory_passes_a_good_trajectory(traj):
    assert check_trajectory(traj) == []
    assert check_trajectory(traj, strict=True) == []


@pytest.mark.parametrize("seed", range(10))
def test_random_paths_pass_every_check(seed):
    rng = np.random.default_rng(seed)
    n_wp = 5
    q = [np.array([rng.uniform(-np.pi, np.pi), rng.uniform(-np.pi, np.pi), rng.uniform(-0.1, -0.04)])]
    motions = ["start"]
    for k in range(1, n_wp):
        nxt = q[-1].copy()
        if k % 2:
            nxt[:2] = rng.uniform(-np.pi, np.pi, 2)
            motions.append("rotation")
        else:
            nxt[2] = rng.uniform(-0.1, -0.04)
            motions.append("translation")
        q.append(nxt)
    traj = _param(np.array(q), motions)
    assert check_trajectory(traj) == []
    # Periodic angles move at most pi per phase (the short way).
    assert np.all(np.abs(np.diff(traj.waypoints[:, :2], axis=0)) <= np.pi + 1e-12)


SIX_KINDS = ["rotation"] * 3 + ["translation"] * 3
SIX_VMAX = np.array([1.0, 1.0, 0.8, 0.01, 0.02, 0.01])
SIX_AMAX = np.array([4.0, 4.0, 3.0, 0.04, 0.04, 0.03])
SIX_JMAX = np.array([40.0, 30.0, 40.0, 0.4, 0.4, 0.5])


def _six_segment(q0, q1, motion):
    joints = JointLimits.unnamed(SIX_KINDS, [-9.0] * 3 + [-1.0] * 3, [9.0] * 3 + [1.0] * 3)
    return time_parameterize([q0, q1], ["start", motion], joints, DriveLimits(RATE, SIX_VMAX, SIX_AMAX, SIX_JMAX))


@pytest.mark.parametrize("seed", range(3))
def test_short_multi_joint_segments_stay_on_their_line_and_are_time_optimal(seed):
    """Segments of three joints whose shares span four decades (3e-6 m translations, 2e-4 rad
    rotations beside full ones): a calculation of all joints with Phase synchronization falls back
    to Time synchronization on some of them and leaves the line by up to 5e-4 rad. Every segment
    must stay on its line, and take no longer than ruckig's own Phase-synchronized motion where
    that one is straight (both are the time-optimal straight motion, to one control period)."""
    rng = np.random.default_rng(seed)
    compared = 0
    for trial in range(150):
        q0 = np.concatenate([rng.uniform(-1, 1, 3), rng.uniform(-0.05, 0.0, 3)])
        q1 = q0.copy()
        motion = ("rotation", "translation")[trial % 2]
        group = slice(0, 3) if motion == "rotation" else slice(3, 6)
        span = 3.0 if motion == "rotation" else 0.03
        q1[group] += rng.uniform(-span, span, 3) * rng.choice([1.0, 1e-2, 1e-4], 3)
        traj = _six_segment(q0, q1, motion)
        assert check_trajectory(traj) == [], (q0, q1)
        # reference: ruckig on all joints at once, Phase synchronization
        otg = ruckig.Ruckig(6, 1.0 / RATE)
        inp = ruckig.InputParameter(6)
        inp.current_position, inp.target_position = q0.tolist(), q1.tolist()
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = SIX_VMAX.tolist(), SIX_AMAX.tolist(), SIX_JMAX.tolist()
        inp.synchronization = ruckig.Synchronization.Phase
        inp.duration_discretization = ruckig.DurationDiscretization.Discrete
        out = ruckig.Trajectory(6)
        otg.calculate(inp, out)
        d = q1 - q0
        pts = np.array([out.at_time(t)[0] for t in np.linspace(0.0, out.duration, 50)]) - q0
        off_line = np.linalg.norm(pts - np.outer(pts @ d / (d @ d), d), axis=1).max()
        if off_line < 1e-9:
            compared += 1
            assert traj.duration <= out.duration + 1.0 / RATE + 1e-12
            assert traj.duration >= out.duration - 1.0 / RATE - 1e-12
    assert compared > 100


def test_check_trajectory_catches_an_injected_violation(traj):
    k = traj.segments[0].i_start + 10
    velocity = traj.velocity.copy()
    velocity[k, 1] = 2.0 * VMAX[1]
    bad = _replace(traj, velocity=velocity)
    found = check_trajectory(bad)
    assert [v.check for v in found] == ["velocity"]
    assert found[0].joint == "alpha_3" and found[0].time_s == pytest.approx(traj.t[k])
    assert "rad/s" in str(found[0])
    with pytest.raises(JointLimitError, match="alpha_3"):
        check_trajectory(bad, strict=True)


def test_check_trajectory_catches_motion_of_the_wrong_group(traj):
    seg = traj.segments[1]  # translation phase
    position = traj.position.copy()
    position[seg.i_start + 3, 0] += 1e-3
    found = check_trajectory(_replace(traj, position=position))
    assert "group" in {v.check for v in found}


def test_check_trajectory_catches_tighter_limits_and_joint_limits(traj):
    found = check_trajectory(traj, DriveLimits(RATE, VMAX / 2, AMAX, JMAX),
                             JointLimits(tuple(NAMES), tuple(KINDS), LOWER, [np.pi, np.pi, -0.06], PERIODIC))
    checks = {(v.check, v.joint) for v in found}
    assert ("velocity", "alpha_2") in checks
    assert ("position", "beta_3") in checks


def test_non_positive_limit_names_the_joint():
    with pytest.raises(ValueError, match="beta_3.*max_acceleration"):
        _param(max_acceleration=[2.0, 3.0, 0.0])
    with pytest.raises(ValueError, match="control_rate_hz"):
        _param(control_rate_hz=-1.0)


def test_segment_moving_both_groups_is_rejected():
    q = WAYPOINTS.copy()
    q[1, 2] += 1e-3  # translation changes during a rotation phase
    with pytest.raises(ValueError, match="waypoint 1.*beta_3"):
        _param(q)


def test_round_off_outside_the_group_is_snapped():
    q = WAYPOINTS.copy()
    q[2, 0] += 1e-14  # alpha_2 round-off during the translation phase
    traj = _param(q)
    assert traj.waypoints[2, 0] == traj.waypoints[1, 0]
    assert check_trajectory(traj) == []


def test_bad_motions_are_rejected():
    with pytest.raises(ValueError, match="motions\\[0\\]"):
        _param(motions=["rotation", "rotation", "translation", "rotation"])
    with pytest.raises(ValueError, match="one entry per waypoint"):
        _param(motions=MOTIONS[:-1])


def test_ruckig_failure_names_the_segment(monkeypatch):
    class Failing:
        def __init__(self, *args):
            pass

        def calculate(self, inp, out):
            raise ruckig.RuckigError("simulated")

    monkeypatch.setattr(ruckig, "Ruckig", Failing)
    with pytest.raises(ruckig.RuckigError, match="segment 0 \\(rotation: alpha_2"):
        _param()


def test_single_waypoint_gives_a_single_sample_at_rest():
    traj = _param(WAYPOINTS[:1], ["start"])
    assert traj.t.shape == (1,) and traj.duration == 0.0 and traj.segments == ()
    assert check_trajectory(traj) == []


def test_repeated_waypoint_gives_an_empty_segment():
    q = np.vstack([WAYPOINTS[:2], WAYPOINTS[1:2]])
    traj = _param(q, ["start", "rotation", "translation"])
    assert traj.segments[1].duration == 0.0
    assert check_trajectory(traj) == []


def test_from_robot_uses_joint_names_and_limits():
    robot = table2_robot()
    limits = {name: dict(zip(NAMES, values)) for name, values in
              (("max_velocity", VMAX), ("max_acceleration", AMAX), ("max_jerk", JMAX))}
    traj = time_parameterize_robot(robot, WAYPOINTS, MOTIONS, DriveLimits.by_joint(NAMES, control_rate_hz=RATE,
                                                                                   **limits))
    assert traj.joint_names == tuple(NAMES) and list(traj.periodic) == [True, True, False]
    assert check_trajectory(traj) == []
    # limits named in another order are arranged in the robot's
    shuffled = DriveLimits.by_joint(NAMES[::-1], control_rate_hz=RATE, **limits)
    again = time_parameterize_robot(robot, WAYPOINTS, MOTIONS, shuffled)
    np.testing.assert_array_equal(again.position, traj.position)
    np.testing.assert_array_equal(again.max_velocity, VMAX)
    del limits["max_jerk"]["beta_3"]
    with pytest.raises(ValueError, match="max_jerk.*beta_3"):
        DriveLimits.by_joint(NAMES, control_rate_hz=RATE, **limits)
    with pytest.raises(ValueError, match="no value for joint\\(s\\) beta_3"):
        time_parameterize_robot(robot, WAYPOINTS, MOTIONS, DriveLimits(RATE, VMAX[:2], AMAX[:2], JMAX[:2],
                                                                       ("alpha_2", "alpha_3")))


def _replace(traj, **changes):
    return dataclasses.replace(traj, **changes)
