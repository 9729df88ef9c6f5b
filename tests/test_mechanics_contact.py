"""Clearance model (Section II) and friction model (Section III) of Ha et al. 2019."""

import numpy as np
import pytest

from ctrplan.mechanics import (ModelSettings, all_eta, evaluate_bound, solve_clearance,
                               solve_friction, solve_standard)
from ctrplan.mechanics._lie import angle_between
from ctrplan.robot import Joint, Robot, Section, Tube

from _robots import table1_pair, table2_robot

FAST = ModelSettings(ds=2e-3)


def _tip_gap(robot, q, clearance_m, settings):
    r = table1_pair(clearance=clearance_m) if robot is None else robot(clearance_m)
    alpha, beta = r.configuration(q)
    std = solve_standard(r, alpha, beta, settings)
    cl = solve_clearance(r, alpha, beta, settings, standard=std)
    assert cl.diagnostics.converged, cl.diagnostics.message
    return np.linalg.norm(cl.tip_position - std.tip_position)


def test_converges_to_the_standard_model_as_clearance_shrinks():
    """Table I pair at 1 rad: tip difference decreases monotonically over 1.0, 0.3, 0.1,
    0.03 mm. The 17 mm transmission section leaves a slowly vanishing entry effect
    (Section IV-B), so the decrease is checked as a strong reduction, not to zero."""
    gaps = [_tip_gap(None, [1.0], c * 1e-3, FAST) for c in (1.0, 0.3, 0.1, 0.03)]
    assert all(a > b for a, b in zip(gaps, gaps[1:])), gaps
    assert gaps[-1] < 0.25 * gaps[0]


def _pair_without_transmission(clearance):
    k, kappa = 5.07e-2, 1 / 0.15
    t1 = Tube("tube 1", (Section(0.15, (0.0, kappa)),), k, 0.3, inner_diameter=1e-3 + 2 * clearance)
    t2 = Tube("tube 2", (Section(0.15, (0.0, kappa)),), k, 0.3, outer_diameter=1e-3)
    return Robot("pair", (t1, t2), (0.0,), (Joint("rotation", 1, -np.pi, np.pi),))


def test_converges_to_zero_without_transmission_section():
    """Without a collar the difference vanishes like sqrt(c)."""
    gaps = np.array([_tip_gap(_pair_without_transmission, [1.0], c * 1e-3, FAST) for c in (0.1, 0.01)])
    assert gaps[1] < 0.5 * gaps[0]
    assert gaps[1] < 0.05e-3


def test_agrees_with_the_standard_model_where_tubes_do_not_touch():
    """Aligned equal precurvatures: the tubes conform without contact forces."""
    robot = table1_pair(clearance=0.1e-3)
    alpha, beta = robot.configuration([0.0])
    std = solve_standard(robot, alpha, beta, FAST)
    cl = solve_clearance(robot, alpha, beta, FAST, standard=std)
    np.testing.assert_allclose(cl.tip_position, std.tip_position, atol=1e-9)
    assert np.max(cl.contact_force) < 1e-9


def test_constraints_and_complementarity_hold():
    robot = table2_robot()
    alpha, beta = robot.configuration([2.0, 1.0, -0.06])
    cl = solve_clearance(robot, alpha, beta, FAST)
    c = robot.clearances[cl.contact_pair]
    assert np.all(cl.contact_gap <= c * (1 + 1e-3))                 # Eq. (19)
    active = cl.contact_force > 1e-6 * cl.contact_force.max()
    np.testing.assert_allclose(cl.contact_gap[active], c[active], rtol=1e-3)  # f_k > 0 => |d| = c
    assert np.all(cl.contact_force >= 0)


def test_distal_contact_forces_form_the_straightening_couple():
    """Table I pair at 180 deg, clearance 0.05 mm: the distal contact forces form a couple of
    about k_xy * precurvature = 5.07e-2 N m^2 / 0.15 m = 0.338 N m (Section IV-C, Fig. 10).
    At a 0.5 mm step the discretized couple is within 10 % (0.31 N m; it rises towards the
    paper's value as the step shrinks)."""
    robot = table1_pair(clearance=0.05e-3)
    alpha, beta = robot.configuration([np.pi])
    cl = solve_clearance(robot, alpha, beta, ModelSettings(ds=0.5e-3))
    s_outer, p_outer = cl.s[0], cl.centerlines[0]
    node = np.array([np.argmin(np.abs(s_outer - s)) for s in cl.contact_s])
    distal = cl.contact_s > 0.1
    F = cl.contact_force[:, None] * cl.contact_direction
    couple = np.cross(p_outer[node[distal]] - p_outer[-1], F[distal]).sum(axis=0)
    assert np.linalg.norm(couple) == pytest.approx(5.07e-2 / 0.15, rel=0.10)
    # a point force at the tip and an opposite distribution just proximal to it
    assert cl.contact_force[np.argmax(cl.contact_s)] > 10.0


def test_friction_model_is_continuous_in_mu_at_zero():
    """At mu = 1e-3 each of the four friction solutions of the Table II robot lies within a
    small, first-order distance of the clearance solution, and is not the clearance solution.

    The friction terms (Eqs. (38)-(41)) are linear in mu, so the tip moves by mu D + O(mu^2):
    doubling mu to 2e-3 must double the distance (to 1 %; the O(mu) relative correction is
    about 1e-3 here, and the outer loop is run to 1e-9 m so that its stopping test does not
    blur the ratio). The distance itself must be clearly above the solver's tolerance (the
    solutions differ) and below 0.1 mm (a friction effect of 1/200 of the bound's, which is
    about 9 mm at mu = 0.2 here). Catches: a friction term that does not vanish with mu (a jump
    at mu -> 0), friction ignored for small mu, or a friction path that returns the clearance
    solution unchanged (the old test's mu = 0 solve was that solve by construction)."""
    robot = table2_robot()
    alpha, beta = robot.configuration([2.0, 1.0, -0.06])
    settings = FAST.replace(outer_tol=1e-9)
    cl = solve_clearance(robot, alpha, beta, settings)
    for eta in all_eta(3):
        dist = []
        for mu in (1e-3, 2e-3):
            fr = solve_friction(robot, alpha, beta, eta, settings, mu=[mu, mu], warm_start=cl)
            assert fr.diagnostics.converged, fr.diagnostics.message
            dist.append(np.linalg.norm(fr.tip_position - cl.tip_position))
        assert 100 * settings.outer_tol < dist[0] < 0.1e-3, (eta, dist)
        assert dist[1] / dist[0] == pytest.approx(2.0, rel=0.01), (eta, dist)


def test_twist_between_friction_directions_grows_monotonically_with_mu():
    """Table I pair at 1.0, 2.0 and 2.8 rad: the relative tip twist of the eta = -1 solution minus
    that of eta = +1 is zero without friction and grows strictly with mu over 0.05, 0.1, 0.2,
    0.4 (friction torques and forces scale with mu, Eqs. (38), (41)). Catches a friction term
    with the wrong sign or one that saturates or ignores mu."""
    for theta in (1.0, 2.0, 2.8):
        spread = []
        for mu in (0.0, 0.05, 0.1, 0.2, 0.4):
            robot = table1_pair(clearance=0.05e-3, mu=mu)
            alpha, beta = robot.configuration([theta])
            cl = solve_clearance(robot, alpha, beta, FAST)
            ccw = solve_friction(robot, alpha, beta, [1], FAST, warm_start=cl)
            cw = solve_friction(robot, alpha, beta, [-1], FAST, warm_start=cl)
            assert ccw.diagnostics.converged and cw.diagnostics.converged
            spread.append(_tip_twist(cw) - _tip_twist(ccw))
        assert abs(spread[0]) < 1e-12, spread
        assert all(a < b for a, b in zip(spread, spread[1:])), (theta, spread)


def _tip_twist(sol):
    """Relative rotation of the inner tube's frame w.r.t. the outer tube's at the tip [rad]."""
    R1, R2 = sol.frames[0][-1], sol.frames[1][-1]
    Rrel = R1.T @ R2
    return np.arctan2(Rrel[1, 0], Rrel[0, 0])


@pytest.mark.parametrize("theta", [1.0, 2.0, 2.8])
def test_friction_directions_bracket_the_frictionless_twist(theta):
    """Tube pair: the tip twist of the eta = +1 and -1 solutions brackets the frictionless one
    (Section III; Fig. 19), and the CCW prior rotation leaves less twist at the tip."""
    robot = table1_pair(clearance=0.05e-3, mu=0.2)
    alpha, beta = robot.configuration([theta])
    cl = solve_clearance(robot, alpha, beta, FAST)
    ccw = solve_friction(robot, alpha, beta, [1], FAST, warm_start=cl)
    cw = solve_friction(robot, alpha, beta, [-1], FAST, warm_start=cl)
    assert ccw.diagnostics.converged and cw.diagnostics.converged
    t0, tp, tm = _tip_twist(cl), _tip_twist(ccw), _tip_twist(cw)
    assert tp < t0 < tm


def test_friction_solutions_mirror_at_180_degrees():
    robot = table1_pair(clearance=0.05e-3, mu=0.2)
    alpha, beta = robot.configuration([np.pi])
    a = solve_friction(robot, alpha, beta, [1], FAST)
    b = solve_friction(robot, alpha, beta, [-1], FAST)
    np.testing.assert_allclose(b.tip_position, a.tip_position * [1, -1, 1], atol=1e-6)
    assert abs(a.tip_position[1]) > 1e-3  # friction moves the tip sideways (Fig. 7)


def test_friction_spread_grows_with_mu():
    spreads = []
    for mu in (0.05, 0.2, 0.4):
        robot = table1_pair(clearance=0.05e-3, mu=mu)
        alpha, beta = robot.configuration([2.0])
        a = solve_friction(robot, alpha, beta, [1], FAST)
        b = solve_friction(robot, alpha, beta, [-1], FAST)
        spreads.append(np.linalg.norm(a.tip_position - b.tip_position))
    assert spreads[0] < spreads[1] < spreads[2]


def test_bound_covers_all_directions_and_matches_its_parts():
    robot = table2_robot()
    alpha, beta = robot.configuration([2.0, 1.0, -0.06])
    bound = evaluate_bound(robot, alpha, beta, FAST)
    assert bound.diagnostics.converged
    assert sorted(bound.friction) == sorted(all_eta(3)) and len(bound.friction) == 4
    dists = [np.linalg.norm(f.tip_position - bound.standard.tip_position) for f in bound.friction.values()]
    assert bound.position == pytest.approx(max(dists))
    assert bound.angle == pytest.approx(max(float(angle_between(f.tip_tangent, bound.standard.tip_tangent))
                                            for f in bound.friction.values()))
    assert bound.translation_last_position == pytest.approx(
        np.linalg.norm(bound.clearance.tip_position - bound.standard.tip_position))


def test_bound_without_friction_is_the_translation_last_bound():
    robot = table2_robot(mu=0.0)
    alpha, beta = robot.configuration([1.0, -2.0, -0.05])
    bound = evaluate_bound(robot, alpha, beta, FAST)
    assert bound.position == pytest.approx(bound.translation_last_position, abs=1e-12)
