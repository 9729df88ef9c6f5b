"""Time to read a recorded run from a ROS 2 bag: 100,000 joint states and 10,000 tip poses.

A synthetic run of the Table II robot (``model/ha2019-table2-nominal.toml``): joint states of
its three joints at 1 kHz for 100 s (a smooth seeded motion, stamped on the drive's clock) and
``PoseStamped`` tip poses at 100 Hz, offset from the joint stamps, written once per storage
(MCAP and sqlite3) by ``rosbags``. Then :func:`ctrplan.io.ros2.read_bag_measurements` reads each
bag ``--repeats`` times, alternating the storages; the wall time of each read (open, deserialize,
check, interpolate the joints to the pose stamps, build the table) is reported as mean, median,
90th percentile and max, with the bag sizes, the share spent deserializing, and the load average
before and after (the machine is shared; compare the storages' ratio rather than absolute times).

Usage::

    python benchmarks/bench_ros2_read.py                 # 100,000 joint states, 10,000 poses, 5 repeats
    python benchmarks/bench_ros2_read.py --joint-states 20000 --poses 2000 --repeats 3
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the frozen reference ctrplan_reference (tests/, not installed)


def _stats(times):
    t = np.asarray(times)
    return f"mean {t.mean():.2f} s, median {np.median(t):.2f} s, p90 {np.percentile(t, 90):.2f} s, max {t.max():.2f} s"


def _write(path, storage, n_joints, n_poses, robot):
    from ctrplan_reference.bags import ORIGIN_NS, joint_state, pose_stamped, quaternions_with_z_axis, write_bag

    rng = np.random.default_rng(0)
    duration = n_joints / 1000.0
    tj = np.arange(n_joints) / 1000.0
    # a smooth motion: a few sines per joint within the joint limits
    lo, hi = robot.joint_lower, robot.joint_upper
    mid, amp = (lo + hi) / 2, np.minimum((hi - lo) / 2, 2.0) * 0.8
    freq = rng.uniform(0.02, 0.2, (3, len(lo)))
    q = mid + amp * np.mean([np.sin(2 * np.pi * f * tj[:, None]) for f in freq], axis=0)
    names = robot.joint_names
    joints = [(ORIGIN_NS + int(x * 1e9) + 1_000_000, joint_state(ORIGIN_NS + int(x * 1e9), names, v))
              for x, v in zip(tj, q)]
    tp = 0.00037 + np.arange(n_poses) * (duration / n_poses)
    tips = 0.1 * rng.uniform(-1, 1, (n_poses, 3))
    tangents = rng.normal(size=(n_poses, 3))
    quats = quaternions_with_z_axis(tangents / np.linalg.norm(tangents, axis=1, keepdims=True))
    poses = [(ORIGIN_NS + int(x * 1e9) + 2_000_000, pose_stamped(ORIGIN_NS + int(x * 1e9), p, qq))
             for x, p, qq in zip(tp, tips, quats)]
    return write_bag(path, {"/joint_states": ("sensor_msgs/msg/JointState", joints),
                            "/tracker/tip": ("geometry_msgs/msg/PoseStamped", poses)}, storage=storage)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--joint-states", type=int, default=100_000)
    ap.add_argument("--poses", type=int, default=10_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)

    from ctrplan.io.robot_file import load_robot
    from ctrplan.io.ros2 import read_bag_measurements

    robot = load_robot(REPO / "model" / "ha2019-table2-nominal.toml")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        bags = {}
        for storage in ("mcap", "sqlite3"):
            t0 = time.perf_counter()
            bags[storage] = _write(Path(tmp) / storage, storage, args.joint_states, args.poses, robot)
            size = sum(f.stat().st_size for f in bags[storage].iterdir())
            print(f"{storage}: wrote {args.joint_states} joint states and {args.poses} poses, {size / 1e6:.1f} MB, "
                  f"in {time.perf_counter() - t0:.1f} s")
        times = {s: [] for s in bags}
        rows = None
        for r in range(args.repeats):
            for storage in (("mcap", "sqlite3") if r % 2 == 0 else ("sqlite3", "mcap")):
                t0 = time.perf_counter()
                read = read_bag_measurements(bags[storage], robot)
                times[storage].append(time.perf_counter() - t0)
                rows = len(read.table)
        # the share of one read spent deserializing messages
        from rosbags.highlevel import AnyReader

        t0 = time.perf_counter()
        with AnyReader([bags["mcap"]]) as reader:
            for conn, _, raw in reader.messages():
                reader.deserialize(raw, conn.msgtype)
        deser = time.perf_counter() - t0
    print(f"read {args.joint_states} joint states + {args.poses} poses -> {rows} samples, {args.repeats} repeats:")
    for storage, t in times.items():
        print(f"  {storage:8s} {_stats(t)}")
    print(f"  ratio sqlite3 / mcap (medians): {np.median(times['sqlite3']) / np.median(times['mcap']):.2f}")
    print(f"  reading and deserializing every message alone (mcap): {deser:.2f} s")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
