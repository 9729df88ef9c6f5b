"""Stage functions of :mod:`ctrplan.discrepancy.workflow`: each returns SI values (m, rad, s), the
out-of-fold errors come from fits that never saw their samples and no fit sees the test split,
the stage key is stable, and the results stage alone converts to mm.

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
from ctrplan.discrepancy import decision, fitting, options, setup as setup_stage, signatures, split as split_stage, stages
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
    baseline = fitting.calibrate_baseline(setup, split, OPTIONS, _quiet)
    candidates = fitting.fit_candidates(setup, split, baseline, None, OPTIONS, _quiet)
    return setup, split, baseline, candidates


def test_out_of_fold_errors_come_from_fits_that_never_saw_their_samples(staged):
    """No fit uses a test-split sample or a sample of the fold it is validated on; the baseline's
    out-of-fold error at each development sample is the prediction of the fit made without that
    sample's fold, recomputed here independently of the stage. Catches a split that lets
    calibration samples into the validated errors (which would flatter every fit) and out-of-fold
    errors assembled in the wrong order."""
    setup, split, baseline, _ = staged
    data = setup.data
    assert split.n_test > 0 and split.n_dev + split.n_test == data.n_samples
    for k in range(split.n_folds):
        fit = split.fit_rows(data, k)
        assert fit.any() and not np.any(fit & split.test_rows) and not np.any(fit & split.validation_rows(k))
    assert not np.any(split.fit_rows(data) & split.test_rows)
    oof = baseline.oof
    dev = np.flatnonzero(split.dev_rows)
    np.testing.assert_array_equal(oof.rows, dev)
    for k in (0, split.n_folds - 1):
        rows = split.validation_rows(k)
        params = baseline.cv.fold_params(k)
        pred = predict(setup.robot, tuple(params), tuple(params.values()), data.take(rows), "standard", setup.settings)
        pos, ang, _ = pose_errors(pred, data.take(rows))
        np.testing.assert_allclose(oof.position[rows[dev]], pos, rtol=0, atol=1e-12)
        np.testing.assert_allclose(oof.angle[rows[dev]], ang, rtol=0, atol=1e-12)
        # a fold's fit differs from the development fit: it did not see that fold
        assert params != baseline.params


def test_time_offset_candidate_is_fitted_in_seconds_and_its_errors_are_in_metres(staged):
    """The lag comes back in s (0.15, not 150), the held-out errors in m (about a mm, i.e.
    ~1e-3) and the tip velocity signature's effect size in m; the results stage writes the
    held-out mean in mm (1e3 times the SI mean) and leaves the lag in s. Catches a stage that
    converts to ms or mm before the report."""
    setup, split, baseline, candidates = staged
    c = candidates["time_offset"]
    assert c.shown["time_offset"] == pytest.approx(LAG_S, abs=0.02)
    assert c.units == {"time_offset": "s"}
    base_mean = float(np.nanmean(baseline.oof.position))
    cand_mean = float(np.nanmean(c.oof.position))
    assert 3e-4 < cand_mean < base_mean < 1e-2, (cand_mean, base_mean)       # m
    assert c.improvement_position["mean_difference"] == pytest.approx(base_mean - cand_mean, rel=0.3)
    tests = signatures.diagnose_residuals(setup, split, baseline, OPTIONS, _quiet)
    assert 1e-4 < tests["time_offset"].effect_size_m < 1e-2
    noise = decision.check_noise(setup, split, baseline, OPTIONS, _quiet)
    naming = decision.name_effect(split, candidates, tests, noise, OPTIONS, _quiet)
    assert naming.named == "time_offset" and naming.candidates["time_offset"].eligible
    report = fitting.candidate_report(naming.candidates["time_offset"])
    assert report["parameters"]["time_offset"] == pytest.approx(LAG_S, abs=0.02)          # s stays s
    assert report["out_of_fold"]["position_mean_mm"] == pytest.approx(1e3 * cand_mean, rel=1e-12)
    se = dict(zip(c.fit.names, c.fit.stderr))["time_offset"]
    assert 0 < se < 0.02                                                                   # s, not ms


def test_noise_check_is_in_metres_and_the_report_form_in_millimetres():
    """An out-of-fold rms of 1 mm against a stated 0.8 mm noise: the check holds rms 1e-3 m and
    ratio 1.25; its report form says 1.0 mm and 0.8 mm. Catches an rms kept in mm in the stage
    result or converted twice."""
    from ctrplan.discrepancy.statistics import noise_test

    noise = {"position_rms_m": 0.8e-3, "source": "stated", "n": 0, "dof": None, "upper_bound": False,
             "description": "x"}
    test = noise_test((1e-3) ** 2 / 3, 300, (0.8e-3) ** 2 / 3, None, n_parameters=3, n_fitted=300, alpha=0.01)
    check = decision.NoiseCheck(noise=noise, rms_m=1e-3, ratio=1.25, test=test)
    d = check.as_dict()
    assert d["rms_mm"] == pytest.approx(1.0, rel=1e-12) and d["noise_rms_mm"] == pytest.approx(0.8, rel=1e-12)
    assert check.consistent is False                            # 1.25^2 / 1.01 = 1.55 >> chi2 threshold 1.2
    assert decision.NoiseCheck(noise={**noise, "position_rms_m": None}, rms_m=1e-3, ratio=None,
                               test=None).consistent is None


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
    for changed in (DiscrepancyOptions(ds=6e-3), DiscrepancyOptions(n_blocks=10), DiscrepancyOptions(test_fraction=0.3), DiscrepancyOptions(seed=1),
                    DiscrepancyOptions(effects=("backlash",))):
        assert stages.stage_key(robot, data, changed) != key
    data.write_bytes(b"data2")
    assert stages.stage_key(robot, data, base) != key
    data.write_bytes(b"data")
    monkeypatch.setattr(stages, "FIT_VERSION", options.FIT_VERSION + 1)
    assert stages.stage_key(robot, data, base) != key
