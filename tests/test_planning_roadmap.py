"""The roadmap of interactive planning (ctrplan.planning.roadmap): its edges, costs, queries and
storage, on the analytic test robot with a bump in the bound between two goals."""

import numpy as np
import pytest

from ctrplan.boundmap import compute_field
from ctrplan.errors import UnreachableGoalError
from ctrplan.planning import JointStateSpace
from ctrplan.planning.roadmap import Roadmap, build_roadmap, motion_terms, prm_star_neighbours
from ctrplan.planning.validity import BatchValidityChecker
from test_planning_helpers import bump, fake_bound, fake_robot

START = np.array([-1.2, 0.0, -0.07])
GOAL = np.array([1.2, 0.0, -0.07])
WEIGHT = 1000.0


@pytest.fixture(scope="module")
def setup():
    robot = fake_robot()
    field = compute_field(robot, fake_bound, (16, 16, 3))
    js = JointStateSpace(robot)
    checker = BatchValidityChecker(robot, None, field, check_stability=False, joint_space=js)
    roadmap = build_roadmap(checker, js, field, n_nodes=300, seed=4)
    return robot, field, js, checker, roadmap


def _dense_max_bound(robot, js, waypoints):
    pts = np.vstack([js.interpolate(a, b, np.linspace(0, 1, 60)) for a, b in zip(waypoints[:-1], waypoints[1:])])
    return max(bump(np.array([0.0, q[0], q[1]]), None) for q in pts)


def test_edges_join_near_valid_states_with_valid_motions(setup):
    """Every state is valid, every edge joins a state to one of its k nearest and its motion is
    valid for a fresh checker, and the PRM* neighbour count is e (1 + 1/d) ln n rounded up.
    Catches edges between far states (a wrong distance or axis), unchecked motions or a checker
    that lets invalid states in."""
    robot, field, js, _, rm = setup
    fresh = BatchValidityChecker(robot, None, field, check_stability=False, joint_space=js)
    assert rm.n_nodes == 300 and rm.neighbours == int(np.ceil(np.e * (4 / 3) * np.log(300))) == prm_star_neighbours(300, 3)
    assert fresh.check(rm.nodes).all()
    assert np.all(rm.edges[:, 0] < rm.edges[:, 1]) and len({tuple(e) for e in rm.edges.tolist()}) == rm.n_edges
    dist = js.distance(rm.nodes[:, None, :], rm.nodes[None, :, :])
    np.fill_diagonal(dist, np.inf)
    kth = np.sort(dist, axis=1)[:, rm.neighbours - 1]
    for i, j in rm.edges[::7]:
        assert dist[i, j] <= max(kth[i], kth[j]) + 1e-15
        assert fresh.check_motion(rm.nodes[i], rm.nodes[j])
    assert rm.n_edges > 2 * rm.n_nodes


def test_edge_costs_are_length_plus_weighted_bound_along_the_executed_motion(setup):
    """An edge costs L + w I, I the integral of the friction bound along its rotations and of the
    translation-last bound along its translations after them (the motion the drive executes),
    checked each way against a fine midpoint rule on the map written out here (to 0.5 %): catches
    a cost along the straight segment, the phases' bounds swapped, the weight applied twice, the
    directions mixed up, or the long way round a periodic joint."""
    robot, field, js, _, rm = setup

    def executed(a, b):
        corner = np.where(js.is_rotation, a + js.difference(a, b), a)
        t = (np.arange(400) + 0.5) / 400
        rot = js.distance(a, corner) * np.mean(field(js.interpolate(a, corner, t), "position"))
        tr = js.distance(corner, b) * np.mean(field(js.interpolate(corner, b, t), "translation_last_position"))
        return rot + tr

    checked = 0
    for e in range(0, rm.n_edges, rm.n_edges // 40):
        i, j = rm.edges[e]
        a, b = rm.nodes[i], rm.nodes[j]
        assert rm.length[e] == pytest.approx(js.distance(a, b), rel=1e-12)
        assert rm.integral[e] == pytest.approx(executed(a, b), rel=5e-3)
        assert rm.integral_reverse[e] == pytest.approx(executed(b, a), rel=5e-3)
        assert rm.cost(WEIGHT)[e] == pytest.approx(rm.length[e] + WEIGHT * executed(a, b), rel=5e-3)
        checked += abs(executed(a, b) - executed(b, a)) > 0.02 * executed(a, b)
    assert checked > 0      # the two directions differ on some edges: the test sees a swap


def test_query_is_the_cheapest_roadmap_path(setup):
    """Without shortcutting, the query's cost is the least over all paths of the roadmap joined to
    the start and the goal, each motion at its cost in its direction, computed here by
    Bellman-Ford relaxation on the directed edge list (no scipy): catches a graph without the way
    back, the directions' costs swapped, dropped edges or a wrong predecessor walk."""
    robot, field, js, checker, rm = setup
    terms = motion_terms(js, field)
    path = rm.query(START, GOAL, checker, terms, js, bound_weight=WEIGHT, shortcut=False)

    def cost(a, b):
        length, integral = terms(a, b)
        return length + WEIGHT * integral

    n = rm.n_nodes
    edges = [(int(i), int(j), float(c)) for (i, j), c in zip(rm.edges, rm.cost(WEIGHT))]
    edges += [(int(j), int(i), float(c)) for (i, j), c in zip(rm.edges, rm.cost(WEIGHT, reverse=True))]
    order = np.argsort(js.distance(rm.nodes, START))[:rm.neighbours]
    edges += [(n, int(i), cost(START, rm.nodes[i])) for i in order if checker.check_motion(START, rm.nodes[i])]
    order = np.argsort(js.distance(rm.nodes, GOAL))[:rm.neighbours]
    edges += [(int(i), n + 1, cost(rm.nodes[i], GOAL)) for i in order if checker.check_motion(GOAL, rm.nodes[i])]
    if checker.check_motion(START, GOAL):
        edges.append((n, n + 1, cost(START, GOAL)))
    best = np.full(n + 2, np.inf)
    best[n] = 0.0
    for _ in range(n + 2):
        changed = False
        for u, v, c in edges:
            if best[u] + c < best[v] - 1e-15:
                best[v] = best[u] + c
                changed = True
        if not changed:
            break
    assert path.cost == pytest.approx(best[n + 1], rel=1e-12)
    assert path.cost_before_shortcut == pytest.approx(best[n + 1], rel=1e-12)
    np.testing.assert_array_equal(path.waypoints[0], START)
    np.testing.assert_array_equal(path.waypoints[-1], GOAL)
    # the path's cost is the sum of its motions' costs
    assert path.cost == pytest.approx(sum(cost(a, b) for a, b in zip(path.waypoints[:-1], path.waypoints[1:])),
                                      rel=1e-9)


def test_bound_aware_roadmap_goes_round_the_bump_and_shortcuts_only_downhill(setup):
    """The 10.5 mm bump sits between start and goal: the bound-aware roadmap path keeps the bound
    below 3 mm, the length-only query of the same roadmap (weight 0) crosses it above 8 mm; shortcutting
    never raises the cost. Catches a query that ignores the costs or a shortcut that is not
    cost-aware."""
    robot, field, js, checker, rm = setup
    aware = rm.query(START, GOAL, checker, motion_terms(js, field), js, bound_weight=WEIGHT)
    assert aware.cost <= aware.cost_before_shortcut + 1e-12
    assert _dense_max_bound(robot, js, aware.waypoints) < 3e-3
    blind = rm.query(START, GOAL, checker, motion_terms(js, field), js, bound_weight=0.0)
    assert _dense_max_bound(robot, js, blind.waypoints) > 8e-3


def test_disconnected_or_invalid_ends_are_unreachable(setup):
    """An invalid goal, and a goal beyond a wall no motion crosses, raise UnreachableGoalError with
    the reason."""
    robot, field, js, _, rm = setup
    wall = BatchValidityChecker(robot, None, field, check_stability=False, joint_space=js)
    wall._evaluate = lambda Q: np.abs(Q[:, 0]) > 0.3          # alpha_2 in (-0.3, 0.3) is invalid
    terms = motion_terms(js, field)
    with pytest.raises(UnreachableGoalError, match="goal configuration .* is invalid"):
        rm.query(START, np.array([0.0, 0.0, -0.07]), wall, terms, js, bound_weight=WEIGHT)
    # alpha_2 is periodic: the two sides of a wall at 0 meet across +-pi, so close that way too
    sub2 = BatchValidityChecker(robot, None, field, check_stability=False, joint_space=js)
    sub2._evaluate = lambda Q: ((Q[:, 0] < -0.3) & (Q[:, 0] > -2.8)) | ((Q[:, 0] > 0.3) & (Q[:, 0] < 2.8))
    walled = build_roadmap(sub2, js, field, n_nodes=150, seed=2)
    assert len(set(walled.components().tolist())) >= 2
    with pytest.raises(UnreachableGoalError, match="no path through the roadmap"):
        walled.query(np.array([-1.2, 0.0, -0.07]), np.array([1.2, 0.0, -0.07]), sub2, terms, js,
                     bound_weight=WEIGHT)


def test_two_processes_build_the_same_roadmap(setup):
    """Built on two processes, the roadmap is the one built here, bit for bit: catches chunks
    joined out of order or lost."""
    robot, field, js, checker, rm = setup
    fresh = BatchValidityChecker(robot, None, field, check_stability=False, joint_space=js)
    two = build_roadmap(fresh, js, field, n_nodes=300, seed=4, n_jobs=2)
    for name in ("nodes", "edges", "length", "integral", "integral_reverse"):
        np.testing.assert_array_equal(getattr(two, name), getattr(rm, name))


def test_save_and_load_round_trip(setup, tmp_path):
    """A stored roadmap reads back identical; another file is refused naming it."""
    *_, rm = setup
    path = rm.save(tmp_path / "r.npz")
    back = Roadmap.load(path)
    np.testing.assert_array_equal(back.nodes, rm.nodes)
    np.testing.assert_array_equal(back.edges, rm.edges)
    np.testing.assert_array_equal(back.length, rm.length)
    np.testing.assert_array_equal(back.integral, rm.integral)
    np.testing.assert_array_equal(back.integral_reverse, rm.integral_reverse)
    assert (back.neighbours, back.settings, back.draws) == (rm.neighbours, rm.settings, rm.draws)
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="other.npz"):
        Roadmap.load(tmp_path / "other.npz")
