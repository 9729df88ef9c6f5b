import numpy as np
import pytest

from ctrplan.errors import UnreachableGoalError
from ctrplan.boundmap import compute_field
from ctrplan.planning import IKSearch, TaskGoal, resolve_goal
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

    field = compute_field(robot, bound, (24, 8, 3))
    sol = resolve_goal(TaskGoal(target, 1e-4), robot, lambda q: True, field=field,
                       solve_standard=fake_solve_standard, search=IKSearch(seed=0))
    assert sol.tip_error < 1e-4
    np.testing.assert_allclose(fake_tip(*robot.configuration(sol.q)), target, atol=1e-4)
    assert len(sol.candidates) >= 2  # the mirrored elbow also reaches the target
    assert sol.bound == pytest.approx(np.nanmin(sol.candidate_bounds))


def test_unreachable_names_target_in_mm():
    robot = fake_robot()
    with pytest.raises(UnreachableGoalError, match=r"\(100\.00, 0\.00, 50\.00\) mm; best distance reached"):
        resolve_goal({"tip_position_m": [0.1, 0.0, 0.05], "tolerance_m": 1e-3}, robot,
                     solve_standard=fake_solve_standard, search=IKSearch(starts_per_joint=2))


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

    field = compute_field(robot, flat, (12, 6, 3))
    sol = resolve_goal(TaskGoal(target, 1e-3), robot, lambda q: True, field=field,
                       solve_standard=fake_solve_standard, search=IKSearch(seed=0))
    assert len(sol.candidates) >= 2
    np.testing.assert_array_equal(sol.candidate_bounds, sol.candidate_bounds[0])
    assert np.all(sol.candidate_errors < 1e-6)
    assert np.argmin(sol.candidate_errors) != 0   # the smaller residual is not the first found
    np.testing.assert_array_equal(sol.q, sol.candidates[0])


def test_one_goal_type_pair_for_scenarios_and_planning():
    """The scenario loader and the planning package share JointGoal and TaskGoal (catches a
    second goal type drifting from the first); the types store read-only float arrays and refuse
    malformed values; dicts in scenario-file form and bare joint vectors become them."""
    import ctrplan.io.scenario as scenario
    import ctrplan.planning as planning

    assert planning.JointGoal is scenario.JointGoal and planning.TaskGoal is scenario.TaskGoal
    g = planning.TaskGoal([0.01, 0.0, 0.2])
    assert g.tolerance == 1e-3 and g.tip_position.dtype == float and not g.tip_position.flags.writeable
    with pytest.raises(ValueError, match="tip_position must be 3 finite numbers"):
        planning.TaskGoal([0.01, 0.2])
    with pytest.raises(ValueError, match="tolerance must be a finite distance > 0"):
        planning.TaskGoal([0.01, 0.0, 0.2], 0.0)
    with pytest.raises(ValueError, match="finite joint values"):
        planning.JointGoal([0.1, float("nan")])
    t = planning.as_goal({"tip_position_m": [0.01, 0.0, 0.2], "tolerance_m": 2e-3})
    assert isinstance(t, planning.TaskGoal) and t.tolerance == 2e-3
    j = planning.as_goal([0.1, 0.2, -0.05])
    assert isinstance(j, planning.JointGoal) and j.q.tolist() == [0.1, 0.2, -0.05]
    assert planning.as_goal({"q": [0.1]}).q.tolist() == [0.1]
    with pytest.raises(ValueError, match="needs 'q'"):
        planning.as_goal({"tip": [0, 0, 0]})


def test_the_former_names_warn_and_give_the_one_types():
    """ctrplan.planning.PlanResult and TaskSpaceGoal still resolve, with a DeprecationWarning,
    to SearchResult and to a TaskGoal made from the old keywords (catches scripts broken by the
    renaming without a word)."""
    import ctrplan.planning as planning

    with pytest.warns(DeprecationWarning, match="use ctrplan.planning.SearchResult"):
        assert planning.PlanResult is planning.SearchResult
    with pytest.warns(DeprecationWarning, match=r"use ctrplan.planning.TaskGoal\(tip_position, tolerance\)"):
        make = planning.TaskSpaceGoal
    g = make(tip_position_m=(0.01, 0.0, 0.2), tolerance_m=2e-3)
    assert isinstance(g, planning.TaskGoal) and g.tolerance == 2e-3
    with pytest.raises(AttributeError):
        planning.NoSuchName


def test_the_functions_renamed_to_one_meaning_per_name_warn_and_give_the_new_ones():
    """A script written against the former names still runs, warned: ``ctrplan.planning.plan``
    (one search, not ``ctrplan.plan``); ``ctrplan.pipeline``'s stages, now in ``ctrplan.planning``,
    among them ``load_bound_map``, ``time_parameterize`` and ``write_report`` under their new names
    (not the map reader, the waypoint timing or the discrepancy report); and
    ``ctrplan.boundmap.evaluate_configuration`` (not ``ctrplan.batch``'s)."""
    import ctrplan.boundmap as boundmap
    import ctrplan.pipeline as pipeline
    import ctrplan.planning as planning

    for module, old, new in ((planning, "plan", planning.plan_leg),
                             (pipeline, "load_bound_map", planning.prepare_bound_map),
                             (pipeline, "time_parameterize", planning.drive_trajectory),
                             (pipeline, "write_report", planning.write_plan_report),
                             (pipeline, "run_stages", planning.run_stages),
                             (pipeline, "PlanSetup", planning.PlanSetup),
                             (boundmap, "evaluate_configuration", boundmap.node_values)):
        home = "ctrplan.planning" if module is pipeline else module.__name__
        with pytest.warns(DeprecationWarning, match=f"use {home}.{new.__name__}"):
            assert getattr(module, old) is new
    for module in (pipeline, planning, boundmap):
        with pytest.raises(AttributeError):
            module.no_such_stage
