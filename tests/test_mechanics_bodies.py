"""Compiled robot bodies (solve_standard_bodies) against the reference path
solve_standard(..., multistart=0).body(robot), on the shipped Table VII and six-joint robots."""

from pathlib import Path

import numpy as np
import pytest

from ctrplan.errors import JointLimitError
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, solve_standard, solve_standard_batch, solve_standard_bodies
from ctrplan.mechanics import _standard_bodies

REPO = Path(__file__).resolve().parent.parent
SETTINGS = ModelSettings(multistart=0)
# Agreement required between the compiled body and StandardSolution.body [m] (they are computed
# by the same kernels; measured: bitwise equal).
BODY_TOL = 1e-9


def _configurations(robot, Q):
    cfg = [robot.configuration(q) for q in Q]
    return np.array([c[0] for c in cfg]), np.array([c[1] for c in cfg])


def _random_q(robot, rng, m):
    lo, hi = robot.joint_lower, robot.joint_upper
    return lo + (hi - lo) * rng.random((m, lo.size))


def _compare_with_reference(robot, alpha, beta):
    """Every configuration's body and flags equal the reference; returns the flag counts."""
    bodies = solve_standard_bodies(robot, alpha, beta, SETTINGS)
    batch = solve_standard_batch(robot, alpha, beta, SETTINGS)
    np.testing.assert_array_equal(bodies.valid, batch.valid)
    np.testing.assert_array_equal(bodies.converged, batch.converged)
    np.testing.assert_array_equal(bodies.unstable, batch.unstable)
    np.testing.assert_array_equal(bodies.iterations, batch.iterations)
    np.testing.assert_allclose(bodies.tip_position, batch.tip_position, atol=BODY_TOL)
    P = bodies.points.shape[1]
    assert P == bodies.counts.max()
    for k in range(alpha.shape[0]):
        if not bodies.valid[k]:
            assert bodies.counts[k] == 0
            with pytest.raises(JointLimitError):
                solve_standard(robot, alpha[k], beta[k], SETTINGS)
            continue
        sol = solve_standard(robot, alpha[k], beta[k], SETTINGS)
        ref_points, ref_radii = sol.body(robot)
        points, radii = bodies.body(k)
        assert points.shape == ref_points.shape, k
        np.testing.assert_allclose(points, ref_points, atol=BODY_TOL, rtol=0)
        np.testing.assert_allclose(radii, ref_radii, atol=BODY_TOL, rtol=0)
        assert np.all(np.isnan(bodies.points[k, bodies.counts[k]:]))
        assert bodies.converged[k] == sol.diagnostics.converged, k
        assert bodies.unstable[k] == sol.diagnostics.unstable, k
        assert bodies.ok[k] == sol.diagnostics.ok
        np.testing.assert_allclose(bodies.tip_position[k], sol.tip_position, atol=BODY_TOL, rtol=0)
    return int(bodies.valid.sum()), int(bodies.converged.sum()), int(bodies.unstable.sum())


def _capacity_must_hold(*args):
    raise AssertionError("the body capacity bound did not hold")


def test_table7_bodies_equal_the_reference(monkeypatch):
    """250 random joint vectors of the Table VII robot plus 3 impossible configurations
    (inner base in front of its outer base; curved section inside the drive); the capacity
    bound holds (no exact-sizing pass)."""
    monkeypatch.setattr(_standard_bodies, "_body_counts", _capacity_must_hold)
    robot = load_robot(REPO / "model" / "ha2019-table7-calibrated.toml")
    alpha, beta = _configurations(robot, _random_q(robot, np.random.default_rng(7), 250))
    bad_beta = np.array([[0.0, 0.005, -0.03], [-0.02, -0.017, -0.034], [0.0, -0.017, 0.001]])
    alpha = np.vstack([alpha, np.zeros((3, 3))])
    beta = np.vstack([beta, bad_beta])
    valid, converged, unstable = _compare_with_reference(robot, alpha, beta)
    assert valid == 250 and converged == 250


def test_six_joint_bodies_and_flags_equal_the_reference(monkeypatch):
    """150 random joint vectors of the six-joint robot, plus 100 with tube 3 turned about pi
    against tube 2 (where the determinant test flags unstable equilibria), chosen so that the
    unstable ones are all included; the capacity bound holds."""
    monkeypatch.setattr(_standard_bodies, "_body_counts", _capacity_must_hold)
    robot = load_robot(REPO / "model" / "ha2019-table2-six-joint.toml")
    rng = np.random.default_rng(11)
    Q = _random_q(robot, rng, 150)
    names = robot.joint_names
    cand = _random_q(robot, rng, 1500)
    a2, a3 = names.index("alpha_2"), names.index("alpha_3")
    cand[:, a3] = (cand[:, a2] + np.pi + rng.normal(0.0, 0.3, len(cand)) + np.pi) % (2 * np.pi) - np.pi
    ca, cb = _configurations(robot, cand)
    screen = solve_standard_bodies(robot, ca, cb, SETTINGS)
    unstable = np.flatnonzero(screen.unstable)
    stable = np.flatnonzero(~screen.unstable)
    pick = np.concatenate([unstable[:20], stable[:100 - min(20, unstable.size)]])
    Q = np.vstack([Q, cand[pick]])
    alpha, beta = _configurations(robot, Q)
    valid, converged, n_unstable = _compare_with_reference(robot, alpha, beta)
    assert valid == 250
    assert n_unstable >= 5   # the flag is exercised


def test_shapes_are_checked_and_empty_batches_work():
    robot = load_robot(REPO / "model" / "ha2019-table7-calibrated.toml")
    with pytest.raises(ValueError, match="shape"):
        solve_standard_bodies(robot, np.zeros((2, 3)), np.zeros((2, 2)))
    empty = solve_standard_bodies(robot, np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.points.shape == (0, 0, 3) and empty.counts.shape == (0,)


def test_bodies_larger_than_the_first_allocation_are_sized_exactly(monkeypatch):
    """If the allocated capacity is too small, the kernel stops writing and the bodies are
    recomputed in exactly sized arrays: the same result as with the normal capacity."""
    robot = load_robot(REPO / "model" / "ha2019-table7-calibrated.toml")
    Q = _random_q(robot, np.random.default_rng(23), 20)
    alpha, beta = _configurations(robot, Q)
    alpha[3], beta[3] = 0.0, [0.0, 0.01, 0.0]           # impossible: no body
    normal = solve_standard_bodies(robot, alpha, beta, SETTINGS)
    assert normal.counts.max() > 3
    monkeypatch.setattr(_standard_bodies, "_body_capacity", lambda *args: 3)
    small = solve_standard_bodies(robot, alpha, beta, SETTINGS)
    np.testing.assert_array_equal(small.counts, normal.counts)
    np.testing.assert_array_equal(small.points, normal.points)
    np.testing.assert_array_equal(small.radii, normal.radii)
    np.testing.assert_array_equal(small.converged, normal.converged)
    assert small.counts[3] == 0 and not small.valid[3]
