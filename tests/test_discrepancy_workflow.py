"""The discrepancy workflow: bad data, parameters, splits, signature tests, registration recovery,
the updated model file, and (slow) naming of hidden effects on synthetic data and real data."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from ctrplan.discrepancy import Noise, SynthProtocol, synthesize, write_synth
from ctrplan.discrepancy.fits.fitoptions import FitRun, GridSpec
from ctrplan.discrepancy.fits.gridsearch import grid_search_friction
from ctrplan.discrepancy.measured.data import MeasuredData, load_measured_data
from ctrplan.discrepancy.verdict.decision import cautions
from ctrplan.discrepancy.outputs.output import reproduce_errors
from ctrplan.discrepancy.fits.parameters import ParameterError, apply_parameters, read_parameters
from ctrplan.discrepancy.outputs.report import write_report
from ctrplan.discrepancy.verdict.signatures import friction_signature, regression_signature, registration_signature
from ctrplan.discrepancy.measured.split import configurations_repeat, make_split, sample_units
from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy
from ctrplan.history import MotionRecord
from ctrplan.errors import DataFileError
from ctrplan.io.robot_file import load_robot, robot_to_toml
from ctrplan.mechanics import ModelSettings

ROOT = Path(__file__).resolve().parents[1]
TABLE7 = ROOT / "model" / "ha2019-table7-calibrated.toml"
HA_DATA = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"
COARSE = ModelSettings(ds=6e-3)


def _write_model(robot, path, header):
    path.write_text(robot_to_toml(robot, header=header))
    return path


def _no_effects_model(tmp_path, offplane_zero=False):
    """Table VII with friction switched off (and optionally its off-plane precurvature)."""
    robot = load_robot(TABLE7).replace(friction_coefficients=(0.0, 0.0))
    if offplane_zero:
        robot = apply_parameters(robot, ("precurvature_x_1", "precurvature_x_2", "precurvature_x_3"), (0, 0, 0))
    return robot, _write_model(robot, tmp_path / "model.toml", "Table VII, effects off")


def _synth(robot, effects, path, grid, seed=0, settings=COARSE, noise=Noise()):
    """The paper's protocol by ``ctrplan synth`` (the code under test): for the grid search and
    the resumption, which test the fitting, not whether an effect is recognized."""
    res = synthesize(robot, effects, protocol=SynthProtocol.paper(grid), noise=noise, seed=seed,
                     settings=settings, n_jobs=2)
    write_synth(path, res)
    return res


def _reference_grid(truth, path, grid, seed=0, ds=6e-3, **kwargs):
    """The paper's protocol made independently of the code under test (``tests/ctrplan_reference``)."""
    from ctrplan_reference.synth_reference import synthesize_reference_grid

    frame, _ = synthesize_reference_grid(truth, grid=grid, seed=seed, ds=ds, **kwargs)
    frame.to_csv(path, index=False)


# --------------------------------------------------------------------------- bad data
def _good_frame(k=12):
    rng = np.random.default_rng(0)
    d = {"alpha_1": np.zeros(k), "alpha_2": rng.uniform(-3, 3, k), "alpha_3": rng.uniform(-3, 3, k),
         "beta_1": np.zeros(k), "beta_2": np.full(k, -0.017), "beta_3": rng.uniform(-0.1, -0.04, k),
         "tip_x": rng.normal(0.05, 0.01, k), "tip_y": rng.normal(0, 0.01, k), "tip_z": np.full(k, 0.15)}
    return pd.DataFrame(d)


@pytest.mark.parametrize("edit, match", [
    (lambda f: f.drop(columns=["tip_y"]), r"missing column 'tip_y'"),
    (lambda f: f.assign(tip_z=[0.15] * 5 + [float("nan")] + [0.15] * 6), r"column 'tip_z', row 6"),
    (lambda f: f.assign(tip_z=f["tip_z"] * 1e3), r"column 'tip_z', row 1 .*millimetres"),
    (lambda f: f.assign(beta_3=f["beta_3"] * 1e3), r"column 'beta_3', row 1 .*millimetres"),
])
def test_bad_data_names_the_column_and_row(tmp_path, edit, match):
    robot = load_robot(TABLE7)
    path = tmp_path / "bad.csv"
    edit(_good_frame()).to_csv(path, index=False)
    with pytest.raises(DataFileError, match=match):
        load_measured_data(path, robot)


def test_too_few_samples_are_refused_before_any_work(tmp_path):
    """Twelve samples cannot hold a test split of 8 units and folds with more samples than
    parameters: refused with the file named, before any fit (no stage written)."""
    robot, model = _no_effects_model(tmp_path)
    path = tmp_path / "few.csv"
    _good_frame(12).to_csv(path, index=False)
    with pytest.raises(DataFileError, match=r"few.csv: .*(too few for a test split|are not more than the 5 baseline parameters)"):
        run_discrepancy(model, path, tmp_path / "out", DiscrepancyOptions(effects=("offplane",)))
    assert not (tmp_path / "out" / ".stages").exists()


def test_joint_outside_limits_names_the_row(tmp_path):
    robot = load_robot(TABLE7)
    f = _good_frame()
    f.loc[3, "beta_3"] = -0.2
    path = tmp_path / "limits.csv"
    f.to_csv(path, index=False)
    with pytest.raises(DataFileError, match=r"limits.csv: row 4"):
        load_measured_data(path, robot)


# --------------------------------------------------------------------------- parameters and split
def test_parameters_round_trip_and_refuse_what_does_not_exist():
    robot = load_robot(TABLE7)
    names = ("precurvature_y_3", "precurvature_x_2", "k_xy_relative_3", "poisson_ratio_1", "mu_2")
    values = np.array([15.0, 0.5, 0.25, 0.2, 0.3])
    moved = apply_parameters(robot, names, values)
    np.testing.assert_allclose(read_parameters(moved, names), values, rtol=1e-12)
    # tube 3's straight transmission section stays straight; other tubes untouched
    assert moved.tubes[2].sections[0].is_straight and moved.tubes[0] == robot.tubes[0].__class__(
        **{**robot.tubes[0].__dict__, "poisson_ratio": 0.2})
    for bad, match in (("precurvature_y_4", "has 3 tubes"), ("k_xy_relative_1", "stiffness reference"),
                       ("mu_3", r"unknown calibration parameter .mu_3.*\(friction: mu_1, mu_2;"),
                       ("twist_1", "unknown calibration parameter")):
        with pytest.raises(ParameterError, match=match):
            apply_parameters(robot, (bad,), (1.0,))
    with pytest.raises(ParameterError, match="outside"):
        apply_parameters(robot, ("poisson_ratio_2",), (0.7,))


def _toy_data(config_id, sequence):
    k = len(config_id)
    z = np.zeros((k, 3))
    return MeasuredData(alpha=z, beta=z, tip=z, tangent=None, eta=np.zeros((k, 2), int),
                        translation_last=np.zeros((k, 2), bool), sequence=np.asarray(sequence),
                        config_id=np.asarray(config_id), subset=None, time=None, file="toy", frame="robot",
                        record=MotionRecord(z, z, sequence=np.asarray(sequence)), rows=np.arange(k),
                        given_eta=np.zeros((k, 2), int))


@pytest.mark.parametrize("seed", range(5))
def test_split_never_separates_a_configuration_or_a_sequence(seed):
    """Rows linked by a configuration or a sequence are one unit: all in the test split or all in
    one fold. Catches a split that lets one configuration's approaches be fitted and validated."""
    rng = np.random.default_rng(seed + 7100)
    unit = rng.integers(0, 40, 200)           # rows of a unit share configurations and sequences
    config = unit * 10 + rng.integers(0, 3, 200)
    seq = unit * 10 + rng.integers(0, 2, 200)
    split = make_split(_toy_data(config, seq), n_blocks=20, seed=seed)
    assert split.unit_kind == "configuration group", split.rule
    for ids in (config, seq):
        for u in np.unique(ids):
            assert np.unique(split.fold[ids == u]).size == 1, split.rule


def test_a_trajectory_that_passes_home_twice_is_not_a_repeated_protocol():
    """The friction test groups rows by exact configuration only for a protocol that revisits
    them (the paper's grid from four directions); a trajectory that returns home once must get
    binned groups and time-block units, or its friction test has almost no informative group."""
    grid = np.repeat(np.arange(64), 4)                 # 64 configurations x 4 directions
    assert configurations_repeat(grid)
    path = np.concatenate([[0], np.arange(1, 999), [0], [0]])   # starts and ends at home
    assert not configurations_repeat(path)
    units, kind, block = sample_units(_toy_data(path, np.zeros(path.size, int)), n_blocks=20)
    assert kind == "time block" and np.unique(units).size == 20      # not ~1000 single-row units

# --------------------------------------------------------------------------- signature tests
def test_signature_tests_find_planted_patterns_and_not_noise():
    rng = np.random.default_rng(3)
    g = np.repeat(np.arange(200), 4)
    eta = np.tile([[1, 1], [1, -1], [-1, 1], [-1, -1]], (200, 1))
    noise = rng.normal(0, 0.8e-3, (800, 3))
    direction = rng.normal(size=(200, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    planted = noise + 1e-3 * eta[:, :1] * direction[g]
    null = friction_signature(noise, eta, g, n_permutations=199)
    hit = friction_signature(planted, eta, g, n_permutations=199)
    assert null.p_value > 0.01 and hit.p_value < 0.01
    # +-1 mm on pair 1 only: half-difference 1 mm, RMS over the two pairs 1 mm / sqrt(2)
    assert hit.effect_size_m == pytest.approx(1e-3 / np.sqrt(2), rel=0.15)
    assert null.effect_size_m < 0.15e-3
    feats = rng.normal(size=(800, 2))
    feats = np.repeat(feats[::4], 4, axis=0)                        # configuration-level features
    assert regression_signature("x", noise, feats, g, n_permutations=199).p_value > 0.01
    assert regression_signature("x", noise + 1e-3 * feats[:, :1], feats, g, n_permutations=199).p_value < 0.01
    tip = rng.normal(size=(800, 3)) * 0.05
    assert registration_signature(noise, tip, g, n_permutations=199).p_value > 0.01
    rigid = noise + np.array([1e-3, 0, 0]) + np.cross([0, 0.01, 0], tip)
    assert registration_signature(rigid, tip, g, n_permutations=199).p_value < 0.01


# --------------------------------------------------------------------------- registration, model file
def test_hidden_registration_is_recovered_and_the_updated_model_reproduces_the_errors(tmp_path):
    robot, model = _no_effects_model(tmp_path)
    rv, t = np.array([0.05, -0.1, 0.3]), np.array([0.012, -0.004, 0.02])
    data = tmp_path / "reg.csv"
    _reference_grid(robot, data, grid=3, registration=tuple(rv) + tuple(t))
    out = tmp_path / "out"
    opts = DiscrepancyOptions(effects=("offplane",), frame="tracker", ds=6e-3, n_permutations=99, n_jobs=1)
    result = run_discrepancy(model, data, out, opts, progress=False)
    res = result.to_dict()
    fit = res["baseline"]["fit"]["parameters"]
    rv_fit = np.array([fit[f"registration_r{a}"] for a in "xyz"])
    t_fit = np.array([fit[f"registration_t{a}"] for a in "xyz"])
    angle = (Rotation.from_rotvec(rv_fit) * Rotation.from_rotvec(rv).inv()).magnitude()
    n_fit = res["baseline"]["fit"]["n_samples"]
    # within the noise: 1.4 mm rms over n samples, 0.5 deg tangent noise
    assert np.linalg.norm(t_fit - t) < 5 * 1.4e-3 / np.sqrt(n_fit) + 0.3e-3
    assert np.rad2deg(angle) < 0.5
    assert res["baseline"]["out_of_fold"]["position_mean_mm"] < 2.0       # noise floor ~1.3 mm
    # every fitted baseline parameter reported with a finite standard error (clustered over units)
    fitted = [r for r in res["baseline"]["parameter_table"] if r["fitted"]]
    assert len(fitted) >= 6 and all(np.isfinite(r["stderr"]) for r in fitted)
    # the written model loads back, names its model and registration, and reproduces the errors
    assert res["reproduced"]
    written = load_robot(res["updated_model_file"])
    assert written.metadata["tracker_registration"] is not None
    data_obj = load_measured_data(data, robot, frame="tracker")
    test_rows = make_split(data_obj).test_rows
    again = reproduce_errors(res["updated_model_file"], data_obj.take(test_rows), ModelSettings(ds=6e-3, multistart=0))
    assert np.nanmean(again["position"]) * 1e3 == pytest.approx(res["test_split"]["after"]["position_mean_mm"],
                                                                abs=1e-9)
    paths = write_report(result, out)
    assert Path(paths["markdown"]).read_text().count("|") > 20
    assert json.loads(Path(paths["json"]).read_text())["reproduced"] is True
    assert all((out / p).stat().st_size > 1000 for p in paths["plots"])


def test_an_interrupted_run_resumes_from_finished_stages(tmp_path, caplog, capsys):
    """A real run in a subprocess is killed (SIGKILL) right after its first stage file appears;
    the rerun reuses that stage (file untouched, "reused" in the log) and ends with the same
    result as an uninterrupted run. Catches stages that are not written before the run ends,
    written non-atomically (a half-written file would not parse), keyed differently on rerun,
    or reused with different content. The runs log under ``ctrplan.discrepancy`` and print
    nothing (catches a stage that writes to the caller's stdout)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    robot, model = _no_effects_model(tmp_path)
    data = tmp_path / "d.csv"
    _synth(robot, {}, data, grid=3)
    fit = ("precurvature_y_3", "k_xy_relative_3")
    opts = DiscrepancyOptions(fit=fit, effects=("offplane",), ds=6e-3, n_permutations=99, n_jobs=1)
    out = tmp_path / "out"
    script = ("import sys; from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy; "
              f"run_discrepancy({str(model)!r}, {str(data)!r}, {str(out)!r}, DiscrepancyOptions(fit={fit!r}, "
              "effects=('offplane',), ds=6e-3, n_permutations=99, n_jobs=1), progress=False)")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, env=env)
    stage_dir = out / ".stages"
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and proc.poll() is None:
        if stage_dir.exists() and any(stage_dir.glob("*-fit-baseline-fold0.json")):
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.02)
    proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the run ended before it could be interrupted"
    assert not (out / "results.json").exists()
    stage = next(stage_dir.glob("*-pilot.json"))
    stamp = stage.stat().st_mtime_ns
    with caplog.at_level(logging.INFO, logger="ctrplan"):
        resumed = run_discrepancy(model, data, out, opts, progress=False).to_dict()
    assert "  pilot: reused from an earlier run" in caplog.messages
    assert resumed["stage_reused"]["baseline"] == "partly reused"      # the pilot and a fold's fit read
    assert caplog.records and all(r.name.startswith("ctrplan.discrepancy.") for r in caplog.records)
    assert capsys.readouterr().out == ""
    assert stage.stat().st_mtime_ns == stamp
    fresh = run_discrepancy(model, data, tmp_path / "fresh", opts, progress=False).to_dict()
    assert fresh["stage_reused"] == {}
    untimed = (lambda d: {k: v for k, v in d.items() if k != "evaluation_ms_per_sample"})
    assert untimed(resumed["test_split"]["after"]) == untimed(fresh["test_split"]["after"])
    assert resumed["baseline"]["fit"]["parameters"] == fresh["baseline"]["fit"]["parameters"]
    assert resumed["candidates"]["offplane"]["parameters"] == fresh["candidates"]["offplane"]["parameters"]


# --------------------------------------------------------------------------- hidden effects (slow)
@pytest.mark.slow
def test_hidden_friction_is_named_and_the_gap_shrinks_by_40_percent(tmp_path):
    robot, model = _no_effects_model(tmp_path)
    data = tmp_path / "friction.csv"
    _reference_grid(robot, data, grid=5, ds=3e-3, mu=(0.22, 0.12))
    res = run_discrepancy(model, data, tmp_path / "out", DiscrepancyOptions(n_jobs=2, n_permutations=199), progress=False).to_dict()
    assert res["named_effect"] == "friction"
    before, after = res["test_split"]["before"], res["test_split"]["after"]
    assert after["position_mean_mm"] <= 0.6 * before["position_mean_mm"]
    assert after["position_max_mm"] <= 0.6 * before["position_max_mm"]
    assert res["reproduced"]


@pytest.mark.slow
def test_hidden_offplane_precurvature_is_named_not_friction(tmp_path):
    robot, model = _no_effects_model(tmp_path, offplane_zero=True)
    data = tmp_path / "offplane.csv"
    _reference_grid(apply_parameters(robot, ("precurvature_x_2", "precurvature_x_3"), (0.5, 2.5)), data, grid=5)
    opts = DiscrepancyOptions(n_jobs=2, n_permutations=199, ds=6e-3, friction_grid=(0.0, 0.15, 0.3),
                              friction_search_samples=48)
    res = run_discrepancy(model, data, tmp_path / "out", opts, progress=False).to_dict()
    assert res["named_effect"] == "offplane"
    assert not res["candidates"]["friction"]["eligible"]


@pytest.mark.slow
def test_noise_only_names_no_effect(tmp_path):
    robot, model = _no_effects_model(tmp_path)
    data = tmp_path / "noise.csv"
    _reference_grid(robot, data, grid=5, seed=4)
    opts = DiscrepancyOptions(n_jobs=2, n_permutations=199, ds=6e-3, friction_grid=(0.0, 0.15, 0.3),
                              friction_search_samples=48)
    res = run_discrepancy(model, data, tmp_path / "out", opts, progress=False).to_dict()
    assert res["named_effect"] is None and res["verdict"] == "none"
    assert res["baseline"]["out_of_fold"]["position_mean_mm"] < 1.6


@pytest.mark.slow
@pytest.mark.skipif(not HA_DATA.exists(), reason=f"measured data not present at {HA_DATA} (not redistributable; "
                                                  f"get it from github.com/hjhdog1/ConcentricTubes)")
def test_real_trajectory_runs_end_to_end(tmp_path):
    """Ha's measured trajectory with the Table II file: the calibrated baseline (the prior and its
    strength chosen by out-of-fold error) is not significantly worse on the untouched test split
    than the robot file with only a registration (the upper end of the 95 % interval of the
    calibration's shrink is above zero), both figures in the results; the residual is far more
    than the noise; the written file loads back and reproduces its errors. Catches a calibration
    that ends clearly worse than the file it starts from."""
    res = run_discrepancy(ROOT / "model" / "ha2019-table2-nominal.toml", HA_DATA, tmp_path / "out",
                          DiscrepancyOptions(n_jobs=2, n_permutations=199), progress=False).to_dict()
    fig = res["test_split"]["figures"]
    assert res["frame"] == "tracker" and res["n_samples"] == 1307
    assert res["test_split"]["before"]["n_failed"] < 0.05 * res["test_split"]["before"]["n_samples"]
    assert fig["n_units"] >= 8
    assert fig["file"]["mean_mm"]["value"] > 0 and fig["before"]["mean_mm"]["value"] > 0
    assert fig["calibration_shrink"]["mean"]["ci"][1] > 0
    assert res["noise"]["consistent"] is False and res["noise"]["ratio"] > 10
    if res["named_effect"]:
        named = res["candidates"][res["named_effect"]]
        assert named["eligible"] and not named["at_bound"]
    rows = res["prediction"]["rows"]
    assert rows[1]["n"] > 0.95 * res["test_split"]["before"]["n_samples"]
    assert res["reproduced"]


def test_friction_grid_search_extends_past_the_coarse_grid_edge(tmp_path):
    """Hidden mu = 0.53 (off every grid node) on the Table I tube pair, noise-free, coarse grid
    0..0.2: a best point on the grid's upper edge is not a minimum, so the grid grows until it
    brackets the minimum, and two refinements (steps 0.05, 0.025) land within half the last step
    of the truth. Catches a grid that stops at its edge and refinements that wander."""
    pair = load_robot(ROOT / "model" / "ha2019-table1-tube-pair.toml")
    data = tmp_path / "pair.csv"
    _synth(pair, {"friction": {"mu_1": 0.53}}, data, grid=3, noise=Noise(position_rms=0.0, angle_rms=0.0))
    off = pair.replace(friction_coefficients=(0.0,))
    fit = grid_search_friction(off, load_measured_data(data, off), {}, grid=GridSpec(coarse=(0.0, 0.1, 0.2)),
                               run=FitRun(settings=COARSE))
    assert fit.values[0] == pytest.approx(0.53, abs=0.0125 + 1e-9)
    assert fit.converged and not fit.at_bound
    assert "grown to" in fit.message and fit.widened


def _figures(mean_mm, max_mm):
    from ctrplan.discrepancy.fits.evaluation import ErrorFigures

    return ErrorFigures(position_mean=mean_mm * 1e-3, position_std=None, position_p95=None,
                        position_max=max_mm * 1e-3, tangent_mean=None, tangent_max=None, seconds_per_sample=0.0,
                        n_samples=10, n_failed=0)


def test_cautions_flag_an_atypical_friction_coefficient_and_a_worse_maximum():
    """A named friction coefficient beyond its typical range gets a caution with the value, the
    range and its source, and what to check; a maximum error that rises gets another (the
    figures are in m, the caution in mm). The cautions are kinds and numbers in SI; the words come
    from their stored form. Catches a caution that loses what a reader must check, one that prints
    metres as millimetres, and one whose stored form loses a figure."""
    from types import SimpleNamespace

    from ctrplan.choices import CautionKind
    from ctrplan.discrepancy.fits.estimates import AtypicalValue
    from ctrplan.discrepancy.outputs.words import caution

    before, worse_max = _figures(5.2, 16.8), _figures(4.3, 23.2)
    mu = AtypicalValue(name="mu_1", value=0.975, typical=(0.0, 0.5), typical_text="0..0.5", unit="-",
                       why="NiTi on NiTi", check="the tube surfaces")
    notes = cautions("named", SimpleNamespace(label="torsional friction", atypical=(mu,)), before, worse_max)
    assert [c.kind for c in notes] == [CautionKind.ATYPICAL_VALUE, CautionKind.MAXIMUM_RISES]
    assert notes[0].value is mu and notes[1].before_m == pytest.approx(16.8e-3) and notes[1].after_m == pytest.approx(23.2e-3)
    stored = json.loads(json.dumps([c.as_dict() for c in notes]))
    assert caution(stored[0]) == ("torsional friction: mu_1 = 0.975, more than its typical 0..0.5 (NiTi on NiTi): "
                                  "check the tube surfaces")
    assert "16.80 to 23.20 mm" in caution(stored[1])
    assert cautions("named", SimpleNamespace(label="torsional friction", atypical=()), before,
                    _figures(2.0, 8.0)) == []
    assert cautions("none", None, before, before) == []


def test_a_baseline_parameter_outside_its_range_is_a_caution_in_report_units(caplog):
    """A registration rotation of 0.2 rad outside its typical range and a translation of 4 mm at
    its bound are cautions in degrees and millimetres (11.46 deg, 4 mm), logged as warnings, with
    the range's source; a parameter within its range is none. Catches SI values printed as they
    are stored ("0.2 rad") and cautions that a caller's logging cannot see."""
    from types import SimpleNamespace

    from ctrplan.discrepancy.fits.estimates import ParameterEstimate
    from ctrplan.discrepancy.fits.evaluation import Errors
    from ctrplan.discrepancy.outputs.output import run_cautions
    from ctrplan.discrepancy.outputs.words import caution

    def row(name, unit, value, *, typical=True, at_bound=False):
        return ParameterEstimate(name=name, unit=unit, value=value, stderr=None, ci=None, typical=None,
                                 in_typical_range=typical, typical_source="a stated range", check=None,
                                 at_bound=at_bound, resolution=None, fitted=True)

    baseline = SimpleNamespace(parameters=(row("registration_rx", "rad", 0.2, typical=False),
                                           row("registration_tx", "m", 4e-3, at_bound=True),
                                           row("k_xy_relative_2", "-", 0.9)))
    errors = Errors(rows=np.arange(3), position=np.full(3, 1e-3), angle=np.zeros(3), residual_base=np.zeros((3, 3)),
                    tip_base=np.zeros((3, 3)), seconds=0.0)
    naming = SimpleNamespace(verdict="none", named=None, candidates={})
    with caplog.at_level(logging.WARNING, logger="ctrplan"):
        notes = run_cautions(naming, None, baseline, SimpleNamespace(baseline=errors, final=errors))
    text = [caution(c.as_dict()) for c in notes]
    assert text == ["baseline registration_rx = 11.46 deg; typical: a stated range",
                    "baseline registration_tx = 4 mm: at its bound; typical: a stated range"]
    assert [r.getMessage() for r in caplog.records] == [f"caution: {n}" for n in text]


def test_friction_grid_search_that_cannot_bracket_the_minimum_says_at_bound(tmp_path, monkeypatch):
    """The same data with the friction coefficient's limit at 0.3 (below the hidden 0.55): the
    grid grows to its limit, the best point sits there, so the fit is "at the edge of the grid,
    not converged" and carries an at-bound flag the naming rule reads. Catches a grid search
    that calls an edge it could not grow past converged (mu_1 = 1.075 on Ha's trajectory was
    such a cap)."""
    import dataclasses
    import importlib

    calibration = importlib.import_module("ctrplan.discrepancy.fits.gridsearch")

    pair = load_robot(ROOT / "model" / "ha2019-table1-tube-pair.toml")
    data = tmp_path / "pair.csv"
    _synth(pair, {"friction": {"mu_1": 0.55}}, data, grid=3, noise=Noise(position_rms=0.0, angle_rms=0.0))
    off = pair.replace(friction_coefficients=(0.0,))
    original = calibration.parameter

    def capped(robot, name):
        spec = original(robot, name)
        return dataclasses.replace(spec, upper=0.3, typical=(0.0, 0.25)) if name == "mu_1" else spec

    monkeypatch.setattr(calibration, "parameter", capped)
    fit = grid_search_friction(off, load_measured_data(data, off), {}, grid=GridSpec(coarse=(0.0, 0.1, 0.2)),
                               run=FitRun(settings=COARSE, uncertainty=False))
    assert not fit.converged and fit.at_bound and "mu_1 (edge of the grid at its limit 0.3" in fit.at_bound[0]
    assert "not converged" in fit.message

