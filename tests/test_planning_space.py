import numpy as np
import pytest
from ompl import base as ob

from ctrplan.planning import JointStateSpace, unwrap_path, wrap_angle
from ctrplan.robot import Joint
from test_planning_helpers import fake_robot


def test_round_trip_and_wrap():
    robot = fake_robot()
    js = JointStateSpace(robot)
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = robot.joint_lower + rng.random(3) * (robot.joint_upper - robot.joint_lower)
        s = js.from_numpy(q)
        np.testing.assert_allclose(js.to_numpy(s), np.where(js.periodic, wrap_angle(q), q), atol=1e-12)
    s = js.from_numpy([3.0 * np.pi, -0.5, -0.05])  # outside [-pi, pi): wrapped
    np.testing.assert_allclose(js.to_numpy(s), [-np.pi, -0.5, -0.05], atol=1e-12)
    with pytest.raises(ValueError, match="shape"):
        js.from_numpy([0.0, 0.0])


def test_numpy_distance_matches_ompl():
    robot = fake_robot()
    js = JointStateSpace(robot, meters_per_radian=0.05)
    si = ob.SpaceInformation(js.space)
    si.setStateValidityChecker(lambda s: True)
    si.setup()
    rng = np.random.default_rng(1)
    for _ in range(20):
        q0, q1 = (robot.joint_lower + rng.random(3) * (robot.joint_upper - robot.joint_lower) for _ in range(2))
        a, b = js.from_numpy(q0), js.from_numpy(q1)
        assert js.distance(q0, q1) == pytest.approx(si.distance(a, b), rel=1e-12)
    # 1 rad of rotation weighs 0.05 m
    assert js.distance([0, 0, -0.05], [1, 0, -0.05]) == pytest.approx(0.05)


def test_bounded_rotation_uses_bounded_subspace():
    base = fake_robot()
    robot = base.replace(joints=(Joint("rotation", 1, -1.0, 1.0),) + base.joints[1:])
    js = JointStateSpace(robot)
    assert not js.periodic[0] and js.periodic[1]
    s = js.from_numpy([0.9, 0.1, -0.05])
    np.testing.assert_allclose(js.to_numpy(s), [0.9, 0.1, -0.05])
    assert js.space.satisfiesBounds(s)


def test_unwrap_path_removes_jumps():
    robot = fake_robot()
    w = np.array([[3.0, 0.0, -0.05], [-3.1, 0.1, -0.06], [-2.9, 0.2, -0.07]])
    u = unwrap_path(w, robot)
    assert np.all(np.abs(np.diff(u[:, 0])) < np.pi)
    np.testing.assert_allclose(u[:, 2], w[:, 2])
    np.testing.assert_allclose(wrap_angle(u[:, 0]), wrap_angle(w[:, 0]))
