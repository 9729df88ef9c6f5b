"""The friction bound against measured tips (ctrplan.discrepancy.coverage): the split-conformal
factor's finite-sample coverage, the failing flag, and, through the whole workflow on synthetic
data, a calibrated bound and a prediction check that planning reads from the written robot file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.discrepancy.coverage import calibrate_bound, conformal_factor, coverage_figures
from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy
from ctrplan.io.robot_file import load_robot, load_robot_calibration, robot_to_toml
from ctrplan.pipeline import aim_decision
from reference.synth_reference import synthesize_reference

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"


# --------------------------------------------------------------------------- conformal factor
def test_conformal_factor_covers_its_target_on_new_exchangeable_samples():
    """Scores e / (b + m) exchangeable between calibration and test (errors proportional to a
    varying bound, heavy-tailed): over 400 seeds the calibrated bound covers on average at least
    the target, and not much more (split-conformal: between t and t + 1 / (n + 1)). Catches an
    off-by-one in the rank (the plain empirical quantile undercovers) and a factor on the wrong
    side of the scores."""
    rng = np.random.default_rng(61803)
    n, target, covers = 99, 0.9, []
    for _ in range(400):
        b = rng.uniform(0.2e-3, 3e-3, n + 500)
        e = b * np.abs(rng.standard_t(4, n + 500))
        f = conformal_factor(e[:n], b[:n], 0.1e-3, target)
        covers.append(np.mean(e[n:] <= f * (b[n:] + 0.1e-3)))
    assert target - 0.005 <= np.mean(covers) <= target + 1 / (n + 1) + 0.01, np.mean(covers)
    assert conformal_factor(np.ones(5), np.ones(5), 0.0, 0.9) == np.inf       # rank 6 of 5: no finite factor


def test_calibrated_bound_that_misses_its_target_is_failing():
    """Calibration errors within the bound, test errors three times larger: the calibrated bound
    covers far less than 90 % of the test tips and is reported failing; with test errors like the
    calibration ones it is not. Catches a check that cannot fail."""
    rng = np.random.default_rng(1414)
    b = rng.uniform(1e-3, 2e-3, 400)
    e = b * rng.uniform(0.0, 1.0, 400)
    units = np.repeat(np.arange(20), 10)
    good = calibrate_bound(e[:200], b[:200], e[200:], b[200:], units, noise_rms=0.0)
    bad = calibrate_bound(e[:200], b[:200], 3 * e[200:], b[200:], units, noise_rms=0.0)
    assert not good.failing and good.status == "met" and good.test["covered"] == pytest.approx(0.9, abs=0.07)
    assert bad.failing and bad.status == "failing" and bad.test["covered"] < 0.5
    wide = calibrate_bound(3 * e[:200], b[:200], e[200:], b[200:], units, noise_rms=0.0)
    assert not wide.failing and wide.status == "conservative" and wide.test["covered"] == 1.0
    fig = coverage_figures(e[200:], b[200:], 0.0, units)
    assert fig["covered"] == 1.0 and fig["ratio"]["max"] <= 1.0


# --------------------------------------------------------------------------- through the workflow
def _run(tmp_path, hidden, seed, candidates, file_mu):
    """Synthesize the Table I pair's trajectory with the ``hidden`` effects (keywords of the
    independent reference synthesizer), run the workflow from the pair with friction coefficient
    ``file_mu`` in its file."""
    base = load_robot(PAIR).replace(friction_coefficients=(file_mu,))
    model = tmp_path / "pair.toml"
    model.write_text(robot_to_toml(base, header="Table I tube pair"))
    data = tmp_path / "d.csv"
    frame, _ = synthesize_reference(base.replace(friction_coefficients=(0.0,)), samples=500, seed=seed, ds=6e-3,
                                    noise_position_rms=0.5e-3, **hidden)
    frame.to_csv(data, index=False)
    opts = DiscrepancyOptions(effects=candidates, ds=6e-3, n_permutations=199, max_evaluations=200, n_folds=5,
                              prior_strengths=(0.03, float("inf")), max_calibration_samples=200,
                              friction_search_samples=48, bound_samples=100, n_jobs=1)
    return run_discrepancy(model, data, tmp_path / "out", opts, echo=lambda s: None, progress=False)


def test_friction_measurements_give_a_bound_that_covers_and_a_prediction_planning_uses(tmp_path):
    """Measurements from the friction model (mu = 0.3) plus 0.5 mm noise: friction is named, the
    calibrated bound is not failing on the test split (coverage not short of 90 % by more than
    its interval or 5 points), the history-aware prediction beats the standard model there (the
    interval of their paired difference lies below zero), and the written robot file makes
    ``ctrplan plan`` aim with it. Catches a coverage computed on the
    calibration samples, a prediction check that is not written, and a planner gate that refuses
    a validated prediction."""
    res = _run(tmp_path, {"mu": (0.3,)}, 5021, ("friction",), file_mu=0.0)
    assert res["named_effect"] == "friction", res["decision"]
    bound = res["bound"]
    assert not bound["failing"] and bound["status"] in ("met", "conservative"), bound["test"]
    assert bound["test"]["covered"] >= 0.85
    assert bound["raw_test"]["n"] == bound["test"]["n"] > 50
    pc = res["prediction_check"]
    assert pc["history_beats_standard"], pc
    robot = load_robot(res["updated_model_file"])
    assert robot.metadata["bound_calibration"]["factor"] == pytest.approx(bound["factor"])
    assert robot.metadata["prediction_validation"]["history_beats_standard"] is True
    assert aim_decision(load_robot_calibration(res["updated_model_file"]).prediction).use_history


def test_measurements_of_another_effect_refuse_the_prediction_and_widen_the_bound(tmp_path):
    """Measurements from the standard model with a tracker lag of 0.2 s (no friction), the robot
    file claiming mu = 0.3 and friction the only candidate: the history-aware prediction does not
    beat the standard model, so the written file makes ``ctrplan plan`` aim with the standard
    model; the calibrated bound is wider than the raw one (factor > 1: the friction bound does
    not account for the lag). Catches a gate that trusts any fitted friction model, and a bound
    calibration that can only shrink the bound."""
    res = _run(tmp_path, {"time_offset": 0.2}, 5022, ("friction",), file_mu=0.3)
    pc = res["prediction_check"]
    robot = load_robot(res["updated_model_file"])
    assert not pc["history_beats_standard"], pc
    assert robot.metadata["prediction_validation"]["history_beats_standard"] is False
    decision = aim_decision(load_robot_calibration(res["updated_model_file"]).prediction)
    assert not decision.use_history and "does not beat" in decision.reason
    assert res["bound"]["factor"] > 1.0
