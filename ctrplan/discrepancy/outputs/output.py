"""Stages 10-12 of the discrepancy workflow: the test split, the history-aware prediction's check,
the updated robot file and its reload, and the run's cautions."""

from __future__ import annotations

import datetime
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..._log import progress_level
from ...choices import CautionKind, EffectStore, Verdict
from ...effects import REGISTRY, EffectSet, robot_effects
from ...io.atomic import atomic_write_text
from ..fits.baseline import Baseline
from ..fits.predictions import pose_errors, predict
from ..measured.data import MeasuredData
from ..verdict.decision import Naming, NoiseCheck, cautions
from ..verdict.reasons import Caution
from ..fits.evaluation import ErrorFigures, Errors, evaluate_rows
from ..fits.fitting import Candidate
from .logtext import figure, interval
from .results import candidate_dict, noise_dict
from .words import buffer_text, caution as caution_text, noise_text, split_text, verdict_lines
from ..options import CONFIDENCE, DiscrepancyOptions
from ..fits.pairs import Combination
from ..fits.parameters import REGISTRATION, apply_parameters
from ..setup import DiscrepancySetup
from ..measured.split import DataSplit
from ..verdict.statistics import Interval, mean_interval, shrink_interval

__all__ = ["ModelFigures", "TestFigures", "PredictionCheck", "TestSplit", "evaluate_test_split", "UpdatedModel",
           "Reproduction", "write_updated_model", "check_reproduction", "reproduce_errors", "final_candidate",
           "final_parameters", "validate_prediction", "run_cautions", "log_verdict", "log_split", "log_pilot",
           "log_blocks", "log_noise"]

logger = logging.getLogger(__name__)


def final_candidate(naming: Naming, combination: Combination | None) -> Candidate | None:
    """The model the run ends with: the named pair; else the second effect alone when the named
    effect went to zero with it; else the named effect; else None (the recalibrated baseline), also
    for an ambiguous verdict: which of its two effects is there is the open question, and a
    robot file with the wrong one predicts worse off the recorded motion than the baseline."""
    if naming.verdict == Verdict.AMBIGUOUS:
        return None
    if combination is not None and combination.named:
        return combination.tried[combination.named]
    if combination is not None and combination.replaced_by:
        return naming.candidates[combination.replaced_by]
    return naming.candidates[naming.named] if naming.named else None


def final_parameters(naming: Naming, combination: Combination | None, baseline: Baseline) -> dict:
    """The parameters of the model the run ends with [SI] (the baseline's when nothing is named)."""
    final = final_candidate(naming, combination)
    return dict(final.params if final is not None else baseline.params)


@dataclass(frozen=True)
class ModelFigures:
    """One model's tip position errors on the test split.

    Attributes
    ----------
    mean : Interval
        Mean error with its t-interval over the test split's units [m].
    p95, max : float or None
        [m]; None without a finite error.
    """

    mean: Interval
    p95: float | None
    max: float | None


def _figures(errors: dict, units) -> dict:
    """:class:`ModelFigures` of each model's tip errors [m], on the samples where every model is
    finite."""
    ok = np.all([np.isfinite(v) for v in errors.values()], axis=0)
    u = np.asarray(units)[ok]
    out = {}
    for name, e in errors.items():
        x = np.asarray(e, float)[ok]
        out[name] = ModelFigures(mean=mean_interval(x, u, confidence=CONFIDENCE),
                                 p95=float(np.percentile(x, 95)) if x.size else None,
                                 max=float(x.max()) if x.size else None)
    return out


@dataclass(frozen=True)
class PredictionCheck:
    """The history-aware prediction against the standard model on the test split
    (:func:`validate_prediction`).

    Attributes
    ----------
    standard, history : ModelFigures
        The written robot file evaluated with the standard model and along the recorded history
        with the friction model [m].
    difference : Interval
        Per-unit paired difference of their mean errors, history - standard [m].
    history_label : str
    history_beats_standard : bool
        ``difference``'s interval lies below zero: planning may aim with the history-aware
        prediction.
    n_samples, n_units : int
        Test samples where both are finite, and their units.
    confidence : float
        Level of the intervals.
    method : str
    """

    standard: ModelFigures
    history: ModelFigures
    difference: Interval
    history_label: str
    history_beats_standard: bool
    n_samples: int
    n_units: int
    confidence: float
    method: str

    def file_table(self, data_file: str, data_sha256: str, date: str) -> dict:
        """The robot file's ``[prediction_validation]`` table (SI)."""
        return {"standard_mean_m": self.standard.mean.value, "standard_max_m": self.standard.max,
                "history_mean_m": self.history.mean.value, "history_max_m": self.history.max,
                "history_beats_standard": bool(self.history_beats_standard),
                "difference_mean_m": self.difference.value, "difference_low_m": self.difference.low,
                "difference_high_m": self.difference.high, "test_units": self.n_units,
                "test_samples": self.n_samples, "data_file": data_file, "data_sha256": data_sha256, "date": date}


def validate_prediction(prediction, split: DataSplit) -> PredictionCheck | None:
    """The history-aware prediction against the standard model on the test split: mean (with a
    t-interval over units), p95 and max tip position error of each [mm], and the per-unit paired
    difference of their means with its t-interval; the history "beats" the standard model when
    that interval lies below zero (:func:`~ctrplan.discrepancy.verdict.statistics.mean_interval` of the
    paired differences). Planning aims with the history-aware prediction only then.

    Parameters
    ----------
    prediction : HistoryPrediction or None
        Its first row is the standard model, its second the history-aware model with the fitted
        friction coefficients, both on the test split in data order.
    split : DataSplit

    Returns
    -------
    PredictionCheck or None
        None without a prediction.
    """
    if prediction is None or len(prediction.rows) < 2:
        return None
    units = split.units[split.test_rows]
    std, hist = (np.asarray(prediction.rows[i][1], float) for i in (0, 1))
    ok = np.isfinite(std) & np.isfinite(hist)
    figs = _figures({"standard": std, "history": hist}, units)
    diff = mean_interval(hist[ok] - std[ok], units[ok], confidence=CONFIDENCE)
    return PredictionCheck(standard=figs["standard"], history=figs["history"], difference=diff,
                           history_label=prediction.rows[1][0],
                           history_beats_standard=bool(np.isfinite(diff.high) and diff.high < 0.0),
                           n_samples=int(ok.sum()), n_units=int(np.unique(units[ok]).size), confidence=CONFIDENCE,
                           method="t-interval over the test split's units of the per-unit paired difference of the "
                                  "mean errors")


@dataclass(frozen=True)
class TestFigures:
    """The test split's figures (:func:`evaluate_test_split`), on the samples where every model is
    finite.

    Attributes
    ----------
    file, before, after : ModelFigures
        The robot file with only a registration, the calibrated baseline, and the final model [m].
    shrink : Interval
        Relative fall of the mean error from ``before`` to ``after``, with a t-interval from the
        per-unit paired sums [-].
    calibration_shrink : Interval
        The same from ``file`` to ``before`` [-].
    n_samples, n_units : int
    confidence : float
        Level of the intervals.
    method : str
    """

    file: ModelFigures
    before: ModelFigures
    after: ModelFigures
    shrink: Interval
    calibration_shrink: Interval
    n_samples: int
    n_units: int
    confidence: float
    method: str

    __test__ = False    # a result, not a pytest test class


@dataclass(frozen=True, eq=False)
class TestSplit:
    """Stage 10: the robot file (with only a registration), the calibrated baseline and the final
    model on the untouched test split (used once).

    Attributes
    ----------
    file : Errors
        The robot file's tube parameters with only a registration fitted on the development
        samples [m, rad].
    baseline, final : Errors
        The calibrated baseline's and the final model's errors on the test samples (``final`` is
        the baseline's when nothing is named).
    label : str
        The final model.
    figures : TestFigures
    """

    file: Errors
    baseline: Errors
    final: Errors
    label: str
    figures: TestFigures

    __test__ = False    # a result, not a pytest test class


def _test_figures(file: Errors, before: Errors, after: Errors, units) -> TestFigures:
    ok = np.isfinite(before.position) & np.isfinite(after.position) & np.isfinite(file.position)
    u = np.asarray(units)[ok]
    figs = _figures({"file": file.position[ok], "before": before.position[ok], "after": after.position[ok]}, u)
    return TestFigures(
        **figs, shrink=shrink_interval(before.position[ok], after.position[ok], u, confidence=CONFIDENCE),
        calibration_shrink=shrink_interval(file.position[ok], before.position[ok], u, confidence=CONFIDENCE),
        n_samples=int(ok.sum()), n_units=int(np.unique(u).size), confidence=CONFIDENCE,
        method=f"t-intervals over the test split's {np.unique(u).size} units (means and the shrink of the mean from "
               f"per-unit sums, paired; Cochran 1977, Sec. 6.4); p95 and max without an interval")


def evaluate_test_split(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, naming: Naming,
                        combination: Combination | None, options: DiscrepancyOptions,
                        progress: bool = False) -> TestSplit:
    """Stage 10: evaluate the robot file with only a registration, the calibrated baseline and the
    final model (their development fits) on the test split, once, and the gains there with
    t-intervals over units.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    baseline : Baseline
    naming : Naming
    combination : Combination or None
    options : DiscrepancyOptions
    progress : bool
        Progress bars of the model evaluations.

    Returns
    -------
    TestSplit
    """
    final = final_candidate(naming, combination)
    test = split.test_rows
    file = evaluate_rows(setup, test, "test-file", "standard", baseline.file_cv.params, n_jobs=options.n_jobs,
                         progress=progress)
    before = evaluate_rows(setup, test, "test-baseline", "standard", baseline.params, n_jobs=options.n_jobs,
                           progress=progress)
    after = before if final is None else evaluate_rows(setup, test, f"test-{final.cv.name}", final.model, final.params,
                                                       n_jobs=options.n_jobs, progress=progress)
    f = _test_figures(file, before, after, split.units[test])
    label = final.label if final is not None else "baseline (nothing named)"
    logger.log(progress_level(), _test_split_line(split.n_test, f, label))
    return TestSplit(file=file, baseline=before, final=after, label=label, figures=f)


def _test_split_line(n_test: int, f: TestFigures, label: str) -> str:
    """The log line of :func:`evaluate_test_split` (millimetres, %): the three models' mean errors,
    the shrinks with their intervals and the maxima; a figure the test split leaves undefined (no
    finite sample: mean and maximum None or NaN; one unit: no interval) prints as "undefined".

    Parameters
    ----------
    n_test : int
        Samples of the test split (finite or not).
    f : TestFigures
        Its figures [m; shrinks -].
    label : str
        The final model.

    Returns
    -------
    str
    """
    s, c = f.shrink, f.calibration_shrink
    return (f"test split ({n_test} samples, {f.n_samples} with every model finite, in {f.n_units} units, untouched "
            f"until now): robot file with a registration {figure(f.file.mean.value, '.3f', 1e3, ' mm')}, calibrated "
            f"baseline {figure(f.before.mean.value, '.3f', 1e3, ' mm')} (shrink {figure(c.value, '.0f', 100, ' %')}, "
            f"interval {interval(c.low, c.high, '.0f', 100, ' %')}), {label} "
            f"{figure(f.after.mean.value, '.3f', 1e3, ' mm')} "
            f"(shrink {figure(s.value, '.0f', 100, ' %')}, {CONFIDENCE:.0%} interval "
            f"{interval(s.low, s.high, '.0f', 100, ' %')}); max {figure(f.before.max, '.2f', 1e3, ' mm')} -> "
            f"{figure(f.after.max, '.2f', 1e3, ' mm')}")


@dataclass(frozen=True, eq=False)
class UpdatedModel:
    """Stage 11: the updated robot model file.

    Attributes
    ----------
    path : pathlib.Path
        The written model file (tube parameters, ``[effects]`` with ``[effects_source]``).
    model : str
        Mechanics model it is evaluated with.
    params : dict of str to float
        Its calibrated parameters [SI].
    named_effects : tuple of str
    candidate : Candidate or None
        The candidate it comes from (None: the recalibrated baseline).
    cautions : tuple of Caution
        Written values outside their typical range, each with the range's source and what to
        check (in words in the file's ``[effects_source]``).
    """

    path: Path
    model: str
    params: dict
    named_effects: tuple
    candidate: Candidate | None
    cautions: tuple = ()


@dataclass(frozen=True, eq=False)
class Reproduction:
    """Stage 12: the written model file reloaded and re-evaluated on the test split.

    Attributes
    ----------
    position : ndarray, shape (K_test,)
        Tip position errors with the reloaded file [m].
    reproduced : bool
        Equal to the final model's test errors within 1 nm (NaN where both failed).
    """

    position: np.ndarray
    reproduced: bool


def write_updated_model(setup: DiscrepancySetup, baseline: Baseline, naming: Naming, combination: Combination | None,
                        test: TestSplit, *, bound=None, prediction_check: PredictionCheck | None = None) -> UpdatedModel:
    """Stage 11: write one robot model file with the final model's calibrated parameters (the
    recalibrated baseline when nothing is named) into ``setup.out_dir``, atomically.

    Effects that change the robot go into its tube and pair tables, a registration into
    ``[tracker_registration]``, effects on the motion or the measurement (backlash, time offset,
    gradual friction, ...) into ``[effects]`` with ``[effects_source]``: the data file and its
    SHA-256, the date, the samples, the verdict, the test split's errors and a caution for every
    value outside its typical range (the value is written: the data chose it over every other
    explanation). The values are those of the final model's joint fit. With ``bound`` (a
    :class:`~ctrplan.discrepancy.verdict.coverage.BoundCalibration` with a finite factor), the table
    ``[bound_calibration]``; with ``prediction_check`` (:func:`validate_prediction`),
    ``[prediction_validation]``: planning reads both.

    Parameters
    ----------
    setup : DiscrepancySetup
    baseline : Baseline
    naming : Naming
    combination : Combination or None
    test : TestSplit
    bound : BoundCalibration, optional, keyword-only
    prediction_check : PredictionCheck, optional, keyword-only

    Returns
    -------
    UpdatedModel
    """
    from ...io.robot_file import file_hash, robot_to_toml

    robot = setup.robot
    final = final_candidate(naming, combination)
    named_effects = list(final.effects) if final is not None else []
    final_params = dict(final.params if final else baseline.params)
    final_model = final.model if final else "standard"
    registration = None
    if any(n in final_params for n in REGISTRATION):
        vals = [final_params.get(n, 0.0) for n in REGISTRATION]
        registration = {"rotation_vector_rad": vals[:3], "translation_m": vals[3:]}
    effects, _ = EffectSet.from_parameters(robot, tuple(final_params), tuple(final_params.values()))
    stored = {name: dict(effects[name]) for name in effects if REGISTRY[name].store == EffectStore.EFFECTS}
    written_cautions = (tuple(Caution(CautionKind.ATYPICAL_VALUE, label=final.label, value=b) for b in final.atypical)
                        if final is not None else ())
    notes = tuple(caution_text(c.as_dict()) for c in written_cautions)
    data_name = Path(setup.data_path).name
    updated = apply_parameters(robot, tuple(final_params), tuple(final_params.values()))
    merged = robot_effects(robot).merged(stored)
    verdict = naming.verdict
    if verdict == Verdict.AMBIGUOUS:
        suffix = f"{naming.named}-or-{naming.decision.ambiguous_with}"
    else:
        suffix = "-".join(named_effects) or "recalibrated"
    updated = updated.replace(name=f"{robot.name}-{suffix}",
                              source=f"{robot.source}; recalibrated by ctrplan discrepancy on {data_name}"
                                     + "".join(f"; caution: {c}" for c in notes),
                              effects=tuple((n, tuple(merged[n].items())) for n in merged))
    pos = test.final.position[np.isfinite(test.final.position)]
    note = ""
    if verdict == Verdict.AMBIGUOUS:
        pair = f"{naming.candidates[naming.named].label} or {naming.candidates[naming.decision.ambiguous_with].label}"
        note = (f"ambiguous: {pair}, " + ("not separable on the recorded motion" if naming.decision.inseparable else
                                          "equally good within their uncertainty") + "; neither written")
    source = {"method": "ctrplan discrepancy (fitted on the development split; errors on the untouched test split)",
              "data_file": data_name, "data_sha256": file_hash(setup.data_path),
              "date": datetime.date.today().isoformat(), "samples": int(setup.data.n_samples),
              "held_out_position_mean_m": float(pos.mean()) if pos.size else None,
              "held_out_position_p95_m": float(np.percentile(pos, 95)) if pos.size else None,
              "held_out_position_max_m": float(pos.max()) if pos.size else None, "note": note,
              "cautions": list(notes)}
    setup.out_dir.mkdir(parents=True, exist_ok=True)
    model_path = setup.out_dir / f"{updated.name}.toml"
    header = (f"Written by `ctrplan discrepancy` from {Path(setup.robot_path).name} and {data_name}.\n"
              f"Verdict: {verdict}; model: {test.label}; evaluate with the {final_model} model.\nCalibrated parameters: "
              + ", ".join(f"{n} = {v:.6g}" for n, v in final_params.items() if n not in REGISTRATION)
              + "".join(f"\nCaution: {c}" for c in notes))
    sha = source["data_sha256"]
    bound_table = (bound.file_table(data_name, sha) if bound is not None and np.isfinite(bound.factor) else None)
    pred_table = (None if prediction_check is None else
                  prediction_check.file_table(data_name, sha, source["date"]))
    atomic_write_text(model_path, robot_to_toml(updated, header=header, model=final_model, registration=registration,
                                                effects_source=source if updated.effects else None,
                                                bound_calibration=bound_table, prediction_validation=pred_table))
    for c in notes:
        logger.warning(f"  written with a caution: {c}")
    return UpdatedModel(path=model_path, model=final_model, params=final_params, named_effects=tuple(named_effects),
                        candidate=final, cautions=written_cautions)


def reproduce_errors(model_path, data: MeasuredData, settings=None, *, n_jobs: int = 1) -> dict:
    """Load an updated model file and evaluate its errors on ``data`` with the model it names.

    Parameters
    ----------
    model_path : path
        Robot model file written by the workflow (its ``model`` key names the mechanics model;
        ``[tracker_registration]`` maps to the data's frame; its ``[effects]`` apply).
    data : MeasuredData
    settings : ModelSettings, optional
    n_jobs : int

    Returns
    -------
    dict
        ``position`` (K,) [m], ``angle`` (K,) [rad]: tip position and tangent errors (Eq. (49)
        terms), NaN where the model failed.

    Raises
    ------
    ModelFileError, PhysicalParameterError
        The file does not load.
    """
    from ...io.robot_file import load_robot

    robot = load_robot(model_path)
    model = robot.metadata.get("model") or "standard"
    reg = robot.metadata.get("tracker_registration")
    names, values = (), ()
    if reg:
        names, values = REGISTRATION, tuple(reg["rotation_vector_rad"]) + tuple(reg["translation_m"])
    pred = predict(robot, names, values, data, model, settings, n_jobs=n_jobs)
    pos, ang, _ = pose_errors(pred, data)
    return {"position": pos, "angle": ang}


def check_reproduction(setup: DiscrepancySetup, split: DataSplit, updated: UpdatedModel, test: TestSplit,
                       options: DiscrepancyOptions) -> Reproduction:
    """Stage 12: load the written model file back (:func:`reproduce_errors`) and check that it
    gives the final model's errors on the test split (the whole split, so that each motion's
    branch following is the same).

    Returns
    -------
    Reproduction

    Raises
    ------
    ModelFileError, PhysicalParameterError
        The written file does not load.
    """
    check = reproduce_errors(updated.path, setup.data.take(split.test_rows), setup.settings, n_jobs=options.n_jobs)
    reproduced = bool(np.allclose(check["position"], test.final.position, atol=1e-9, equal_nan=True))
    logger.log(progress_level(), f"wrote {updated.path}; reloaded, it reproduces the test split's errors of "
                                 f"{split.n_test} samples: {reproduced} (mean "
                                 f"{np.nanmean(check['position']) * 1e3:.3f} mm)")
    return Reproduction(position=check["position"], reproduced=reproduced)


def run_cautions(naming: Naming, combination: Combination | None, baseline: Baseline, test: TestSplit) -> tuple:
    """What a reader of the run must not overlook (logged as warnings): the final model's values
    outside their typical range and a maximum error that rises on the test split
    (:func:`~ctrplan.discrepancy.verdict.decision.cautions`), and baseline parameters outside their typical
    range or at a bound.

    Parameters
    ----------
    naming : Naming
    combination : Combination or None
    baseline : Baseline
    test : TestSplit

    Returns
    -------
    tuple of Caution
        In words by :func:`~ctrplan.discrepancy.outputs.words.caution`.
    """
    final = final_candidate(naming, combination)
    notes = cautions(naming.verdict, final, ErrorFigures.of(test.baseline), ErrorFigures.of(test.final))
    notes += [Caution(CautionKind.BASELINE_PARAMETER, parameter=r) for r in baseline.parameters
              if not r.in_typical_range or r.at_bound]
    for c in notes:
        logger.warning(f"caution: {caution_text(c.as_dict())}")
    return tuple(notes)


def log_verdict(naming: Naming, noise: NoiseCheck) -> None:
    """Log stage 7's verdict in words (:func:`~ctrplan.discrepancy.outputs.words.verdict_lines`):
    the named effect or why none is at the progress level, its cautions as warnings, then the
    notes of the naming rule."""
    stored = {"decision": naming.decision.as_dict(), "noise": noise_dict(noise),
              "candidates": {e: candidate_dict(c) for e, c in naming.candidates.items()}}
    for level, line in verdict_lines(stored):
        logger.log(level if level >= logging.WARNING else progress_level(), line)


def log_split(data: MeasuredData, split: DataSplit) -> None:
    """Log stage 2's split in words (:func:`~ctrplan.discrepancy.outputs.words.split_text`): the
    samples, the units, the test split and the folds; for a ROS 2 bag, its summary."""
    logger.log(progress_level(), f"data: {data.n_samples} samples ({data.frame} frame) from {data.file}; "
                                 f"{split_text(split.as_dict())}")
    if data.source is not None:
        from ...io.ros2 import describe_bag_summary

        for line in describe_bag_summary(data.source):
            logger.log(progress_level(), f"  {line}")


def log_pilot(split: DataSplit, scale: float) -> None:
    """Log stage 3's pilot fit: the buffer it chose and the prior's scale [mm + deg]."""
    logger.log(progress_level(), f"  buffer: {buffer_text(split.as_dict())}; prior scale: the pilot's rms "
                                 f"Eq. (49) residual {scale:.3g} mm + deg")


def log_blocks(before: DataSplit, after: DataSplit) -> None:
    """Log stage 3a's blocks when they were lengthened: the split and the buffer in words."""
    if after.block_samples != before.block_samples:
        d = after.as_dict()
        logger.log(progress_level(), f"  blocks: {split_text(d)}; buffer: {buffer_text(d)}")


def log_noise(check: NoiseCheck) -> None:
    """Log stage 5's noise check: the sensor noise estimate, the baseline's out-of-fold rms and
    the test of the residual against the noise."""
    test = check.test
    logger.log(progress_level(),
               f"  sensor noise: {noise_text(check.noise.as_dict())}; out-of-fold baseline rms "
               f"{check.rms_m * 1e3:.3f} mm"
               + (f" = {check.ratio:.2f} x noise; consistent with noise: {check.consistent} (F = {test.statistic:.3g}, "
                  f"threshold {test.threshold:.3g} at false-alarm rate {test.false_alarm_rate:g})" if test else ""))
