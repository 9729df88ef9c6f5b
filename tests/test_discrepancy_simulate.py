"""ctrplan.discrepancy.fits.simulate (models along a motion).

Branch following of the standard model, the friction/clearance choice per sample from the
friction applied per pair (Sections III and V-B of Ha, Fagogenis & Dupont 2019,
doi:10.1109/TRO.2018.2878906; the history rule itself is tested in tests/test_history.py),
robustness to failing samples, parallel = serial. Robots: tests/_robots.py at a coarse ds for speed.
"""

from __future__ import annotations

import numpy as np
import pytest

from ctrplan.discrepancy import simulate
from ctrplan.history import MotionRecord, motion_state
from ctrplan.mechanics import ModelSettings, solve_clearance, solve_contact, solve_friction, solve_standard
from ctrplan.robot import Joint, Robot, Section, Tube

from _robots import table2_robot

DS = 0.004  # [m] coarse arc-length step, for speed
SETTINGS = ModelSettings(ds=DS)
PI = np.pi


def _configs(robot, q):
    a, b = zip(*[robot.configuration(x) for x in q])
    return np.array(a), np.array(b)


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
    # applied friction per pair: sample 1 released, sample 2 with pair 1 never rotated, sample 3 neither
    eta = np.array([[1, -1], [0, 0], [0, 1], [0, 0], [-1, 1], [1, 1]])
    sim = simulate(robot, alpha, beta, model="friction", eta=eta, settings=SETTINGS)
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
    h = motion_state(MotionRecord(alpha, beta))
    # tubes 2 and 3 turn together: pair 1 rotates (and translates) in every step, so it carries
    # friction everywhere but at the first sample; pair 2 never rotates: no friction
    assert not h.released[:, 0].any() and not h.eta[:, 1].any()
    np.testing.assert_array_equal(sim.eta[1:, 0], h.eta[1:, 0])
    assert sim.n_released == 1 and (sim.mu[0] == 0).all() and (sim.mu[:, 1] == 0).all()
    with pytest.raises(ValueError, match="eta or sequence"):
        simulate(robot, alpha, beta, model="friction", settings=SETTINGS)


def test_failing_sample_is_flagged_not_fatal_and_parallel_equals_serial(robot, path, monkeypatch):
    import importlib

    simulate_module = importlib.import_module("ctrplan.discrepancy.fits.simulate")  # not the function
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
