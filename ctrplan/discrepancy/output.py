"""Stages 10-12 of the discrepancy workflow: the test split, the updated robot file, its check, and
the results."""

from __future__ import annotations

import datetime
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from ..effects import REGISTRY, EffectSet, robot_effects
from ..io.atomic import atomic_write_text
from .calibrate import pose_errors, predict
from .data import MeasuredData
from .decision import Naming, NoiseCheck, atypical_caution, cautions
from .evaluation import Errors, error_summary, evaluate_rows
from .fitting import Baseline, Candidate, Combination, CrossValidated, candidate_report, candidate_reports
from .options import CONFIDENCE, DiscrepancyOptions
from .parameters import REGISTRATION, apply_parameters, parameter
from .provenance import provenance
from .setup import DiscrepancySetup
from .split import DataSplit
from .statistics import mean_interval, shrink_interval

__all__ = ["TestSplit", "evaluate_test_split", "UpdatedModel", "Reproduction", "write_updated_model",
           "check_reproduction", "reproduce_errors", "discrepancy_results", "final_candidate", "final_parameters",
           "validate_prediction"]


def final_candidate(naming: Naming, combination: Combination | None) -> Candidate | None:
    """The model the run ends with: the named pair; else the second effect alone when the named
    effect went to zero with it; else the named effect (the first of an ambiguous pair); else None
    (the recalibrated baseline)."""
    if combination is not None and combination.named:
        return combination.tried[combination.named]
    if combination is not None and combination.replaced_by:
        return naming.candidates[combination.replaced_by]
    return naming.candidates[naming.named] if naming.named else None


def final_parameters(naming: Naming, combination: Combination | None, baseline: Baseline) -> dict:
    """The parameters of the model the run ends with [SI] (the baseline's when nothing is named)."""
    final = final_candidate(naming, combination)
    return dict(final.params if final is not None else baseline.params)


def _figures(errors: dict, units) -> dict:
    """Mean (with a t-interval over units), p95 and max of each model's tip errors [m] -> mm, on the
    samples where every model is finite."""
    ok = np.all([np.isfinite(v) for v in errors.values()], axis=0)
    u = np.asarray(units)[ok]
    out = {}
    for name, e in errors.items():
        x = np.asarray(e, float)[ok] * 1e3
        m = mean_interval(x, u, confidence=CONFIDENCE)
        out[name] = {"mean_mm": m, "p95_mm": float(np.percentile(x, 95)) if x.size else None,
                     "max_mm": float(x.max()) if x.size else None}
    return out


def validate_prediction(prediction, split: DataSplit, seed: int = 0) -> dict | None:
    """The history-aware prediction against the standard model on the test split: mean (with a
    t-interval over units), p95 and max tip position error of each [mm], and the per-unit paired
    difference of their means with its t-interval; the history "beats" the standard model when
    that interval lies below zero (:func:`~ctrplan.discrepancy.statistics.mean_interval` of the
    paired differences). Planning aims with the history-aware prediction only then.

    Parameters
    ----------
    prediction : HistoryPrediction or None
        Its first row is the standard model, its second the history-aware model with the fitted
        friction coefficients, both on the test split in data order.
    split : DataSplit
    seed : int
        Unused (kept for callers).

    Returns
    -------
    dict or None
        ``standard`` and ``history`` ({``mean_mm``: {value, ci, ...}, ``p95_mm``, ``max_mm``}),
        ``difference_mm`` (history - standard, per-unit paired, {value, ci}), ``history_label``,
        ``history_beats_standard``, ``n_samples``, ``n_units``; None without a prediction.
    """
    if prediction is None or len(prediction.rows) < 2:
        return None
    units = split.units[split.test_rows]
    std, hist = (np.asarray(prediction.rows[i][1], float) for i in (0, 1))
    ok = np.isfinite(std) & np.isfinite(hist)
    figs = _figures({"standard": std, "history": hist}, units)
    diff = mean_interval((hist[ok] - std[ok]) * 1e3, units[ok], confidence=CONFIDENCE)
    return {"n_samples": int(ok.sum()), "n_units": int(np.unique(units[ok]).size),
            "history_label": prediction.rows[1][0], "confidence": CONFIDENCE, **figs, "difference_mm": diff,
            "history_beats_standard": bool(np.isfinite(diff["ci"][1]) and diff["ci"][1] < 0.0),
            "method": "t-interval over the test split's units of the per-unit paired difference of the mean errors"}


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
    figures : dict
        ``file``, ``before`` (the calibrated baseline) and ``after`` (the final model): mean
        (with a t-interval over units), p95 and max of the tip position error [mm]; ``shrink``:
        the relative fall of the mean from before to after (and ``calibration_shrink``, from
        the file to the calibrated baseline), with t-intervals from the per-unit paired sums;
        ``units``, ``n_samples``, ``confidence``, ``method``.
    """

    file: Errors
    baseline: Errors
    final: Errors
    label: str
    figures: dict


def _shrink_figures(file: Errors, before: Errors, after: Errors, units) -> dict:
    ok = np.isfinite(before.position) & np.isfinite(after.position) & np.isfinite(file.position)
    u = np.asarray(units)[ok]
    figs = _figures({"file": file.position[ok], "before": before.position[ok], "after": after.position[ok]}, u)
    return {**figs,
            "shrink": {"mean": shrink_interval(before.position[ok], after.position[ok], u, confidence=CONFIDENCE)},
            "calibration_shrink": {"mean": shrink_interval(file.position[ok], before.position[ok], u,
                                                           confidence=CONFIDENCE)},
            "n_samples": int(ok.sum()), "n_units": int(np.unique(u).size), "confidence": CONFIDENCE,
            "method": f"t-intervals over the test split's {np.unique(u).size} units (means and the shrink of the "
                      f"mean from per-unit sums, paired; Cochran 1977, Sec. 6.4); p95 and max without an interval"}


def evaluate_test_split(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, naming: Naming,
                        combination: Combination | None, options: DiscrepancyOptions, echo=print,
                        progress: bool = False) -> TestSplit:
    """Stage 10: evaluate the robot file with only a registration, the calibrated baseline and the
    final model (their development fits) on the test split, once, and the gains there with
    t-intervals over units.

    Returns
    -------
    TestSplit
    """
    final = final_candidate(naming, combination)
    test = split.test_rows
    file = evaluate_rows(setup, test, "test-file", "standard", baseline.file_cv.params, n_jobs=options.n_jobs,
                         progress=progress, echo=echo)
    before = evaluate_rows(setup, test, "test-baseline", "standard", baseline.params, n_jobs=options.n_jobs,
                           progress=progress, echo=echo)
    after = before if final is None else evaluate_rows(setup, test, f"test-{final.cv.name}", final.model, final.params,
                                                       n_jobs=options.n_jobs, progress=progress, echo=echo)
    figures = _shrink_figures(file, before, after, split.units[test])
    label = final.label if final is not None else "baseline (nothing named)"
    s, c = figures["shrink"]["mean"], figures["calibration_shrink"]["mean"]
    echo(f"test split ({split.n_test} samples in {figures['n_units']} units, untouched until now): robot file with a "
         f"registration {figures['file']['mean_mm']['value']:.3f} mm, calibrated baseline "
         f"{figures['before']['mean_mm']['value']:.3f} mm (shrink {100 * c['value']:.0f} %, {100 * c['ci'][0]:.0f}.."
         f"{100 * c['ci'][1]:.0f} %), {label} {figures['after']['mean_mm']['value']:.3f} mm (shrink "
         f"{100 * s['value']:.0f} %, {CONFIDENCE:.0%} interval {100 * s['ci'][0]:.0f}..{100 * s['ci'][1]:.0f} %); max "
         f"{figures['before']['max_mm']:.2f} -> {figures['after']['max_mm']:.2f} mm")
    return TestSplit(file=file, baseline=before, final=after, label=label, figures=figures)


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
    cautions : tuple of str
        Written values outside their typical range, each with the range's source and what to
        check (also in the file's ``[effects_source]``).
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
                        test: TestSplit, echo=print, *, bound=None, prediction_check: dict | None = None) -> UpdatedModel:
    """Stage 11: write one robot model file with the final model's calibrated parameters (the
    recalibrated baseline when nothing is named) into ``setup.out_dir``, atomically.

    Effects that change the robot go into its tube and pair tables, a registration into
    ``[tracker_registration]``, effects on the motion or the measurement (backlash, time offset,
    gradual friction, ...) into ``[effects]`` with ``[effects_source]``: the data file and its
    SHA-256, the date, the samples, the verdict, the test split's errors and a caution for every
    value outside its typical range (the value is written: the data chose it over every other
    explanation). The values are those of the final model's joint fit. With ``bound`` (a
    :class:`~ctrplan.discrepancy.coverage.BoundCalibration` with a finite factor), the table
    ``[bound_calibration]``; with ``prediction_check`` (:func:`validate_prediction`),
    ``[prediction_validation]``: planning reads both.

    Returns
    -------
    UpdatedModel
    """
    from ..io.robot_file import file_hash, robot_to_toml

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
    stored = {name: dict(effects[name]) for name in effects if REGISTRY[name].store == "effects"}
    notes = tuple(atypical_caution(final.label, b) for b in final.atypical) if final is not None else ()
    data_name = Path(setup.data_path).name
    updated = apply_parameters(robot, tuple(final_params), tuple(final_params.values()))
    merged = robot_effects(robot).merged(stored)
    verdict = naming.verdict
    if verdict == "ambiguous":
        suffix = f"{naming.named}-or-{naming.decision['ambiguous_with']}"
    else:
        suffix = "-".join(named_effects) or "recalibrated"
    updated = updated.replace(name=f"{robot.name}-{suffix}",
                              source=f"{robot.source}; recalibrated by ctrplan discrepancy on {data_name}"
                                     + "".join(f"; caution: {c}" for c in notes),
                              effects=tuple((n, tuple(merged[n].items())) for n in merged))
    pos = test.final.position[np.isfinite(test.final.position)]
    note = ("ambiguous: " + naming.candidates[naming.decision["ambiguous_with"]].label + " explains the data equally "
            "well" if verdict == "ambiguous" else "")
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
    pred_table = None
    if prediction_check is not None:
        pc = prediction_check
        pred_table = {"standard_mean_m": pc["standard"]["mean_mm"]["value"] * 1e-3,
                      "standard_max_m": pc["standard"]["max_mm"] * 1e-3,
                      "history_mean_m": pc["history"]["mean_mm"]["value"] * 1e-3,
                      "history_max_m": pc["history"]["max_mm"] * 1e-3,
                      "history_beats_standard": bool(pc["history_beats_standard"]),
                      "difference_mean_m": pc["difference_mm"]["value"] * 1e-3,
                      "difference_low_m": pc["difference_mm"]["ci"][0] * 1e-3,
                      "difference_high_m": pc["difference_mm"]["ci"][1] * 1e-3, "test_units": pc["n_units"],
                      "test_samples": pc["n_samples"],
                      "data_file": data_name, "data_sha256": sha, "date": source["date"]}
    atomic_write_text(model_path, robot_to_toml(updated, header=header, model=final_model, registration=registration,
                                                effects_source=source if updated.effects else None,
                                                bound_calibration=bound_table, prediction_validation=pred_table))
    for c in notes:
        echo(f"  written with a caution: {c}")
    return UpdatedModel(path=model_path, model=final_model, params=final_params, named_effects=tuple(named_effects),
                        candidate=final, cautions=notes)


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
    from ..io.robot_file import load_robot

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
                       options: DiscrepancyOptions, echo=print) -> Reproduction:
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
    echo(f"wrote {updated.path}; reloaded, it reproduces the test split's errors of {split.n_test} samples: "
         f"{reproduced} (mean {np.nanmean(check['position']) * 1e3:.3f} mm)")
    return Reproduction(position=check["position"], reproduced=reproduced)


def _combination_report(combination: Combination | None) -> dict | None:
    if combination is None:
        return None
    return {"first": combination.first, "first_label": combination.first_label, "named": combination.named,
            "tried": {e: candidate_report(c) for e, c in combination.tried.items()},
            "not_tried": dict(combination.not_tried), "family": list(combination.family), "rule": combination.rule,
            "dropped": combination.dropped, "replaced_by": combination.replaced_by}


def _errors_arrays(e: Errors) -> dict:
    return {"position": e.position, "angle": e.angle, "residual": e.residual_base, "tip_base": e.tip_base}


def discrepancy_results(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, contact: CrossValidated | None,
                        tests: Mapping, noise: NoiseCheck, naming: Naming, combination: Combination | None,
                        test: TestSplit, prediction, updated: UpdatedModel, reproduction: Reproduction,
                        options: DiscrepancyOptions, echo=print, *, bound=None,
                        prediction_check: dict | None = None) -> dict:
    """The run's results as ``results.json`` stores them (report units: keys ending ``_mm`` in mm,
    ``_deg`` in degrees, others SI), with the cautions a reader must not overlook (echoed).

    Returns
    -------
    dict
        JSON-ready results (``seconds`` is None: the caller sets it); arrays for plots under
        ``"_arrays"`` (SI).
    """
    base_oof = baseline.oof
    final = final_candidate(naming, combination)
    before_test = error_summary(test.baseline.position, test.baseline.angle, test.baseline.seconds, split.n_test)
    after_test = error_summary(test.final.position, test.final.angle, test.final.seconds, split.n_test)
    candidates = candidate_reports(naming.candidates)
    file_test = error_summary(test.file.position, test.file.angle, test.file.seconds, split.n_test)
    notes = cautions(naming.verdict, None if final is None else candidate_report(final), before_test, after_test)
    bad_base = [r for r in baseline.parameters if not r["in_typical_range"] or r["at_bound"]]
    for r in bad_base:
        change = "" if r.get("relative_change") is None else f", {100 * r['relative_change']:+.0f} % from the robot file"
        notes.append(f"baseline {r['name']} = {r['value']:.4g} {r['unit']}{change}"
                     + (": at its bound" if r["at_bound"] else "") + f"; typical: {r['typical_source']}")
    for line in notes:
        echo(f"caution: {line}")
    opts = asdict(options)
    opts["effects"] = list(setup.effects) if options.effects is None else list(options.effects)
    dev = setup.data.take(split.dev_rows)
    test_data = setup.data.take(split.test_rows)
    return {
        "robot_file": str(setup.robot_path), "data_file": str(setup.data_path), "frame": setup.data.frame,
        "data_source": setup.data.source,
        "n_samples": setup.data.n_samples, "split": split.as_dict(), "baseline_parameters": list(setup.base_names),
        "baseline": {"fit": baseline.fit.as_dict(), "folds": [f.as_dict() for f in baseline.cv.folds],
                     "bic": baseline.bic, "parameter_table": baseline.parameters,
                     "out_of_fold": error_summary(base_oof.position, base_oof.angle, base_oof.seconds, base_oof.rows.size),
                     "prior_strength": baseline.strength, "prior_choices": baseline.choices,
                     "residual_scale": baseline.residual_scale,
                     "file_fit": baseline.file_cv.fit.as_dict()},
        "contact_baseline": None if contact is None else {"fit": contact.fit.as_dict(),
                                                          "folds": [f.as_dict() for f in contact.folds]},
        "signature_tests": {e: t.as_dict() for e, t in tests.items()},
        "skipped_effects": dict(setup.skipped), "noise": noise.as_dict(), "decision": naming.decision,
        "verdict": naming.verdict, "named_effect": naming.named,
        "named_label": REGISTRY[naming.named].label if naming.named else None,
        "ambiguous_with": naming.decision.get("ambiguous_with"),
        "candidates": candidates, "named_effects": list(updated.named_effects),
        "combination": _combination_report(combination),
        "test_split": {"label": test.label, "file": file_test, "before": before_test, "after": after_test,
                       "figures": test.figures},
        "prediction": None if prediction is None else prediction.as_dict(),
        "prediction_check": prediction_check, "bound": None if bound is None else bound.as_dict(),
        "updated_model_file": str(updated.path), "updated_model": updated.model,
        "reproduced": reproduction.reproduced, "reproduced_samples": split.n_test,
        "reproduced_position_mean_mm": float(np.nanmean(reproduction.position) * 1e3),
        "cautions": notes, "significance": options.significance, "options": opts, "seconds": None,
        "provenance": provenance(options),
        "_arrays": {"dev_eta": dev.eta, "test_eta": test_data.eta, "oof": _errors_arrays(base_oof),
                    "oof_final": None if final is None else _errors_arrays(final.oof),
                    "test_before": _errors_arrays(test.baseline), "test_after": _errors_arrays(test.final),
                    "test_file": _errors_arrays(test.file)},
    }
