"""Reading ROS 2 bags: measured runs (joint states and tip poses) as the project's table (see
:mod:`ctrplan.io.ros2`)."""


from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from ...choices import BagStorage, RosDistro, TangentAxis
from ...errors import DataFileError

__all__ = ["BagSelection", "BagMeasurements", "is_bag", "bag_topics", "read_bag_measurements", "describe_bag_summary",
           "DISTROS", "PLAN_TOPICS"]

JOINT_STATE = "sensor_msgs/msg/JointState"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POSE_TYPES = (POSE_STAMPED, TRANSFORM_STAMPED, TF_MESSAGE)
JOINT_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"

#: ROS 2 distributions whose message definitions a written bag can carry (``rosbags`` typestores).
DISTROS = tuple(RosDistro)
#: Topics of a written plan bag.
PLAN_TOPICS = {"trajectory": "/ctrplan/joint_trajectory", "joint_states": "/ctrplan/planned_joint_states",
               "path": "/ctrplan/tip_path", "bound": "/ctrplan/bound_markers"}
_MARKER = "ctrplan"   # key of the metadata's custom data that marks a bag written here
_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class BagSelection:
    """What to read from a bag (every field optional when the bag leaves no choice).

    Attributes
    ----------
    joint_topic : str, optional
        ``sensor_msgs/msg/JointState`` topic. Default: the bag's only one.
    pose_topic : str, optional
        Tip pose topic (``PoseStamped``, ``TransformStamped`` or ``TFMessage``). Default: the bag's
        only ``PoseStamped`` or ``TransformStamped`` topic, else its only ``TFMessage`` topic.
    child_frame : str, optional
        Child frame of the tip in a ``TFMessage`` or ``TransformStamped`` topic. Default: the
        topic's only child frame.
    joint_names : tuple of (str, str)
        ``(name in the bag, robot joint name)`` pairs; joints not listed keep their own name.
    max_gap_periods : float
        A pause in the joint stream longer than this many of its median periods starts a new
        continuous motion [-].
    tangent_axis : TangentAxis or str
        Axis of the pose's orientation that is the tip tangent (``"x"``, ``"y"``, ``"z"``);
        ``"none"``: positions only. Stored as the member.
    """

    joint_topic: str | None = None
    pose_topic: str | None = None
    child_frame: str | None = None
    joint_names: tuple = ()
    max_gap_periods: float = 5.0
    tangent_axis: TangentAxis = TangentAxis.Z

    def __post_init__(self):
        object.__setattr__(self, "joint_names", tuple((str(a), str(b)) for a, b in self.joint_names))
        if not (self.max_gap_periods > 1.0 and math.isfinite(self.max_gap_periods)):
            raise ValueError(f"max_gap_periods must be a finite number > 1, got {self.max_gap_periods!r}")
        if self.tangent_axis not in tuple(TangentAxis):
            raise ValueError(f"tangent_axis must be one of {', '.join(TangentAxis)}; got {self.tangent_axis!r}")
        object.__setattr__(self, "tangent_axis", TangentAxis(self.tangent_axis))

    @classmethod
    def parse_joint_names(cls, text: str | None) -> tuple:
        """``"bag_a=alpha_2,bag_b=beta_3"`` -> ``(("bag_a", "alpha_2"), ("bag_b", "beta_3"))``.

        Raises
        ------
        ValueError
            An item without ``=`` or with an empty side.
        """
        if not text:
            return ()
        pairs = []
        for item in text.split(","):
            if not item.strip():
                continue
            bag, sep, robot = item.partition("=")
            if not sep or not bag.strip() or not robot.strip():
                raise ValueError(f"{item.strip()!r} is not BAG_NAME=ROBOT_JOINT")
            pairs.append((bag.strip(), robot.strip()))
        return tuple(pairs)


@dataclass(frozen=True, eq=False)
class BagMeasurements:
    """Measured samples read from a bag.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per used pose, project schema (SI): ``time`` [s] from ``summary["time_origin_ns"]``,
        ``sequence``, ``alpha_1..n`` [rad], ``beta_1..n`` [m], ``tip_x..z`` [m] and, unless the
        tangent axis is ``"none"`` or the poses carry no orientation, ``tangent_x..z``.
    summary : dict
        Topics present (with types and counts), topics, frames and joint names used, rates [Hz],
        time span [s], motions, poses dropped (before, after, in pauses), cautions.
    """

    table: pd.DataFrame
    summary: dict


# --------------------------------------------------------------------------- reading
def is_bag(path) -> bool:
    """True for a rosbag2 folder (``metadata.yaml`` inside) or a ``.mcap`` / ``.db3`` file."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").exists() or any(p.glob("*.mcap")) or any(p.glob("*.db3"))
    return p.suffix.lower() in (".mcap", ".db3")


def _typestore(distro: str = "humble"):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore({RosDistro.HUMBLE: Stores.ROS2_HUMBLE, RosDistro.JAZZY: Stores.ROS2_JAZZY}[distro])


def _open(path):
    """An open AnyReader, or DataFileError naming the bag."""
    from rosbags.highlevel import AnyReader

    p = Path(path)
    if not p.exists():
        raise DataFileError(f"{p}: bag does not exist")
    if p.is_dir() and not (p / "metadata.yaml").exists():
        found = sorted(x.name for x in p.iterdir())[:5]
        raise DataFileError(f"{p}: not a rosbag2 folder (no metadata.yaml; found {found}); give the folder "
                            f"`ros2 bag record` wrote, or the .mcap file itself")
    try:
        reader = AnyReader([p], default_typestore=_typestore())
        reader.open()
    except Exception as exc:  # rosbags raises several unrelated types for unreadable bags
        raise DataFileError(f"{p}: cannot read the bag: {exc}") from None
    return reader


def bag_topics(path) -> list[dict]:
    """Topics of a bag: ``[{"topic", "type", "count"}]`` in topic order.

    Raises
    ------
    DataFileError
        The bag does not exist or cannot be read.
    """
    reader = _open(path)
    try:
        return _topics(reader)
    finally:
        reader.close()


def _topics(reader) -> list[dict]:
    seen: dict[str, dict] = {}
    for c in reader.connections:
        entry = seen.setdefault(c.topic, {"topic": c.topic, "type": c.msgtype, "count": 0})
        entry["count"] += int(c.msgcount)
    return [seen[t] for t in sorted(seen)]


def _listing(topics) -> str:
    return ", ".join(f"{t['topic']} ({t['type']}, {t['count']})" for t in topics) or "none"


def _choose_topic(bag: str, topics, wanted: str | None, types: Sequence[str], what: str, option: str) -> dict:
    if wanted is not None:
        match = [t for t in topics if t["topic"] == wanted]
        if not match:
            raise DataFileError(f"{bag}: no topic {wanted!r} ({option}); topics present: {_listing(topics)}")
        if match[0]["type"] not in types:
            raise DataFileError(f"{bag}: topic {wanted!r} has type {match[0]['type']}; {what} must be "
                                f"{' or '.join(types)}; topics present: {_listing(topics)}")
        return match[0]
    for group in ([tuple(types)] if len(types) == 1 else [tuple(types[:2]), tuple(types[2:])]):
        match = [t for t in topics if t["type"] in group and t["count"] > 0]
        if len(match) == 1:
            return match[0]
        if len(match) > 1:
            raise DataFileError(f"{bag}: {len(match)} topics could be the {what} "
                                f"({', '.join(t['topic'] for t in match)}); choose one with {option}")
    raise DataFileError(f"{bag}: no {what} topic ({' or '.join(types)}) with messages; topics present: "
                        f"{_listing(topics)}")


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _check_stamps(bag: str, topic: str, stamps: np.ndarray) -> None:
    d = np.diff(stamps)
    bad = np.flatnonzero(d <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        kind = "duplicate" if d[bad[0]] == 0 else "unsorted"
        raise DataFileError(
            f"{bag}: topic {topic!r}: {kind} header stamps: message {k + 1} is stamped "
            f"{stamps[k] * 1e-9:.9f} s, message {k} {stamps[k - 1] * 1e-9:.9f} s ({bad.size} such "
            f"message(s)); stamps must increase within a topic")


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions (x, y, z, w), shape (K, 3, 3)."""
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def _read_joints(bag: str, reader, conns, topic: str, joints: list[str], bag_names: dict[str, str]):
    """Stamps [ns], values (M, J) in the order of ``joints``, names seen, record-time count."""
    stamps, values, record_used = [], [], 0
    seen_names: set[str] = set()
    cache: dict[tuple, np.ndarray] = {}
    wanted = [bag_names.get(j, j) for j in joints]
    for m, (c, t_rec, raw) in enumerate(reader.messages(connections=conns)):
        msg = reader.deserialize(raw, c.msgtype)
        names = tuple(msg.name)
        idx = cache.get(names)
        if idx is None:
            seen_names.update(names)
            missing = [w for w in wanted if w not in names]
            if missing:
                robot_names = [j for j, w in zip(joints, wanted) if w in missing]
                raise DataFileError(
                    f"{bag}: topic {topic!r}, message {m + 1}: no joint {', '.join(map(repr, missing))} "
                    f"(robot joint(s) {', '.join(robot_names)}); the message names {list(names)}. Map the bag's "
                    f"names to the robot's with --joint-names BAG_NAME=ROBOT_JOINT,...")
            idx = cache[names] = np.array([names.index(w) for w in wanted])
        pos = np.asarray(msg.position, dtype=float)
        if pos.shape != (len(names),):
            raise DataFileError(f"{bag}: topic {topic!r}, message {m + 1}: {len(names)} names but "
                                f"{pos.size} positions")
        v = pos[idx]
        if not np.all(np.isfinite(v)):
            j = int(np.flatnonzero(~np.isfinite(v))[0])
            raise DataFileError(f"{bag}: topic {topic!r}, message {m + 1}: joint {wanted[j]!r} is {float(v[j])!r} "
                                f"(not a finite number)")
        s = _stamp_ns(msg.header)
        if s == 0:
            s, record_used = int(t_rec), record_used + 1
        stamps.append(s)
        values.append(v)
    return np.asarray(stamps, dtype=np.int64), np.asarray(values, dtype=float).reshape(-1, len(joints)), \
        sorted(seen_names), record_used


def _read_poses(bag: str, reader, conns, topic: str, msgtype: str, child: str | None):
    """Stamps [ns], positions (M, 3), quaternions (M, 4), parent frames, child frame, record-time count."""
    stamps, pos, quat, parents, record_used = [], [], [], set(), 0
    children_seen: set[str] = set()
    for m, (c, t_rec, raw) in enumerate(reader.messages(connections=conns)):
        msg = reader.deserialize(raw, c.msgtype)
        if msg.__msgtype__ == POSE_STAMPED:
            items = [(msg.header, None, msg.pose.position, msg.pose.orientation)]
        elif msg.__msgtype__ == TRANSFORM_STAMPED:
            items = [(msg.header, msg.child_frame_id, msg.transform.translation, msg.transform.rotation)]
        else:
            items = [(tf.header, tf.child_frame_id, tf.transform.translation, tf.transform.rotation)
                     for tf in msg.transforms]
        for header, ch, p, q in items:
            if ch is not None:
                children_seen.add(ch)
                if child is not None and ch != child:
                    continue
            v = np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w], dtype=float)
            if not np.all(np.isfinite(v)):
                raise DataFileError(f"{bag}: topic {topic!r}, message {m + 1}: pose {v.tolist()} is not finite")
            s = _stamp_ns(header)
            if s == 0:
                s, record_used = int(t_rec), record_used + 1
            stamps.append(s)
            pos.append(v[:3])
            quat.append(v[3:])
            parents.add(header.frame_id)
        if child is None and msgtype != POSE_STAMPED and len(children_seen) > 1:
            raise DataFileError(f"{bag}: topic {topic!r} holds transforms of several child frames "
                                f"({', '.join(sorted(children_seen))}); choose the tip's with --child-frame")
    if child is not None and child not in children_seen:
        raise DataFileError(f"{bag}: topic {topic!r} has no transform with child frame {child!r}; child frames "
                            f"present: {', '.join(sorted(children_seen)) or 'none'}")
    used_child = child if child is not None else (next(iter(children_seen)) if children_seen else None)
    return (np.asarray(stamps, dtype=np.int64), np.asarray(pos, dtype=float).reshape(-1, 3),
            np.asarray(quat, dtype=float).reshape(-1, 4), sorted(parents), used_child, record_used)


def _motions(stamps: np.ndarray, max_gap_periods: float):
    """Start and end index (inclusive) of each continuous motion, the median period [ns] and the
    gap threshold [ns]."""
    d = np.diff(stamps)
    period = float(np.median(d))
    threshold = max_gap_periods * period
    cuts = np.flatnonzero(d > threshold)
    starts = np.concatenate([[0], cuts + 1])
    ends = np.concatenate([cuts, [stamps.size - 1]])
    return list(zip(starts.tolist(), ends.tolist())), period, threshold


def read_bag_measurements(path, robot, selection: BagSelection = BagSelection()) -> BagMeasurements:
    """Measured tip poses and the joint values at their stamps, from a ROS 2 bag.

    Parameters
    ----------
    path : str or path-like
        rosbag2 folder (sqlite3 or MCAP storage) or ``.mcap`` file.
    robot : Robot
        Its actuated joints (``robot.joint_names``, [rad] or [m]) are read from the joint states;
        tubes without a joint keep the file's ``[home]`` and links (:meth:`Robot.configuration`).
    selection : BagSelection
        Topics, child frame, joint name map, pause length, tangent axis.

    Returns
    -------
    BagMeasurements
        ``table`` in the project schema (SI units), ``summary`` of what was used.

    Raises
    ------
    DataFileError
        Naming the bag, the topic and what was found: no such bag, no joint-state or pose topic
        (the topics present, with their types), several candidates and no choice, a topic of
        another type, a robot joint missing from the joint states (the names found), unsorted or
        duplicate header stamps, a value that is not finite, poses of several child frames and
        no choice, fewer than 2 joint states or no pose within the joint stream, a quaternion
        of zero length among non-zero ones.
    """
    bag = str(path)
    sel = selection
    joints = list(robot.joint_names)
    bag_names = {r: b for b, r in sel.joint_names}
    unknown = [r for r in bag_names if r not in joints]
    if unknown:
        raise DataFileError(f"{bag}: --joint-names maps to {', '.join(map(repr, unknown))}, not a joint of robot "
                            f"{robot.name!r} ({', '.join(joints)})")
    reader = _open(path)
    try:
        topics = _topics(reader)
        jt = _choose_topic(bag, topics, sel.joint_topic, (JOINT_STATE,), "joint-state", "--joint-topic")
        pt = _choose_topic(bag, topics, sel.pose_topic, POSE_TYPES, "tip pose", "--pose-topic")
        if sel.child_frame is not None and pt["type"] == POSE_STAMPED:
            raise DataFileError(f"{bag}: --child-frame {sel.child_frame!r} given but topic {pt['topic']!r} is "
                                f"{POSE_STAMPED}, which has no child frame")
        jconns = [c for c in reader.connections if c.topic == jt["topic"]]
        pconns = [c for c in reader.connections if c.topic == pt["topic"]]
        j_ns, q, names_seen, j_record = _read_joints(bag, reader, jconns, jt["topic"], joints, bag_names)
        p_ns, tip, quat, parents, child, p_record = _read_poses(bag, reader, pconns, pt["topic"], pt["type"],
                                                                sel.child_frame)
        storage = (BagStorage.MCAP if Path(path).suffix == ".mcap" or any(Path(path).glob("*.mcap"))
                   else BagStorage.SQLITE3)
    finally:
        reader.close()
    if j_ns.size < 2:
        raise DataFileError(f"{bag}: topic {jt['topic']!r}: {j_ns.size} joint state(s); at least 2 are needed")
    if p_ns.size < 1:
        raise DataFileError(f"{bag}: topic {pt['topic']!r}: no pose"
                            + (f" of child frame {child!r}" if child else ""))
    _check_stamps(bag, jt["topic"], j_ns)
    _check_stamps(bag, pt["topic"], p_ns)
    if len(parents) > 1:
        raise DataFileError(f"{bag}: topic {pt['topic']!r}: poses in several parent frames "
                            f"({', '.join(map(repr, parents))}); the tip must be measured in one frame")

    motions, period, threshold = _motions(j_ns, sel.max_gap_periods)
    from scipy.interpolate import PchipInterpolator

    # joint values at the pose stamps, within the motion that spans each stamp
    t0 = int(p_ns[0])
    seq = np.full(p_ns.size, -1)
    qp = np.full((p_ns.size, len(joints)), np.nan)
    before = int(np.sum(p_ns < j_ns[0]))
    after = int(np.sum(p_ns > j_ns[-1]))
    for m, (a, b) in enumerate(motions):
        inside = (p_ns >= j_ns[a]) & (p_ns <= j_ns[b])
        if b == a or not inside.any():
            continue
        ts = (j_ns[a:b + 1] - t0) * 1e-9
        qp[inside] = PchipInterpolator(ts, q[a:b + 1], axis=0)((p_ns[inside] - t0) * 1e-9)
        seq[inside] = m
    used = seq >= 0
    in_gaps = int(p_ns.size - used.sum() - before - after)
    if not used.any():
        raise DataFileError(
            f"{bag}: no pose of {pt['topic']!r} ({p_ns.size}, {p_ns[0] * 1e-9:.3f}..{p_ns[-1] * 1e-9:.3f} s) "
            f"falls within the joint stream of {jt['topic']!r} ({j_ns[0] * 1e-9:.3f}..{j_ns[-1] * 1e-9:.3f} s); "
            f"are both stamped by the same clock?")
    # renumber the motions that hold poses 0, 1, ...
    _, sequence = np.unique(seq[used], return_inverse=True)

    k = int(used.sum())
    alpha = np.empty((k, robot.n_tubes))
    beta = np.empty((k, robot.n_tubes))
    for r, qr in enumerate(qp[used]):
        alpha[r], beta[r] = robot.configuration(qr, check_limits=False)
    origin = int(p_ns[used][0])
    columns = {"time": (p_ns[used] - origin) * 1e-9, "sequence": sequence.astype(int)}
    columns.update({f"alpha_{i + 1}": alpha[:, i] for i in range(robot.n_tubes)})
    columns.update({f"beta_{i + 1}": beta[:, i] for i in range(robot.n_tubes)})
    columns.update({c: tip[used, i] for i, c in enumerate(("tip_x", "tip_y", "tip_z"))})

    cautions = []
    tangent_note = None
    norms = np.linalg.norm(quat, axis=1)
    if sel.tangent_axis == TangentAxis.NONE:
        tangent_note = "not read (--tangent-axis none)"
    elif np.all(norms < 1e-6):
        tangent_note = "not given (every orientation is a zero quaternion)"
    else:
        zero = np.flatnonzero(norms < 1e-6)
        if zero.size:
            raise DataFileError(f"{bag}: topic {pt['topic']!r}, pose {zero[0] + 1}: orientation is a zero "
                                f"quaternion while others are not; give --tangent-axis none to read positions only")
        rot = _quat_matrix(quat[used] / norms[used, None])
        if np.allclose(quat[used] / norms[used, None], [0.0, 0.0, 0.0, 1.0], atol=1e-12):
            tangent_note = "not given (every orientation is the identity)"
        else:
            tangent = rot[:, :, _AXES[sel.tangent_axis]]
            columns.update({c: tangent[:, i] for i, c in enumerate(("tangent_x", "tangent_y", "tangent_z"))})
            tangent_note = f"{sel.tangent_axis} axis of the pose orientation"
    if j_record:
        cautions.append(f"{j_record} joint state(s) of {jt['topic']!r} had an empty header stamp; their record "
                        f"time was used, which includes the recorder's delay")
    if p_record:
        cautions.append(f"{p_record} pose(s) of {pt['topic']!r} had an empty header stamp; their record time was "
                        f"used, which includes the recorder's delay")
    ignored = sorted(set(names_seen) - {bag_names.get(j, j) for j in joints})
    span = lambda ns: [float((ns[0] - origin) * 1e-9), float((ns[-1] - origin) * 1e-9)]  # noqa: E731
    summary = {
        "bag": bag,
        "storage": storage,
        "topics": topics,
        "joint_topic": jt["topic"],
        "joint_names": {j: bag_names.get(j, j) for j in joints},
        "ignored_joint_names": ignored,
        "joint_states": int(j_ns.size),
        "joint_rate_hz": float(1e9 / period) if period > 0 else None,
        "pose_topic": pt["topic"],
        "pose_type": pt["type"],
        "pose_frame": parents[0] if parents else "",
        "child_frame": child,
        "poses": int(p_ns.size),
        "pose_rate_hz": float(1e9 / np.median(np.diff(p_ns))) if p_ns.size > 1 else None,
        "tangent": tangent_note,
        "time_origin_ns": origin,
        "joint_span_s": span(j_ns),
        "pose_span_s": span(p_ns),
        "motions": int(sequence.max() + 1),
        "pauses": len(motions) - 1,
        "pause_threshold_s": threshold * 1e-9,
        "max_gap_periods": sel.max_gap_periods,
        "poses_used": k,
        "poses_dropped": {"before_joint_stream": before, "after_joint_stream": after, "in_pauses": in_gaps},
        "cautions": cautions,
    }
    return BagMeasurements(table=pd.DataFrame(columns), summary=summary)


def describe_bag_summary(summary: dict) -> list[str]:
    """Report lines (mm, degrees, Hz) of a :class:`BagMeasurements` summary."""
    s = summary
    names = ", ".join(j if b == j else f"{j} <- {b}" for j, b in s["joint_names"].items())
    drop = s["poses_dropped"]
    lines = [
        f"bag {s['bag']} ({s['storage']}): joint states {s['joint_topic']} ({s['joint_states']} at "
        f"{s['joint_rate_hz']:.4g} Hz; joints {names}"
        + (f"; ignored {', '.join(s['ignored_joint_names'])}" if s["ignored_joint_names"] else "") + ")",
        f"tip poses {s['pose_topic']} ({s['pose_type']}, frame {s['pose_frame']!r}"
        + (f", child {s['child_frame']!r}" if s["child_frame"] else "")
        + f"; {s['poses']}" + (f" at {s['pose_rate_hz']:.4g} Hz" if s["pose_rate_hz"] else "")
        + f"; tangent {s['tangent']})",
        f"time span: joints {s['joint_span_s'][0]:.3f}..{s['joint_span_s'][1]:.3f} s, poses "
        f"{s['pose_span_s'][0]:.3f}..{s['pose_span_s'][1]:.3f} s (from the first used pose, stamp "
        f"{s['time_origin_ns'] * 1e-9:.9f} s); {s['motions']} continuous motion(s), a pause longer than "
        f"{s['pause_threshold_s']:.4g} s ({s['max_gap_periods']:g} joint periods) starts a new one",
        f"poses used {s['poses_used']} of {s['poses']}; outside the joint stream: {drop['before_joint_stream']} "
        f"before, {drop['after_joint_stream']} after, {drop['in_pauses']} in pauses",
    ]
    return lines + [f"caution: {c}" for c in s["cautions"]]


