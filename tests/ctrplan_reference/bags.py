"""Recorded runs as ROS 2 bags, written with ``rosbags`` directly (not through ``ctrplan.io.ros2``,
the code these bags test): joint states and tip poses on their own clocks and rates, as a drive
and a tracker publish them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
#: Stamp of time 0 of a synthetic record [ns since the epoch].
ORIGIN_NS = 1_750_000_000 * 1_000_000_000


def header(ns: int, frame: str = ""):
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                                    frame_id=frame)


def joint_state(ns: int, names, positions):
    empty = np.zeros(0)
    return T["sensor_msgs/msg/JointState"](header=header(ns), name=list(names),
                                           position=np.asarray(positions, float), velocity=empty, effort=empty)


def pose(p, q):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2])),
        orientation=T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def pose_stamped(ns: int, p, q, frame: str = "tracker"):
    return T["geometry_msgs/msg/PoseStamped"](header=header(ns, frame), pose=pose(p, q))


def transform_stamped(ns: int, p, q, child: str, frame: str = "tracker"):
    tr = T["geometry_msgs/msg/Transform"](
        translation=T["geometry_msgs/msg/Vector3"](x=float(p[0]), y=float(p[1]), z=float(p[2])),
        rotation=T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))
    return T["geometry_msgs/msg/TransformStamped"](header=header(ns, frame), child_frame_id=child, transform=tr)


def quaternions_with_z_axis(tangent) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotations whose z axis is each tangent, shape (K, 4)."""
    out = []
    for t in np.asarray(tangent, float):
        rot, _ = Rotation.align_vectors([t], [[0.0, 0.0, 1.0]])
        out.append(rot.as_quat())
    return np.asarray(out)


def write_bag(path, streams, storage: str = "mcap") -> Path:
    """Write ``streams``: ``{topic: (msgtype, [(record_ns, message), ...])}``; messages are written
    in the order of their record times across topics, as a recorder would."""
    path = Path(path)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        conns = {topic: (w.add_connection(topic, msgtype, typestore=TS), msgtype)
                 for topic, (msgtype, _) in streams.items()}
        items = [(ns, topic, msg) for topic, (_, msgs) in streams.items() for ns, msg in msgs]
        for ns, topic, msg in sorted(items, key=lambda x: x[0]):
            conn, msgtype = conns[topic]
            w.write(conn, ns, TS.serialize_cdr(msg, msgtype))
    return path


def measured_run(path, motion, pose_times, tips, tangents, *, joint_rate_hz: float = 50.0,
                 joint_offset_s: float = 0.0037, names=None, extra_joint: str | None = "gripper",
                 pauses=(), margins=(-0.3, 0.3), storage: str = "mcap", pose_topic: str = "/tracker/tip",
                 joint_topic: str = "/joint_states") -> Path:
    """A bag of one recorded run: joint states of ``motion`` (callable t [s] -> (K, J) joints)
    every ``1 / joint_rate_hz`` s from ``margins[0]`` s after the first pose (negative: before) to
    ``margins[1]`` s after the last, offset
    by ``joint_offset_s`` so that no joint stamp meets a pose stamp, none during the ``pauses``
    ((start, end) [s]); the tip poses (``PoseStamped`` in frame ``tracker``, orientation's z axis
    the tangent) at ``pose_times``. Both stamped on one clock from :data:`ORIGIN_NS`, recorded
    2 ms after their stamps."""
    pose_times = np.asarray(pose_times, float)
    tj = np.arange(pose_times[0] + margins[0], pose_times[-1] + margins[1], 1.0 / joint_rate_hz) + joint_offset_s
    for a, b in pauses:
        tj = tj[(tj < a) | (tj > b)]
    q = motion(tj)
    names = list(names) if names is not None else [f"q{j}" for j in range(q.shape[1])]
    full_names = names + ([extra_joint] if extra_joint else [])
    joints = []
    for t, qk in zip(tj, q):
        ns = ORIGIN_NS + int(round(t * 1e9))
        values = list(qk) + ([0.0] if extra_joint else [])
        joints.append((ns + 2_000_000, joint_state(ns, full_names, values)))
    quats = quaternions_with_z_axis(tangents)
    poses = [(ORIGIN_NS + int(round(t * 1e9)) + 2_000_000, pose_stamped(ORIGIN_NS + int(round(t * 1e9)), p, qq))
             for t, p, qq in zip(pose_times, tips, quats)]
    return write_bag(path, {joint_topic: ("sensor_msgs/msg/JointState", joints),
                            pose_topic: ("geometry_msgs/msg/PoseStamped", poses)}, storage=storage)
