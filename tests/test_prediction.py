"""History-aware prediction (:func:`ctrplan.mechanics.predict_tip`), the history of planned paths
(:mod:`ctrplan.planning.approach`) and compensated targeting
(:func:`ctrplan.planning.aiming.compensate_goal`); Section V-B of Ha, Fagogenis & Dupont 2019.

All on the Table II robot built in code (``tests/_robots.py``), seeded or fixed configurations;
the whole file runs in about 10 s.
"""

import numpy as np
import pytest

from ctrplan.errors import JointLimitError
from ctrplan.history import PairState
from ctrplan.mechanics import (ModelSettings, PAIR_CASES, all_eta, evaluate_bound, predict_tip, solve_clearance,
                               solve_friction)
from ctrplan.planning.aiming import compensate_goal
from ctrplan.planning.approach import approach_history, end_with, goal_indices, path_history
from ctrplan.planning.ordering import OrderedPath, OrderedWaypoint

from _robots import table2_robot

SETTINGS = ModelSettings(ds=3e-3)
Q = [2.0, 1.0, -0.06]           # a configuration where the four friction solutions differ by mm


@pytest.fixture(scope="module")
def robot():
    return table2_robot()


@pytest.fixture(scope="module")
def bound(robot):
    alpha, beta = robot.configuration(Q)
    return evaluate_bound(robot, alpha, beta, SETTINGS)


# ------------------------------------------------------------------------------ predict_tip
def test_without_friction_the_prediction_is_the_clearance_solution():
    """mu = 0 on every pair: whatever the directions, the prediction is the clearance model.
    Catches a prediction that solves friction with the directions but ignores mu (or uses a
    default mu instead of the robot's)."""
    robot = table2_robot(mu=0.0)
    alpha, beta = robot.configuration(Q)
    cl = solve_clearance(robot, alpha, beta, SETTINGS)
    for eta in all_eta(3):
        p = predict_tip(robot, alpha, beta, eta, False, SETTINGS)
        assert p.model == "clearance" and p.cases == ("frictionless", "frictionless")
        np.testing.assert_allclose(p.tip_position, cl.tip_position, atol=1e-9)
        np.testing.assert_array_equal(p.mu, [0.0, 0.0])


def test_translation_last_prediction_is_the_clearance_solution(robot, bound):
    """Translation-last on every pair releases friction (Section V-B): the tip is the clearance
    model's, several mm from the friction solutions here. Catches a translation-last flag that is
    ignored."""
    alpha, beta = robot.configuration(Q)
    for eta in ((1, 1), (-1, 1)):
        p = predict_tip(robot, alpha, beta, eta, True, SETTINGS)
        assert p.model == "clearance" and p.cases == ("translation_last", "translation_last")
        np.testing.assert_allclose(p.tip_position, bound.clearance.tip_position, atol=1e-9)
        np.testing.assert_allclose(p.offset, bound.translation_last_position, atol=1e-9)
    # the test is not vacuous: friction moves the tip by more than 0.5 mm from the clearance solution
    assert max(np.linalg.norm(f.tip_position - bound.clearance.tip_position) for f in bound.friction.values()) > 5e-4


def test_full_histories_are_the_bounding_solutions(robot, bound):
    """eta = +-1 per pair, no translation after: the prediction is the friction solution of
    ``evaluate_bound`` for that eta (same tip), and the largest offset over the four histories is
    the bound. Catches a sign error in eta (the +1 and -1 solutions are mm apart) and a wrong
    mapping of eta to pairs."""
    alpha, beta = robot.configuration(Q)
    offsets = []
    for eta in all_eta(3):
        p = predict_tip(robot, alpha, beta, eta, False, SETTINGS)
        assert p.model == "friction" and p.cases == ("friction", "friction") and not p.reused
        np.testing.assert_array_equal(p.eta, eta)
        np.testing.assert_allclose(p.tip_position, bound.friction[eta].tip_position, atol=2e-6)
        offsets.append(p.offset)
        # with the bound given, its solution is reused (no solve) and is the same
        r = predict_tip(robot, alpha, beta, eta, False, SETTINGS, bound=bound)
        assert r.reused and r.solution is bound.friction[eta]
    assert max(offsets) == pytest.approx(bound.position, abs=2e-6)
    tips = np.array([bound.friction[e].tip_position for e in all_eta(3)])
    assert np.max(np.linalg.norm(tips[:, None] - tips[None], axis=2)) > 1e-3   # the directions matter here


def test_partial_history_releases_only_its_pairs(robot, bound):
    """A pair that has not rotated (eta 0) or whose rotation was followed by a translation gets
    mu = 0, the other keeps its friction: the prediction is the friction solution with mu =
    (0, mu_2), not the clearance nor the full friction solution. Catches a partial history
    treated as all-or-nothing (as one flag per sample would)."""
    alpha, beta = robot.configuration(Q)
    ref = solve_friction(robot, alpha, beta, (1, -1), SETTINGS, mu=(0.0, 0.2), warm_start=bound.clearance)
    for eta, tl, case in (((0, -1), False, "no_history"), ((1, -1), (True, False), "translation_last"),
                          ((-1, -1), np.array([True, False]), "translation_last")):
        p = predict_tip(robot, alpha, beta, eta, tl, SETTINGS, bound=bound)
        assert p.cases == (case, "friction") and p.model == "friction" and not p.reused
        np.testing.assert_array_equal(p.eta, [0, -1])
        np.testing.assert_array_equal(p.mu, [0.0, 0.2])
        np.testing.assert_allclose(p.tip_position, ref.tip_position, atol=2e-6)
    assert np.linalg.norm(ref.tip_position - bound.clearance.tip_position) > 2e-4
    assert np.linalg.norm(ref.tip_position - bound.friction[(1, -1)].tip_position) > 2e-5
    assert set(PAIR_CASES) == {"friction", "translation_last", "no_history", "frictionless"}


def test_bad_history_input_raises(robot):
    """Wrong shapes or values of eta / translation_last raise ValueError naming them; an
    impossible configuration raises JointLimitError. Catches silent broadcasting of a short eta."""
    alpha, beta = robot.configuration(Q)
    with pytest.raises(ValueError, match=r"eta must have shape \(2,\)"):
        predict_tip(robot, alpha, beta, (1, 1, 1), False, SETTINGS)
    with pytest.raises(ValueError, match="eta values must be -1, 0 or \\+1"):
        predict_tip(robot, alpha, beta, (1, 2), False, SETTINGS)
    with pytest.raises(ValueError, match=r"translation_last must be one bool or shape \(2,\)"):
        predict_tip(robot, alpha, beta, (1, 1), (True, False, True), SETTINGS)
    with pytest.raises(ValueError, match="translation_last must hold booleans"):
        predict_tip(robot, alpha, beta, (1, 1), (0.5, 1.0), SETTINGS)
    with pytest.raises(JointLimitError):
        predict_tip(robot, alpha, np.array([0.0, -0.017, 0.01]), (1, 1), False, SETTINGS)


# ------------------------------------------------------------------------------ history of a path
def test_path_history_tracks_eta_and_translation_last_per_pair(robot):
    """A hand-made ordered path: rotate both pairs, translate, rotate tube 3 only, translate,
    rotate tube 3 back. Pair 1 stays released after the first translation although pair 2 rotates
    later (per-pair flags); eta follows the last relative rotation. Catches one flag per sample
    and eta taken from absolute instead of relative angles."""
    q = np.array([[0.0, 0.0, -0.07],     # start: no history
                  [1.0, 0.0, -0.07],     # alpha_2 up: rel 1 (a2 - a1) +, rel 2 (a3 - a2) -
                  [1.0, 0.0, -0.06],     # translation
                  [1.0, -1.0, -0.06],    # alpha_3 down: rel 2 -, rel 1 unchanged
                  [1.0, -1.0, -0.05],    # translation
                  [1.0, -0.5, -0.05]])   # alpha_3 up: rel 2 +
    h = path_history(robot, q)
    np.testing.assert_array_equal(h.eta, [[0, 0], [1, -1], [1, -1], [1, -1], [1, -1], [1, 1]])
    np.testing.assert_array_equal(h.released, [[False, False], [False, False], [True, True],
                                               [True, False], [True, True], [True, False]])
    # a translation below the 0.1 mm threshold does not release
    h2 = path_history(robot, np.array([[0.0, 0.0, -0.07], [1.0, 0.0, -0.07], [1.0, 0.0, -0.07 + 5e-5]]))
    np.testing.assert_array_equal(h2.released[-1], [False, False])
    with pytest.raises(ValueError, match=r"q must have shape \(K, 3\)"):
        path_history(robot, np.zeros((4, 2)))


def test_approach_history_follows_the_final_motion_and_the_short_way(robot):
    """From the start to a goal: translation-last releases every pair, rotation-last keeps the
    directions, which follow the short way round (+3 rad then -3 rad on alpha_3 - alpha_2 = -6 rad
    read the short way is +0.28 rad: eta +1). Catches the long way round and a swapped order."""
    s = approach_history(robot, [0.0, 0.0, -0.07], [1.0, 3.0, -0.06], "translation-last")
    np.testing.assert_array_equal(s.eta, [1, 1])
    np.testing.assert_array_equal(s.released, [True, True])
    s = approach_history(robot, [0.0, 0.0, -0.07], [1.0, -1.0, -0.06], "rotation-last")
    np.testing.assert_array_equal(s.eta, [1, -1])
    np.testing.assert_array_equal(s.released, [False, False])
    # alpha_3 from +3 to -3 rad: the short way is +0.28 rad (across pi), so rel 2 rises: eta +1
    s = approach_history(robot, [0.0, 3.0, -0.07], [0.0, -3.0, -0.07], "rotation-last")
    np.testing.assert_array_equal(s.eta, [0, 1])
    # with the motion before: pair 1 rotated earlier, so it has a direction although the
    # segment does not rotate it
    s = approach_history(robot, [0.0, 3.0, -0.07], [0.0, -3.0, -0.07], "rotation-last",
                         before=[[-0.5, 3.0, -0.07], [0.0, 3.0, -0.07]])
    np.testing.assert_array_equal(s.eta, [1, 1])
    with pytest.raises(ValueError, match="final_motion must be one of"):
        approach_history(robot, [0.0, 0.0, -0.07], [1.0, 3.0, -0.06], "rotation_last")


def test_end_with_swaps_the_last_two_phases_or_says_why_not(robot):
    """rotation-last on a path that ends rotation -> translation swaps the two phases (same end,
    rotations last, the middle waypoint has the translation done and the rotations not); a check
    that rejects the new phases leaves the path unchanged and says so. Catches a wrong middle
    waypoint (e.g. the old one relabelled)."""
    a, mid, b = np.array([0.0, 0.0, -0.07]), np.array([1.0, -1.0, -0.07]), np.array([1.0, -1.0, -0.05])
    path = OrderedPath([OrderedWaypoint("start", a), OrderedWaypoint("rotation", mid),
                        OrderedWaypoint("translation", b)])
    new, status = end_with(path, 2, "rotation-last")
    assert status == "reordered" and new.motions == ["start", "translation", "rotation"]
    np.testing.assert_array_equal(new.q, [a, [0.0, 0.0, -0.05], b])
    same, status = end_with(path, 2, "translation-last")
    assert status == "already" and same is path
    rejected, status = end_with(path, 2, "rotation-last", motion_check=lambda p, q: False)
    assert status.startswith("rejected") and rejected is path
    short = OrderedPath([OrderedWaypoint("start", a), OrderedWaypoint("translation", np.array([0.0, 0.0, -0.05]))])
    assert end_with(short, 1, "rotation-last")[1].startswith("impossible")
    assert goal_indices(path, [np.array([1.0, -1.0 + 2 * np.pi, -0.05])], robot) == [2]


# ------------------------------------------------------------------------------ compensation
def test_compensated_goal_puts_the_predicted_tip_on_the_target(robot):
    """The standard-model IK solution misses the target by the predicted offset (mm); the
    compensated configuration brings the predicted tip within 10 um, for a translation-last
    (clearance) and a rotation-last (friction, eta (+1, -1)) approach. Catches a compensation
    that moves toward the standard tip instead of the predicted one, and a sign error of the
    step."""
    q_std = np.array([2.0, 1.0, -0.06])
    alpha, beta = robot.configuration(q_std)
    from ctrplan.mechanics import solve_standard

    target = solve_standard(robot, alpha, beta, SETTINGS).tip_position     # standard IK exact at q_std
    for eta, tl, model in (((1, -1), True, "clearance"), ((1, -1), False, "friction")):
        c = compensate_goal(target, robot, q_std, PairState.abrupt(eta, tl), SETTINGS, tolerance=1e-3)
        assert c.model == model and c.accepted and c.converged, c.message
        assert c.predicted_miss < 1e-5
        assert c.predicted_miss_standard > 5e-4                                # the uncompensated miss is real
        p = predict_tip(robot, *robot.configuration(c.q), eta, tl, SETTINGS)   # independent re-check
        assert np.linalg.norm(p.tip_position - target) < 1e-5
        assert c.standard_tip_error == pytest.approx(np.linalg.norm(p.standard.tip_position - target), abs=1e-9)
        assert c.iterations <= 8
    # an invalid compensated configuration is not used
    c = compensate_goal(target, robot, q_std, PairState.abrupt((1, -1), True), SETTINGS, tolerance=1e-3,
                        validity_fn=lambda q: False)
    assert not c.accepted and "invalid" in c.message
    np.testing.assert_array_equal(c.q, q_std)
    with pytest.raises(ValueError, match="tolerance must be > 0"):
        compensate_goal(target, robot, q_std, PairState.abrupt((1, -1), True), SETTINGS, tolerance=0.0)


# ------------------------------------------------------------------------------ drive backlash
def test_a_dead_band_shifts_the_prediction_by_the_band_and_compensation_removes_it(robot):
    """A robot file with a 5 deg dead band on tube 2's drive (friction off: only the play acts).
    Approaching the same commanded alpha_2 from below and from above moves the predicted tip by
    |d tip/d alpha_2| x 5 deg, half of it on each side of the drive centred in its band; the
    Jacobian is the standard model's, by central differences here. Compensated targeting with
    the approach's history puts the predicted tip within a 0.5 mm tolerance where the
    uncompensated goal misses it. Catches a prediction that ignores the file's backlash, a lag of
    the whole band (or of none) on each side, a lag of the wrong sign, and a compensation that
    ignores the state."""
    from ctrplan.mechanics import solve_standard

    band = float(np.deg2rad(5.0))
    r = robot.replace(friction_coefficients=(0.0, 0.0), effects=(("backlash", (("backlash_2", band),)),))
    goal = np.array([2.0, 1.0, -0.06])
    alpha, beta = r.configuration(goal)
    below = approach_history(r, goal - [0.4, 0.0, 0.0], goal)          # the drive last turned +: the tube lags
    above = approach_history(r, goal + [0.4, 0.0, 0.0], goal)
    assert below.alpha_offset[1] == pytest.approx(-band / 2) and above.alpha_offset[1] == pytest.approx(band / 2)
    p_below = predict_tip(r, alpha, beta, settings=SETTINGS, state=below)
    p_above = predict_tip(r, alpha, beta, settings=SETTINGS, state=above)
    centred = predict_tip(r, alpha, beta, settings=SETTINGS, state=PairState(
        np.zeros(3), np.zeros(3), below.eta, below.released, below.friction))

    def tip(a2):
        a = alpha.copy()
        a[1] = a2
        return solve_standard(r, a, beta, SETTINGS).tip_position

    h = 1e-4
    jac = (tip(alpha[1] + h) - tip(alpha[1] - h)) / (2 * h)               # d tip / d alpha_2 [m/rad]
    np.testing.assert_allclose(p_above.tip_position - p_below.tip_position, jac * band, rtol=0.05,
                               atol=0.02 * np.linalg.norm(jac) * band)
    for p, side in ((p_below, -1), (p_above, +1)):
        np.testing.assert_allclose(p.tip_position - centred.tip_position, side * jac * band / 2, rtol=0.05,
                                   atol=0.02 * np.linalg.norm(jac) * band)
    with pytest.raises(ValueError, match="history effects"):
        predict_tip(r, alpha, beta, (1, -1), False, SETTINGS)
    # compensated targeting: the standard-model IK goal for this target misses by the lag
    target = tip(alpha[1])
    start = goal - [0.4, 0.0, 0.0]
    c = compensate_goal(target, r, goal, lambda q: approach_history(r, start, q), SETTINGS, tolerance=0.5e-3)
    assert c.accepted and c.predicted_miss < 0.5e-3, c.message
    assert c.predicted_miss_standard > 0.5e-3
    again = predict_tip(r, *r.configuration(c.q), settings=SETTINGS, state=approach_history(r, start, c.q))
    assert np.linalg.norm(again.tip_position - target) < 0.5e-3
