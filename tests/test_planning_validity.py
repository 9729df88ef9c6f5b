"""Batched collision checking, batched validity and the OMPL motion validator, each against
the reference path (CollisionChecker.check_body, ValidityChecker, OMPL's own
DiscreteMotionValidator)."""

from pathlib import Path

import fcl
import numpy as np
import pytest
from ompl import base as ob, geometric as og, util as ou

from ctrplan.io.robot_file import load_robot
from ctrplan.io.scenario import load_scenario
from ctrplan.mechanics import ModelSettings, solve_standard_bodies
from ctrplan.planning import BoundCostObjective, CollisionChecker, JointStateSpace, ValidityChecker
from ctrplan.planning.validity import BatchValidityChecker, bisection_order, use_motion_validator
from test_planning_helpers import fake_robot

REPO = Path(__file__).resolve().parent.parent
# The pipeline's capsule length [m] (ctrplan.planning.COLLISION_SEGMENT).
SEGMENT = 5e-3
# Obstacles added to the scenario's mesh, sphere and box so that about a third of random states
# collide, and a capsule is among them.
EXTRA_OBSTACLES = [
    {"type": "capsule", "a_m": [-0.05, 0.03, 0.16], "b_m": [0.05, 0.03, 0.16], "radius_m": 0.008},
    {"type": "sphere", "center_m": [0.05, -0.03, 0.17], "radius_m": 0.01},
    {"type": "box", "center_m": [0.06, -0.04, 0.17], "size_m": [0.02, 0.03, 0.04], "rpy_rad": [0.3, 0.0, 0.5]},
]


@pytest.fixture(scope="module")
def scenario():
    sc = load_scenario(REPO / "scenarios" / "obstacles.toml")
    obstacles = [o.as_dict() for o in sc.obstacles] + EXTRA_OBSTACLES
    assert {o["type"] for o in obstacles} == {"mesh", "sphere", "box", "capsule"}
    settings = (ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()).replace(multistart=0)
    return sc.robot, obstacles, settings


def _random_q(robot, rng, m):
    lo, hi = robot.joint_lower, robot.joint_upper
    return lo + (hi - lo) * rng.random((m, lo.size))


def _bodies(robot, Q, settings):
    cfg = [robot.configuration(q) for q in Q]
    return solve_standard_bodies(robot, np.array([c[0] for c in cfg]), np.array([c[1] for c in cfg]), settings)


# ---------------------------------------------------------------------------- collision
@pytest.mark.parametrize("segment_length, padding", [(SEGMENT, 0.0), (2e-3, 3e-4)])
def test_collides_batch_equals_check_body(scenario, segment_length, padding):
    """320 random states of the obstacles scenario (mesh, sphere, box, capsule): the batched
    broad + narrow phase gives the answer of the capsule-manager reference for every body."""
    robot, obstacles, settings = scenario
    checker = CollisionChecker(obstacles, segment_length=segment_length, padding=padding)
    bodies = _bodies(robot, _random_q(robot, np.random.default_rng(3), 320), settings)
    hit = checker.collides_batch(bodies.points, bodies.radii, bodies.counts)
    ref = np.array([checker.check_body(*bodies.body(k)).collides for k in range(len(hit))])
    np.testing.assert_array_equal(hit, ref)
    assert 0.2 < ref.mean() < 0.5                     # enough colliding and free states
    # the broad phase culls: fewer narrow-phase calls than capsule-obstacle pairs, and states
    # that never reach FCL
    assert checker.n_batch_bodies == 320
    assert checker.n_batch_narrow_bodies < 320
    assert checker.n_batch_narrow_calls < 320 * len(obstacles)


def test_each_obstacle_type_alone(scenario):
    """Per obstacle, batch and reference agree; each type (mesh, sphere, box, capsule) is hit
    by some of the 200 states (the scenario's wall beyond the workspace by none)."""
    robot, obstacles, settings = scenario
    bodies = _bodies(robot, _random_q(robot, np.random.default_rng(5), 200), settings)
    hit_types = set()
    for obstacle in obstacles:
        checker = CollisionChecker([obstacle], segment_length=SEGMENT)
        hit = checker.collides_batch(bodies.points, bodies.radii, bodies.counts)
        ref = np.array([checker.check_body(*bodies.body(k)).collides for k in range(len(hit))])
        np.testing.assert_array_equal(hit, ref, err_msg=obstacle["type"])
        if ref.any():
            hit_types.add(obstacle["type"])
    assert hit_types == {"mesh", "sphere", "box", "capsule"}


def test_obstacle_boxes_contain_the_obstacles(scenario):
    _, obstacles, _ = scenario
    checker = CollisionChecker(obstacles)
    lo, hi = checker.obstacle_aabbs()
    assert lo.shape == hi.shape == (len(obstacles), 3)
    verts = checker.obstacles[0].triangles()[0]            # the mesh
    assert np.all(verts >= lo[0]) and np.all(verts <= hi[0])
    np.testing.assert_allclose(lo[1], np.array(obstacles[1]["center_m"]) - 0.006 - 1e-5)
    np.testing.assert_allclose(hi[2] - lo[2], np.array([0.2, 0.2, 0.01]) + 2e-5)


def test_single_point_empty_and_unknown_obstacles():
    """A one-point body is a ball (as in check_body); an empty body never collides; an obstacle
    of an unknown type is never culled; malformed input raises."""

    class CylinderObstacle:   # duck-typed obstacle without a known box
        def collision_object(self):
            return fcl.CollisionObject(fcl.Cylinder(0.002, 0.01), fcl.Transform(np.eye(3), np.array([0.0, 0, 0.1])))

    checker = CollisionChecker([{"type": "sphere", "center_m": [0.0, 0.0, 0.0], "radius_m": 0.001},
                                CylinderObstacle()])
    assert np.all(np.isinf(checker.obstacle_aabbs()[0][1]))
    points = np.zeros((4, 2, 3))
    points[1, 0] = [0.0025, 0.0, 0.0]       # one point 2.5 mm from the sphere centre: radius 1.6 mm hits
    points[2, 0] = [0.0030, 0.0, 0.0]       # 3 mm: misses
    points[3] = [[0.003, 0.0, 0.1], [0.004, 0.0, 0.1]]   # two points inside the cylinder
    radii = np.full((4, 2), 1.6e-3)
    counts = np.array([0, 1, 1, 2])
    hit = checker.collides_batch(points, radii, counts)
    ref = [False] + [checker.check_body(points[k, :counts[k]], radii[k, :counts[k]]).collides for k in (1, 2, 3)]
    np.testing.assert_array_equal(hit, ref)
    np.testing.assert_array_equal(hit, [False, True, False, True])
    with pytest.raises(ValueError, match="counts"):
        checker.collides_batch(points, radii, np.array([0, 1, 1, 3]))
    with pytest.raises(ValueError, match="shape|need"):
        checker.collides_batch(points, radii[:, :1], counts)
    assert not CollisionChecker([]).collides_batch(points, radii, counts).any()


# ---------------------------------------------------------------------------- states
class BandField:
    """Duck-typed field: invalid where 0.5 <= alpha_2 <= 1.0 rad (the first joint)."""

    def is_valid(self, q):
        q = np.asarray(q, dtype=float)
        return ~((q[..., 0] >= 0.5) & (q[..., 0] <= 1.0))


def _states_with_edge_cases(robot, rng, m):
    Q = _random_q(robot, rng, m)
    Q[:10, 2] = robot.joint_upper[2] + np.linspace(-2e-12, 1e-3, 10)   # at and beyond the limit
    Q[10:15, 2] = robot.joint_lower[2] - np.linspace(-2e-12, 1e-3, 5)
    Q[15, 0] = np.nan
    Q[16:20, 0] += 2 * np.pi                                          # periodic: not a limit
    return Q


def test_batch_checker_equals_validity_checker(scenario):
    """300 states (random, at and beyond joint limits, non-finite, periodic beyond pi) with a
    field band and the obstacles: the same decisions as the pipeline's ValidityChecker, with
    the cheaper tests first and a per-state cache."""
    robot, obstacles, settings = scenario
    collision = CollisionChecker(obstacles, segment_length=SEGMENT)
    field = BandField()
    reference = ValidityChecker(robot, collision=collision, field=field, settings=settings)
    checker = BatchValidityChecker(robot, collision=collision, field=field, settings=settings)
    Q = _states_with_edge_cases(robot, np.random.default_rng(9), 300)
    expected = np.array([reference(q) for q in Q])
    got = checker.check(Q)
    np.testing.assert_array_equal(got, expected)
    assert 0.2 < expected.mean() < 0.8
    assert checker.n_evaluations == 300
    assert checker.n_model < 300 and checker.n_collision_checked <= checker.n_model
    assert checker.seconds_model > 0.0 and checker.seconds_collision > 0.0
    # cache: single calls return real bools and evaluate nothing new
    values = [checker(q) for q in Q[:40]]
    assert all(type(v) is bool for v in values)
    assert values == expected[:40].tolist()
    assert checker.n_evaluations == 300 and checker.n_calls == 340
    with pytest.raises(ValueError, match="shape"):
        checker.check(np.zeros((2, 4)))


@pytest.mark.parametrize("check_stability", [True, False])
def test_stability_rule_equals_validity_checker(check_stability):
    """Six-joint robot with tube 3 turned about pi against tube 2 (unstable equilibria among
    them), no obstacles: the determinant test rejects exactly what ValidityChecker rejects."""
    robot = load_robot(REPO / "model" / "ha2019-table2-six-joint.toml")
    settings = ModelSettings(multistart=0)
    rng = np.random.default_rng(13)
    Q = _random_q(robot, rng, 400)
    a2, a3 = robot.joint_names.index("alpha_2"), robot.joint_names.index("alpha_3")
    Q[:, a3] = (Q[:, a2] + 2 * np.pi + rng.normal(0.0, 0.15, len(Q))) % (2 * np.pi) - np.pi
    screen = _bodies(robot, Q, settings)
    Q = np.vstack([Q[screen.unstable][:10], Q[~screen.unstable][:30]])
    reference = ValidityChecker(robot, settings=settings, check_stability=check_stability)
    checker = BatchValidityChecker(robot, settings=settings, check_stability=check_stability)
    expected = np.array([reference(q) for q in Q])
    np.testing.assert_array_equal(checker.check(Q), expected)
    assert expected.all() != check_stability          # some rejected only when checking stability


# ---------------------------------------------------------------------------- motions
def test_check_motion_equals_a_validity_checker_reference(scenario):
    """Motions of the obstacles scenario: the compiled checker and the reference mode driven by
    the pipeline's ValidityChecker give the same answers and evaluate the same states."""
    robot, obstacles, settings = scenario
    collision = CollisionChecker(obstacles, segment_length=SEGMENT)
    js = JointStateSpace(robot)
    compiled = BatchValidityChecker(robot, collision=collision, settings=settings, joint_space=js)
    reference = BatchValidityChecker(robot, joint_space=js,
                                     reference=ValidityChecker(robot, collision=collision, settings=settings))
    rng = np.random.default_rng(29)
    q0, q1 = _random_q(robot, rng, 16), _random_q(robot, rng, 16)
    q1 = q0 + js.difference(q0, q1) * np.minimum(1.0, 0.03 / js.distance(q0, q1))[:, None]
    answers = [compiled.check_motion(a, b) for a, b in zip(q0, q1)]
    assert answers == [reference.check_motion(a, b) for a, b in zip(q0, q1)]
    assert 0 < sum(answers) < len(answers)
    assert compiled.n_evaluations == reference.n_evaluations
    assert reference.seconds_reference > 0.0 and reference.seconds_model == 0.0


def _analytic_validity(q):
    """Joint-space obstacles for the fake robot: two discs in the (alpha_2, alpha_3) plane
    (periodic distance) and a slab of beta_3."""
    q = np.asarray(q, dtype=float)
    d = (q[:2] + np.pi) % (2 * np.pi) - np.pi
    if np.hypot(d[0] - 1.0, d[1] - 1.0) < 0.6 or np.hypot(d[0] + 2.0, d[1] - 0.5) < 0.5:
        return False
    return not (-0.06 < q[2] < -0.055 and d[0] > 0.0)


def _ompl_setup(js, resolution, validity):
    si = ob.SpaceInformation(js.space)
    si.setStateValidityChecker(lambda s: bool(validity(js.to_numpy(s))))
    si.setStateValidityCheckingResolution(min(1.0, resolution / js.space.getMaximumExtent()))
    return si


def test_bisection_order_is_ompls():
    assert bisection_order(0).tolist() == [1]
    assert bisection_order(1).tolist() == [1]
    assert bisection_order(6).tolist() == [6, 3, 1, 4, 2, 5]
    order = bisection_order(37)
    assert sorted(order.tolist()) == list(range(1, 38))


def test_motion_states_and_order_equal_ompls_discrete_motion_validator():
    """For 60 random motions (some across +-pi), the states checked and their order equal those
    OMPL's DiscreteMotionValidator passes to the state validity checker, and so does the
    segment count."""
    robot = fake_robot()
    js = JointStateSpace(robot)
    resolution = 2e-3
    seen = []
    si = _ompl_setup(js, resolution, lambda q: seen.append(q) or True)
    si.setup()
    checker = BatchValidityChecker(robot, joint_space=js, resolution=resolution, reference=lambda q: True)
    rng = np.random.default_rng(17)
    for _ in range(60):
        q0, q1 = _random_q(robot, rng, 2)
        q1 = q0 + (q1 - q0) * rng.random()
        q1[:2] = (q1[:2] + np.pi) % (2 * np.pi) - np.pi
        s0, s1 = js.from_numpy(q0), js.from_numpy(q1)
        seen.clear()
        assert si.checkMotion(s0, s1)
        n = js.space.validSegmentCount(s0, s1)
        assert checker.segment_count(q0, q1) == n
        ours = checker.motion_states(q0, q1)
        assert ours.shape == (max(n, 1), 3)
        np.testing.assert_allclose(ours, np.array(seen), atol=1e-12, rtol=0)
        # spacing at most the resolution in the weighted metric
        if n >= 1:
            step = js.distance(q0, js.interpolate(q0, q1, [1.0 / n])[0])
            assert step <= resolution + 1e-12


def test_check_motion_is_all_states_valid_with_early_exit():
    robot = fake_robot()
    js = JointStateSpace(robot)
    evaluated = []

    def recording(q):
        evaluated.append(np.array(q))
        return _analytic_validity(q)

    checker = BatchValidityChecker(robot, joint_space=js, resolution=2e-3, reference=recording)
    rng = np.random.default_rng(19)
    n_invalid = 0
    for _ in range(40):
        q0, q1 = _random_q(robot, rng, 2)
        expected = all(_analytic_validity(q) for q in checker.motion_states(q0, q1))
        assert checker.check_motion(q0, q1) == expected
        n_invalid += not expected
    assert 5 < n_invalid < 35
    # an invalid end state is the only state evaluated
    evaluated.clear()
    assert not checker.check_motion(np.array([-1.0, -1.0, -0.07]), np.array([1.0, 1.0, -0.07]))
    assert len(evaluated) == 1
    assert checker.n_motions == 41 and checker.n_invalid_motions == n_invalid + 1


def _plan(js, validity, resolution, seed, planner_name, iterations, with_motion_validator):
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        ou.RNG.setSeed(seed)
        checker = None
        if with_motion_validator:
            checker = BatchValidityChecker(js.robot, joint_space=js, resolution=resolution, reference=validity)
            si = ob.SpaceInformation(js.space)
            mv = use_motion_validator(si, js, checker)
        else:
            si = _ompl_setup(js, resolution, validity)
            mv = None
        si.setup()
        pdef = ob.ProblemDefinition(si)
        pdef.setStartAndGoalStates(js.from_numpy([0.0, 0.0, -0.07]), js.from_numpy([2.0, 2.0, -0.05]))
        # path length in the joint metric (OMPL's own length objective makes BITstar raise on
        # this compound space)
        pdef.setOptimizationObjective(BoundCostObjective(si, js, None, bound_weight=0.0))
        planner = getattr(og, planner_name)(si)
        planner.setProblemDefinition(pdef)
        planner.setup()
        planner.solve(ob.PlannerTerminationCondition(lambda: planner.numIterations() >= iterations))
        assert pdef.hasExactSolution()
        path = pdef.getSolutionPath()
        waypoints = np.array([js.to_numpy(path.getState(i)) for i in range(path.getStateCount())])
        return waypoints, mv, checker
    finally:
        ou.setLogLevel(level)


@pytest.mark.parametrize("planner_name, iterations", [("RRTstar", 300), ("BITstar", 150)])
def test_planner_uses_the_motion_validator_and_plans_the_same_path(planner_name, iterations, in_child_process):
    """Same seed, same validity function, same resolution: the plan with the batched motion
    validator equals OMPL's plan with its DiscreteMotionValidator state for state (the motion
    checks see the same states, so every answer is the same), and the validator was called."""
    if planner_name == "BITstar" and in_child_process():
        return
    robot = fake_robot()
    js = JointStateSpace(robot)
    plain, _, _ = _plan(js, _analytic_validity, 2e-3, 5, planner_name, iterations, False)
    batched, mv, checker = _plan(js, _analytic_validity, 2e-3, 5, planner_name, iterations, True)
    assert mv.n_checked > 0 and mv.n_invalid > 0
    assert checker.n_motions == mv.n_checked
    np.testing.assert_array_equal(batched, plain)
