import numpy as np
import pytest

from ctrplan.errors import UnreachableGoalError
from ctrplan.planning import bounds_given_last_motion, order_path
from test_planning_helpers import fake_bound, fake_robot


def test_phases_and_dropped_duplicates():
    robot = fake_robot()
    w = np.array([[0.0, 0.0, -0.05],
                  [0.5, 0.2, -0.06],    # both change -> rotation, translation
                  [0.5, 0.2, -0.08],    # translation only
                  [0.9, 0.2, -0.08],    # rotation only
                  [0.9, 0.2, -0.08]])   # duplicate -> nothing
    op = order_path(w, robot, lambda q: True)
    assert op.motions == ["start", "rotation", "translation", "translation", "rotation"]
    np.testing.assert_allclose(op.q[1], [0.5, 0.2, -0.05])
    np.testing.assert_allclose(op.q[-1], w[-1])
    assert op.n_subdivisions == 0


def test_unwrapped_across_pi():
    robot = fake_robot()
    op = order_path([[3.0, 0.0, -0.05], [-3.0, 0.0, -0.05]], robot, lambda q: True)
    assert op.motions == ["start", "rotation"]
    assert op.q[1, 0] == pytest.approx(2 * np.pi - 3.0)  # short way, continuous angle


def test_invalid_corner_is_bisected():
    robot = fake_robot()
    # forbidden square around the corner (rotation done, translation not yet) of the L-shaped detour
    def valid(q):
        return not (0.8 < q[0] < 1.2 and -0.06 < q[2] < -0.045)

    w = np.array([[0.0, 0.0, -0.04], [1.0, 0.0, -0.08]])  # the straight segment passes at q0=1: beta=-0.08
    assert all(valid(q) for q in np.linspace(w[0], w[1], 200))
    op = order_path(w, robot, valid, resolution=5e-4)
    assert op.n_subdivisions > 0
    assert all(valid(q) for q in op.q)
    for a, b, m in zip(op.q[:-1], op.q[1:], op.motions[1:]):
        for q in np.linspace(a, b, 50):
            assert valid(q)
    with pytest.raises(UnreachableGoalError, match="bisections"):
        order_path(w, robot, valid, resolution=5e-4, max_subdivisions=0)


def test_bound_given_last_motion():
    robot = fake_robot()
    op = order_path([[0.0, 0.0, -0.05], [0.5, 0.2, -0.06]], robot, lambda q: True)
    lb = bounds_given_last_motion(op, robot, fake_bound)
    for i, m in enumerate(lb.motions):
        res = fake_bound(robot, *robot.configuration(op.q[i]))
        want = res.translation_last_position if m == "translation" else res.position
        assert lb.position[i] == pytest.approx(want)
    assert lb.valid.all() and lb.motions == ["start", "rotation", "translation"]
    assert lb.position[2] < lb.position[1] * 1.5  # translation-last bound is the smaller one here
