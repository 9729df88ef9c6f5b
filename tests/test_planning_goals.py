import numpy as np
import pytest

from ctrplan.errors import UnreachableGoalError
from ctrplan.boundmap import compute_field
from ctrplan.planning import TaskSpaceGoal, resolve_goal
from test_planning_helpers import fake_robot, fake_solve_standard, fake_tip


def test_ik_finds_both_elbows_and_picks_lowest_bound():
    robot = fake_robot()
    q_true = np.array([0.4, 1.6, -0.06])
    target = fake_tip(*robot.configuration(q_true))

    # bound grows with alpha_2: the IK branch with the smaller alpha_2 must win
    def bound(robot_, alpha, beta, settings=None):
        from types import SimpleNamespace
        p = 1e-3 * (2.0 + np.sin(alpha[1]))
        return SimpleNamespace(position=p, angle=p, translation_last_position=p, translation_last_angle=p,
                               diagnostics=SimpleNamespace(converged=True, unstable=False))

    field = compute_field(robot, bound, (24, 8, 3), progress=False)
    sol = resolve_goal(TaskSpaceGoal(tuple(target), 1e-4), robot, lambda q: True, field=field,
                       solve_standard=fake_solve_standard, seed=0)
    assert sol.tip_error < 1e-4
    np.testing.assert_allclose(fake_tip(*robot.configuration(sol.q)), target, atol=1e-4)
    assert len(sol.candidates) >= 2  # the mirrored elbow also reaches the target
    assert sol.bound == pytest.approx(np.nanmin(sol.candidate_bounds))


def test_unreachable_names_target_in_mm():
    robot = fake_robot()
    with pytest.raises(UnreachableGoalError, match=r"\(100\.00, 0\.00, 50\.00\) mm; best distance reached"):
        resolve_goal({"tip_position_m": [0.1, 0.0, 0.05], "tolerance_m": 1e-3}, robot,
                     solve_standard=fake_solve_standard, starts_per_joint=2)


def test_joint_goal_passthrough():
    robot = fake_robot()
    sol = resolve_goal([0.1, 0.2, -0.05], robot, lambda q: True)
    np.testing.assert_array_equal(sol.q, [0.1, 0.2, -0.05])
    with pytest.raises(UnreachableGoalError):
        resolve_goal([0.1, 0.2, -0.05], robot, lambda q: False)


def test_scenario_goal_objects():
    from types import SimpleNamespace

    robot = fake_robot()
    q_true = np.array([0.4, 1.6, -0.06])
    target = fake_tip(*robot.configuration(q_true))
    sol = resolve_goal(SimpleNamespace(tip_position=target, tolerance=1e-4), robot,
                       solve_standard=fake_solve_standard)
    assert sol.tip_error < 1e-4
    sol = resolve_goal(SimpleNamespace(q=np.array([0.1, 0.2, -0.05])), robot)
    np.testing.assert_array_equal(sol.q, [0.1, 0.2, -0.05])


def test_tie_in_bound_and_residual_goes_to_the_solution_found_first():
    """On a flat bound map, two elbows both converged far inside a 1 mm tolerance (residuals of
    order 0.1 um, set by where least squares stopped) are a tie: the choice goes to the solution
    the seeded starts found first, not to the smaller residual, whose order is rounding noise."""
    from types import SimpleNamespace

    robot = fake_robot()
    target = fake_tip(*robot.configuration(np.array([0.4, 1.6, -0.06])))

    def flat(robot_, alpha, beta, settings=None):
        p = 1e-3
        return SimpleNamespace(position=p, angle=p, translation_last_position=p, translation_last_angle=p,
                               diagnostics=SimpleNamespace(converged=True, unstable=False))

    field = compute_field(robot, flat, (12, 6, 3), progress=False)
    sol = resolve_goal(TaskSpaceGoal(tuple(target), 1e-3), robot, lambda q: True, field=field,
                       solve_standard=fake_solve_standard, seed=0)
    assert len(sol.candidates) >= 2
    np.testing.assert_array_equal(sol.candidate_bounds, sol.candidate_bounds[0])
    assert np.all(sol.candidate_errors < 1e-6)
    assert np.argmin(sol.candidate_errors) != 0   # the smaller residual is not the first found
    np.testing.assert_array_equal(sol.q, sol.candidates[0])
