"""The friction bound against measured tips (ctrplan.discrepancy.coverage): the split-conformal
factor's finite-sample coverage, the failing flag, and, through the whole workflow on synthetic
data, a calibrated bound and a prediction check that planning reads from the written robot file."""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ctrplan.discrepancy import coverage
from ctrplan.discrepancy.coverage import Coverage, calibrate_bound, conformal_factor, coverage_figures
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
    assert not good.failing and good.status == "met" and good.test.covered == pytest.approx(0.9, abs=0.07)
    assert bad.failing and bad.status == "failing" and bad.test.covered < 0.5
    wide = calibrate_bound(3 * e[:200], b[:200], e[200:], b[200:], units, noise_rms=0.0)
    assert not wide.failing and wide.status == "conservative" and wide.test.covered == 1.0
    fig = coverage_figures(e[200:], b[200:], 0.0, units)
    assert fig.covered == 1.0 and fig.ratio["max"] <= 1.0


def test_a_test_split_of_one_unit_is_judged_by_the_tolerance_alone():
    """One test unit: the coverage interval has no finite ends (None). A coverage far below the
    target is failing, far above it conservative, near it met, by :data:`COVERAGE_TOLERANCE`
    alone. Catches the comparison of a None end with the target (a TypeError)."""
    rng = np.random.default_rng(2718)
    b = rng.uniform(1e-3, 2e-3, 300)
    e = b * rng.uniform(0.0, 1.0, 300)
    one = np.zeros(100, int)
    good = calibrate_bound(e[:200], b[:200], e[200:], b[200:], one, noise_rms=0.0)
    bad = calibrate_bound(e[:200], b[:200], 3 * e[200:], b[200:], one, noise_rms=0.0)
    wide = calibrate_bound(3 * e[:200], b[:200], e[200:], b[200:], one, noise_rms=0.0)
    for cal in (good, bad, wide):
        assert cal.test.ci == (None, None) and cal.test.n_units == 1
    assert good.status == "met" and abs(good.test.covered - 0.9) <= coverage.COVERAGE_TOLERANCE
    assert bad.failing and bad.status == "failing"
    assert not wide.failing and wide.status == "conservative"


def test_coverage_is_frozen_and_its_dict_is_the_former_one():
    """:class:`Coverage` is frozen, its ``ratio`` read-only, it pickles, and ``as_dict`` gives the
    former dict (``ci`` a list, ``ratio`` a dict, plain Python values); the calibrated bound's median
    is that of ``factor (b + m)``. Catches a result that can be changed after the fact."""
    rng = np.random.default_rng(31)
    b = rng.uniform(1e-3, 2e-3, 120)
    e = b * rng.uniform(0.0, 1.2, 120)
    units = np.repeat(np.arange(12), 10)
    fig = coverage_figures(e, b, 0.1e-3, units)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fig.covered = 0.0
    with pytest.raises(TypeError):
        fig.ratio["max"] = 0.0
    assert pickle.loads(pickle.dumps(fig)) == fig
    d = fig.as_dict()
    assert list(d) == ["n", "covered", "ci", "n_units", "ratio", "bound_median_m", "error_median_m"]
    assert isinstance(d["ci"], list) and isinstance(d["ratio"], dict) and list(d["ratio"]) == ["median", "p90",
                                                                                                   "p95", "max"]
    assert d["n"] == 120 and d["n_units"] == 12 and d["bound_median_m"] == float(np.median(b))
    empty = coverage_figures([np.nan], [1e-3], 0.0, [0])
    assert empty == Coverage(0, None, (None, None), 0, dict.fromkeys(("median", "p90", "p95", "max")), None, None)
    cal = calibrate_bound(e[:60], b[:60], e[60:], b[60:], units[60:], noise_rms=0.5e-4)
    m = coverage.NOISE_MULTIPLE * 0.5e-4
    assert cal.test.bound_median_m == pytest.approx(float(np.median(cal.factor * (b[60:] + m))))
    assert cal.raw_test.bound_median_m == float(np.median(b[60:]))
    assert cal.file_table("d.csv", "0" * 64)["test_samples"] == 60


# --------------------------------------------------------------------------- stored bounds
def _bound_stage_names(monkeypatch, robot) -> list:
    """The stage names under which :func:`coverage.check_bound` looks for stored bounds of ``robot``
    (three development and three test samples; the bound itself is not evaluated)."""
    k, n = 6, robot.n_tubes
    names = []

    class Store:
        def load(self, name):
            names.append(name)
            return None

        def save(self, name, value):
            pass

    def bounds(robot, alpha, beta, settings=None, *, n_jobs=1):
        m = len(alpha)
        return coverage.BoundValues(position=np.full(m, 1e-3), translation_last=np.full(m, 1e-3),
                                    ok=np.ones(m, bool))

    monkeypatch.setattr(coverage, "bound_values", bounds)
    state = SimpleNamespace(alpha=np.zeros((k, n)), beta=np.tile(robot.home_beta, (k, 1)))
    data = SimpleNamespace(state=lambda robot, effects: state, translation_last=np.zeros((k, n - 1), bool))
    setup = SimpleNamespace(robot=robot, data=data, stages=Store(), settings=None)
    dev = np.arange(k) < 3
    split = SimpleNamespace(dev_rows=dev, test_rows=~dev, units=np.arange(k))
    errors = SimpleNamespace(position=np.full(k, 0.5e-3), rows=np.arange(k))
    options = SimpleNamespace(bound_samples=100, n_jobs=1, bound_target=0.9, seed=0)
    coverage.check_bound(setup, split, SimpleNamespace(oof=errors), errors, {}, SimpleNamespace(rms=1e-4), options)
    return names


def test_stored_bounds_are_tagged_with_every_parameter_of_the_robot(monkeypatch):
    """Two robots that differ only in a Poisson ratio, or only in a tube diameter, store their
    bounds under different stage names (``bound-development-<samples>-<tag>``); the same robot
    under the same ones. Catches a tag that leaves parameters out, under which the bounds of
    another calibration would be reused."""
    robot = load_robot(PAIR)
    tubes = list(robot.tubes)
    poisson = robot.replace(tubes=(dataclasses.replace(tubes[0], poisson_ratio=0.35), tubes[1]))
    diameter = robot.replace(tubes=(tubes[0], dataclasses.replace(tubes[1], outer_diameter=0.9e-3)))
    first = _bound_stage_names(monkeypatch, robot)
    assert len(first) == 2 and first[0].startswith("bound-development-100-") and first[1].startswith("bound-test-100-")
    assert _bound_stage_names(monkeypatch, robot) == first
    for other in (poisson, diameter):
        names = _bound_stage_names(monkeypatch, other)
        assert names[0].rsplit("-", 1)[0] == first[0].rsplit("-", 1)[0]
        assert not set(names) & set(first), names


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
                              friction_search_samples=48, bound_samples=100, n_jobs=2)
    return run_discrepancy(model, data, tmp_path / "out", opts, progress=False).to_dict()


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
