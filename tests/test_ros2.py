"""ROS 2 bags in and out (:mod:`ctrplan.io.ros2`).

Bags are written by ``rosbags`` itself (``tests/ctrplan_reference/bags.py``), in both storages, from an analytic
motion (``tests/ctrplan_reference``), so the expected joint values at any stamp are known exactly.
Reading: the joints at the pose stamps (the time-offset effect's interpolant), pauses, dropped
poses, ``/tf`` child frames, empty stamps, and each malformed bag as a clear error that names the
bag, the topic and what was found, with nothing written. Writing: the exported trajectory read
back equals ``trajectory.csv``; path, spheres and the ``ros2 topic pub`` YAML agree with
``path.csv``.
"""

from __future__ import annotations

import csv
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ctrplan_reference.bags import (ORIGIN_NS, T, joint_state, measured_run, pose_stamped, quaternions_with_z_axis,
                                    transform_stamped, write_bag)
from ctrplan import cli
from ctrplan.errors import DataFileError
from ctrplan.history import MotionRecord, joints_at
from ctrplan.io.robot_file import load_robot
from ctrplan.io.ros2 import (BagSelection, bag_topics, read_bag_measurements, read_joint_trajectory,
                             trajectory_yaml, write_plan_bag, PlanBagContent)
from ctrplan_reference.synth_reference import reference_motion
from test_pipeline import _scenario, cached_map  # noqa: F401 (fixture)

ROOT = Path(__file__).resolve().parents[1]
NOMINAL = ROOT / "model" / "ha2019-table2-nominal.toml"
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"


@pytest.fixture(scope="module")
def robot():
    return load_robot(NOMINAL)


@pytest.fixture(scope="module")
def motion(robot):
    return reference_motion(robot, samples=300, rate_hz=10.0, seed=11)


def _tips(k, seed=0):
    rng = np.random.default_rng(seed)
    tips = 0.1 * rng.uniform(-1, 1, (k, 3))
    tangents = rng.normal(size=(k, 3))
    return tips, tangents / np.linalg.norm(tangents, axis=1, keepdims=True)


def _names(robot):
    return [f"drive_{j}" for j in robot.joint_names]


def _selection(robot, **kw):
    return BagSelection(joint_names=tuple(zip(_names(robot), robot.joint_names)), **kw)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_joints_are_read_at_the_pose_stamps_and_tubes_without_a_joint_keep_home(tmp_path, robot, motion, storage):
    """Joint states at 50 Hz and poses at 10 Hz on one clock, never at the same instant: each
    pose's joints equal the analytic motion at its stamp within the interpolation error of a
    50 Hz record of a minimum-jerk move (< 2e-4 rad, < 2e-6 m), tips and tangents are the
    poses', tube 1 (no joint) keeps its home and tube 2 follows its link. Catches joints taken
    from the nearest sample or from the record time, a tangent from the wrong axis or a
    quaternion in the wrong order, and joint names matched by position instead of by name."""
    t = motion.times[:-20]     # the analytic motion stops at its end: the joint stream ends before
    tips, tangents = _tips(t.size)
    # the drive publishes its joints in another order than the robot file's
    bag = measured_run(tmp_path / "run", lambda x: motion(x)[:, ::-1], t, tips, tangents, names=_names(robot)[::-1],
                       storage=storage)
    read = read_bag_measurements(bag, robot, _selection(robot))
    table, s = read.table, read.summary
    assert len(table) == t.size and s["poses_used"] == t.size and s["motions"] == 1
    np.testing.assert_allclose(table["time"], t - t[0], atol=1e-9)
    alpha, beta = np.array([robot.configuration(q, check_limits=False) for q in motion(t)]).transpose(1, 0, 2)
    got_a = table[[f"alpha_{i}" for i in (1, 2, 3)]].to_numpy()
    got_b = table[[f"beta_{i}" for i in (1, 2, 3)]].to_numpy()
    assert np.abs(got_a - alpha).max() < 2e-4 and np.abs(got_b - beta).max() < 2e-6
    np.testing.assert_array_equal(got_a[:, 0], 0.0)
    np.testing.assert_allclose(got_b[:, 1], got_b[:, 0] - 0.017, atol=1e-15)
    np.testing.assert_allclose(table[["tip_x", "tip_y", "tip_z"]], tips, atol=1e-15)
    np.testing.assert_allclose(table[["tangent_x", "tangent_y", "tangent_z"]], tangents, atol=1e-12)
    assert s["ignored_joint_names"] == ["gripper"] and s["joint_rate_hz"] == pytest.approx(50.0, rel=1e-6)
    assert s["pose_rate_hz"] == pytest.approx(10.0, rel=1e-6) and s["pose_frame"] == "tracker"
    assert s["storage"] == storage


def test_the_interpolant_is_the_time_offset_effects(tmp_path, robot, motion):
    """Poses stamped 37 ms after each joint state: the joints read from the bag equal
    :func:`ctrplan.history.joints_at` on the joint stream at those times to 1e-12, so a lag
    fitted on bag data and a lag applied by the effect read the motion alike."""
    tj = np.arange(0.0, 20.0, 0.02)
    q = motion(tj)
    names = _names(robot)
    joints = [(ORIGIN_NS + int(round(x * 1e9)), joint_state(ORIGIN_NS + int(round(x * 1e9)), names, v))
              for x, v in zip(tj, q)]
    tp = tj[:-2] + 0.037
    tips, tangents = _tips(tp.size)
    quats = quaternions_with_z_axis(tangents)
    poses = [(ORIGIN_NS + int(round(x * 1e9)), pose_stamped(ORIGIN_NS + int(round(x * 1e9)), p, qq))
             for x, p, qq in zip(tp, tips, quats)]
    bag = write_bag(tmp_path / "b", {"/js": ("sensor_msgs/msg/JointState", joints),
                                     "/tip": ("geometry_msgs/msg/PoseStamped", poses)})
    table = read_bag_measurements(bag, robot, _selection(robot)).table
    ab = np.array([robot.configuration(v, check_limits=False) for v in q])
    record = MotionRecord(ab[:, 0], ab[:, 1], tj - tp[0])
    alpha, beta = joints_at(record, record.time + 0.037)
    np.testing.assert_allclose(table[[f"alpha_{i}" for i in (1, 2, 3)]], alpha[:-2], atol=1e-12)
    np.testing.assert_allclose(table[[f"beta_{i}" for i in (1, 2, 3)]], beta[:-2], atol=1e-12)


def test_a_pause_starts_a_new_motion_and_poses_outside_the_joint_stream_are_counted(tmp_path, robot, motion):
    """A 1.5 s pause of the joint stream (75 periods) starts a second motion; the poses in the
    pause, before the first joint state and after the last are dropped and each kind counted as
    the test counts them from the stamps; with a pause threshold above the pause, one motion."""
    t = motion.times[:200]
    tips, tangents = _tips(t.size)
    bag = measured_run(tmp_path / "run", motion, t, tips, tangents, names=_names(robot), pauses=[(8.0, 9.5)],
                       margins=(1.0, -0.55))
    # the joint stamps as measured_run makes them
    tj = np.arange(t[0] + 1.0, t[-1] - 0.55, 0.02) + 0.0037
    tj = tj[(tj < 8.0) | (tj > 9.5)]
    before, after = int(np.sum(t < tj[0])), int(np.sum(t > tj[-1]))
    in_pause = int(np.sum((t > tj[tj < 8.0][-1]) & (t < tj[tj > 9.5][0])))
    assert before == 11 and after == 6 and in_pause == 16
    read = read_bag_measurements(bag, robot, _selection(robot))
    s = read.summary
    assert s["motions"] == 2 and s["pauses"] == 1
    assert s["poses_dropped"] == {"before_joint_stream": before, "after_joint_stream": after, "in_pauses": in_pause}
    assert s["poses_used"] == len(read.table) == t.size - before - after - in_pause
    assert sorted(set(read.table["sequence"])) == [0, 1]
    one = read_bag_measurements(bag, robot, _selection(robot, max_gap_periods=100.0)).summary
    assert one["motions"] == 1 and one["poses_used"] == t.size - before - after


def test_tf_topic_with_several_child_frames_needs_a_choice(tmp_path, robot, motion):
    """``/tf`` with the tip and a reference sensor: without ``child_frame`` an error lists both
    frames; with it, the tip's transforms are read and the other's ignored."""
    tj = np.arange(0.0, 6.0, 0.02)
    names = _names(robot)
    joints = [(ORIGIN_NS + int(x * 1e9), joint_state(ORIGIN_NS + int(x * 1e9), names, v)) for x, v in zip(tj, motion(tj))]
    tp = np.arange(0.5, 5.5, 0.1)
    tips, tangents = _tips(tp.size)
    quats = quaternions_with_z_axis(tangents)
    tfs = []
    for x, p, qq in zip(tp, tips, quats):
        ns = ORIGIN_NS + int(round(x * 1e9))
        msg = T["tf2_msgs/msg/TFMessage"](transforms=[transform_stamped(ns, p, qq, "em_tip"),
                                                      transform_stamped(ns, p + 1.0, qq, "em_reference")])
        tfs.append((ns, msg))
    bag = write_bag(tmp_path / "tf", {"/joint_states": ("sensor_msgs/msg/JointState", joints),
                                      "/tf": ("tf2_msgs/msg/TFMessage", tfs)})
    with pytest.raises(DataFileError, match=r"tf.*several child frames \(em_reference, em_tip\).*--child-frame"):
        read_bag_measurements(bag, robot, _selection(robot))
    read = read_bag_measurements(bag, robot, _selection(robot, child_frame="em_tip"))
    np.testing.assert_allclose(read.table[["tip_x", "tip_y", "tip_z"]], tips, atol=1e-15)
    assert read.summary["child_frame"] == "em_tip" and read.summary["pose_type"] == "tf2_msgs/msg/TFMessage"
    with pytest.raises(DataFileError, match="no transform with child frame 'em_probe'.*em_reference, em_tip"):
        read_bag_measurements(bag, robot, _selection(robot, child_frame="em_probe"))


def test_empty_header_stamps_use_the_record_time_with_a_caution(tmp_path, robot, motion):
    """Poses whose header stamp is empty are placed at their record time, and the summary says
    how many and why that is worse."""
    tj = np.arange(0.0, 6.0, 0.02)
    names = _names(robot)
    joints = [(ORIGIN_NS + int(x * 1e9), joint_state(ORIGIN_NS + int(x * 1e9), names, v)) for x, v in zip(tj, motion(tj))]
    tp = np.arange(0.5, 5.5, 0.1)
    tips, tangents = _tips(tp.size)
    poses = [(ORIGIN_NS + int(round(x * 1e9)), pose_stamped(0, p, qq))
             for x, p, qq in zip(tp, tips, quaternions_with_z_axis(tangents))]
    bag = write_bag(tmp_path / "b", {"/joint_states": ("sensor_msgs/msg/JointState", joints),
                                     "/tip": ("geometry_msgs/msg/PoseStamped", poses)})
    read = read_bag_measurements(bag, robot, _selection(robot))
    np.testing.assert_allclose(read.table["time"], tp - tp[0], atol=1e-9)
    assert any(f"{tp.size} pose(s) of '/tip' had an empty header stamp" in c for c in read.summary["cautions"])


def _bad_bag(tmp_path, kind, robot, motion):
    tj = np.arange(0.0, 4.0, 0.02)
    names = _names(robot)
    q = motion(tj)
    recorded = [ORIGIN_NS + int(round(x * 1e9)) + 2_000_000 for x in tj]
    stamps = [ORIGIN_NS + int(round(x * 1e9)) for x in tj]
    if kind == "unsorted":
        stamps[50], stamps[51] = stamps[51], stamps[50]
    if kind == "duplicate":
        stamps[51] = stamps[50]
    if kind == "nan":
        q[60, 1] = np.nan
    if kind == "unknown_names":
        names = ["joint_a", "joint_b", "joint_c"]
    joints = [(r, joint_state(s, names, v)) for r, s, v in zip(recorded, stamps, q)]
    tp = np.arange(0.5, 3.5, 0.1)
    tips, tangents = _tips(tp.size)
    poses = [(ORIGIN_NS + int(round(x * 1e9)), pose_stamped(ORIGIN_NS + int(round(x * 1e9)), p, qq))
             for x, p, qq in zip(tp, tips, quaternions_with_z_axis(tangents))]
    if kind == "nan_pose":
        poses[3] = (poses[3][0], pose_stamped(poses[3][0], [np.nan, 0, 0], [0, 0, 0, 1]))
    streams = {"/joint_states": ("sensor_msgs/msg/JointState", joints),
               "/tip": ("geometry_msgs/msg/PoseStamped", poses)}
    if kind == "joints_only":
        del streams["/tip"]
    return write_bag(tmp_path / f"bag-{kind}", streams)


BAD = [
    ("joints_only", (), r"no tip pose topic .*topics present: /joint_states \(sensor_msgs/msg/JointState, 200\)"),
    ("unknown_names", (), r"topic '/joint_states', message 1: no joint 'drive_alpha_2'.*names \['joint_a', "
                          r"'joint_b', 'joint_c'\].*--joint-names"),
    ("unsorted", (), r"topic '/joint_states': unsorted header stamps: message 52 .*message 51"),
    ("duplicate", (), r"topic '/joint_states': duplicate header stamps: message 52"),
    ("nan", (), r"topic '/joint_states', message 61: joint 'drive_alpha_3' is nan"),
    ("nan_pose", (), r"topic '/tip', message 4: pose \[nan, "),
    ("wrong_type", ("--pose-topic", "/joint_states"), r"topic '/joint_states' has type sensor_msgs/msg/JointState; "
                                                      r"tip pose must be .*topics present: /joint_states"),
]


@pytest.mark.parametrize("kind,extra,message", BAD, ids=[b[0] for b in BAD])
def test_a_malformed_bag_is_a_clear_error_and_nothing_is_written(tmp_path, robot, motion, monkeypatch, capsys,
                                                                  kind, extra, message):
    """``ctrplan discrepancy`` on each malformed bag: exit code 2, one ``error:`` line naming the
    bag, the topic and what was found, and no output folder."""
    bag = _bad_bag(tmp_path, "ok" if kind == "wrong_type" else kind, robot, motion)
    out = tmp_path / "out"
    mapping = ",".join(f"{b}={r}" for b, r in zip(_names(robot), robot.joint_names))
    monkeypatch.setattr(sys, "argv", ["ctrplan", "discrepancy", "--robot", str(NOMINAL), "--data", str(bag),
                                      "--out", str(out), "--joint-names", mapping, *extra])
    with pytest.raises(SystemExit) as info:
        cli.run()
    err = capsys.readouterr().err
    assert info.value.code == 2 and err.startswith(f"error: {bag}: "), err
    assert re.search(message, err), err
    assert not out.exists()


def test_bag_options_on_a_csv_are_refused(tmp_path, monkeypatch, capsys):
    data = tmp_path / "d.csv"
    data.write_text("alpha_1,alpha_2,beta_1,beta_2,tip_x,tip_y,tip_z\n0,0,0,-0.017,0,0,0.1\n")
    monkeypatch.setattr(sys, "argv", ["ctrplan", "discrepancy", "--robot", str(PAIR), "--data", str(data),
                                      "--out", str(tmp_path / "o"), "--pose-topic", "/tip"])
    with pytest.raises(SystemExit) as info:
        cli.run()
    assert info.value.code == 2 and "read a ROS 2 bag" in capsys.readouterr().err


# --------------------------------------------------------------------------- writing
def _content(seed=0, k=5):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.001, 0.01, 300)) + 1e-10 * rng.uniform(size=300)
    t -= t[0]
    names = ["alpha_2", "alpha_3", "beta_3"]
    pos, vel, acc = (rng.normal(size=(t.size, 3)) for _ in range(3))
    tips, tangents = _tips(k, seed)
    rots = Rotation.from_quat(quaternions_with_z_axis(tangents)).as_matrix()
    radius = rng.uniform(1e-3, 5e-3, k)
    radius[2] = np.nan
    return PlanBagContent(joint_names=names, t=t, position=pos, velocity=vel, acceleration=acc, tips=tips,
                          tip_rotations=rots, bound_radius=radius, frame_id="ctr_base")


@pytest.mark.parametrize("storage,distro", [("mcap", "jazzy"), ("sqlite3", "humble")])
def test_plan_bag_reads_back_exactly(tmp_path, storage, distro):
    """The trajectory read back (``rosbags``' reader) has the times within 1 ns and positions,
    velocities and accelerations bit for bit; the path's poses are the tips with orientations
    whose z axis is the tangent; one sphere per finite bound, diameter twice the bound."""
    from rosbags.highlevel import AnyReader

    c = _content()
    bag = write_plan_bag(tmp_path / "plan_bag", c, storage=storage, distro=distro, start_ns=ORIGIN_NS)
    names, t, pos, vel, acc = read_joint_trajectory(bag)
    assert names == list(c.joint_names)
    assert np.abs(t - c.t).max() <= 1e-9
    for a, b in ((pos, c.position), (vel, c.velocity), (acc, c.acceleration)):
        np.testing.assert_array_equal(a, b)
    with AnyReader([bag]) as reader:
        msgs = {conn.topic: reader.deserialize(raw, conn.msgtype)
                for conn, _, raw in reader.messages() if conn.topic != "/ctrplan/planned_joint_states"}
        n_states = sum(1 for conn, _, _ in reader.messages() if conn.topic == "/ctrplan/planned_joint_states")
    assert n_states == c.t.size
    path = msgs["/ctrplan/tip_path"]
    assert path.header.frame_id == "ctr_base" and len(path.poses) == 5
    for ps, tip, rot in zip(path.poses, c.tips, c.tip_rotations):
        p, o = ps.pose.position, ps.pose.orientation
        np.testing.assert_allclose([p.x, p.y, p.z], tip, atol=0)
        np.testing.assert_allclose(Rotation.from_quat([o.x, o.y, o.z, o.w]).as_matrix(), rot, atol=1e-12)
    spheres = msgs["/ctrplan/bound_markers"].markers
    assert [m.id for m in spheres] == [0, 1, 3, 4]
    for m in spheres:
        assert m.type == 2 and m.scale.x == m.scale.y == m.scale.z == pytest.approx(2 * c.bound_radius[m.id], rel=1e-15)
    assert bag_topics(bag)[1] == {"topic": "/ctrplan/joint_trajectory", "type": "trajectory_msgs/msg/JointTrajectory",
                                  "count": 1}


def test_plan_bag_replaces_its_own_bag_but_nothing_else(tmp_path):
    c = _content()
    bag = write_plan_bag(tmp_path / "b", c)
    write_plan_bag(bag, _content(seed=1))
    np.testing.assert_array_equal(read_joint_trajectory(bag)[2], _content(seed=1).position)
    other = tmp_path / "notes"
    other.mkdir()
    (other / "keep.txt").write_text("data")
    with pytest.raises(FileExistsError, match="not a plan bag written by ctrplan"):
        write_plan_bag(other, c)
    assert (other / "keep.txt").read_text() == "data"


def test_trajectory_yaml_is_the_message(tmp_path):
    """The YAML parses (as ``ros2 topic pub`` does) to the message's fields: names, positions
    bit for bit, time_from_start within 1 ns."""
    from ruamel.yaml import YAML

    c = _content()
    msg = YAML(typ="safe").load(trajectory_yaml(c.joint_names, c.t, c.position, c.velocity, c.acceleration))
    assert msg["joint_names"] == list(c.joint_names) and msg["header"]["stamp"] == {"sec": 0, "nanosec": 0}
    pts = msg["points"]
    np.testing.assert_array_equal([p["positions"] for p in pts], c.position)
    np.testing.assert_array_equal([p["accelerations"] for p in pts], c.acceleration)
    t = np.array([p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"] for p in pts])
    assert np.abs(t - c.t).max() <= 1e-9


def test_plan_with_ros2_writes_the_trajectory_csv_as_a_bag(tmp_path, monkeypatch, capsys, cached_map):
    """``ctrplan plan SCENARIO --ros2 OUT`` (synthetic bound field, a short move): the bag's
    trajectory equals ``trajectory.csv`` (times within 1 ns, values within 1e-12), its path the
    tips of ``path.csv``, its spheres twice the bound of ``path.csv`` (the calibrated one where
    the robot file has one); the YAML beside the outputs holds the same trajectory."""
    from ruamel.yaml import YAML

    import ctrplan.api
    import ctrplan.io.scenario

    sc = _scenario(tmp_path, "{alpha_2 = 0.6, alpha_3 = -0.4, beta_3 = -0.06}")
    out, bag = tmp_path / "plan", tmp_path / "plan_bag"
    monkeypatch.setattr(sys, "argv", ["ctrplan", "plan", str(sc), "--out", str(out), "--iterations", "20",
                                      "--no-blind", "--ros2", str(bag)])
    loads = []
    load = ctrplan.io.scenario.load_scenario

    def counted(*args, **kwargs):
        loads.append(args[0])
        return load(*args, **kwargs)

    monkeypatch.setattr(ctrplan.io.scenario, "load_scenario", counted)
    monkeypatch.setattr(ctrplan.api, "load_scenario", counted)
    with pytest.raises(SystemExit) as info:
        cli.run()
    assert info.value.code in (0, None), capsys.readouterr().err
    assert len(loads) == 1, loads          # the scenario is read once (checked for --ros2, then planned)
    with open(out / "trajectory.csv") as fh:
        rows = list(csv.reader(fh))
    header, values = rows[0], np.array(rows[1:], dtype=float)
    names, t, pos, vel, acc = read_joint_trajectory(bag)
    assert header[1::3] == names
    assert np.abs(t - values[:, 0]).max() <= 1e-9
    np.testing.assert_allclose(pos, values[:, 1::3], atol=1e-12, rtol=0)
    np.testing.assert_allclose(vel, values[:, 2::3], atol=1e-12, rtol=0)
    np.testing.assert_allclose(acc, values[:, 3::3], atol=1e-12, rtol=0)
    with open(out / "path.csv") as fh:
        path_rows = list(csv.DictReader(fh))
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        msgs = {conn.topic: reader.deserialize(raw, conn.msgtype) for conn, _, raw in reader.messages()
                if conn.topic in ("/ctrplan/tip_path", "/ctrplan/bound_markers")}
    tips = np.array([[float(r[k]) for k in ("tip_x", "tip_y", "tip_z")] for r in path_rows])
    got = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in msgs["/ctrplan/tip_path"].poses])
    np.testing.assert_allclose(got, tips, atol=1e-15)
    bound = np.array([float(r["calibrated_bound_m"] or r["bound_position_m"]) for r in path_rows])
    np.testing.assert_allclose([m.scale.x for m in msgs["/ctrplan/bound_markers"].markers], 2 * bound, rtol=1e-12)
    msg = YAML(typ="safe").load((out / "joint_trajectory.yaml").read_text())
    np.testing.assert_array_equal([p["positions"] for p in msg["points"]], pos)


def test_plan_ros2_refuses_a_folder_that_is_not_its_bag_before_planning(tmp_path, monkeypatch, capsys):
    target = tmp_path / "results"
    target.mkdir()
    (target / "notes.txt").write_text("keep")
    monkeypatch.setattr(sys, "argv", ["ctrplan", "plan", str(ROOT / "scenarios" / "task-target.toml"),
                                      "--out", str(tmp_path / "o"), "--ros2", str(target)])
    with pytest.raises(SystemExit) as info:
        cli.run()
    assert info.value.code == 2 and "not a plan bag written by ctrplan" in capsys.readouterr().err
    assert (target / "notes.txt").read_text() == "keep" and not (tmp_path / "o").exists()
