"""History effects (drive backlash, tracker time offset, gradually developing friction): their
operators, signature tests, synth options, plausibility and ambiguity rules, and (slow) the
workflow naming each when hidden in a continuous trajectory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.discrepancy import Effects, Noise, synthesize, write_synth
from ctrplan.discrepancy.history import (apply_backlash, apply_time_offset, friction_state, rotation_direction,
                                         rotation_since_reversal, tip_velocity)
from ctrplan.discrepancy.parameters import ParameterError, apply_parameters, history_parameters, parameter
from ctrplan.discrepancy.signatures import vector_signature
from ctrplan.discrepancy.workflow import (DiscrepancyOptions, _decide, estimate_noise, hull_distance,
                                         run_discrepancy)
from ctrplan.errors import PhysicalParameterError
from ctrplan.io.robot_file import load_robot, robot_to_toml
from ctrplan.mechanics import ModelSettings

ROOT = Path(__file__).resolve().parents[1]
TABLE7 = ROOT / "model" / "ha2019-table7-calibrated.toml"
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
COARSE = ModelSettings(ds=6e-3)


# --------------------------------------------------------------------------- operators
def test_backlash_lags_by_half_the_band_after_each_reversal():
    """Play operator: moving up, the tube lags by b/2; after the reversal it stays put until the
    motor has crossed the band, then lags by b/2 the other way. Catches a lag on the wrong side,
    a full-band lag, or a lag without reversal."""
    up = np.linspace(0.0, 1.0, 11)
    motor = np.concatenate([up, up[::-1][1:]])[:, None] * np.array([[0.0, 1.0]])
    a = apply_backlash(motor, [0.0, 0.2])
    np.testing.assert_allclose(a[:, 0], 0.0)
    np.testing.assert_allclose(a[1:11, 1], motor[1:11, 1] - 0.1, atol=1e-12)     # lagging below
    np.testing.assert_allclose(a[11, 1], a[10, 1])                               # inside the band: stays
    np.testing.assert_allclose(a[13:, 1], motor[13:, 1] + 0.1, atol=1e-12)       # lagging above
    assert np.all(np.abs(a - motor) <= 0.1 + 1e-12)
    # direction of the last rotation, the sign of the lag
    s = rotation_direction(motor)
    assert s[5, 1] == 1 and s[-1, 1] == -1 and np.all(s[:, 0] == 0)
    with pytest.raises(ValueError, match="backlash widths"):
        apply_backlash(motor, [0.0, -0.1])


def test_time_offset_interpolates_the_joint_record():
    """Joints at t - tau by linear interpolation, held at the record's start; a ramp shifted by
    0.25 s reads 0.25 s x slope lower. Catches a shift of the wrong sign or by whole samples."""
    t = np.arange(10) * 0.1
    alpha = np.column_stack([np.zeros(10), t * 2.0])
    beta = np.column_stack([np.zeros(10), -0.05 + 0.01 * t])
    a, b = apply_time_offset(alpha, beta, t, 0.25)
    np.testing.assert_allclose(a[5:, 1], 2.0 * (t[5:] - 0.25), atol=1e-12)
    np.testing.assert_allclose(a[:3, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(b[5:, 1], -0.05 + 0.01 * (t[5:] - 0.25), atol=1e-12)
    with pytest.raises(ValueError, match="needs sample times"):
        apply_time_offset(alpha, beta, None, 0.1)
    v = tip_velocity(np.column_stack([t, 0 * t, 0 * t]), t)
    np.testing.assert_allclose(v[:, 0], 1.0)


def test_friction_state_develops_exponentially_and_translation_releases_it():
    """Dahl-type state: after a long positive rotation e ~ +1; after reversing by theta_c it is
    1 - 2 exp(-1); theta_c = 0 gives the abrupt eta of the paper; a translation resets it to 0.
    Catches a wrong law, a missing release or a state that does not restart."""
    theta = np.deg2rad(10.0)
    rel = np.concatenate([np.linspace(0, 1.5, 151), np.linspace(1.5, 1.5 - theta, 11)[1:]])
    alpha = np.column_stack([np.zeros(rel.size), rel])
    beta = np.tile([0.0, -0.02], (rel.size, 1))
    e = friction_state(alpha, beta, theta)
    assert e[150, 0] == pytest.approx(1.0 - np.exp(-1.5 / theta), abs=1e-9)      # from 0: 1 - exp(-r/theta)
    assert e[-1, 0] == pytest.approx(-1.0 + (1.0 + e[150, 0]) * np.exp(-1.0), abs=1e-9)
    assert e[-1, 0] == pytest.approx(-(1 - 2 * np.exp(-1.0)), abs=1e-3)
    e0 = friction_state(alpha, beta, 0.0)
    assert e0[100, 0] == 1 and e0[-1, 0] == -1
    alpha2 = np.vstack([alpha, np.repeat(alpha[-1:], 3, axis=0)])
    beta2 = np.vstack([beta, [[0.0, -0.019], [0.0, -0.018], [0.0, -0.017]]])   # a translation after it
    e2 = friction_state(alpha2, beta2, theta)
    assert e2[-4, 0] == pytest.approx(e[-1, 0]) and np.all(e2[-3:, 0] == 0.0)
    d = rotation_since_reversal(alpha)
    assert d[150, 0] == pytest.approx(1.5) and d[-1, 0] == pytest.approx(theta)


# --------------------------------------------------------------------------- parameters, synth
def test_history_parameters_have_units_bounds_and_plausible_ranges():
    """Catches a history parameter that changes the robot, has no unit or plausible range, or
    accepts values outside its bounds."""
    robot = load_robot(TABLE7)
    for name, unit in (("backlash_2", "rad"), ("time_offset", "s"), ("friction_angle", "rad")):
        p = parameter(robot, name)
        assert p.history and not p.mechanical and p.unit == unit and p.plausible is not None
    assert parameter(robot, "mu_1").is_plausible(0.22) and not parameter(robot, "mu_1").is_plausible(1.075)
    assert apply_parameters(robot, ("backlash_2", "time_offset"), (0.05, 0.1)) == robot
    h = history_parameters(robot, ("backlash_3", "time_offset", "precurvature_y_3"), (0.05, 0.1, 15.0))
    np.testing.assert_allclose(h["backlash"], [0, 0, 0.05])
    assert h["time_offset"] == 0.1
    with pytest.raises(ParameterError, match="outside"):
        history_parameters(robot, ("backlash_2",), (-0.1,))


def test_synth_hides_history_effects_and_refuses_them_on_the_paper_protocol():
    """The truth moves along the changed history, the recorded joints and eta do not change;
    the paper protocol and gradual friction without mu are refused. Catches effects that do
    nothing or that leak into the recorded joints."""
    robot = load_robot(TABLE7).replace(friction_coefficients=(0.0, 0.0))
    clean = Noise(position_rms=0.0, angle_rms=0.0)
    kw = dict(protocol="trajectory", samples=120, noise=clean, seed=3, settings=COARSE)
    base = synthesize(robot, Effects(), **kw).frame
    for eff in (Effects(backlash=(0.0, 0.08, 0.08)), Effects(time_offset=(0.2,))):
        f = synthesize(robot, eff, **kw).frame
        joints = [c for c in base if c.startswith(("alpha", "beta", "eta"))]
        assert f[joints].equals(base[joints])
        moved = np.linalg.norm(f[["tip_x", "tip_y", "tip_z"]].values - base[["tip_x", "tip_y", "tip_z"]].values, axis=1)
        assert moved.max() > 1e-3
    with pytest.raises(PhysicalParameterError, match="trajectory protocol"):
        synthesize(robot, Effects(backlash=(0, 0.1, 0.1)), protocol="paper", grid=2, noise=clean, settings=COARSE)
    with pytest.raises(PhysicalParameterError, match="friction coefficients"):
        synthesize(robot, Effects(friction_angle=(0.1,)), **kw)


def test_cli_synth_history_options(tmp_path):
    """The synth options hide the effects and name the option on bad input."""
    from click.testing import CliRunner

    from ctrplan.cli import main

    out = tmp_path / "s.csv"
    r = CliRunner().invoke(main, ["synth", "--robot", str(PAIR), "--out", str(out), "--protocol", "trajectory",
                                  "--samples", "40", "--backlash-rad", "0,0.05", "--time-offset-s", "0.1",
                                  "--ds", "0.006", "--jobs", "1", "--no-progress"])
    assert r.exit_code == 0, r.output
    assert '"backlash": [\n      0.0,\n      0.05' in (tmp_path / "s.csv.truth.json").read_text()
    r = CliRunner().invoke(main, ["synth", "--robot", str(PAIR), "--out", str(out), "--friction-angle-rad", "0.1",
                                  "--protocol", "trajectory", "--samples", "40"])
    assert r.exit_code != 0 and "--friction-angle-rad" in str(r.exception)


# --------------------------------------------------------------------------- signatures and rules
def test_vector_signature_finds_a_planted_lag_and_not_noise():
    """A residual of -tau v (tracker lag) along a smooth trajectory is found (p < 0.01), pure
    noise is not. Catches a statistic blind to the pattern or a null that always rejects."""
    rng = np.random.default_rng(0)
    t = np.arange(600) * 0.1
    tip = np.column_stack([0.02 * np.sin(0.7 * t), 0.02 * np.cos(0.4 * t), 0.01 * np.sin(0.2 * t)])
    v = tip_velocity(tip, t)
    noise = rng.normal(0, 0.3e-3, (600, 3))
    seq = np.zeros(600, int)
    hit = vector_signature("time_offset", noise - 0.1 * v, -v[:, :, None], np.arange(600), sequence=seq,
                           n_permutations=199)
    null = vector_signature("time_offset", noise, -v[:, :, None], np.arange(600), sequence=seq, n_permutations=199)
    assert hit.p_value < 0.01 and null.p_value > 0.01
    assert not vector_signature("x", noise, np.zeros((600, 3, 1)), np.arange(600)).testable


def test_decision_passes_over_implausible_values_and_lists_equally_good_effects():
    """Friction with mu_1 = 1.075 (implausible) is not named while plausible backlash is
    eligible; two candidates whose held-out residuals do not differ significantly are both
    listed. Catches the old rule (largest improvement wins, silently)."""
    rng = np.random.default_rng(1)
    units = np.repeat(np.arange(20), 10)
    r_fr = rng.normal(1.0, 0.1, 200)
    cands = {
        "friction": {"label": "torsional friction", "plausible": False,
                     "implausible": [{"name": "mu_1", "value": 1.075, "unit": "-", "plausible": [0, 0.5]}],
                     "improvement_eq49": {"mean_difference": 2.0}, "_r": r_fr},
        "backlash": {"label": "drive backlash", "plausible": True, "implausible": [],
                     "improvement_eq49": {"mean_difference": 1.9}, "_r": r_fr + rng.normal(0, 0.01, 200)},
        "time_offset": {"label": "time offset", "plausible": True, "implausible": [],
                        "improvement_eq49": {"mean_difference": 1.85}, "_r": r_fr + rng.normal(0, 0.01, 200)},
    }
    d = _decide(cands, ["friction", "backlash", "time_offset"], units, DiscrepancyOptions())
    assert d["named"] == "backlash" and d["passed_over_implausible"] == ["friction"]
    assert [x["effect"] for x in d["equally_good"]] == ["time_offset"]
    assert any("equally well" in n for n in d["notes"])
    cands["time_offset"]["_r"] = r_fr + 0.5                  # clearly worse held out
    assert _decide(cands, ["friction", "backlash", "time_offset"], units, DiscrepancyOptions())["equally_good"] == []


def test_hull_distance():
    """Distance to the convex hull of the bounding tips: 0 inside, the gap outside."""
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    assert hull_distance(P, [0.2, 0.2, 0.0]) == pytest.approx(0.0, abs=1e-9)
    assert hull_distance(P, [0.2, 0.2, 0.5]) == pytest.approx(0.5, abs=1e-9)
    assert hull_distance(P, [2.0, 0.0, 0.0]) == pytest.approx(1.0, rel=1e-5)


# --------------------------------------------------------------------------- hidden effects (slow)
def _trajectory_case(tmp_path, effects, *, seed, samples=800, candidates=None, truth_robot=None, jobs=2):
    """Table VII robot, continuous trajectory of 80 s, 0.5 mm / 0.3 deg noise; the workflow
    starts from the model with friction off. Blocks of 50 samples, one in four for calibration
    (200 samples spread over the motion; one block of 100 samples from one part of it leaves the
    tube parameters poorly determined), 600 held out in 12 units."""
    robot = load_robot(TABLE7).replace(friction_coefficients=(0.0, 0.0))
    model = tmp_path / "model.toml"
    model.write_text(robot_to_toml(robot, header="Table VII, friction off"))
    data = tmp_path / "d.csv"
    write_synth(data, synthesize(truth_robot or robot, effects, protocol="trajectory", samples=samples,
                                 noise=Noise(position_rms=0.5e-3, angle_rms=float(np.deg2rad(0.3))), seed=seed,
                                 settings=COARSE, n_jobs=jobs))
    opts = DiscrepancyOptions(effects=candidates or ("friction", "backlash", "time_offset", "gradual_friction"),
                              ds=6e-3, n_permutations=199, n_jobs=jobs, friction_grid=(0.0, 0.15, 0.3),
                              friction_search_samples=60, max_evaluations=400, block_samples=50)
    return run_discrepancy(model, data, tmp_path / "out", opts, echo=print, progress=False)


@pytest.mark.slow
def test_hidden_backlash_on_a_trajectory_is_named_not_friction(tmp_path):
    """Hidden 4 deg dead band in the drives of tubes 2 and 3: backlash is named, friction is not
    (a friction model imitates part of the hysteresis, but a translation releases friction and
    not the play). Catches a workflow that mistakes backlash for friction (issue 13, Sec. 4)."""
    res = _trajectory_case(tmp_path, Effects(backlash=(0.0, 0.07, 0.07)), seed=11)
    assert res["named_effect"] == "backlash", res["decision"]
    assert "friction" not in [d["effect"] for d in res["decision"]["equally_good"]]
    assert res["noise"]["consistent"] is False


@pytest.mark.slow
def test_hidden_friction_on_a_trajectory_is_named_not_backlash(tmp_path):
    """Hidden friction (0.22, 0.12) along a continuous trajectory: friction (abrupt or
    gradual) is named, backlash is not. Catches a backlash candidate that absorbs friction."""
    res = _trajectory_case(tmp_path, Effects(friction_coefficients=(0.22, 0.12)), seed=12,
                           truth_robot=load_robot(TABLE7))
    assert res["named_effect"] in ("friction", "gradual_friction"), res["decision"]
    assert "backlash" not in [d["effect"] for d in res["decision"]["equally_good"]]


@pytest.mark.slow
def test_hidden_time_offset_on_a_trajectory_is_named(tmp_path):
    """Hidden 0.2 s tracker lag: the time offset is named with tau within 0.05 s. Catches
    the old report, which called this trajectory's residual consistent with noise."""
    res = _trajectory_case(tmp_path, Effects(time_offset=(0.2,)), seed=13)
    assert res["named_effect"] == "time_offset", res["decision"]
    assert res["candidates"]["time_offset"]["parameters"]["time_offset"] == pytest.approx(0.2, abs=0.05)
    assert res["noise"]["consistent"] is False


@pytest.mark.slow
def test_hidden_gradual_friction_on_a_trajectory_is_named_not_backlash(tmp_path):
    """Hidden friction (0.22, 0.12) that develops over theta_c = 20 deg after each reversal: the
    gradual-friction effect is named (not backlash, not the abrupt friction of the paper), with
    theta_c within 10 deg of the truth. Catches a friction-angle fit that cannot see the ramp and
    a backlash candidate that absorbs it (issue 13, Sec. 4)."""
    theta = float(np.deg2rad(20.0))
    res = _trajectory_case(tmp_path, Effects(friction_coefficients=(0.22, 0.12), friction_angle=(theta,)), seed=14,
                           truth_robot=load_robot(TABLE7), candidates=("friction", "backlash", "gradual_friction"),
                           jobs=1)
    assert res["named_effect"] == "gradual_friction", (res["decision"], {e: c["held_out"] for e, c in
                                                                         res["candidates"].items()})
    assert res["candidates"]["gradual_friction"]["parameters"]["friction_angle"] == pytest.approx(theta, abs=np.deg2rad(10))
    assert "backlash" not in res["named_effects"]
    assert "backlash" not in [d["effect"] for d in res["decision"]["equally_good"]]
