"""Writing ROS 2 bags: a plan's drive trajectory, tip path and error bound (see :mod:`ctrplan.io.ros2`)."""

from __future__ import annotations

import json
import math
import os
import shutil
import time as _time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ...choices import BagStorage
from ...errors import DataFileError
from ._read import (DISTROS, JOINT_STATE, JOINT_TRAJECTORY, PLAN_TOPICS, _MARKER, _choose_topic, _open, _topics,
                    _typestore)

__all__ = ["PlanBagContent", "write_plan_bag", "check_plan_bag_target", "read_joint_trajectory", "trajectory_yaml"]

@dataclass(frozen=True, eq=False)
class PlanBagContent:
    """What :func:`write_plan_bag` writes (SI units).

    Attributes
    ----------
    joint_names : sequence of str
        Robot joint names, the columns of the trajectory arrays.
    t : ndarray, shape (T,)
        Trajectory sample times from its start [s].
    position, velocity, acceleration : ndarray, shape (T, J)
        [rad or m], [per s], [per s^2].
    tips : ndarray, shape (K, 3)
        Planned tip positions at the waypoints [m].
    tip_rotations : ndarray or None, shape (K, 3, 3)
        Tip frames (columns: x, y, z axes, z the tangent); None: identity orientations.
    bound_radius : ndarray, shape (K,)
        Tip error bound at the waypoints [m] (spheres of this radius; NaN: no sphere).
    bound_label : str
        What the bound is (written into each marker's namespace).
    frame_id : str
        Frame of the tips (the robot's base frame).
    """

    joint_names: Sequence[str]
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    tips: np.ndarray
    tip_rotations: np.ndarray | None
    bound_radius: np.ndarray
    bound_label: str = "bound"
    frame_id: str = "ctr_base"


def _duration(ts, seconds: float):
    ns = int(round(seconds * 1e9))
    return ts.types["builtin_interfaces/msg/Duration"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _time_msg(ts, ns: int):
    return ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _matrix_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method)."""
    tr = np.trace(r)
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def _check_content(c: PlanBagContent) -> None:
    t = np.asarray(c.t, float)
    j = len(c.joint_names)
    for name in ("position", "velocity", "acceleration"):
        a = np.asarray(getattr(c, name), float)
        if a.shape != (t.size, j):
            raise ValueError(f"{name} must have shape ({t.size}, {j}), got {a.shape}")
    if t.size < 1 or np.any(np.diff(t) <= 0) or t[0] < 0:
        raise ValueError("t must be >= 0 and increasing")
    if np.asarray(c.tips).shape != (len(c.bound_radius), 3):
        raise ValueError(f"tips must have shape ({len(c.bound_radius)}, 3), got {np.asarray(c.tips).shape}")


def write_plan_bag(out, content: PlanBagContent, *, storage: str = "mcap", distro: str = "jazzy",
                   start_ns: int | None = None) -> Path:
    """Write a plan as a rosbag2 folder that RViz, Foxglove or ``ros2 bag play`` can show.

    Topics (:data:`PLAN_TOPICS`): ``/ctrplan/joint_trajectory`` (one
    ``trajectory_msgs/msg/JointTrajectory``: header stamp 0, i.e. start on receipt; per sample
    ``positions``, ``velocities``, ``accelerations``, ``time_from_start``),
    ``/ctrplan/planned_joint_states`` (the samples as ``sensor_msgs/msg/JointState`` stamped
    ``start_ns + t``), ``/ctrplan/tip_path`` (``nav_msgs/msg/Path`` through the waypoint tips) and
    ``/ctrplan/bound_markers`` (``visualization_msgs/msg/MarkerArray``: a sphere of diameter twice
    the bound at each waypoint tip).

    Parameters
    ----------
    out : str or path-like
        Bag folder to create. An existing folder is replaced only if it is a bag written here
        (its metadata says so); anything else there is an error, so no data is lost.
    content : PlanBagContent
    storage : BagStorage or str
        ``"mcap"`` or ``"sqlite3"``.
    distro : RosDistro or str
        ``"humble"`` or ``"jazzy"``.
        Message definitions written with the messages (``visualization_msgs/msg/Marker`` differs
        between them). The metadata is rosbag2 format version 8.
    start_ns : int, optional
        Record time of the first message [ns since the epoch]; default now.

    Returns
    -------
    pathlib.Path
        The bag folder.

    Raises
    ------
    FileExistsError
        ``out`` exists and is not a bag written by ctrplan.
    ValueError
        Bad storage or distro, or arrays of inconsistent shapes.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    if storage not in tuple(BagStorage):
        raise ValueError(f"storage must be one of {', '.join(BagStorage)}, got {storage!r}")
    if distro not in DISTROS:
        raise ValueError(f"distro must be one of {', '.join(DISTROS)}, got {distro!r}")
    _check_content(content)
    out = Path(out)
    check_plan_bag_target(out)
    ts = _typestore(distro)
    T = ts.types
    start = int(_time.time_ns() if start_ns is None else start_ns)
    names = list(content.joint_names)
    header0 = T["std_msgs/msg/Header"](stamp=_time_msg(ts, 0), frame_id=content.frame_id)
    empty = np.zeros(0, dtype=float)

    def point(i):
        return T["trajectory_msgs/msg/JointTrajectoryPoint"](
            positions=np.asarray(content.position[i], float), velocities=np.asarray(content.velocity[i], float),
            accelerations=np.asarray(content.acceleration[i], float), effort=empty,
            time_from_start=_duration(ts, float(content.t[i])))

    traj = T[JOINT_TRAJECTORY](header=header0, joint_names=names,
                               points=[point(i) for i in range(len(content.t))])
    rot = content.tip_rotations
    poses = []
    for k, tip in enumerate(np.asarray(content.tips, float)):
        qx, qy, qz, qw = (0.0, 0.0, 0.0, 1.0) if rot is None else _matrix_quat(np.asarray(rot[k], float))
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(tip[0]), y=float(tip[1]), z=float(tip[2])),
            orientation=T["geometry_msgs/msg/Quaternion"](x=float(qx), y=float(qy), z=float(qz), w=float(qw)))
        poses.append(pose)
    path_msg = T["nav_msgs/msg/Path"](header=header0, poses=[
        T["geometry_msgs/msg/PoseStamped"](header=header0, pose=p) for p in poses])
    markers = []
    for k, (pose, r) in enumerate(zip(poses, np.asarray(content.bound_radius, float))):
        if not math.isfinite(r):
            continue
        markers.append(_sphere(ts, header0, k, pose, 2.0 * float(r), content.bound_label))
    marker_array = T["visualization_msgs/msg/MarkerArray"](markers=markers)

    # written beside, then moved into place: an interrupted write leaves no half bag at ``out``
    scratch = out.with_name(f".{out.name}.tmp-{os.getpid()}")
    if scratch.exists():
        shutil.rmtree(scratch)
    scratch.mkdir(parents=True)
    tmp = scratch / out.name
    plugin = StoragePlugin.MCAP if storage == BagStorage.MCAP else StoragePlugin.SQLITE3
    with Writer(tmp, version=8, storage_plugin=plugin) as w:
        w.set_custom_data(_MARKER, json.dumps({"writer": "ctrplan", "distro": distro}))
        ct = w.add_connection(PLAN_TOPICS["trajectory"], JOINT_TRAJECTORY, typestore=ts)
        cj = w.add_connection(PLAN_TOPICS["joint_states"], JOINT_STATE, typestore=ts)
        cp = w.add_connection(PLAN_TOPICS["path"], "nav_msgs/msg/Path", typestore=ts)
        cm = w.add_connection(PLAN_TOPICS["bound"], "visualization_msgs/msg/MarkerArray", typestore=ts)
        w.write(ct, start, ts.serialize_cdr(traj, JOINT_TRAJECTORY))
        w.write(cp, start, ts.serialize_cdr(path_msg, "nav_msgs/msg/Path"))
        w.write(cm, start, ts.serialize_cdr(marker_array, "visualization_msgs/msg/MarkerArray"))
        for i, ti in enumerate(content.t):
            stamp = start + int(round(float(ti) * 1e9))
            js = T[JOINT_STATE](header=T["std_msgs/msg/Header"](stamp=_time_msg(ts, stamp), frame_id=""),
                                name=names, position=np.asarray(content.position[i], float),
                                velocity=np.asarray(content.velocity[i], float), effort=empty)
            w.write(cj, stamp, ts.serialize_cdr(js, JOINT_STATE))
    if out.exists():
        shutil.rmtree(out)
    os.replace(tmp, out)
    scratch.rmdir()
    return out


def _sphere(ts, header, k: int, pose, diameter: float, label: str):
    T = ts.types
    M = T["visualization_msgs/msg/Marker"]
    fields = dict(header=header, ns=f"ctrplan/{label}", id=k, type=M.SPHERE, action=M.ADD, pose=pose,
                  scale=T["geometry_msgs/msg/Vector3"](x=diameter, y=diameter, z=diameter),
                  color=T["std_msgs/msg/ColorRGBA"](r=1.0, g=0.55, b=0.0, a=0.35),
                  lifetime=_duration(ts, 0.0), frame_locked=False, points=[], colors=[], text="",
                  mesh_resource="", mesh_use_embedded_materials=False)
    if "texture" in M.__dataclass_fields__:   # Jazzy's Marker: texture and mesh file fields, empty here
        empty = np.zeros(0, np.uint8)
        fields.update(texture_resource="", uv_coordinates=[],
                      texture=T["sensor_msgs/msg/CompressedImage"](header=header, format="", data=empty),
                      mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=empty))
    return M(**fields)


def check_plan_bag_target(out) -> None:
    """Raise FileExistsError unless ``out`` is free: missing, an empty folder, or a plan bag
    written by ctrplan (which :func:`write_plan_bag` replaces)."""
    out = Path(out)
    if out.exists() and not (out.is_dir() and (not any(out.iterdir()) or _written_here(out))):
        raise FileExistsError(f"{out}: exists and is not a plan bag written by ctrplan; choose a new folder")


def _written_here(path: Path) -> bool:
    meta = path / "metadata.yaml"
    try:
        return path.is_dir() and _MARKER in meta.read_text() and '"writer": "ctrplan"' in meta.read_text()
    except OSError:
        return False


def read_joint_trajectory(path, topic: str = PLAN_TOPICS["trajectory"]):
    """The first ``trajectory_msgs/msg/JointTrajectory`` of a bag.

    Returns
    -------
    joint_names : list of str
    t : ndarray, shape (T,)
        ``time_from_start`` [s].
    position, velocity, acceleration : ndarray, shape (T, J)

    Raises
    ------
    DataFileError
        No such bag or topic (the topics present), or a topic of another type.
    """
    bag = str(path)
    reader = _open(path)
    try:
        topics = _topics(reader)
        _choose_topic(bag, topics, topic, (JOINT_TRAJECTORY,), "joint trajectory", "topic")
        conns = [c for c in reader.connections if c.topic == topic]
        for c, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, c.msgtype)
            pts = msg.points
            t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in pts])
            arr = lambda key: np.array([np.asarray(getattr(p, key), float) for p in pts])  # noqa: E731
            return list(msg.joint_names), t, arr("positions"), arr("velocities"), arr("accelerations")
    finally:
        reader.close()
    raise DataFileError(f"{bag}: topic {topic!r} has no message")


def trajectory_yaml(joint_names: Sequence[str], t, position, velocity, acceleration, frame_id: str = "") -> str:
    """A ``trajectory_msgs/msg/JointTrajectory`` as the YAML that ``ros2 topic pub`` accepts.

    Usage: ``ros2 topic pub --once /TOPIC trajectory_msgs/msg/JointTrajectory "$(cat FILE)"``. The
    header stamp is 0 (a controller starts the trajectory on receipt); ``time_from_start`` is
    rounded to the nanosecond; values are written with full double precision.

    Parameters
    ----------
    joint_names : sequence of str
    t : array-like, shape (T,)
        [s] from the trajectory's start.
    position, velocity, acceleration : array-like, shape (T, J)
        [rad or m], [per s], [per s^2].
    frame_id : str

    Returns
    -------
    str
    """
    t = np.asarray(t, float)

    def seq(v):
        return "[" + ", ".join(repr(float(x)) for x in v) + "]"

    lines = ["header:", "  stamp: {sec: 0, nanosec: 0}", f"  frame_id: {json.dumps(frame_id)}",
             "joint_names: [" + ", ".join(json.dumps(n) for n in joint_names) + "]", "points:"]
    for i, ti in enumerate(t):
        ns = int(round(float(ti) * 1e9))
        lines += [f"- positions: {seq(position[i])}", f"  velocities: {seq(velocity[i])}",
                  f"  accelerations: {seq(acceleration[i])}", "  effort: []",
                  f"  time_from_start: {{sec: {ns // 1_000_000_000}, nanosec: {ns % 1_000_000_000}}}"]
    return "\n".join(lines) + "\n"
