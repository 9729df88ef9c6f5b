"""ROS 2 bags in and out: measured runs from rosbag2, plans and drive trajectories as ROS 2 messages.

Bags are read and written by the pure-Python ``rosbags`` library (rosbag2 folders with sqlite3 or
MCAP storage, or a bare ``.mcap`` file; no ROS installation needed). ROS messages carry SI units
(m, rad, s), as ctrplan's files do.

Reading (:func:`read_bag_measurements`): joint values come from a ``sensor_msgs/msg/JointState``
topic, the tip pose from a ``geometry_msgs/msg/PoseStamped`` or ``TransformStamped`` topic or from
``/tf`` (``tf2_msgs/msg/TFMessage``, one child frame). Times are the messages' header stamps; the
bag's record time is used only for a message whose header stamp is empty (zero), with a caution.
The joint stream is cut into continuous motions where it pauses for longer than
``max_gap_periods`` of its median period, and the joints are read at each pose stamp within its
motion by the interpolant of :func:`ctrplan.history.joints_at` (PCHIP: shape preserving, C1,
through every sample), so a tracker's own clock and rate are kept; poses outside every motion
(before the first joint state, after the last, or in a pause) are dropped and counted. The result
is a table in the project's CSV schema (:mod:`ctrplan.io.tables`) and a summary of what was used.

Writing (:func:`write_plan_bag`): the drive trajectory as ``trajectory_msgs/msg/JointTrajectory``,
the same samples as ``sensor_msgs/msg/JointState`` at their times (for plotting), the planned tip
path as ``nav_msgs/msg/Path`` and the error bound at the waypoints as
``visualization_msgs/msg/MarkerArray`` spheres; :func:`trajectory_yaml` gives the trajectory as
the YAML message that ``ros2 topic pub`` accepts.
"""

from ._read import (DISTROS, JOINT_STATE, JOINT_TRAJECTORY, PLAN_TOPICS, POSE_STAMPED, POSE_TYPES, TF_MESSAGE,
                    TRANSFORM_STAMPED, BagMeasurements, BagSelection, bag_topics, describe_bag_summary, is_bag,
                    read_bag_measurements)
from ._write import (PlanBagContent, check_plan_bag_target, read_joint_trajectory, trajectory_yaml,
                     write_plan_bag)

__all__ = ["BagSelection", "BagMeasurements", "PlanBagContent", "is_bag", "bag_topics", "read_bag_measurements",
           "read_joint_trajectory", "write_plan_bag", "check_plan_bag_target", "trajectory_yaml", "describe_bag_summary",
           "DISTROS", "PLAN_TOPICS", "JOINT_STATE", "JOINT_TRAJECTORY", "POSE_STAMPED", "POSE_TYPES", "TF_MESSAGE",
           "TRANSFORM_STAMPED"]
