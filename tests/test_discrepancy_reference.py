"""The discrepancy workflow's fitting path against data made independently of it.

Reference records come from ``tests/ctrplan_reference/synth_reference.py``: an analytic motion, the
history rules written again from their definitions (``tests/ctrplan_reference/history_reference.py``)
and the frozen reference solvers, none of which imports ``ctrplan.history``,
``ctrplan.effects`` or ``ctrplan.discrepancy``. The fitting path
(:func:`ctrplan.discrepancy.fits.predictions.predict` on the record loaded by
:func:`ctrplan.discrepancy.measured.data.load_measured_data`) must reproduce them for the same effect
values. Each test also plants a wrongly-signed operator where the workflow looks it up and
checks that the same comparison then fails by a wide margin, so a sign or convention error in
an operator cannot pass.

Noise-free records, ds = 6 mm, 90-150 samples at 10 Hz.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator

import ctrplan.effects._builtin as effects_builtin
import ctrplan.history as history
import ctrplan.history._apply as history_apply
import ctrplan.history._operators as history_operators
import ctrplan.history._state as history_state
from ctrplan.discrepancy.fits.predictions import pose_errors, predict
from ctrplan.discrepancy.measured.data import load_measured_data
from ctrplan.history._state import HistoryState
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings
from ctrplan_reference import standard_reference
from ctrplan_reference.history_reference import applied_friction, pair_history
from ctrplan_reference.synth_reference import synthesize_reference

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
TABLE7 = ROOT / "model" / "ha2019-table7-calibrated.toml"
DS = 6e-3                                             # [m]
SETTINGS = ModelSettings(ds=DS, multistart=0)
NO_NOISE = dict(noise_position_rms=0.0, noise_angle_rms=0.0)
#: Standard-model tips of the fitting path and the reference at the same configuration [m]: the
#: same shooting algorithm with tolerance 1e-9 1/m on the tip torsion; the fast path is held to
#: the reference to 1e-8 m (tests/test_mechanics_fast_vs_reference.py).
STANDARD_TIP_TOL = 1e-8
#: Standard-model tangents [-] (difference of unit vectors), same reason.
STANDARD_TANGENT_TOL = 1e-7
#: Clearance / friction tips [m]: both solvers stop their outer loop on a 1 um centerline change
#: (ModelSettings.outer_tol), from different starts (the fitting path warm-starts a friction
#: solve from a clearance solve); tests/test_mechanics_fast_vs_reference.py uses 5 um.
CONTACT_TIP_TOL = 5e-6
#: A mutant must exceed the tolerance by at least this factor at its worst sample ...
MUTANT_FACTOR = 20.0
#: ... and exceed it at more than this share of the samples it can affect.
MUTANT_SHARE = 0.5


# --------------------------------------------------------------------------- helpers
def _record(tmp_path, robot, name, **kwargs):
    """A noise-free reference record written as CSV: (path, truth)."""
    frame, truth = synthesize_reference(robot, rate_hz=10.0, ds=DS, **NO_NOISE, **kwargs)
    assert not truth["dropped"], truth["dropped"]
    path = tmp_path / f"{name}.csv"
    frame.to_csv(path, index=False)     # repr-precise floats: the file holds the exact values
    return path, truth


def _fitting_errors(robot, path, names, values, model):
    """Tip position errors (K,) [m], tangent errors (K,) [rad] and ok flags of the fitting path's
    prediction on freshly loaded data (no history state cached from another call)."""
    data = load_measured_data(path, robot)
    pred = predict(robot, names, values, data, model, SETTINGS)
    pos, ang, _ = pose_errors(pred, data)
    return pos, ang, pred.ok


def _patch_everywhere(monkeypatch, name, original, replacement):
    """Replace ``original`` by ``replacement`` in every module of the fitting path that holds it
    under ``name`` (the effects registry's operators look it up in ctrplan.effects._builtin)."""
    patched = 0
    for module in (effects_builtin, history, history_operators, history_apply):
        if getattr(module, name, None) is original:
            monkeypatch.setattr(module, name, replacement)
            patched += 1
    assert patched, f"{name} is no longer where the workflow looks it up"


def _mutant_margin(err, tol, affected):
    """How far a mutant's errors (K,) [m] exceed ``tol`` [m]: the worst ratio, and the share of the
    ``affected`` samples (bool (K,)) above ``tol`` (compared with MUTANT_FACTOR and MUTANT_SHARE)."""
    share = float(np.mean(err[affected] > tol))
    return float(np.nanmax(err / tol)), share


# --------------------------------------------------------------------------- backlash
@pytest.mark.parametrize("robot_file, widths, samples, seed",
                         [(PAIR, (0.0, 0.06), 120, 11), (TABLE7, (0.0, 0.06, 0.04), 150, 27)],
                         ids=["table1-pair", "table7"])
def test_backlash_prediction_equals_reference_play(tmp_path, monkeypatch, robot_file, widths, samples, seed):
    """Catches a wrong sign of the play operator's lag (the tube dragged AHEAD of the drive
    instead of behind it), a band of the wrong width (b instead of b/2 each side) or a motion
    that does not start centred: the fitting path's tips with the true dead band must equal the
    reference's (play on a fine grid of the analytic motion, standard reference solver) to
    solver precision, and the mutant with the lag's sign flipped must miss them by far."""
    robot = load_robot(robot_file)
    path, truth = _record(tmp_path, robot, "backlash", samples=samples, backlash=widths, seed=seed)
    drives = [robot.joint_names.index(f"alpha_{i + 1}") for i, w in enumerate(widths) if w > 0]
    assert np.all(truth["reversals"][drives] >= 2)          # reversals at rest: the play's lag changes sign
    names = tuple(f"backlash_{i + 1}" for i, w in enumerate(widths) if w > 0)
    values = tuple(w for w in widths if w > 0)

    pos, ang, ok = _fitting_errors(robot, path, names, values, "standard")
    assert ok.all()
    assert np.max(pos) <= STANDARD_TIP_TOL, f"max tip error {np.max(pos):.3g} m"
    assert np.max(ang) <= STANDARD_TANGENT_TOL

    # the effect is there: without it the prediction misses the reference
    pos0, _, _ = _fitting_errors(robot, path, names, (0.0,) * len(values), "standard")
    displaced = pos0 > 1e-4
    assert np.mean(displaced) > 0.3

    original = history_operators.play

    def play_ahead(record, w):          # mutant: the tube leads the drive by the lag
        return record.replace(alpha=2.0 * record.alpha - original(record, w).alpha)

    _patch_everywhere(monkeypatch, "play", original, play_ahead)
    pos_m, _, _ = _fitting_errors(robot, path, names, values, "standard")
    worst, share = _mutant_margin(pos_m, STANDARD_TIP_TOL, displaced)
    assert worst > 1e4 and share > MUTANT_SHARE, (worst, share)


# --------------------------------------------------------------------------- time offset
def _interpolation_envelope(robot, truth):
    """Tip displacement [m] per sample, shape (K,), that reading the 10 Hz commanded joints at
    ``t - tau`` by interpolation instead of the exact motion causes: the larger of linear
    interpolation and a PCHIP (C1, shape-preserving) interpolant of the samples, each solved
    with the reference standard solver on the truth's branch."""
    motion, times, seen = truth["motion"], truth["times"], truth["seen_times"]
    q_samples = motion(times)
    q_true = motion(seen)
    q_lin = np.column_stack([np.interp(seen, times, q_samples[:, j]) for j in range(q_samples.shape[1])])
    q_pchip = PchipInterpolator(times, q_samples, axis=0, extrapolate=False)(seen)
    out = np.zeros(times.size)
    for k in range(times.size):
        for q in (q_lin[k], q_pchip[k]):
            if np.max(np.abs(q - q_true[k])) == 0.0:
                continue
            a, b = robot.configuration(q, check_limits=False)
            sol = standard_reference.solve_standard(robot, a, b, SETTINGS, initial_guess=truth["base_torsion"][k],
                                                    check_stability=False)
            assert sol.diagnostics.ok
            out[k] = max(out[k], float(np.linalg.norm(sol.tip_position - truth["tip"][k])))
    return out


@pytest.mark.parametrize("robot_file, tau, seed", [(PAIR, 0.17, 21), (TABLE7, -0.13, 22)],
                         ids=["table1-pair", "table7"])
def test_time_offset_prediction_within_interpolation_of_reference(tmp_path, monkeypatch, robot_file, tau, seed):
    """Catches a time shift of the wrong sign (joints read at t + tau instead of t - tau) or of
    the wrong size: the fitting path's tips with the true tau must be within what interpolating the 10 Hz joint
    samples explains (twice the larger tip displacement of linear and PCHIP interpolation,
    computed per sample with the reference solver, plus the solver tolerance; exact at rest),
    and the mutant reading t + tau must miss by far more."""
    robot = load_robot(robot_file)
    path, truth = _record(tmp_path, robot, "time-offset", samples=120, time_offset=tau, seed=seed)
    bound = 2.0 * _interpolation_envelope(robot, truth) + STANDARD_TIP_TOL

    pos, _, ok = _fitting_errors(robot, path, ("time_offset",), (tau,), "standard")
    assert ok.all()
    worst = int(np.argmax(pos / bound))
    assert np.all(pos <= bound), f"sample {worst}: {pos[worst]:.3g} m > {bound[worst]:.3g} m"
    moving = np.linalg.norm(np.diff(truth["tip"], axis=0, prepend=truth["tip"][:1]), axis=1) > 1e-4

    original = history_operators.time_shift

    def shift_ahead(record, t):         # mutant: joints read at t + tau
        return original(record, -t)

    _patch_everywhere(monkeypatch, "time_shift", original, shift_ahead)
    pos_m, _, _ = _fitting_errors(robot, path, ("time_offset",), (tau,), "standard")
    assert np.max(pos_m) > MUTANT_FACTOR * np.max(bound)
    assert np.mean(pos_m[moving] > bound[moving]) > MUTANT_SHARE


# --------------------------------------------------------------------------- friction
FRICTION_CASES = [
    (PAIR, (0.3,), 0.0, 90, 3),
    (PAIR, (0.3,), float(np.deg2rad(10.0)), 90, 3),
    (TABLE7, (0.22, 0.12), 0.0, 120, 37),
]


@pytest.mark.parametrize("robot_file, mu, friction_angle, samples, seed", FRICTION_CASES,
                         ids=["table1-pair-abrupt", "table1-pair-gradual", "table7-abrupt"])
def test_friction_prediction_equals_reference_friction(tmp_path, monkeypatch, robot_file, mu, friction_angle,
                                                       samples, seed):
    """Catches a friction direction eta of the wrong sign where the history hands it to the
    model (or a wrong relative-angle convention, alpha_k - alpha_(k+1)), friction applied before
    the pair has rotated, a translation after the last rotation that does not release the pair
    (or a concurrent one that does), and a wrong development law or missing reset of gradual
    friction: the fitting path's friction-model tips along the recorded history must equal the
    reference's (the history rule written again, the frozen reference contact solver) to solver
    precision, and the mutant with eta flipped must miss them by far. Table I tube pair with
    mu 0.3 (Table I's range 0-0.5) and the Table VII robot with its mu (0.22, 0.12), whose
    third tube translates (translation-last samples)."""
    robot = load_robot(robot_file).replace(friction_coefficients=mu)
    path, truth = _record(tmp_path, robot, "friction", samples=samples, mu=mu, friction_angle=friction_angle,
                          seed=seed)
    mu_applied = truth["mu_applied"]
    for k in range(robot.n_tubes - 1):
        rubbing = mu_applied[:, k] > 0.0
        assert np.mean(rubbing) > 0.1 and set(truth["eta_applied"][rubbing, k]) == {-1, 1}
    if robot.n_tubes > 2:
        assert np.sum(truth["released"] & (truth["eta"] != 0)) > 20           # translation-last samples
    names, values = (("friction_angle",), (friction_angle,)) if friction_angle > 0 else ((), ())

    pos, _, ok = _fitting_errors(robot, path, names, values, "friction")
    assert ok.all()
    worst = int(np.argmax(pos))
    assert pos[worst] <= CONTACT_TIP_TOL, f"sample {worst}: tip error {pos[worst]:.3g} m"

    original = HistoryState.applied

    def applied_flipped(self, mu_robot):   # mutant: friction direction flipped
        eta, coefficient = original(self, mu_robot)
        return -eta, coefficient

    monkeypatch.setattr(HistoryState, "applied", applied_flipped)
    pos_m, _, _ = _fitting_errors(robot, path, names, values, "friction")
    developed = np.any(mu_applied > 0.5 * np.asarray(mu)[None, :], axis=1)
    worst, share = _mutant_margin(pos_m, CONTACT_TIP_TOL, developed)
    assert worst > MUTANT_FACTOR and share > MUTANT_SHARE, (worst, share)


def test_history_state_equals_reference_rules_with_translations(tmp_path, monkeypatch):
    """Catches errors in the per-pair rule that the tube-pair friction test cannot see, on the
    three-tube robot whose third tube translates: release by a translation after the pair's
    last rotation (translation-last), no release by a concurrent translation, a rotation ending
    the release, the 1 mrad hysteresis of eta, backlash feeding the state, the reset of gradual
    friction at a release, and the applied direction and coefficient. The workflow's state
    (:meth:`MeasuredData.state`) must equal the reference rules exactly (eta, release) and to
    rounding (friction state); with the relative angle read the other way round (alpha_k -
    alpha_(k+1), the direction rule's sign flipped) the directions must differ."""
    robot = load_robot(TABLE7)
    widths, theta_c, mu = (0.0, 0.05, 0.03), float(np.deg2rad(15.0)), np.array([0.22, 0.12])
    path, truth = _record(tmp_path, robot, "state", samples=300, backlash=widths, seed=5)
    data = load_measured_data(path, robot)
    effects = {"backlash": {"backlash_2": widths[1], "backlash_3": widths[2]},
               "gradual_friction": {"friction_angle": theta_c}}
    state = data.state(robot, effects)
    ref = pair_history(truth["alpha"], truth["beta"], friction_angle=theta_c)
    assert np.sum(np.any(ref.released & (ref.eta != 0), axis=1)) > 30      # translation-last samples
    assert np.sum(ref.rotated & np.roll(ref.released, 1, axis=0)) > 0       # releases ended by a rotation
    np.testing.assert_array_equal(state.eta, ref.eta)
    np.testing.assert_array_equal(state.released, ref.released)
    np.testing.assert_allclose(state.friction, ref.friction, rtol=0, atol=1e-12)
    eta_ref, mu_ref = applied_friction(ref.friction, mu)
    eta_fit, mu_fit = state.applied(mu)
    np.testing.assert_array_equal(eta_fit, eta_ref)
    np.testing.assert_allclose(mu_fit, mu_ref, rtol=0, atol=1e-12)
    abrupt_ref = pair_history(truth["alpha"], truth["beta"])                      # e = eta unless released
    np.testing.assert_array_equal(data.state(robot, {"backlash": effects["backlash"]}).friction, abrupt_ref.friction)

    original = history_state._directions
    monkeypatch.setattr(history_state, "_directions", lambda x, tol: original(-x, tol))
    mutant = load_measured_data(path, robot).state(robot, effects)
    assert np.all(mutant.eta[ref.eta != 0] == -ref.eta[ref.eta != 0])
    abrupt = load_measured_data(path, robot).state(robot, {"backlash": effects["backlash"]})   # e = eta
    eta_m, _ = abrupt.applied(mu)
    eta_abrupt, _ = applied_friction(abrupt_ref.friction, mu)
    assert np.all(eta_m[eta_abrupt != 0] == -eta_abrupt[eta_abrupt != 0])


# --------------------------------------------------------------------------- the synthesizer itself
def test_reference_record_loads_with_noise_registration_and_its_motion_has_what_the_workflow_needs(tmp_path):
    """Catches a reference record the workflow cannot read or that misstates its noise or
    registration: the CSV loads as tracker-frame data, the noise-free truth mapped by the
    registration is the measured tip up to noise of the requested rms (3-D length) and AR(1)
    coefficient, the tangent noise has the requested rms angle, and the motion has reversals of
    every rotation joint and translation-last samples."""
    from scipy.spatial.transform import Rotation

    robot = load_robot(TABLE7)
    reg = (0.02, -0.01, 0.03, 0.004, -0.002, 0.01)
    rms, ang_rms, phi = 0.5e-3, float(np.deg2rad(0.3)), 0.6
    frame, truth = synthesize_reference(robot, samples=400, ds=DS, seed=9, registration=reg,
                                        noise_position_rms=rms, noise_angle_rms=ang_rms, noise_ar1=phi)
    path = tmp_path / "noisy.csv"
    frame.to_csv(path, index=False)
    data = load_measured_data(path, robot, frame="tracker")
    assert data.n_samples == int(truth["kept"].sum()) == 400
    np.testing.assert_array_equal(data.alpha, truth["alpha_commanded"])
    R = Rotation.from_rotvec(reg[:3]).as_matrix()
    noise = data.tip - (truth["tip"] @ R.T + np.asarray(reg[3:]))
    assert 0.85 * rms < np.sqrt(np.mean(np.sum(noise ** 2, axis=1))) < 1.15 * rms
    lag1 = np.mean([np.corrcoef(noise[1:, i], noise[:-1, i])[0, 1] for i in range(3)])
    assert abs(lag1 - phi) < 0.1
    cos = np.clip(np.einsum("ij,ij->i", data.tangent, truth["tangent"] @ R.T), -1.0, 1.0)
    assert 0.85 * ang_rms < np.sqrt(np.mean(np.arccos(cos) ** 2)) < 1.15 * ang_rms
    assert np.all(truth["reversals"][[robot.joint_names.index("alpha_2"), robot.joint_names.index("alpha_3")]] >= 2)
    assert truth["translation_last_samples"] > 30
