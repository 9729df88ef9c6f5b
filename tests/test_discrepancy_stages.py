"""Stage functions of :mod:`ctrplan.discrepancy.workflow`: each returns SI values (m, rad, s); the
out-of-fold errors come from fits that never saw their samples, their buffers or a fit that did;
no fit sees the test split; the stage key is stable; the report alone converts to mm.

The stages run on a record made independently of the fitting code (``tests/ctrplan_reference``: the
Table I tube pair, 500 samples of a continuous motion at 10 Hz, a tracker lag of 0.15 s evaluated
exactly on the analytic motion, seen in a tracker frame, 0.5 mm / 0.3 deg noise), with only the
time offset tried and 5 folds, so the module takes well under a minute. ``test_discrepancy_fast`` and
``test_discrepancy_workflow`` check whole runs.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ctrplan.discrepancy import options, setup as setup_stage, stages
from ctrplan.discrepancy.fits import baseline as baseline_stage, fitting
from ctrplan.discrepancy.measured import split as split_stage
from ctrplan.discrepancy.verdict import decision, signatures
from ctrplan.discrepancy.outputs import results as results_json
from ctrplan.discrepancy.fits.calibrate import CalibrationResult
from ctrplan.discrepancy.fits.predictions import pose_errors, predict
from ctrplan.discrepancy.verdict.consistency import NoiseTest
from ctrplan.discrepancy.measured.noise import estimate_noise
from ctrplan.discrepancy.workflow import DiscrepancyOptions
from ctrplan.io.robot_file import load_robot, robot_to_toml
from ctrplan_reference.synth_reference import synthesize_reference

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
LAG_S = 0.15
OPTIONS = DiscrepancyOptions(effects=("time_offset",), ds=6e-3, n_permutations=199, max_evaluations=200, n_folds=5,
                             n_jobs=2, frame="tracker")
#: Robot-to-tracker registration of the record: rotation vector [rad], translation [m].
REGISTRATION = (0.02, -0.03, 0.4, 0.01, -0.02, 0.15)


@pytest.fixture(scope="module")
def staged(tmp_path_factory):
    """Stages 1-6 of a run on data with a hidden 0.15 s tracker lag."""
    tmp = tmp_path_factory.mktemp("discrepancy-stages")
    robot = load_robot(PAIR).replace(friction_coefficients=(0.0,))
    model = tmp / "pair.toml"
    model.write_text(robot_to_toml(robot, header="Table I tube pair, friction off"))
    data = tmp / "d.csv"
    frame, _ = synthesize_reference(robot, samples=500, time_offset=LAG_S, registration=REGISTRATION, seed=1, ds=6e-3)
    frame.to_csv(data, index=False)
    setup = setup_stage.load_inputs(model, data, tmp / "out", OPTIONS)
    split = split_stage.split_samples(setup, OPTIONS)
    split, scale, pilot = baseline_stage.pilot_fit(setup, split, OPTIONS)
    baseline = baseline_stage.calibrate_baseline(setup, split, OPTIONS, residual_scale=scale)
    candidates = fitting.fit_candidates(setup, split, baseline, None, OPTIONS)
    return setup, split, baseline, candidates


def test_out_of_fold_errors_come_from_fits_that_never_saw_their_samples(staged):
    """No fit uses a test-split sample, a sample of the fold it is validated on, or a sample
    within the buffer of either; the baseline's out-of-fold error at each development sample is
    the prediction of the fit made without that sample's fold, recomputed here independently of
    the stage. Catches a split that lets calibration samples or their neighbours into the
    validated errors (which would flatter every fit) and out-of-fold errors assembled in the
    wrong order."""
    setup, split, baseline, _ = staged
    data = setup.data
    assert split.n_test > 0 and split.n_dev + split.n_test == data.n_samples
    assert split.buffer > 0 and split.unit_kind == "time block"
    idx = np.arange(data.n_samples)
    for k in range(split.n_folds):
        fit = split.fit_rows(data, k)
        judged = np.flatnonzero(split.test_rows | split.validation_rows(k))
        dist = np.min(np.abs(idx[fit][:, None] - judged[None, :]), axis=1)
        assert fit.any() and np.all(dist > split.buffer)
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


def test_every_fold_fit_starts_cold_from_its_own_fold(staged):
    """The fold fits of the prior-free baseline start from the robot file's tube parameters like
    the development fit, with the closed-form registration of their own samples (not the
    development fit's result), and run the first least-squares stage; the time-offset
    candidate's fold fits start from that fold's own baseline. Catches fold fits warm-started
    from a fit that saw the fold's samples (the basin chosen by the data a fold is scored on)."""
    setup, split, baseline, candidates = staged
    free = CalibrationResult.from_dict(setup.stages.load("fit-baseline"))
    tube = [j for j, n in enumerate(free.names) if not n.startswith("registration")]
    reg = [j for j, n in enumerate(free.names) if n.startswith("registration")]
    for k in range(split.n_folds):
        fold = CalibrationResult.from_dict(setup.stages.load(f"fit-baseline-fold{k}"))
        np.testing.assert_array_equal(fold.initial[tube], free.initial[tube])
        assert not np.allclose(fold.initial[reg], free.values[reg], rtol=0, atol=1e-9)
        assert "skipped" not in fold.message
    c = candidates["time_offset"]
    n_base = len(baseline.fit.names)
    assert n_base >= 6                                      # at least the registration
    for k in range(split.n_folds):
        np.testing.assert_allclose(c.cv.folds[k].initial[:n_base], baseline.cv.folds[k].values)


def test_time_offset_candidate_is_fitted_in_seconds_and_its_errors_are_in_metres(staged):
    """The lag comes back in s (0.15, not 150), the held-out errors in m (about a mm, i.e.
    ~1e-3) and the tip velocity signature's effect size in m; the results stage writes the
    held-out mean in mm (1e3 times the SI mean) and leaves the lag in s. Catches a stage that
    converts to ms or mm before the report, and a time shift of the wrong sign against data
    made by independent code."""
    setup, split, baseline, candidates = staged
    c = candidates["time_offset"]
    assert c.shown["time_offset"] == pytest.approx(LAG_S, abs=0.01)
    assert c.units == {"time_offset": "s"}
    base_mean = float(np.nanmean(baseline.oof.position))
    cand_mean = float(np.nanmean(c.oof.position))
    assert 3e-4 < cand_mean < base_mean < 1e-2, (cand_mean, base_mean)       # m
    assert c.improvement_position.mean_difference == pytest.approx(base_mean - cand_mean, rel=0.3)
    assert c.out_of_fold_figures.position_mean == pytest.approx(cand_mean, rel=1e-12)          # m
    tests = signatures.diagnose_residuals(setup, split, baseline, OPTIONS)
    assert 1e-4 < tests["time_offset"].effect_size_m < 1e-2
    noise = decision.check_noise(setup, split, baseline, OPTIONS)
    naming = decision.name_effect(split, candidates, tests, noise, OPTIONS)
    assert naming.named == "time_offset" and naming.candidates["time_offset"].eligible
    written = results_json.candidate_dict(naming.candidates["time_offset"])
    assert written["parameters"]["time_offset"] == pytest.approx(LAG_S, abs=0.01)          # s stays s
    assert written["out_of_fold"]["position_mean_mm"] == pytest.approx(1e3 * cand_mean, rel=1e-12)
    se = dict(zip(c.fit.names, c.fit.stderr))["time_offset"]
    assert 0 < se < 0.02                                                                   # s, not ms


def test_noise_check_is_in_metres_and_the_report_form_in_millimetres():
    """An out-of-fold rms of 1 mm against a noise of 0.8 mm: the check holds rms 1e-3 m and
    ratio 1.25; its report form says 1.0 mm and 0.8 mm. Catches an rms kept in mm in the stage
    result or converted twice."""
    stated, unknown = (estimate_noise(_toy_data(), stated=s) for s in (0.8e-3, None))
    test = NoiseTest(statistic=1.55, threshold=1.2, p_value=0.001, inflation=1.01, n_fitted_effective=300.0,
                     dof_residual=400.0, dof_noise=None, n_samples=100, n_rest_samples_left_out=0, consistent=False,
                     false_alarm_rate=0.01, noise_lower_bound=False, noise_upper_bound=False)
    check = decision.NoiseCheck(noise=stated, rms_m=1e-3, ratio=1.25, test=test)
    assert check.rms == pytest.approx(0.8e-3, rel=1e-12)
    d = results_json.noise_dict(check)
    assert d["rms_mm"] == pytest.approx(1.0, rel=1e-12) and d["noise_rms_mm"] == pytest.approx(0.8, rel=1e-12)
    assert d["test"]["statistic"] == 1.55 and d["noise"]["position_rms_m"] == pytest.approx(0.8e-3, rel=1e-12)
    assert check.consistent is False
    assert unknown.position_rms_m is None
    assert decision.NoiseCheck(noise=unknown, rms_m=1e-3, ratio=None, test=None).consistent is None


def _toy_data():
    """A record of 20 samples without rests (the noise can only be stated)."""
    from ctrplan.discrepancy.measured.data import MeasuredData
    from ctrplan.history import MotionRecord

    k = 20
    z = np.linspace(0.0, 1.0, 2 * k).reshape(k, 2)
    return MeasuredData(alpha=z, beta=z, tip=np.zeros((k, 3)), tangent=None, eta=np.zeros((k, 1), int),
                        translation_last=np.zeros((k, 1), bool), sequence=np.zeros(k, int), config_id=np.arange(k),
                        subset=None, time=None, file="toy.csv", frame="robot",
                        record=MotionRecord(z, z, sequence=np.zeros(k, int)), rows=np.arange(k),
                        given_eta=np.zeros((k, 1), int))


def test_stage_key_ignores_workers_and_tests_and_follows_fits_inputs_and_procedure(tmp_path, monkeypatch):
    """The key is unchanged by the workers, the permutations, the level, the stated noise, the
    envelope, the reference friction and the bound's samples and target; it changes with an
    option that changes a fit, with the effects tried, with either input file's bytes, with the
    fitting procedure's version, with the mechanics version and with the digest of the code. Catches
    a key that sends every rerun back to the start, or reuses stages fitted with other options,
    other data, an earlier procedure, other mechanics or other code."""
    robot, data = tmp_path / "r.toml", tmp_path / "d.csv"
    robot.write_bytes(b"robot")
    data.write_bytes(b"data")
    base = DiscrepancyOptions()
    key = stages.stage_key(robot, data, base)
    same = DiscrepancyOptions(n_jobs=2, n_permutations=99, significance=0.05, noise_position=2e-4,
                              envelope_samples=10, reference_friction=(0.2,), bound_samples=7, bound_target=0.8)
    assert stages.stage_key(robot, data, same) == key
    for changed in (DiscrepancyOptions(ds=6e-3), DiscrepancyOptions(n_blocks=10), DiscrepancyOptions(test_fraction=0.3),
                    DiscrepancyOptions(seed=1), DiscrepancyOptions(effects=("backlash",)),
                    DiscrepancyOptions(prior_strengths=(0.1,)), DiscrepancyOptions(n_folds=5)):
        assert stages.stage_key(robot, data, changed) != key
    data.write_bytes(b"data2")
    assert stages.stage_key(robot, data, base) != key
    data.write_bytes(b"data")
    robot.write_bytes(b"robot2")
    assert stages.stage_key(robot, data, base) != key
    robot.write_bytes(b"robot")
    assert stages.stage_key(robot, data, base) == key
    monkeypatch.setattr(stages, "FIT_VERSION", options.FIT_VERSION + 1)
    assert stages.stage_key(robot, data, base) != key
    monkeypatch.setattr(stages, "FIT_VERSION", options.FIT_VERSION)
    from ctrplan import constants

    monkeypatch.setattr(constants, "MECHANICS_VERSION", f"{constants.MECHANICS_VERSION}-changed")
    assert stages.stage_key(robot, data, base) != key
    monkeypatch.setattr(constants, "MECHANICS_VERSION", constants.MECHANICS_VERSION.removesuffix("-changed"))
    assert stages.stage_key(robot, data, base) == key
    monkeypatch.setattr(stages, "source_digest", lambda: "0" * 64)
    assert stages.stage_key(robot, data, base) != key


def test_the_store_records_what_an_earlier_run_stored_apart_from_what_this_run_wrote(tmp_path):
    """A store reading a value an earlier run stored records "read", one reading back what it wrote
    itself "read back", a save "written", and a load that finds nothing nothing. Catches a fresh
    run whose stages read back their own fits and are reported as reused."""
    earlier = stages.StageStore(tmp_path, "k")
    earlier.save("pilot", {"x": 1})
    store = stages.StageStore(tmp_path, "k")
    assert store.load("pilot") == {"x": 1} and store.load("fit-baseline") is None
    store.save("fit-baseline", {"x": 2})
    store.load("fit-baseline")
    assert [e[:2] for e in store.events] == [("pilot", "read"), ("fit-baseline", "written"),
                                             ("fit-baseline", "read back")]
    assert all(a[2] <= b[2] for a, b in zip(store.events, store.events[1:]))


def test_stage_clock_times_each_stage_and_divides_the_candidates_at_their_out_of_fold_errors():
    """The workflow's clock: each stage's wall time in order; the candidates' stage divided at
    the moment each candidate's out-of-fold errors were stored or read (the last candidate to the
    stage's end), summing to the stage's time; a stage that read an earlier run's values and wrote
    none is "reused", one that did both "partly reused", one that only read back its own values
    neither. Catches a division that loses time between candidates or marks a fresh run reused."""
    import time

    from ctrplan.discrepancy.workflow import CANDIDATE_STAGE, _StageClock

    store = SimpleNamespace(events=[])

    def event(name, kind, pause=0.01):
        time.sleep(pause)
        store.events.append((name, kind, time.perf_counter()))

    clock = _StageClock()
    with clock.stage("setup"):
        time.sleep(0.01)
    clock.store = store
    with clock.stage("baseline"):
        event("pilot", "read")
        event("fit-baseline", "written")
        event("fit-baseline", "read back")
    with clock.stage("candidates"):
        event("fit-friction", "read")
        event("oof-friction", "read")
        event("fit-offplane", "written")
        event("oof-offplane", "written")
        time.sleep(0.01)
    candidates = clock.seconds["candidates"]
    clock.divide("candidates", {CANDIDATE_STAGE.format(e): f"oof-{e}" for e in ("friction", "offplane")})
    with clock.stage("naming"):
        event("oof-friction", "read back")
    assert list(clock.seconds) == ["setup", "baseline", "candidate:friction", "candidate:offplane", "naming"]
    assert all(s > 0 for s in clock.seconds.values())
    assert clock.seconds["candidate:friction"] + clock.seconds["candidate:offplane"] == pytest.approx(candidates)
    assert clock.seconds["candidate:friction"] >= 0.02 and clock.seconds["candidate:offplane"] >= 0.03
    assert clock.reused == {"baseline": "partly reused", "candidate:friction": "reused"}
