"""Stage functions of :mod:`ctrplan.planning`: each returns a frozen result in SI values (m, rad),
and the report (``plan_summary``, ``write_plan_report``) alone converts to mm and degrees.

The stages run on the Table VII robot with a synthetic constant bound field (friction 1 mm,
0.1 rad; translation-last 0.5 mm, 0.05 rad), so no bound map is read or computed and each test
takes seconds. ``test_pipeline`` checks the whole run's outputs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan import planning
from ctrplan.boundmap import BoundField, map_coordinates, uniform_axis
from ctrplan.errors import UnreachableGoalError
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import solve_standard
from ctrplan.planning import JointStateSpace
from ctrplan.planning.verify import DEFAULT_MAX_BODY_STEP

REPO = Path(__file__).resolve().parents[1]
TABLE7 = REPO / "model" / "ha2019-table7-calibrated.toml"
SYNTHETIC = (1e-3, 0.1, 5e-4, 0.05)   # position [m], angle [rad], translation-last position, angle


def _field(robot, resolution=(4, 4, 3)):
    coords = map_coordinates(robot)
    axes = [uniform_axis(lo, hi, n, per) for lo, hi, n, per in zip(coords.lower, coords.upper, resolution,
                                                                     coords.periodic)]
    shape = tuple(len(a) for a in axes)
    values = np.broadcast_to(np.array(SYNTHETIC), shape + (4,)).copy()
    return BoundField(axes, coords.periodic, values, np.ones(shape, bool), key="synthetic", coordinates=coords)


def _write(tmp_path, goals: str, obstacles: str = "", name: str = "stages", output: str = "") -> Path:
    text = f"""
name = "{name}"
robot = "{TABLE7.as_posix()}"

[start]
q = {{alpha_2 = 0.0, alpha_3 = 0.0, beta_3 = -0.07}}
{goals}
{obstacles}
[planner]
name = "RRTstar"
iterations = 20
seed = 1
bound_weight = 500.0

[bound_field]
resolution = [4, 4, 3]
ds_m = 0.004
{output}
[drive]
control_rate_hz = 250.0
max_velocity = {{alpha_2 = 1.0, alpha_3 = 1.0, beta_3 = 0.01}}
max_acceleration = {{alpha_2 = 4.0, alpha_3 = 4.0, beta_3 = 0.04}}
max_jerk = {{alpha_2 = 40.0, alpha_3 = 40.0, beta_3 = 0.4}}
"""
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


JOINT_GOAL = """
[[goals]]
type = "joint"
q = {alpha_2 = 0.6, alpha_3 = -0.4, beta_3 = -0.06}
"""


def test_load_setup_keeps_the_step_in_metres_and_the_default_output_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    setup = planning.load_setup(_write(tmp_path, JOINT_GOAL))
    assert setup.settings.ds == pytest.approx(0.004, rel=1e-12)       # ds_m = 0.004, not 4
    assert setup.check_settings.ds == setup.settings.ds and setup.check_settings.multistart == 0
    assert setup.spec.resolution == (4, 4, 3)
    np.testing.assert_allclose(setup.scenario.start, [0.0, 0.0, -0.07], atol=0)
    assert setup.out_dir == Path("out") / "stages"
    assert planning.load_setup(_write(tmp_path, JOINT_GOAL), tmp_path / "o").out_dir \
        == tmp_path / "o"


def test_a_task_goal_given_in_metres_is_resolved_to_a_tip_within_its_tolerance_in_metres(tmp_path):
    """The goal's tip position and tolerance are in m; the resolved joint vector's standard-model
    tip (solved here, independently of the stage) is within the tolerance, the stage's tip error
    is that distance in m, and the field's bound there is the synthetic 1 mm, in m."""
    robot = load_robot(TABLE7)
    q_true = np.array([1.0, 0.5, -0.05])
    alpha, beta = robot.configuration(q_true)
    setup_probe = planning.load_setup(_write(tmp_path, JOINT_GOAL, name="probe"))
    target = solve_standard(robot, alpha, beta, setup_probe.check_settings).tip_position
    goal = f"""
[[goals]]
type = "task"
tip_position_m = [{float(target[0])!r}, {float(target[1])!r}, {float(target[2])!r}]
tolerance_m = 1.0e-3
"""
    setup = planning.load_setup(_write(tmp_path, goal))
    field = _field(setup.robot)
    validity = planning.check_start(setup, field)
    resolved = planning.resolve_goals(setup, field, validity)
    (g,) = resolved.goals
    a, b = setup.robot.configuration(g.q)
    tip = solve_standard(setup.robot, a, b, setup.check_settings).tip_position
    miss = float(np.linalg.norm(tip - target))
    assert miss <= 1e-3, miss
    assert g.tip_error == pytest.approx(miss, abs=1e-6)
    assert g.bound == pytest.approx(SYNTHETIC[0], rel=1e-9)
    assert resolved.time_s > 0
    # joint goals come back from the aiming stage as resolved (no compensation, nothing to say)
    setup_j = planning.load_setup(_write(tmp_path, JOINT_GOAL, name="joint"))
    resolved_j = planning.resolve_goals(setup_j, field, validity)
    aimed = planning.aim_goals(setup_j, resolved_j, validity)
    np.testing.assert_array_equal(aimed.q[0], [0.6, -0.4, -0.06])
    assert aimed.compensations == (None,) and dict(aimed.errors) == {}


def test_check_start_rejects_a_start_in_collision(tmp_path):
    robot = load_robot(TABLE7)
    setup = planning.load_setup(_write(tmp_path, JOINT_GOAL, name="free"))
    field = _field(robot)
    assert planning.check_start(setup, field)(setup.scenario.start)   # control: free start is valid
    alpha, beta = robot.configuration(setup.scenario.start)
    tip = solve_standard(robot, alpha, beta, setup.check_settings).tip_position
    sphere = f"""
[[obstacles]]
type = "sphere"
center_m = [{float(tip[0])!r}, {float(tip[1])!r}, {float(tip[2])!r}]
radius_m = 0.004
"""
    blocked = planning.load_setup(_write(tmp_path, JOINT_GOAL, sphere, name="blocked"))
    with pytest.raises(UnreachableGoalError, match="start configuration"):
        planning.check_start(blocked, field)


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """Stages 1-6 on a short joint-space move with the synthetic field (20 RRT* iterations)."""
    tmp_path = tmp_path_factory.mktemp("stages")
    setup = planning.load_setup(_write(tmp_path, JOINT_GOAL), tmp_path / "out")
    bound_map = planning.given_bound_map(setup, _field(setup.robot))
    validity = planning.check_start(setup, bound_map.field)
    resolved = planning.resolve_goals(setup, bound_map.field, validity)
    aimed = planning.aim_goals(setup, resolved, validity)
    plans = planning.plan_routes(setup, bound_map.field, aimed, compare_blind=True, n_jobs=1)
    traj = planning.drive_trajectory(setup, plans.aware.ordered)
    run = planning.PlanRun(setup=setup, bound_map=bound_map, goal_checks=planning.GoalCheckCounts.of(validity),
                           resolved=resolved, aimed=aimed, plans=plans, trajectory=traj,
                           waypoints=planning.waypoint_table(plans.aware, setup.calibration.bound),
                           comparison=planning.compare_plans(plans),
                           goals=planning.goal_outcomes(setup.robot, bound_map.field, aimed, plans.aware), time_s=1.5)
    return setup, bound_map, validity, resolved, aimed, plans, traj, run


def test_plan_routes_returns_bounds_and_lengths_in_si_units(planned):
    setup, _, _, _, aimed, plans, _, _ = planned
    assert list(plans.routes) == ["bound_aware", "bound_blind"] and not plans.in_parallel
    for plan in plans.routes.values():
        ordered = plan.ordered
        np.testing.assert_allclose(ordered.q[0], setup.scenario.start, atol=1e-12)
        np.testing.assert_allclose(ordered.q[-1], aimed.q[-1], atol=1e-9)      # the planned goal is reached
        # the map's bound of each waypoint's motion, in m (synthetic: 1 mm friction, 0.5 mm after a translation)
        expected = [SYNTHETIC[2] if m == "translation" else SYNTHETIC[0] for m in ordered.motions]
        np.testing.assert_allclose(plan.bounds.planned, expected, rtol=1e-12)
        np.testing.assert_allclose(plan.bounds.dense_given_last,
                                   [SYNTHETIC[2] if m == "translation" else SYNTHETIC[0]
                                    for m in plan.bounds.dense_motion], rtol=1e-12)
        # the path length is the joint-space length of the ordered waypoints [m of the metric]
        space = JointStateSpace(setup.robot)
        length = sum(space.distance(a, b) for a, b in zip(ordered.q[:-1], ordered.q[1:]))
        assert plan.bounds.dense_s[-1] == pytest.approx(length, rel=1e-9)
        assert plan.max_body_step_m == DEFAULT_MAX_BODY_STEP
        # exact bounds of the Table VII robot are millimetres, i.e. ~1e-3 in m, and angles in rad
        exact = plan.bounds.exact
        assert np.all((exact.position > 1e-5) & (exact.position < 0.03)), exact.position
        assert np.all((exact.angle > 0) & (exact.angle < 1.0)), exact.angle
        assert np.all(plan.prediction.offset[plan.prediction.ok] < 0.03)


def test_evaluation_stages_are_in_si_units(planned):
    """The waypoint table, the plans' metrics and the goal outcomes hold m and rad: the exact
    bounds of the Table VII robot (millimetres, i.e. ~1e-3) and the synthetic map's 1 mm as 1e-3."""
    setup, bound_map, _, _, aimed, plans, _, run = planned
    exact = plans.aware.bounds.exact
    table = run.waypoints
    assert len(table) == len(plans.aware.ordered) and table.q.shape == (len(table), 3)
    np.testing.assert_array_equal(table.bound_position_m, exact.position)
    np.testing.assert_array_equal(table.q, plans.aware.ordered.q)
    assert not table.q.flags.writeable                                    # frozen arrays
    assert np.all(np.isnan(table.calibrated_bound_m))                     # no [bound_calibration]
    assert list(table.bound_kind) == ["translation_last" if m == "translation" else "friction"
                                      for m in table.motion]
    aware, blind = run.comparison.aware, run.comparison.blind
    assert aware.max_bound_at_waypoints_m == np.nanmax(exact.position) and 1e-5 < aware.final_bound_m < 0.03
    assert aware.final_bound_angle_rad == exact.angle[-1]
    assert aware.max_interpolated_friction_bound_m == pytest.approx(SYNTHETIC[0], rel=1e-12)
    assert blind is not None and blind.joint_path_length_m == plans.routes["bound_blind"].bounds.dense_s[-1]
    (goal,) = run.goals
    assert goal.waypoint == plans.aware.goal_indices[0] == len(table) - 1
    assert goal.planned_field_bound_m == pytest.approx(SYNTHETIC[0], rel=1e-12)
    assert goal.predicted_miss_m is None and goal.planned_history_as_assumed is None   # a joint goal
    assert run.timings_s["total"] == 1.5 and run.timings_s["bound_map"] == 0.0


def test_report_stage_converts_the_si_results_to_mm_and_degrees_once(planned):
    setup, bound_map, validity, resolved, aimed, plans, traj, run = planned
    rows = planning.path_rows(run.waypoints)
    exact = plans.aware.bounds.exact
    assert [r["bound_position_m"] for r in rows] == [float(x) for x in exact.position]
    summary = planning.plan_summary(run)
    aware = summary["bound_aware"]
    assert aware["max_bound_at_waypoints_mm"] == pytest.approx(1e3 * np.nanmax(exact.position), rel=1e-12)
    assert aware["final_bound_angle_deg"] == pytest.approx(np.degrees(exact.angle[-1]), rel=1e-12)
    assert aware["final_check"]["max_body_step_mm"] == pytest.approx(1e3 * DEFAULT_MAX_BODY_STEP)
    assert aware["joint_path_length_m"] == plans.aware.bounds.dense_s[-1]            # m stays m
    assert summary["goals"][0]["field_bound_planned_mm"] == pytest.approx(1e3 * SYNTHETIC[0], rel=1e-12)
    assert summary["bound_map"]["ds_m"] == setup.settings.ds
    assert summary["duration_s"] == traj.duration and summary["times_s"]["total"] == 1.5
    assert summary["bound_map"]["source"] == "given" and summary["bound_map"]["time_s"] == 0.0
    assert set(summary["comparison"]["final_bound_mm"]) == {"bound_aware", "bound_blind"}
    # the summary read back in SI units gives the plans' metrics again
    import json

    path = setup.out_dir.parent / "summary-back.json"
    path.write_text(json.dumps(summary))
    record = planning.read_plan_record(path)
    assert record.time_s == 1.5
    for back, metrics in ((record.comparison.aware, run.comparison.aware),
                          (record.comparison.blind, run.comparison.blind)):
        assert back.max_bound_at_waypoints_m == pytest.approx(metrics.max_bound_at_waypoints_m, rel=1e-12)
        assert back.final_bound_angle_rad == pytest.approx(metrics.final_bound_angle_rad, rel=1e-12)
        assert (back.cost, back.repairs, back.failures) == (metrics.cost, metrics.repairs, metrics.failures)


def test_report_writes_the_plan_view_with_one_step_per_waypoint_in_mm(planned, monkeypatch):
    """``write_plan_report`` writes ``plan.html`` beside the other outputs: one slider step per ordered
    waypoint, the standard centerline and friction tips of the exact bound in mm, the joint
    goal's tip as the target."""
    import re

    from ctrplan.planning.outputs import view

    setup, bound_map, validity, resolved, aimed, plans, traj, run = planned
    captured = {}
    write = view.write_plan_view

    def spy(path, frames, **kw):          # keeps what write_plan_report gives the view, and writes it
        captured.update(kw, frames=frames)
        return write(path, frames, **kw)

    monkeypatch.setattr(view, "write_plan_view", spy)
    written = planning.write_plan_report(run)
    html = written["plan.html"].read_text(encoding="utf-8")
    K = len(plans.aware.ordered)
    assert len(re.findall(r'"method":\s*"update"', html)) == K
    assert not re.search(r"<script[^>]*src=[\"']?https?:", html)
    fig = view.plan_view_figure(**captured)
    exact = plans.aware.bounds.exact
    for k in (0, K - 1):
        (std,) = [t for t in fig.data if t.name == f"standard (waypoint {k})"]
        np.testing.assert_allclose(np.column_stack([std.x, std.y, std.z]),
                                   1e3 * exact.results[k].standard.centerline, atol=1e-4)
        (tips,) = [t for t in fig.data if t.name == f"friction tips (waypoint {k})"]
        np.testing.assert_allclose(np.column_stack([tips.x, tips.y, tips.z]),
                                   1e3 * np.array([f.tip_position for f in exact.results[k].friction.values()]),
                                   atol=1e-4)
        assert len(tips.x) == 2 ** (setup.robot.n_tubes - 1)
    pred = plans.aware.prediction
    ok = np.flatnonzero(pred.ok)
    assert ok.size and all(np.allclose(pred.shape[k][-1], pred.tip[k]) for k in ok)  # shape ends at the tip
    (target,) = [t for t in fig.data if t.name == "targets"]
    gi = plans.aware.goal_indices[0]
    np.testing.assert_allclose([target.x[0], target.y[0], target.z[0]],
                               1e3 * exact.results[gi].standard.tip_position, atol=1e-4)


SPHERE_AWAY = """
[[obstacles]]
type = "sphere"
center_m = [0.05, 0.05, 0.05]
radius_m = 0.005
"""


def _count_builds(monkeypatch):
    """Counts of the constructions of the joint space and the checkers from here on."""
    from ctrplan.planning import collision, space, validity, verify

    counts = {}
    for cls in (space.JointStateSpace, collision.CollisionChecker, validity.BatchValidityChecker,
                verify.MotionVerifier):
        init = cls.__init__

        def counted(self, *args, _init=init, _name=cls.__name__, **kwargs):
            counts[_name] = counts.get(_name, 0) + 1
            _init(self, *args, **kwargs)

        monkeypatch.setattr(cls, "__init__", counted)
    return counts


def test_a_plan_builds_its_checkers_and_joint_space_once_and_each_stage_counts_its_own_work(tmp_path, monkeypatch):
    """Stages 3 to 7 with both plans and an obstacle build the joint space and the checkers as
    often as one ``route_checks`` call does (the start, the goal and both plans share them); the
    goal stage's and the plans' counters add up to the shared checkers' totals, so no stage
    reports another's work; and the plans equal those of checkers built afresh for each."""
    from ctrplan.planning import route_checks

    setup = planning.load_setup(_write(tmp_path, JOINT_GOAL, SPHERE_AWAY))
    field = _field(setup.robot)
    counts = _count_builds(monkeypatch)
    route_checks(setup.robot, list(setup.obstacles), field, setup.check_settings)
    one = dict(counts)
    assert one == {"JointStateSpace": 1, "CollisionChecker": 2, "BatchValidityChecker": 2, "MotionVerifier": 1}
    counts.clear()
    run = planning.run_stages(setup, planning.given_bound_map(setup, field), compare_blind=True, n_jobs=1)
    assert counts == one
    assert setup.route_checks(field) is setup.route_checks(field)

    total = setup.route_checks(field).counters()
    plans = run.plans.routes.values()
    assert len(plans) == 2
    assert run.goal_checks.n_calls + sum(p.checks["validity_calls"] for p in plans) == total["validity_calls"]
    for key in ("final_check_states", "final_check_motions", "search_motions_checked"):
        assert sum(p.checks[key] for p in plans) == total[key] and all(p.checks[key] > 0 for p in plans), key
    # the states evaluated before the plans are the goal stage's (the start and the goal, not cached yet)
    assert 0 < total["search_states_evaluated"] - sum(p.checks["search_states_evaluated"] for p in plans) \
        <= run.goal_checks.n_calls

    # a copy of the setup (as another process gets it) has no checkers: it builds its own, and
    # plans the same paths with them
    import pickle

    fresh = pickle.loads(pickle.dumps(setup))
    assert "_route_checks" not in fresh.__dict__ and "joint_space" not in fresh.__dict__
    again = planning.plan_routes(fresh, field, run.aimed, compare_blind=True, n_jobs=1)
    for mode, plan in run.plans.routes.items():
        np.testing.assert_array_equal(again.routes[mode].ordered.q, plan.ordered.q)


def test_the_checkers_of_a_refined_map_share_the_collision_tests_and_decide_as_new_ones(tmp_path, monkeypatch):
    """A second map read by the same plan (a refined one) gets checkers of its own (its validity
    flags, an empty cache) that reuse the first checkers' collision tests and joint space instead
    of building them again, and that accept and reject the same states and motions as checkers
    built afresh for that map (catches a derived checker that keeps the first map's flags or cache,
    or loses its collision test)."""
    from ctrplan.planning import route_checks

    setup = planning.load_setup(_write(tmp_path, JOINT_GOAL, SPHERE_AWAY))
    first, second = _field(setup.robot), _field(setup.robot)
    valid = np.array(second.valid, copy=True)
    valid.reshape(-1)[::3] = False                       # the refined map rejects other nodes
    second = type(second)(second.axes, second.periodic, second.values, valid, key="second",
                          coordinates=second.coordinates)
    a = setup.route_checks(first)
    counts = _count_builds(monkeypatch)
    b = setup.route_checks(second)
    assert counts.get("CollisionChecker", 0) == 0 and counts.get("JointStateSpace", 0) == 0
    assert b.search.collision is a.search.collision and b.final.collision is a.final.collision
    assert b.search.field is second and b.final.field is second and b.search.joint_space is setup.joint_space
    fresh = route_checks(setup.robot, list(setup.obstacles), second, setup.check_settings)
    rng = np.random.default_rng(7)
    lo, hi = setup.robot.joint_lower, setup.robot.joint_upper
    q = rng.uniform(np.where(np.isfinite(lo), lo, -np.pi), np.where(np.isfinite(hi), hi, np.pi), (60, len(lo)))
    got, want = b.search.check(q), fresh.search.check(q)
    np.testing.assert_array_equal(got, want)
    assert 0 < want.sum() < len(want)                     # both kinds of state occur
    assert not np.array_equal(a.search.check(q), want)    # the first map decides otherwise
    for q0, q1 in zip(q[:8], q[8:16]):
        assert b.final.check(q0, q1).valid == fresh.final.check(q0, q1).valid
