"""Interactive planning (ctrplan.Planner): one goal after another on the shipped obstacles
scenario, with a small roadmap stored in a temporary cache."""

from pathlib import Path

import numpy as np
import pytest

import ctrplan
from ctrplan.errors import UnreachableGoalError
from ctrplan.io.scenario import load_scenario
from ctrplan.mechanics import solve_standard
from ctrplan.trajectory import check_trajectory

REPO = Path(__file__).resolve().parents[1]
N_NODES = 150


@pytest.fixture(scope="module")
def planner(tmp_path_factory):
    return ctrplan.Planner.from_scenario(REPO / "scenarios" / "obstacles.toml", n_nodes=N_NODES,
                                         cache_dir=tmp_path_factory.mktemp("roadmaps"))


def _random_valid(planner, rng):
    js = planner.joint_space
    lo = np.where(js.periodic, -np.pi, js.lower)
    hi = np.where(js.periodic, np.pi, js.upper)
    while True:
        q = lo + rng.random(len(lo)) * (hi - lo)
        if planner.checks.search(q):
            return q


def _pure_phases(planner, ordered):
    rot = planner.joint_space.is_rotation
    for k in range(1, len(ordered.q)):
        d = planner.joint_space.difference(ordered.q[k - 1], ordered.q[k])
        moving = ~rot if ordered.motions[k] == "translation" else rot
        assert np.all(np.abs(d[~moving]) < 1e-9), (k, ordered.motions[k], d)


def test_goals_one_after_another(planner):
    """Three joint goals in turn, each from where the previous one ended: every plan starts at the
    current configuration, reaches its goal (modulo 2 pi on periodic joints), has pure rotation and
    translation phases, a drive trajectory that passes every check, and the exact bound at each
    waypoint; the planner then stands at the goal. Catches a plan from the scenario's start
    instead of the current configuration, or an unchecked trajectory."""
    rng = np.random.default_rng(11)
    assert planner.roadmap.n_nodes == N_NODES and planner.roadmap_source == "built"
    np.testing.assert_array_equal(planner.current, load_scenario(REPO / "scenarios" / "obstacles.toml").start)
    js = planner.joint_space
    for _ in range(3):
        before = planner.current.copy()
        goal = _random_valid(planner, rng)
        plan = planner.plan_to(goal)
        np.testing.assert_allclose(js.difference(plan.ordered.q[0], before), 0.0, atol=1e-12)
        np.testing.assert_allclose(js.difference(plan.ordered.q[-1], goal), 0.0, atol=1e-9)
        _pure_phases(planner, plan.ordered)
        assert check_trajectory(plan.trajectory) == []
        assert plan.bounds.position.shape == (len(plan.ordered.q),) and np.all(np.isfinite(plan.bounds.position))
        assert plan.max_bound_m >= plan.final_bound_m > 0.0
        assert plan.via in ("roadmap", "search") and plan.times_s["total"] > 0.0
        np.testing.assert_array_equal(planner.current, goal)


def test_task_space_goal_is_reached_within_its_tolerance(planner):
    """A tip position with a tolerance is solved by inverse kinematics: the goal's standard-model
    tip is within the tolerance of the target."""
    robot = planner.robot
    q = _random_valid(planner, np.random.default_rng(3))
    target = solve_standard(robot, *robot.configuration(q)).tip_position
    plan = planner.plan_to({"tip_position_m": target.tolist(), "tolerance_m": 1e-3}, move=False)
    tip = solve_standard(robot, *robot.configuration(plan.goal)).tip_position
    assert np.linalg.norm(tip - target) <= 1e-3
    with pytest.raises(UnreachableGoalError):
        planner.plan_to({"tip_position_m": [0.0, 0.0, 1.0], "tolerance_m": 1e-3}, move=False)


def test_roadmap_is_read_from_the_cache(planner):
    """A second planner with the same robot, map, obstacles and settings reads the stored roadmap
    (same states); other settings build another one."""
    folder = planner.roadmap_path.parent
    again = ctrplan.Planner(planner.setup, planner.field, n_nodes=N_NODES, cache_dir=folder)
    assert again.roadmap_source == "cache" and again.roadmap_path == planner.roadmap_path
    np.testing.assert_array_equal(again.roadmap.nodes, planner.roadmap.nodes)
    other = ctrplan.Planner(planner.setup, planner.field, n_nodes=N_NODES, seed=7, cache_dir=folder)
    assert other.roadmap_source == "built" and other.roadmap_path != planner.roadmap_path


def test_a_goal_the_roadmap_does_not_reach_is_planned_by_search(planner, monkeypatch):
    """When the roadmap joins no path, the scenario's single-query planner plans the goal, and the
    result passes the same checks."""
    def disconnected(*args, **kwargs):
        raise UnreachableGoalError("no path through the roadmap")

    monkeypatch.setattr(type(planner.roadmap), "query", disconnected)
    goal = _random_valid(planner, np.random.default_rng(5))
    plan = planner.plan_to(goal, move=False)
    assert plan.via == "search"
    np.testing.assert_allclose(planner.joint_space.difference(plan.ordered.q[-1], goal), 0.0, atol=1e-9)
    assert check_trajectory(plan.trajectory) == []
