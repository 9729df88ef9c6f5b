"""Stage functions of :mod:`ctrplan.discrepancy.workflow`: each returns SI values (m, rad, s), the
split keeps calibration rows out of every held-out statistic, the stage key is stable, and the
results stage alone converts to mm.

The stages run on the fast case of ``test_discrepancy_fast`` (Table I tube pair, standard model,
coarse grid, 500 samples of a continuous trajectory at 10 Hz) with a hidden tracker lag of
0.15 s; only the time offset is tried, so the module takes about 10 s. ``test_discrepancy_fast``
and ``test_discrepancy_workflow`` check whole runs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.discrepancy import Noise, synthesize, write_synth
from ctrplan.discrepancy import decision, evaluation, fitting, options, setup as setup_stage, signatures, split as split_stage, stages
from ctrplan.discrepancy.calibrate import pose_errors, predict
from ctrplan.discrepancy.workflow import DiscrepancyOptions
from ctrplan.io.robot_file import load_robot, robot_to_toml
from ctrplan.mechanics import ModelSettings

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
LAG_S = 0.15
OPTIONS = DiscrepancyOptions(effects=("time_offset",), ds=6e-3, n_permutations=199, max_evaluations=200, n_jobs=1)


def _quiet(*_):
    pass


@pytest.fixture(scope="module")
def staged(tmp_path_factory):
    """Stages 1-6 of a run on data with a hidden 0.15 s tracker lag."""
    tmp = tmp_path_factory.mktemp("discrepancy-stages")
    robot = load_robot(PAIR).replace(friction_coefficients=(0.0,))
    model = tmp / "pair.toml"
    model.write_text(robot_to_toml(robot, header="Table I tube pair, friction off"))
    data = tmp / "d.csv"
    write_synth(data, synthesize(robot, {"time_offset": {"time_offset": LAG_S}}, protocol="trajectory", samples=500,
                                 noise=Noise(position_rms=0.5e-3, angle_rms=float(np.deg2rad(0.3))), seed=1,
                                 settings=ModelSettings(ds=6e-3)))
    setup = setup_stage.load_inputs(model, data, tmp / "out", OPTIONS)
    split = split_stage.split_samples(setup, OPTIONS, _quiet)

    def held_out(name, model_name, params):
        return evaluation.evaluate_held_out(setup, split, name, model_name, params, progress=False, echo=_quiet)

    baseline = fitting.calibrate_baseline(setup, split, OPTIONS, held_out, _quiet)
    candidates = fitting.fit_candidates(setup, split, baseline, None, OPTIONS, held_out, _quiet)
    return setup, split, baseline, candidates


def test_split_keeps_calibration_rows_out_of_the_held_out_statistics(staged):
    """The held-out samples are exactly the validation rows (none of them calibration rows), the
    fitted rows are calibration rows, and the baseline's held-out errors are those of the
    validation rows, recomputed here independently of the stage. Catches a split that lets
    calibration samples into the held-out error (which would flatter every fit)."""
    setup, split, baseline, _ = staged
    cal, val_rows, fit = split.calibration_rows, split.validation_rows, split.fit_rows
    assert cal.any() and val_rows.any()
    assert not np.any(cal & val_rows)
    assert not np.any(fit & ~cal)
    assert split.n_calibration == int(cal.sum()) and split.n_fit == int(fit.sum())
    k = int(val_rows.sum())
    assert split.val.n_samples == k and split.units.shape == (k,)
    np.testing.assert_array_equal(split.val.tip, setup.data.tip[val_rows])
    # the baseline's held-out errors: its parameters on the validation rows, nothing else
    params = baseline.params
    pred = predict(setup.robot, tuple(params), tuple(params.values()), setup.data.take(val_rows), "standard",
                   setup.settings)
    pos, ang, _ = pose_errors(pred, setup.data.take(val_rows))
    assert baseline.held_out.position.shape == (k,)
    np.testing.assert_allclose(baseline.held_out.position, pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(baseline.held_out.angle, ang, rtol=0, atol=1e-12)


def test_time_offset_candidate_is_fitted_in_seconds_and_its_errors_are_in_metres(staged):
    """The lag comes back in s (0.15, not 150), the held-out errors in m (about a mm, i.e.
    ~1e-3) and the tip velocity signature's effect size in m; the results stage writes the
    held-out mean in mm (1e3 times the SI mean) and leaves the lag in s. Catches a stage that
    converts to ms or mm before the report."""
    setup, split, baseline, candidates = staged
    c = candidates["time_offset"]
    assert c.shown["time_offset"] == pytest.approx(LAG_S, abs=0.02)
    assert c.units == {"time_offset": "s"}
    base_mean = float(np.nanmean(baseline.held_out.position))
    cand_mean = float(np.nanmean(c.held_out.position))
    assert 3e-4 < cand_mean < base_mean < 1e-2, (cand_mean, base_mean)       # m
    assert c.improvement_position["mean_difference"] == pytest.approx(base_mean - cand_mean, rel=0.3)
    tests = signatures.diagnose_residuals(setup, split, baseline, OPTIONS, _quiet)
    assert 1e-4 < tests["time_offset"].effect_size_m < 1e-2
    noise = decision.check_noise(setup, baseline, OPTIONS, _quiet)
    naming = decision.name_effect(split, candidates, tests, noise, OPTIONS, _quiet)
    assert naming.named == "time_offset" and naming.candidates["time_offset"].eligible
    report = fitting.candidate_report(naming.candidates["time_offset"], split.val.n_samples)
    assert report["parameters"]["time_offset"] == c.shown["time_offset"]                  # s stays s
    assert report["held_out"]["position_mean_mm"] == pytest.approx(1e3 * cand_mean, rel=1e-12)


def test_noise_check_is_in_metres_and_the_report_form_in_millimetres():
    """Held-out errors of rms 1 mm against a stated 0.8 mm noise: the check holds rms 1e-3 m and
    ratio 1.25 (consistent, at the threshold); its report form says 1.0 mm and 0.8 mm. Catches
    an rms kept in mm in the stage result or converted twice."""
    pos = np.array([1e-3, -1e-3, 1e-3, np.nan, 1e-3])       # |errors| are what the stage sees
    noise = {"position_rms_m": 0.8e-3, "source": "stated", "n": 0, "upper_bound": False, "description": "x"}
    check = decision.noise_check(np.abs(pos), noise)
    assert check.rms_m == pytest.approx(1e-3, rel=1e-12)
    assert check.ratio == pytest.approx(1.25, rel=1e-12) and check.consistent is True
    d = check.as_dict()
    assert d["rms_mm"] == pytest.approx(1.0, rel=1e-12) and d["noise_rms_mm"] == pytest.approx(0.8, rel=1e-12)
    assert decision.noise_check(np.abs(pos) * 2, noise).consistent is False
    assert decision.noise_check(np.abs(pos), {**noise, "position_rms_m": None}).consistent is None


def test_stage_key_ignores_workers_and_tests_and_follows_fits_inputs_and_procedure(tmp_path, monkeypatch):
    """The key is unchanged by the workers, the permutations, the level, the stated noise, the
    envelope and the reference friction; it changes with an option that changes a fit, with the
    effects tried, with either input file's bytes, and with the fitting procedure's version.
    Catches a key that sends every rerun back to the start, or reuses stages fitted with other
    options, other data or an earlier procedure."""
    robot, data = tmp_path / "r.toml", tmp_path / "d.csv"
    robot.write_bytes(b"robot")
    data.write_bytes(b"data")
    base = DiscrepancyOptions()
    key = stages.stage_key(robot, data, base)
    same = DiscrepancyOptions(n_jobs=2, n_permutations=99, significance=0.05, noise_position=2e-4,
                              envelope_samples=10, reference_friction=(0.2,))
    assert stages.stage_key(robot, data, same) == key
    for changed in (DiscrepancyOptions(ds=6e-3), DiscrepancyOptions(block_samples=50), DiscrepancyOptions(seed=1),
                    DiscrepancyOptions(effects=("backlash",))):
        assert stages.stage_key(robot, data, changed) != key
    data.write_bytes(b"data2")
    assert stages.stage_key(robot, data, base) != key
    data.write_bytes(b"data")
    monkeypatch.setattr(stages, "FIT_VERSION", options.FIT_VERSION + 1)
    assert stages.stage_key(robot, data, base) != key
