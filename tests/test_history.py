"""ctrplan.history: one motion-history rule for measured data, prediction and planning.

The friction state of each tube pair (Eqs. (38)-(39) and Section V-B of Ha, Fagogenis & Dupont
2019, doi:10.1109/TRO.2018.2878906), the history operators (drive backlash, tracker time
offset, gradually developing friction), and the check that the discrepancy workflow's path
(``MeasuredData.state``) and the planning path (``path_history``) give the same per-pair history
of the same recorded motion. Expected values are worked out by hand in each test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.history import (MotionRecord, PairState, apply_history, drive_directions, motion_state, pair_friction,
                             play, play_side, rotation_directions, rotation_since_reversal, time_shift)

ROOT = Path(__file__).resolve().parents[1]
HA_DATA = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"


def _three_tube(alpha2, alpha3, beta3):
    K = len(alpha2)
    alpha = np.column_stack([np.zeros(K), alpha2, alpha3])
    beta = np.column_stack([np.zeros(K), np.full(K, -0.017), beta3])
    return MotionRecord(alpha, beta)


# --------------------------------------------------------------------------- the state rule
def test_reversal_then_translation_then_rotation():
    """alpha_2 up, back down (a reversal), then beta_3 moves, then alpha_2 again. Pair 1's
    relative angle is alpha_2, pair 2's is -alpha_2 (opposite directions). Catches a sign error
    of eta, a translation that does not release, or a rotation that does not end the release."""
    rec = _three_tube([0.0, 0.1, 0.2, 0.15, 0.1, 0.1, 0.1, 0.2], np.zeros(8),
                      [-0.05, -0.05, -0.05, -0.05, -0.05, -0.06, -0.06, -0.06])
    s = motion_state(rec)
    assert s.eta[:, 0].tolist() == [0, 1, 1, -1, -1, -1, -1, 1]
    assert s.eta[:, 1].tolist() == [0, -1, -1, 1, 1, 1, 1, -1]
    released = [False, False, False, False, False, True, True, False]
    assert s.released[:, 0].tolist() == released and s.released[:, 1].tolist() == released
    # abrupt friction state: eta where the pair is not released, 0 before any rotation
    np.testing.assert_array_equal(s.friction, np.where(s.released, 0, s.eta))
    np.testing.assert_array_equal(s.eta, rotation_directions(rec.alpha))


def test_a_release_of_one_pair_survives_a_rotation_of_another():
    """Tube 2 rotates (both pairs), tube 3 translates (releases both), then tube 3 rotates
    (pair 2 only). Pair 1 stays released; pair 2 carries friction again. A rule with one
    translation-last flag per sample, cleared by any pair's rotation, gives pair 1 its friction
    back with an old eta: this test fails on it."""
    rec = _three_tube([0.0, 0.3, 0.3, 0.3, 0.3], [0.0, 0.0, 0.0, 0.0, -0.4],
                      [-0.05, -0.05, -0.05, -0.06, -0.06])
    s = motion_state(rec)
    assert s.released[:, 0].tolist() == [False, False, False, True, True]
    assert s.released[:, 1].tolist() == [False, False, False, True, False]
    assert s.friction[-1].tolist() == [0.0, -1.0]          # pair 2: alpha_3 - alpha_2 decreased
    eta, mu, cases = pair_friction(s.at(4), [0.2, 0.1])
    assert eta.tolist() == [0, -1] and mu.tolist() == [0.0, 0.1]
    assert cases == ("translation_last", "friction")


def test_jitter_below_the_tolerance_neither_flips_nor_rotates():
    """Encoder jitter of 0.3-0.4 mrad (below the 1 mrad hysteresis): eta stays, and the later
    translation still releases (the jitter is no rotation)."""
    rec = _three_tube([0.0, 0.2, 0.2 - 4e-4, 0.2 + 3e-4, 0.2, 0.2], np.zeros(6),
                      [-0.05, -0.05, -0.05, -0.05, -0.052, -0.052])
    s = motion_state(rec, rotation_tol=1e-3)
    assert s.eta[:, 0].tolist() == [0, 1, 1, 1, 1, 1]
    assert s.released[:, 0].tolist() == [False] * 4 + [True, True]


def test_a_translation_concurrent_with_a_rotation_does_not_release():
    """Both joints move in every step: the rotation is still the last motion at every sample."""
    rec = _three_tube(np.linspace(0.0, 0.5, 6), np.zeros(6), np.linspace(-0.05, -0.06, 6))
    s = motion_state(rec)
    assert not s.released.any()
    assert s.eta[1:, 0].tolist() == [1] * 5


def test_motions_restart_and_ids_may_interleave():
    """Rows of one sequence id are one motion in table order; each starts without history."""
    alpha = np.column_stack([np.zeros(6), [0.0, 0.3, 1.0, 0.6, 0.2, 1.2], np.zeros(6)])
    rec = MotionRecord(alpha, np.tile([0.0, -0.017, -0.05], (6, 1)), sequence=[0, 0, 1, 0, 1, 1])
    s = motion_state(rec)
    # sequence 0: rows 0, 1, 3 -> 0.0, 0.3, 0.6; sequence 1: rows 2, 4, 5 -> 1.0, 0.2, 1.2
    assert s.eta[:, 0].tolist() == [0, 1, 0, 1, -1, 1]


def test_given_eta_fills_pairs_without_a_recorded_rotation():
    """One sample per sequence (the paper's protocol): the file's approach directions are the
    history, as a developed friction state."""
    alpha = np.array([[0.0, 0.5, 1.0], [0.0, 0.5, 1.0]])
    rec = MotionRecord(alpha, np.tile([0.0, -0.017, -0.05], (2, 1)), sequence=[0, 1])
    s = motion_state(rec, given_eta=[[1, -1], [-1, 1]])
    assert s.eta.tolist() == [[1, -1], [-1, 1]] and s.friction.tolist() == [[1, -1], [-1, 1]]
    assert not motion_state(rec).friction.any()


def test_bad_inputs_are_named():
    rec = _three_tube([0.0, 0.1], [0.0, 0.0], [-0.05, -0.05])
    with pytest.raises(ValueError, match="integers"):
        MotionRecord(rec.alpha, rec.beta, sequence=[0.0, 0.5])
    with pytest.raises(ValueError, match="shape"):
        MotionRecord(rec.alpha, rec.beta[:, :2])
    with pytest.raises(ValueError, match="tolerances"):
        motion_state(rec, rotation_tol=0.0)
    with pytest.raises(ValueError, match="increase"):
        MotionRecord(rec.alpha, rec.beta, time=[0.1, 0.1])
    with pytest.raises(ValueError, match="row 2"):
        MotionRecord(np.array([[0.0, 0.0, 0.0], [0.0, np.nan, 0.0]]), rec.beta)


# --------------------------------------------------------------------------- gradual friction
def test_friction_develops_exponentially_and_a_translation_releases_it():
    """Dahl-type state: from rest e = 1 - exp(-r / theta_c); reversing by theta_c after a long
    rotation gives e = -1 + (1 + e0) exp(-1) ~ -(1 - 2 exp(-1)); theta_c = 0 is the paper's
    abrupt eta; a translation resets e to 0. Catches a wrong law, a missing release or a state
    that does not restart."""
    theta = np.deg2rad(10.0)
    rel = np.concatenate([np.linspace(0, 1.5, 151), np.linspace(1.5, 1.5 - theta, 11)[1:]])
    alpha = np.column_stack([np.zeros(rel.size), rel])
    beta = np.tile([0.0, -0.02], (rel.size, 1))
    e = motion_state(MotionRecord(alpha, beta), friction_angle=theta).friction
    assert e[150, 0] == pytest.approx(1.0 - np.exp(-1.5 / theta), abs=1e-9)
    assert e[-1, 0] == pytest.approx(-1.0 + (1.0 + e[150, 0]) * np.exp(-1.0), abs=1e-9)
    assert e[-1, 0] == pytest.approx(-(1 - 2 * np.exp(-1.0)), abs=1e-3)
    e0 = motion_state(MotionRecord(alpha, beta)).friction
    assert e0[100, 0] == 1 and e0[-1, 0] == -1
    alpha2 = np.vstack([alpha, np.repeat(alpha[-1:], 3, axis=0)])
    beta2 = np.vstack([beta, [[0.0, -0.019], [0.0, -0.018], [0.0, -0.017]]])   # a translation after it
    e2 = motion_state(MotionRecord(alpha2, beta2), friction_angle=theta).friction
    assert e2[-4, 0] == pytest.approx(e[-1, 0]) and np.all(e2[-3:, 0] == 0.0)
    d = rotation_since_reversal(alpha)
    assert d[150, 0] == pytest.approx(1.5) and d[-1, 0] == pytest.approx(theta)
    eta, mu, cases = pair_friction(PairState(np.zeros(2), np.zeros(2), np.array([-1]), np.array([False]),
                                             np.array([e[-1, 0]])), [0.2])
    assert eta.tolist() == [-1] and mu[0] == pytest.approx(0.2 * abs(e[-1, 0])) and cases == ("friction",)


# --------------------------------------------------------------------------- operators
def test_a_dead_band_of_width_b_changes_the_lag_by_b_across_a_reversal():
    """Play operator: moving up, the tube lags by b/2; after the reversal it stays put until the
    drive has crossed the band, then lags by b/2 the other way: the offset changes by b across
    the reversal (not 2b, not b/2). Catches a lag on the wrong side, a full-band lag, or a lag
    without reversal."""
    up = np.linspace(0.0, 1.0, 11)
    drive = np.concatenate([up, up[::-1][1:]])[:, None] * np.array([[0.0, 1.0]])
    rec = MotionRecord(drive, np.zeros_like(drive))
    seen = play(rec, [0.0, 0.2])
    a = seen.alpha
    np.testing.assert_allclose(a[:, 0], 0.0)
    np.testing.assert_allclose(a[1:11, 1], drive[1:11, 1] - 0.1, atol=1e-12)     # lagging below
    np.testing.assert_allclose(a[11, 1], a[10, 1])                               # inside the band: stays
    np.testing.assert_allclose(a[13:, 1], drive[13:, 1] + 0.1, atol=1e-12)       # lagging above
    offset = a[:, 1] - drive[:, 1]
    assert offset[-1] - offset[10] == pytest.approx(0.2, abs=1e-12)
    assert np.all(np.abs(a - drive) <= 0.1 + 1e-12)
    side = play_side(rec, seen, [0.0, 0.2])
    assert side[10, 1] == pytest.approx(1.0) and side[-1, 1] == pytest.approx(-1.0) and side[11, 1] < 1.0
    s = drive_directions(drive)
    assert s[5, 1] == 1 and s[-1, 1] == -1 and np.all(s[:, 0] == 0)
    with pytest.raises(ValueError, match="backlash widths"):
        play(rec, [0.0, -0.1])


def test_a_positive_time_offset_reads_the_joints_earlier():
    """A tracker lagging by +tau shows the joints at t - tau: a ramp shifted by 0.25 s reads
    0.25 s x slope lower, held at the record's start. Catches a shift of the wrong sign or by
    whole samples."""
    t = np.arange(10) * 0.1
    alpha = np.column_stack([np.zeros(10), t * 2.0])
    beta = np.column_stack([np.zeros(10), -0.05 + 0.01 * t])
    shifted = time_shift(MotionRecord(alpha, beta, t), 0.25)
    np.testing.assert_allclose(shifted.alpha[5:, 1], 2.0 * (t[5:] - 0.25), atol=1e-12)
    np.testing.assert_allclose(shifted.alpha[:3, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(shifted.beta[5:, 1], -0.05 + 0.01 * (t[5:] - 0.25), atol=1e-12)
    with pytest.raises(ValueError, match="needs sample times"):
        time_shift(MotionRecord(alpha, beta), 0.1)


def test_time_offset_reads_a_smooth_interpolant_with_no_kink_at_the_sample_period():
    """A joint moving with changing speed, sampled at 10 Hz: the value read at ``t - tau`` has
    equal one-sided derivatives in tau at tau = 1, 2 sample periods (a C1 interpolant), where
    linear interpolation jumps by the change of slope between samples; a rest between equal
    samples stays at rest (no overshoot); the samples themselves are read back exactly. Catches
    an interpolant that puts a kink in the time-offset cost at every sample period (a fit that
    lands on a multiple of it) or that moves a joint at rest."""
    from ctrplan.history import joints_at

    t = np.arange(40) * 0.1
    a2 = np.where(t < 2.0, np.sin(1.3 * t) + 0.3 * t ** 2, np.sin(2.6) + 1.2)   # a move, then a rest
    rec = MotionRecord(np.column_stack([np.zeros(40), a2]), np.zeros((40, 2)), t)
    k, h = 15, 1e-6
    for tau in (0.1, 0.2):
        left = (time_shift(rec, tau).alpha[k, 1] - time_shift(rec, tau - h).alpha[k, 1]) / h
        right = (time_shift(rec, tau + h).alpha[k, 1] - time_shift(rec, tau).alpha[k, 1]) / h
        assert abs(left - right) < 1e-3 * max(1.0, abs(left)), (tau, left, right)
        lin = [np.interp(t[k] - x, t, a2) for x in (tau - h, tau, tau + h)]
        assert abs((lin[1] - lin[0]) - (lin[2] - lin[1])) / h > 0.05          # linear interpolation kinks here
    rest = t >= 2.05
    shifted = time_shift(rec, 0.05).alpha[:, 1]
    np.testing.assert_allclose(shifted[np.flatnonzero(rest)[1:]], a2[-1], atol=1e-12)
    np.testing.assert_allclose(joints_at(rec, t)[0][:, 1], a2, atol=1e-12)


def test_operators_run_along_each_motion_not_across_motions():
    """Two motions in one record: the second starts centred in the dead band, and the
    interpolation of a time offset never reads the other motion."""
    drive = np.column_stack([np.zeros(6), [0.0, 0.5, 1.0, 0.0, 0.5, 1.0]])
    rec = MotionRecord(drive, np.zeros_like(drive), time=[0.0, 0.1, 0.2, 0.0, 0.1, 0.2], sequence=[0, 0, 0, 1, 1, 1])
    seen = play(rec, [0.0, 0.2])
    np.testing.assert_allclose(seen.alpha[:, 1], [0.0, 0.4, 0.9, 0.0, 0.4, 0.9], atol=1e-12)
    shifted = time_shift(rec, 0.1)
    np.testing.assert_allclose(shifted.alpha[:, 1], [0.0, 0.0, 0.5, 0.0, 0.0, 0.5], atol=1e-12)


def test_apply_history_puts_the_drive_before_the_tracker():
    """The tubes follow the drives through the play; the tracker shows that motion late. Planning
    (tracker=False) sees the play only."""
    from ctrplan.history import HistoryOperator

    t = np.arange(8) * 0.1
    drive = np.column_stack([np.zeros(8), np.linspace(0, 0.7, 8)])
    rec = MotionRecord(drive, np.zeros_like(drive), t)
    ops = [HistoryOperator("tracker", "tracker", lambda r: time_shift(r, 0.1)),
           HistoryOperator("drive", "drive", lambda r: play(r, [0.0, 0.2]))]
    s = apply_history(rec, ops)
    expected = time_shift(play(rec, [0.0, 0.2]), 0.1).alpha
    np.testing.assert_allclose(s.alpha, expected, atol=1e-12)
    np.testing.assert_allclose(s.alpha_offset, expected - drive, atol=1e-12)
    np.testing.assert_allclose(apply_history(rec, ops, tracker=False).alpha, play(rec, [0.0, 0.2]).alpha)


# --------------------------------------------------------------------------- one history, two paths
def _both_paths(robot, data_path):
    from ctrplan.discrepancy.measured.data import load_measured_data
    from ctrplan.planning import path_history

    data = load_measured_data(data_path, robot)
    measured = data.state(robot)
    q = np.array([robot.joint_vector(a, b) for a, b in zip(data.alpha, data.beta)])
    planned = path_history(robot, q)
    return data, measured, planned


def _assert_same(measured, planned):
    np.testing.assert_array_equal(measured.eta, planned.eta)
    np.testing.assert_array_equal(measured.released, planned.released)
    np.testing.assert_array_equal(measured.friction, planned.friction)
    np.testing.assert_array_equal(measured.alpha, planned.alpha)


def test_measured_and_planned_paths_give_the_same_history(tmp_path):
    """A seeded continuous trajectory of the three-tube robot whose file has drive backlash
    (tube 2, 3 deg) and gradually developing friction (theta_c 12 deg): the discrepancy
    workflow's history (MeasuredData.state, from the recorded CSV) and the planner's
    (path_history of the same joint values) agree sample by sample, per pair: directions,
    releases, friction states and the tube angles behind the play. Also on a block of rows
    (a calibration block): its history is the whole record's, not one restarted at the block."""
    from ctrplan.discrepancy.measured.synth import trajectory_protocol
    from ctrplan.io.robot_file import load_robot, robot_from_toml_text, robot_to_toml
    from ctrplan.io.tables import write_table

    base = load_robot(ROOT / "model" / "ha2019-table2-nominal.toml")
    robot = robot_from_toml_text(robot_to_toml(base.replace(effects=(
        ("backlash", (("backlash_2", float(np.deg2rad(3.0))),)),
        ("gradual_friction", (("friction_angle", float(np.deg2rad(12.0))),))))))
    frame = trajectory_protocol(robot, np.random.default_rng(20261125), 400)
    frame[["tip_x", "tip_y", "tip_z"]] = [0.05, 0.0, 0.15]      # the tips do not enter the history
    path = tmp_path / "trajectory.csv"
    write_table(path, frame)
    data, measured, planned = _both_paths(robot, path)
    _assert_same(measured, planned)
    assert measured.released.any() and (np.abs(measured.friction) > 0).any()
    assert np.any(np.abs(measured.alpha_offset[:, 1]) > np.deg2rad(1.4))   # the play acts
    # a block of rows keeps the history of the samples before it
    block = data.take(np.arange(200, 300))
    _assert_same(block.state(robot), planned.take(np.arange(200, 300)))


@pytest.mark.skipif(not HA_DATA.exists(), reason=f"measured data not present at {HA_DATA} (not redistributable; "
                                                  f"get it from github.com/hjhdog1/ConcentricTubes)")
def test_measured_and_planned_paths_agree_on_has_trajectory():
    """The same on the 1307 rows of Ha's measured trajectory (tube 2 reverses about 20 times,
    tube 3 about 8, translations of tube 3 release both pairs)."""
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(ROOT / "model" / "ha2019-table2-nominal.toml")
    data, measured, planned = _both_paths(robot, HA_DATA)
    _assert_same(measured, planned)
    assert data.n_samples == 1307 and measured.released.any() and not measured.released.all()


def _directions_loop(x, tol):
    """Direction of the last change of each column of ``x`` with hysteresis ``tol``, one sample
    at a time (the rule of ``rotation_directions``)."""
    out = np.zeros(x.shape, dtype=int)
    for i in range(x.shape[1]):
        state, anchor = 0, x[0, i]
        for k, v in enumerate(x[:, i]):
            if state >= 0 and v > anchor and (state == 1 or v - anchor > tol):
                state, anchor = 1, v
            elif state <= 0 and v < anchor and (state == -1 or anchor - v > tol):
                state, anchor = -1, v
            elif state == 1 and anchor - v > tol:
                state, anchor = -1, v
            elif state == -1 and v - anchor > tol:
                state, anchor = 1, v
            out[k, i] = state
    return out


def _friction_loop(alpha, beta, sequence, theta_c, rot_tol, trans_tol):
    """The friction state of the module's rule, sample by sample in Python: (eta, released,
    friction), each (K, n - 1)."""
    K, n = alpha.shape
    rel = np.diff(alpha, axis=1)
    eta = np.zeros((K, n - 1), int)
    released = np.zeros((K, n - 1), bool)
    friction = np.zeros((K, n - 1))
    for label in np.unique(sequence):
        idx = np.flatnonzero(sequence == label)
        eta[idx] = _directions_loop(rel[idx], rot_tol)
        for i in range(n - 1):
            ref_rel, ref_beta, free, e = rel[idx[0], i], beta[idx[0]], False, 0.0
            for j, k in enumerate(idx):
                if j > 0:
                    if abs(rel[k, i] - ref_rel) > rot_tol:
                        ref_rel, ref_beta, free = rel[k, i], beta[k], False
                    free = free or np.max(np.abs(beta[k] - ref_beta)) > trans_tol
                    if theta_c > 0:
                        dr = rel[k, i] - rel[idx[j - 1], i]
                        e = np.sign(dr) + (e - np.sign(dr)) * np.exp(-abs(dr) / theta_c)
                released[k, i] = free
                if theta_c > 0:
                    e = 0.0 if free else e
                    friction[k, i] = e
                else:
                    friction[k, i] = 0.0 if free else eta[k, i]
    return eta, released, friction


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_motion_state_equals_the_rule_sample_by_sample(seed):
    """The compiled friction state equals the rule applied one sample and one pair at a time on
    random motions (rotations and translations that pause, interleaved sequences, abrupt and
    gradual friction)."""
    rng = np.random.default_rng(seed)
    K, n = 250, 3
    alpha = np.cumsum(rng.normal(0, 0.05, (K, n)) * (rng.random((K, 1)) < 0.7), axis=0)
    beta = np.cumsum(rng.normal(0, 0.002, (K, n)) * (rng.random((K, 1)) < 0.3), axis=0)
    sequence = rng.integers(0, 3, K) if seed % 2 else np.repeat(np.arange(5), 50)
    for theta_c in (0.0, 0.05):
        st = motion_state(MotionRecord(alpha, beta, sequence=sequence), friction_angle=theta_c,
                          rotation_tol=1e-3, translation_tol=1e-3)
        eta, released, friction = _friction_loop(alpha, beta, sequence, theta_c, 1e-3, 1e-3)
        np.testing.assert_array_equal(st.eta, eta)
        np.testing.assert_array_equal(st.released, released)
        np.testing.assert_allclose(st.friction, friction, rtol=0, atol=1e-14)
        assert released.any() and (~released).any() and (eta == -1).any() and (eta == 1).any()
