import numpy as np
import pytest

from ctrplan.errors import UnreachableGoalError
from ctrplan.boundmap import compute_field
from ctrplan.planning import (PLANNERS, BoundCostObjective, JointStateSpace, SearchSettings, ValidityChecker,
                              order_path, plan_leg)
from test_planning_helpers import fake_bound, fake_robot, fake_solve_standard

START = np.array([-1.2, 0.0, -0.07])
GOAL = np.array([1.2, 0.0, -0.07])


@pytest.fixture(scope="module")
def setup():
    robot = fake_robot()
    field = compute_field(robot, fake_bound, (16, 16, 3))
    return robot, field


def dense_max_bound(robot, field, waypoints):
    js = JointStateSpace(robot)
    pts = np.vstack([js.interpolate(a, b, np.linspace(0, 1, 40)) for a, b in zip(waypoints[:-1], waypoints[1:])])
    return field(pts).max()


def test_reproducible_and_bound_aware(setup):
    robot, field = setup
    valid = ValidityChecker(robot, check_stability=False)
    aware = BoundCostObjective.factory(field, bound_weight=1000.0)
    r1 = plan_leg(robot, START, GOAL, valid, aware, iterations=300, seed=3)
    r2 = plan_leg(robot, START, GOAL, valid, aware, iterations=300, seed=3)
    np.testing.assert_array_equal(r1.waypoints, r2.waypoints)
    assert r1.cost == r2.cost and r1.iterations == 300 and r1.solved
    assert r1.cost <= r1.cost_before_simplification + 1e-12
    np.testing.assert_array_equal(r1.waypoints[0], START)
    blind = plan_leg(robot, START, GOAL, valid, BoundCostObjective.factory(None, bound_weight=0.0),
                     iterations=300, seed=3)
    # the bump (10.5 mm) sits between start and goal; the bound-aware path goes round it
    assert dense_max_bound(robot, field, blind.waypoints) > 8e-3
    assert dense_max_bound(robot, field, r1.waypoints) < 3e-3
    # goal reached modulo 2 pi on the periodic joints
    d = JointStateSpace(robot).difference(r1.waypoints[-1], GOAL)
    np.testing.assert_allclose(d, 0.0, atol=1e-9)


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_every_registered_planner_runs(setup, name, in_child_process):
    if name == "BITstar" and in_child_process():
        return
    robot, field = setup
    valid = ValidityChecker(robot, check_stability=False)
    r = plan_leg(robot, START, GOAL, valid, BoundCostObjective.factory(field, bound_weight=1000.0),
                 planner=name, iterations=60, seed=5)
    assert r.solved and r.planner == name and r.n_vertices >= 2


def test_validity_with_model_and_unreachable(setup):
    robot, _ = setup

    class Wall(ValidityChecker):
        def _evaluate(self, q):
            return super()._evaluate(q) and not (-0.06 < q[2] < -0.05)

    wall = Wall(robot, solve_standard=fake_solve_standard)
    with pytest.raises(UnreachableGoalError, match="no exact path"):
        plan_leg(robot, [0, 0, -0.04], [0, 0, -0.09], wall, BoundCostObjective.factory(None, bound_weight=0.0),
                 iterations=80, seed=1)
    with pytest.raises(UnreachableGoalError, match="goal configuration"):
        plan_leg(robot, [0, 0, -0.04], [0, 0, -0.055], wall, BoundCostObjective.factory(None, bound_weight=0.0),
                 iterations=10, seed=1)
    with pytest.raises(ValueError, match="unknown planner"):
        plan_leg(robot, START, GOAL, wall, BoundCostObjective.factory(None, bound_weight=0.0), planner="PRM")
    assert wall([0, 0, -0.04]) and not wall([0, 0, -0.2])  # joint limit
    assert wall.n_evaluations <= wall.n_calls


def test_ordered_segments_rotate_before_translating(setup):
    robot, field = setup
    valid = ValidityChecker(robot, check_stability=False)
    goal = np.array([1.0, 0.5, -0.04])
    r = plan_leg(robot, START, goal, valid, BoundCostObjective.factory(field), iterations=150, seed=2)
    js = JointStateSpace(robot)
    ordered = order_path(r.waypoints, robot, valid, joint_space=js)
    q = ordered.q
    assert ordered.motions[0] == "start"
    for k in range(1, len(q)):
        dq = q[k] - q[k - 1]
        assert ordered.motions[k] in ("rotation", "translation")
        moved = js.is_rotation if ordered.motions[k] == "rotation" else ~js.is_rotation
        assert np.all(dq[~moved] == 0.0), (k, ordered.motions[k], dq)   # only its own joints move
        assert np.any(dq[moved] != 0.0), (k, ordered.motions[k], dq)    # and something moves
    # every planned waypoint appears, and each segment is rotation then translation
    plan_pts = [tuple(p) for p in r.waypoints]
    idx = [i for i, p in enumerate(map(tuple, q)) if p in plan_pts]
    assert len(idx) == len(r.waypoints)
    # the goal changes every joint, so both phases occur somewhere (the checks below are not vacuous)
    assert {"rotation", "translation"} <= set(ordered.motions[1:])
    rot = js.is_rotation
    for a, b in zip(idx[:-1], idx[1:]):
        seg = ordered.motions[a + 1:b + 1]
        assert seg in (["rotation", "translation"], ["rotation"], ["translation"])
        if seg == ["rotation", "translation"]:
            # the corner of the L: rotations already at the segment's end, translations still at
            # its start (a translate-then-rotate order, or a corner off the segment, fails here)
            corner = q[a + 1]
            np.testing.assert_array_equal(corner[rot], q[b][rot])
            np.testing.assert_array_equal(corner[~rot], q[a][~rot])
    np.testing.assert_allclose(js.difference(q[-1], goal), 0.0, atol=1e-9)


def test_objective_in_a_plain_ompl_setup(setup):
    """The docs/planning.md recipe: BoundCostObjective in a hand-built OMPL problem."""
    from ompl import base as ob, geometric as og, util as ou

    robot, field = setup
    js = JointStateSpace(robot)
    ou.setLogLevel(ou.LOG_WARN)
    ou.RNG.setSeed(1)
    si = ob.SpaceInformation(js.space)
    si.setStateValidityChecker(lambda s: bool(field.is_valid(js.to_numpy(s))))
    si.setup()
    objective = BoundCostObjective(si, js, field, bound_weight=1000.0)
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(js.from_numpy(START), js.from_numpy(GOAL))
    pdef.setOptimizationObjective(objective)
    planner = og.InformedRRTstar(si)
    planner.setProblemDefinition(pdef)
    planner.setup()
    planner.solve(ob.PlannerTerminationCondition(lambda: planner.numIterations() >= 100))
    assert pdef.hasExactSolution()
    path = pdef.getSolutionPath()
    og.PathSimplifier(si, pdef.getGoal(), objective).partialShortcutPath(path)
    after = path.cost(objective).value()
    w = np.array([js.to_numpy(path.getState(i)) for i in range(path.getStateCount())])
    # the shortcut path still joins start and goal through valid motions
    np.testing.assert_allclose(js.difference(w[0], START), 0.0, atol=1e-12)
    np.testing.assert_allclose(js.difference(w[-1], GOAL), 0.0, atol=1e-12)
    assert all(si.checkMotion(path.getState(i), path.getState(i + 1)) for i in range(len(w) - 1))
    # a lower bound the cost must respect: every path is at least as long as the straight
    # start-goal distance, and the fake bound (a bump on a 0.5 mm floor, interpolated between
    # nodes >= 0.5 mm) adds at least w * 0.5 mm per unit length
    floor = 0.5e-3
    assert after >= (1.0 + 1000.0 * floor) * js.distance(START, GOAL) * (1 - 1e-12)
    # OMPL's path cost equals the numpy cost of the same waypoints
    assert objective.path_cost(w) == pytest.approx(after, rel=1e-9)
    # and a pre-built objective can be handed to plan_leg()
    r = plan_leg(robot, START, GOAL, lambda q: True, objective, iterations=50, seed=4, joint_space=js)
    assert r.solved


def test_compiled_motion_cost_equals_the_numpy_one(setup):
    """With a BoundField the objective's motion cost is one compiled call; it equals the numpy
    path (the same field behind a plain callable: interpolate, trapezoid rule) on random motions,
    across +-pi and for the plain length (weight 0)."""
    from ompl import base as ob

    robot, field = setup
    js = JointStateSpace(robot)
    si = ob.SpaceInformation(js.space)
    si.setStateValidityChecker(lambda s: True)
    si.setup()
    rng = np.random.default_rng(4)
    q0 = robot.joint_lower + rng.random((200, 3)) * (robot.joint_upper - robot.joint_lower)
    q1 = np.clip(q0 + rng.normal(0.0, 1.0, (200, 3)) * [1.5, 1.5, 0.02], [-9, -9, -0.104], [9, 9, -0.034])
    for w in (1000.0, 0.0):
        fast = BoundCostObjective(si, js, field if w else None, bound_weight=w)
        slow = BoundCostObjective(si, js, (lambda q: field(q)) if w else None, bound_weight=w)
        assert fast._kernel is not None and slow._kernel is None if w else True
        a = np.array([fast.segment_cost(x, y) for x, y in zip(q0, q1)])
        b = np.array([slow.segment_cost(x, y) for x, y in zip(q0, q1)])
        np.testing.assert_allclose(a, b, rtol=1e-12)
        assert fast.n_bound_evaluations == slow.n_bound_evaluations


def _linear_bound(robot, alpha, beta, settings=None):
    """Bound linear in the relative translation l_3 - l_1 only: 1 mm at -104 mm rising by
    0.05 m/m (4.5 mm at -34 mm); the multilinear map reproduces it exactly."""
    from types import SimpleNamespace

    p = LINEAR_B0 + LINEAR_SLOPE * (beta[2] - beta[0] + 0.104)
    return SimpleNamespace(position=p, angle=p, translation_last_position=p, translation_last_angle=p,
                           diagnostics=SimpleNamespace(converged=True, unstable=False))


_linear_bound.name = "linear-bound"
LINEAR_B0 = 1e-3        # [m]
LINEAR_SLOPE = 0.05     # [m of bound per m of translation]


def test_motion_cost_equals_a_hand_computation_on_a_linear_bound():
    """c = L + w * integral of b over the motion (objective.py; Sec. III bound). With a bound
    linear in beta_3 (exact in the map and under the trapezoid rule) the integral is
    L * (b(q0) + b(q1)) / 2 by hand, and L = sum_rot m_per_rad |d alpha| (short way round) +
    |d beta|. Checked for the compiled path (BoundField) and the numpy path (a plain callable).
    Catches: a wrong metric weight, the long way round +-pi, a missing factor L or w in the
    integral, the bound sampled at the wrong place."""
    from ompl import base as ob

    robot = fake_robot()
    field = compute_field(robot, _linear_bound, (8, 8, 3))
    m_per_rad, w = 0.05, 500.0
    js = JointStateSpace(robot, meters_per_radian=m_per_rad)
    si = ob.SpaceInformation(js.space)
    si.setStateValidityChecker(lambda s: True)
    si.setup()

    def b(beta3):
        return LINEAR_B0 + LINEAR_SLOPE * (beta3 + 0.104)

    cases = [
        # pure translation -90 -> -50 mm: L = 0.04 m
        (([0.3, -0.2, -0.09], [0.3, -0.2, -0.05]), 0.04 * (1 + w * 0.5 * (b(-0.09) + b(-0.05)))),
        # rotation 3.0 -> -3.0 rad goes the short way, 2 pi - 6 rad; bound constant
        (([3.0, -0.2, -0.07], [-3.0, -0.2, -0.07]), m_per_rad * (2 * np.pi - 6.0) * (1 + w * b(-0.07))),
        # both groups: L = 0.05 (1.0 + 0.5) + 0.06 m, bound linear along the motion
        (([0.1, 0.4, -0.10], [1.1, -0.1, -0.04]), (m_per_rad * 1.5 + 0.06) * (1 + w * 0.5 * (b(-0.10) + b(-0.04)))),
    ]
    direct = lambda q: b(np.atleast_2d(q)[:, 2])  # noqa: E731
    for bound in (field, direct):
        objective = BoundCostObjective(si, js, bound, bound_weight=w, sample_spacing=1e-3)
        for (q0, q1), expected in cases:
            assert objective.segment_cost(q0, q1) == pytest.approx(expected, rel=1e-12), (bound, q0, q1)
        path = np.array([c[0][0] for c in cases[:1]] + [[0.3, -0.2, -0.05], [1.0, -0.2, -0.05]])
        leg2 = m_per_rad * 0.7 * (1 + w * b(-0.05))
        assert objective.path_cost(path) == pytest.approx(cases[0][1] + leg2, rel=1e-12)


def test_search_settings_and_keywords_run_the_same_search(setup):
    """One search given as a SearchSettings and as keywords (planner parameters among them) is the
    same search: same waypoints and cost (catches a field of the settings that does not reach the
    planner, e.g. a range or a seed dropped on the way). A seed changed on top of the settings
    changes the search."""
    robot, field = setup
    valid = ValidityChecker(robot, check_stability=False)
    aware = BoundCostObjective.factory(field, bound_weight=1000.0)
    settings = SearchSettings(planner="RRTstar", iterations=200, seed=5, options={"range": 0.3, "goal_bias": 0.2})
    a = plan_leg(robot, START, GOAL, valid, aware, settings)
    b = plan_leg(robot, START, GOAL, valid, aware, planner="RRTstar", iterations=200, seed=5, range_=0.3, goal_bias=0.2)
    np.testing.assert_array_equal(a.waypoints, b.waypoints)
    assert a.cost == b.cost and a.iterations == 200
    c = plan_leg(robot, START, GOAL, valid, aware, settings, seed=6)
    assert c.cost != a.cost or not np.array_equal(c.waypoints, a.waypoints)


def test_search_settings_merge_and_refuse():
    """Keywords go on top of the settings (a planner parameter replaces the settings' value); the
    same parameter twice in one call, or an unknown keyword, is refused; a scenario's [planner]
    table gives its name, budget, seed, range, rewire factor and other declared parameters."""
    from ctrplan.io.scenario import PlannerSettings

    base = SearchSettings(iterations=50, options={"range": 0.5})
    assert SearchSettings.of(base, range_=0.3, seed=4) == SearchSettings(iterations=50, seed=4, options={"range": 0.3})
    assert SearchSettings.of(base, options={"goal_bias": None}).options == {"range": 0.5}
    with pytest.raises(ValueError, match="'range' given twice"):
        SearchSettings.of(base, options={"range": 0.2}, range_=0.3)
    with pytest.raises(TypeError, match="unknown search keyword.*iteration;"):
        SearchSettings.of(base, iteration=10)
    p = PlannerSettings(name="RRTstar", iterations=120, time_limit=2.0, seed=9, range=0.4, rewire_factor=0.2,
                        parameters={"goal_bias": 0.1})
    s = SearchSettings.from_scenario(p, iterations=7)
    assert (s.planner, s.iterations, s.time_limit, s.seed) == ("RRTstar", 7, 2.0, 9)
    assert s.options == {"range": 0.4, "rewire_factor": 0.2, "goal_bias": 0.1}
