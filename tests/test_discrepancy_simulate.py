"""ctrplan.discrepancy.simulate (models along a motion history) and .effects.

Motion history: eta_k of Eq. (38) of Ha, Fagogenis & Dupont 2019 (doi:10.1109/TRO.2018.2878906)
from the joint values, and the translation-last release of Section V-B. Simulation: branch
following of the standard model, the friction/clearance choice per sample, robustness to failing
samples, parallel = serial. Robots: tests/_robots.py at a coarse ds for speed.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctrplan.discrepancy import (Effects, apply_effects, apply_registration, motion_history,
                                 simulate)
from ctrplan.errors import ModelFileError, PhysicalParameterError
from ctrplan.io.tables import rotation_directions
from ctrplan.mechanics import ModelSettings, solve_clearance, solve_contact, solve_friction, solve_standard
from ctrplan.robot import Joint, Robot, Section, Tube

from _robots import table2_robot

DS = 0.004  # [m] coarse arc-length step, for speed
SETTINGS = ModelSettings(ds=DS)
PI = np.pi


def _configs(robot, q):
    a, b = zip(*[robot.configuration(x) for x in q])
    return np.array(a), np.array(b)


# --------------------------------------------------------------------------- motion_history
def _three_tube(alpha2, alpha3, beta3):
    K = len(alpha2)
    alpha = np.column_stack([np.zeros(K), alpha2, alpha3])
    beta = np.column_stack([np.zeros(K), np.full(K, -0.017), beta3])
    return alpha, beta


def test_history_reversal_and_translation_after_rotation():
    # alpha_2 up, then back down (reversal), then beta_3 moves, then alpha_2 moves again
    a2 = [0.0, 0.1, 0.2, 0.15, 0.1, 0.1, 0.1, 0.2]
    b3 = [-0.05, -0.05, -0.05, -0.05, -0.05, -0.06, -0.06, -0.06]
    alpha, beta = _three_tube(a2, np.zeros(8), b3)
    h = motion_history(alpha, beta, np.zeros(8, dtype=int))
    # pair 1: alpha_2 - alpha_1; pair 2: alpha_3 - alpha_2 = -alpha_2 (opposite direction)
    assert h.eta[:, 0].tolist() == [0, 1, 1, -1, -1, -1, -1, 1]
    assert h.eta[:, 1].tolist() == [0, -1, -1, 1, 1, 1, 1, -1]
    assert h.translation_last.tolist() == [False, False, False, False, False, True, True, False]
    assert np.array_equal(h.eta, rotation_directions(alpha))


def test_history_jitter_below_tolerance_neither_flips_nor_counts_as_rotation():
    a2 = [0.0, 0.2, 0.2 - 4e-4, 0.2 + 3e-4, 0.2, 0.2]
    b3 = [-0.05, -0.05, -0.05, -0.05, -0.052, -0.052]
    alpha, beta = _three_tube(a2, np.zeros(6), b3)
    h = motion_history(alpha, beta, np.zeros(6, dtype=int), rotation_tol=1e-3)
    assert h.eta[:, 0].tolist() == [0, 1, 1, 1, 1, 1]
    assert h.translation_last.tolist() == [False] * 4 + [True, True]


def test_history_translation_during_rotation_is_not_translation_last():
    a2 = np.linspace(0.0, 0.5, 6)
    b3 = np.linspace(-0.05, -0.06, 6)
    alpha, beta = _three_tube(a2, np.zeros(6), b3)
    h = motion_history(alpha, beta, np.zeros(6, dtype=int))
    assert not h.translation_last.any()
    assert h.eta[1:, 0].tolist() == [1] * 5


def test_history_new_sequence_resets_and_ids_may_interleave():
    a2 = [0.0, 0.3, 1.0, 0.6, 0.2, 1.2]
    seq = [0, 0, 1, 0, 1, 1]
    alpha, beta = _three_tube(a2, np.zeros(6), np.full(6, -0.05))
    h = motion_history(alpha, beta, seq)
    # sequence 0: rows 0, 1, 3 -> 0.0, 0.3, 0.6; sequence 1: rows 2, 4, 5 -> 1.0, 0.2, 1.2
    assert h.eta[:, 0].tolist() == [0, 1, 0, 1, -1, 1]
    none = motion_history(alpha, beta, None)
    assert not none.eta.any() and not none.translation_last.any()


def test_history_rejects_bad_inputs():
    alpha, beta = _three_tube([0.0, 0.1], [0.0, 0.0], [-0.05, -0.05])
    with pytest.raises(ValueError, match="integers"):
        motion_history(alpha, beta, [0.0, 0.5])
    with pytest.raises(ValueError, match="shape"):
        motion_history(alpha, beta[:, :2], [0, 0])
    with pytest.raises(ValueError, match="tolerances"):
        motion_history(alpha, beta, [0, 0], rotation_tol=0.0)


# --------------------------------------------------------------------------- simulate
@pytest.fixture(scope="module")
def robot():
    return table2_robot(mu=0.2)


@pytest.fixture(scope="module")
def path(robot):
    """A short continuous motion of the Table II robot (unique equilibria all along)."""
    K = 6
    q = np.column_stack([np.linspace(0.2, 1.2, K), np.linspace(-0.5, 0.5, K), np.linspace(-0.09, -0.06, K)])
    return _configs(robot, q)


def test_branch_following_equals_independent_solves_where_unique(robot, path):
    alpha, beta = path
    follow = simulate(robot, alpha, beta, model="standard", sequence=np.zeros(len(alpha), int),
                      settings=SETTINGS)
    indep = simulate(robot, alpha, beta, model="standard", settings=SETTINGS)
    assert follow.ok.all() and indep.ok.all()
    np.testing.assert_allclose(follow.tip, indep.tip, atol=1e-9)
    for k in (0, 3):
        direct = solve_standard(robot, alpha[k], beta[k], SETTINGS)
        assert direct.diagnostics.n_equilibria == 1
        np.testing.assert_allclose(indep.tip[k], direct.tip_position, atol=1e-12)
        np.testing.assert_allclose(indep.tangent[k], direct.tip_tangent, atol=1e-12)


def _bistable_pair():
    """Two equal tubes of strong precurvature (L kappa = 1.5): two stable equilibria near
    180 deg of relative rotation, on either side of the symmetric unstable one."""
    kappa = 1.0 / 0.1
    k = 5.07e-2
    t1 = Tube("tube 1", (Section(0.15, (0.0, kappa)),), k_xy=k, poisson_ratio=0.3, inner_diameter=1.1e-3)
    t2 = Tube("tube 2", (Section(0.017), Section(0.15, (0.0, kappa))), k_xy=k, poisson_ratio=0.3,
              outer_diameter=1.0e-3)
    return Robot("bistable", (t1, t2), joints=(Joint("rotation", 1, -PI, PI),), home_beta=(0.0, -0.017))


def test_branch_following_stays_on_the_branch_near_multiple_equilibria():
    r = _bistable_pair()
    up = np.deg2rad(np.arange(150.0, 181.0, 5.0))          # approach 180 deg from below
    down = np.deg2rad(np.arange(210.0, 179.0, -5.0))       # ... and from above
    at180 = {}
    for name, angles in (("up", up), ("down", down)):
        alpha, beta = _configs(r, angles[:, None])
        sim = simulate(r, alpha, beta, model="standard", sequence=np.zeros(len(angles), int),
                       settings=SETTINGS)
        assert sim.ok.all(), sim.message
        at180[name] = sim.tip[-1]
    # the two histories end on mirror-image branches, both far from the symmetric solution
    assert at180["up"][1] > 0.02 and at180["down"][1] < -0.02
    np.testing.assert_allclose(at180["up"] * [1, -1, 1], at180["down"], atol=1e-6)
    alpha, beta = r.configuration([PI])
    direct = solve_standard(r, alpha, beta, SETTINGS)
    assert direct.diagnostics.n_equilibria > 1          # the configuration is indeed multistable


def test_friction_model_chooses_friction_or_clearance_per_sample(robot, path):
    alpha, beta = path
    eta = np.array([[1, -1], [1, -1], [0, 1], [0, 0], [-1, 1], [1, 1]])
    tl = np.array([False, True, False, False, False, False])
    sim = simulate(robot, alpha, beta, model="friction", eta=eta, translation_last=tl, settings=SETTINGS)
    assert sim.ok.all(), sim.message
    mu = np.asarray(robot.friction_coefficients)
    np.testing.assert_array_equal(sim.mu, [mu, [0, 0], [0, mu[1]], [0, 0], mu, mu])
    assert sim.n_released == 2
    fr = solve_friction(robot, alpha[0], beta[0], [1, -1], SETTINGS)
    np.testing.assert_allclose(sim.tip[0], fr.tip_position, atol=2e-6)
    for k in (1, 3):   # translation-last and no history: the clearance solution
        cl = solve_clearance(robot, alpha[k], beta[k], SETTINGS)
        np.testing.assert_allclose(sim.tip[k], cl.tip_position, atol=2e-6)
        assert not np.allclose(sim.tip[k], solve_friction(robot, alpha[k], beta[k], [1, 1], SETTINGS).tip_position,
                               atol=1e-4)
    mixed = solve_contact(robot, alpha[2], beta[2], SETTINGS, eta=[1, 1], mu=[0.0, mu[1]])
    np.testing.assert_allclose(sim.tip[2], mixed.tip_position, atol=2e-6)


def test_friction_history_from_sequence(robot, path):
    alpha, beta = path
    sim = simulate(robot, alpha, beta, model="friction", sequence=np.zeros(len(alpha), int), settings=SETTINGS)
    h = motion_history(alpha, beta, np.zeros(len(alpha), int))
    # every step rotates and translates together: friction everywhere but at the first sample
    assert not h.translation_last.any()
    np.testing.assert_array_equal(sim.eta[1:], h.eta[1:])
    assert sim.n_released == 1 and (sim.mu[0] == 0).all()
    with pytest.raises(ValueError, match="eta or sequence"):
        simulate(robot, alpha, beta, model="friction", settings=SETTINGS)


def test_failing_sample_is_flagged_not_fatal_and_parallel_equals_serial(robot, path, monkeypatch):
    import importlib

    simulate_module = importlib.import_module("ctrplan.discrepancy.simulate")  # not the function
    monkeypatch.setattr(simulate_module, "_MIN_PARALLEL_SECONDS", 0.0)  # use workers even for 6 rows
    alpha, beta = path
    alpha, beta = alpha.copy(), beta.copy()
    beta[2, 2] = 0.01                       # tube 3's base in front of tube 2's: impossible
    seq = np.array([1, 1, 1, 0, 0, 0])
    serial = simulate(robot, alpha, beta, model="clearance", sequence=seq, settings=SETTINGS)
    assert serial.ok.tolist() == [True, True, False, True, True, True]
    assert "JointLimitError" in serial.message[2] and np.isnan(serial.tip[2]).all()
    par = simulate(robot, alpha, beta, model="clearance", sequence=seq, settings=SETTINGS, n_jobs=2)
    np.testing.assert_allclose(par.tip[serial.ok], serial.tip[serial.ok], atol=1e-12)
    assert par.message == serial.message


def test_repeated_configuration_reuses_and_warm_starts(robot, path):
    alpha, beta = path
    rep_a, rep_b = np.repeat(alpha[:2], 4, axis=0), np.repeat(beta[:2], 4, axis=0)
    eta = np.tile([[1, 1], [1, -1], [-1, 1], [-1, -1]], (2, 1))
    sim = simulate(robot, rep_a, rep_b, model="friction", eta=eta, settings=SETTINGS)
    # per configuration: one clearance solve that warm-starts the first of four friction solves
    assert sim.n_standard == 2 and sim.n_contact == 10 and sim.n_warm == 8
    cold = solve_friction(robot, rep_a[5], rep_b[5], eta[5], SETTINGS)
    np.testing.assert_allclose(sim.tip[5], cold.tip_position, atol=2e-6)


# --------------------------------------------------------------------------- effects
def test_apply_effects_changes_the_robot():
    r = table2_robot(mu=0.2)
    e = Effects(friction_coefficients=(0.1, 0.3), clearances=(1e-4, 2e-4),
                offplane_precurvature=(0.5, -1.0, 2.0), poisson_ratios=(0.3, 0.35, -0.15))
    m = apply_effects(r, e)
    assert m.friction_coefficients == (0.1, 0.3)
    np.testing.assert_allclose(m.clearances, [1e-4, 2e-4])
    assert m.tubes[2].poisson_ratio == -0.15
    assert m.tubes[1].sections[0].precurvature == (0.0, 0.0)          # straight collar stays straight
    assert m.tubes[1].sections[1].precurvature[0] == pytest.approx(r.tubes[1].sections[1].precurvature[0] - 1.0)
    assert m.tubes[2].sections[1].precurvature[1] == r.tubes[2].sections[1].precurvature[1]
    assert apply_effects(r, Effects()) == r
    with pytest.raises(PhysicalParameterError, match="offplane_precurvature"):
        apply_effects(r, Effects(offplane_precurvature=(1.0, 2.0)))
    with pytest.raises(PhysicalParameterError, match="clearances"):
        Effects(clearances=(0.0, 1e-4))
    with pytest.raises(PhysicalParameterError, match="poisson_ratios"):
        Effects(poisson_ratios=(0.3, 0.6, 0.3))


def test_registration_and_json_round_trip():
    e = Effects(registration=(0.0, 0.0, PI / 2, 0.01, 0.0, 0.0), poisson_ratios=(0.3, 0.3, 0.2))
    tip, tan = apply_registration(np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), e)
    np.testing.assert_allclose(tip, [[0.01, 1.0, 0.0]], atol=1e-15)
    np.testing.assert_allclose(tan, [[-1.0, 0.0, 0.0]], atol=1e-15)
    back = Effects.from_dict(json.loads(json.dumps(e.to_dict())))
    assert back == e and back.active() == ["poisson_ratios", "registration"]
    with pytest.raises(ModelFileError, match="friction"):
        Effects.from_dict({"friction": [0.1]}, "truth.json")
    with pytest.raises(ModelFileError, match="clearances"):
        Effects.from_dict({"clearances": [-1.0]}, "truth.json")
