"""Stages 10-12 of the discrepancy workflow: the updated robot file, its check, and the results."""

from __future__ import annotations

import datetime
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from ..effects import REGISTRY, EffectSet, robot_effects
from ..io.atomic import atomic_write_text
from .calibrate import CalibrationResult, pose_errors, predict
from .data import MeasuredData
from .decision import Naming, NoiseCheck, cautions
from .evaluation import HeldOut, error_summary
from .fitting import Baseline, Candidate, Combination, candidate_report, candidate_reports
from .options import BIC_MARGIN, REPRODUCE_SAMPLES, DiscrepancyOptions
from .parameters import REGISTRATION, apply_parameters, parameter
from .setup import DiscrepancySetup
from .split import SampleSplit, configurations_repeat, subsample

__all__ = ["UpdatedModel", "Reproduction", "write_updated_model", "check_reproduction", "reproduce_errors",
           "discrepancy_results"]


@dataclass(frozen=True, eq=False)
class UpdatedModel:
    """Stage 10: the updated robot model file.

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
    held_out : HeldOut
        Its held-out errors as the workflow evaluated them [m, rad].
    left_out : tuple of str
        Effect parameters not written because their values are implausible (a robot file holds
        only plausible ones).
    """

    path: Path
    model: str
    params: dict
    named_effects: tuple
    candidate: Candidate | None
    held_out: HeldOut
    left_out: tuple = ()


@dataclass(frozen=True, eq=False)
class Reproduction:
    """Stage 11: the written model file reloaded and re-evaluated.

    Attributes
    ----------
    rows : ndarray of bool, shape (K,)
        Held-out samples re-evaluated.
    position : ndarray, shape (rows.sum(),)
        Their tip position errors with the reloaded file [m].
    reproduced : bool
        Equal to the workflow's errors within 1 nm (NaN where both failed).
    """

    rows: np.ndarray
    position: np.ndarray
    reproduced: bool

    @property
    def n_samples(self) -> int:
        return int(self.rows.sum())


def write_updated_model(setup: DiscrepancySetup, baseline: Baseline, naming: Naming,
                        combination: Combination | None, echo=print) -> UpdatedModel:
    """Stage 10: write one robot model file with the named effect(s) and their calibrated
    parameters (the recalibrated baseline when none is named) into ``setup.out_dir``, atomically.

    Effects that change the robot go into its tube and pair tables, a registration into
    ``[tracker_registration]``, effects on the motion or the measurement (backlash, time offset,
    gradual friction, ...) into ``[effects]`` with ``[effects_source]``: the data file and its
    SHA-256, the date, the samples fitted and the held-out errors.

    Returns
    -------
    UpdatedModel
    """
    from ..io.robot_file import file_hash, robot_to_toml

    robot, named = setup.robot, naming.named
    pair = combination.named if combination else None
    final = combination.tried[pair] if pair else (naming.candidates[named] if named else None)
    named_effects = ([named] + ([pair] if pair else [])) if named else []
    final_params = dict(final.params if final else baseline.params)
    final_model = final.model if final else "standard"
    reg_names = [n for n in final_params if n in REGISTRATION]
    registration = None
    if reg_names:
        vals = [final_params.get(n, 0.0) for n in REGISTRATION]
        registration = {"rotation_vector_rad": vals[:3], "translation_m": vals[3:]}
    effects, _ = EffectSet.from_parameters(robot, tuple(final_params), tuple(final_params.values()))
    left_out = []
    stored = {}
    for name in effects:
        if REGISTRY[name].store != "effects":
            continue
        vals = {}
        for p, v in effects[name].items():
            if parameter(robot, p).is_plausible(v):
                vals[p] = v
            else:
                left_out.append(p)
        if vals:
            stored[name] = vals
    data_name = Path(setup.data_path).name
    updated = apply_parameters(robot, tuple(final_params), tuple(final_params.values()))
    merged = robot_effects(robot).merged(stored)
    updated = updated.replace(name=f"{robot.name}-{'-'.join(named_effects) or 'recalibrated'}",
                              source=f"{robot.source}; recalibrated by ctrplan discrepancy on {data_name}",
                              effects=tuple((n, tuple(merged[n].items())) for n in merged))
    held = final.held_out if final else baseline.held_out
    pos = held.position[np.isfinite(held.position)]
    source = {"method": "ctrplan discrepancy (calibration split; errors on the held-out split)",
              "data_file": data_name, "data_sha256": file_hash(setup.data_path),
              "date": datetime.date.today().isoformat(), "samples": int(setup.data.n_samples),
              "held_out_position_mean_m": float(pos.mean()) if pos.size else None,
              "held_out_position_p95_m": float(np.percentile(pos, 95)) if pos.size else None,
              "held_out_position_max_m": float(pos.max()) if pos.size else None,
              "note": ("not written, implausible: " + ", ".join(left_out)) if left_out else ""}
    setup.out_dir.mkdir(parents=True, exist_ok=True)
    model_path = setup.out_dir / f"{updated.name}.toml"
    header = (f"Written by `ctrplan discrepancy` from {Path(setup.robot_path).name} and {data_name}.\n"
              f"Named effect: {' + '.join(REGISTRY[e].label for e in named_effects) or 'none'}; evaluate with the "
              f"{final_model} model.\nCalibrated parameters: "
              + ", ".join(f"{n} = {v:.6g}" for n, v in final_params.items() if n not in REGISTRATION))
    atomic_write_text(model_path, robot_to_toml(updated, header=header, model=final_model, registration=registration,
                                                effects_source=source if updated.effects else None))
    if left_out:
        echo(f"  not written to the model file (implausible values): {', '.join(left_out)}")
    return UpdatedModel(path=model_path, model=final_model, params=final_params, named_effects=tuple(named_effects),
                        candidate=final, held_out=held, left_out=tuple(left_out))


def reproduce_errors(model_path, data: MeasuredData, settings=None, *, n_jobs: int = 1) -> dict:
    """Load an updated model file and evaluate its errors on ``data`` with the model it names.

    Parameters
    ----------
    model_path : path
        Robot model file written by the workflow (its ``model`` key names the mechanics model;
        ``[tracker_registration]`` maps to the data's frame; its ``[effects]`` apply to the
        recorded motion).
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


def check_reproduction(setup: DiscrepancySetup, split: SampleSplit, updated: UpdatedModel,
                       options: DiscrepancyOptions, echo=print) -> Reproduction:
    """Stage 11: load the written model file back (:func:`reproduce_errors`) and check that it
    gives the workflow's held-out errors: whole configuration groups of a revisiting protocol
    (at most :data:`REPRODUCE_SAMPLES`); a trajectory is re-run whole, since a subsample would
    break its branch following (each sample starts from the previous one).

    Returns
    -------
    Reproduction

    Raises
    ------
    ModelFileError, PhysicalParameterError
        The written file does not load.
    """
    val = split.val
    check_rows = (subsample(val, np.ones(val.n_samples, bool), REPRODUCE_SAMPLES, options.seed)
                  if configurations_repeat(val.config_id) else np.ones(val.n_samples, bool))
    check = reproduce_errors(updated.path, val.take(check_rows), setup.settings, n_jobs=options.n_jobs)
    reproduced = bool(np.allclose(check["position"], updated.held_out.position[check_rows], atol=1e-9,
                                  equal_nan=True))
    echo(f"wrote {updated.path}; reloaded, it reproduces the held-out errors of {int(check_rows.sum())} "
         f"samples: {reproduced} (mean {np.nanmean(check['position']) * 1e3:.3f} mm)")
    return Reproduction(rows=check_rows, position=check["position"], reproduced=reproduced)


# --------------------------------------------------------------------------- results
def _pair_report(c: Candidate, n_val: int) -> dict:
    """A pair as ``results.json["combination"]["tried"][effect]`` stores it (mm in ``held_out``)."""
    out = {"effects": list(c.effects), "label": c.label, "model": c.model, "fit": c.fit.as_dict(),
           "parameters": c.shown, "units": c.units, "implausible": c.implausible, "plausible": c.plausible,
           "n_parameters": c.n_parameters, "bic": c.bic, "delta_bic": c.delta_bic,
           "held_out": error_summary(c.held_out.position, c.held_out.angle, c.held_out.seconds, n_val),
           "improvement_eq49": c.improvement_eq49, "improvement_position": c.improvement_position,
           "converged": bool(c.fit.converged), "improvement_significant": c.improvement_significant,
           "bic_better": c.bic_better, "significant": c.significant}
    if c.fit_note:
        out["note"] = c.fit_note
    return out


def _combination_report(combination: Combination | None, naming: Naming, n_val: int) -> dict | None:
    """``results.json["combination"]`` (mm)."""
    if combination is None:
        return None
    tried = {e: _pair_report(c, n_val) for e, c in combination.tried.items()}
    steps = []
    if combination.named:
        first = candidate_report(naming.candidates[combination.first], n_val)
        c = tried[combination.named]
        steps = [
            {"effect": combination.first, "label": first["label"],
             "held_out_mean_mm": first["held_out"]["position_mean_mm"],
             "held_out_max_mm": first["held_out"]["position_max_mm"],
             "improvement_eq49": first["improvement_eq49"], "over": "baseline"},
            {"effect": combination.named, "label": naming.candidates[combination.named].label,
             "held_out_mean_mm": c["held_out"]["position_mean_mm"], "held_out_max_mm": c["held_out"]["position_max_mm"],
             "improvement_eq49": c["improvement_eq49"], "over": combination.first}]
    return {"first": combination.first, "first_label": combination.first_label, "named": combination.named,
            "tried": tried, "steps": steps, "notes": list(combination.notes), "rule": combination.rule}


def discrepancy_results(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline,
                        contact: CalibrationResult | None, tests: Mapping, noise: NoiseCheck, naming: Naming,
                        combination: Combination | None, prediction, updated: UpdatedModel,
                        reproduction: Reproduction, options: DiscrepancyOptions, echo=print) -> dict:
    """Stage 12: the run's results as ``results.json`` stores them (report units: keys ending
    ``_mm`` in mm, ``_deg`` in degrees, others SI), with the cautions a reader must not overlook
    (echoed).

    Parameters
    ----------
    setup, split, baseline, contact, tests, noise, naming, combination, prediction, updated, reproduction
        The results of stages 1-11.
    options : DiscrepancyOptions
    echo : callable
        Receives the cautions.

    Returns
    -------
    dict
        JSON-ready results (``seconds`` is None: the caller sets it); arrays for plots under
        ``"_arrays"`` (SI).
    """
    val, n_val, named = split.val, split.val.n_samples, naming.named
    base, base_val = baseline.fit, baseline.held_out
    base_summary = error_summary(base_val.position, base_val.angle, base_val.seconds, n_val)
    final_val = updated.held_out
    after = error_summary(final_val.position, final_val.angle, final_val.seconds, n_val)
    candidates = candidate_reports(naming.candidates, n_val)
    combination_report = _combination_report(combination, naming, n_val)
    pair = combination.named if combination else None
    final = combination_report["tried"][pair] if pair else (candidates[named] if named else None)
    notes = cautions(named, final, base_summary, after)
    if updated.left_out:
        notes.append(f"not written to the model file because implausible: {', '.join(updated.left_out)}")
    for line in notes:
        echo(f"caution: {line}")
    opts = asdict(options)
    opts["effects"] = list(setup.effects) if options.effects is None else list(options.effects)
    return {
        "robot_file": str(setup.robot_path), "data_file": str(setup.data_path), "frame": setup.data.frame,
        "n_samples": setup.data.n_samples, "split": split.how, "n_calibration": split.n_calibration,
        "n_fit": split.n_fit, "n_validation": n_val, "baseline_parameters": list(setup.base_names),
        "baseline": {"fit": base.as_dict(), "bic": baseline.bic, "held_out": base_summary},
        "contact_baseline": contact.as_dict() if contact is not None else None,
        "signature_tests": {e: t.as_dict() for e, t in tests.items()},
        "skipped_effects": dict(setup.skipped), "prediction": None if prediction is None else prediction.as_dict(),
        "noise": noise.as_dict(), "decision": naming.decision,
        "candidates": candidates,
        "named_effect": named, "named_label": REGISTRY[named].label if named else None,
        "named_effects": list(updated.named_effects), "combination": combination_report,
        "after": after, "updated_model_file": str(updated.path), "updated_model": updated.model,
        "reproduced": reproduction.reproduced, "reproduced_samples": reproduction.n_samples,
        "reproduced_position_mean_mm": float(np.nanmean(reproduction.position) * 1e3),
        "cautions": notes,
        "significance": options.significance, "bic_margin": BIC_MARGIN, "options": opts,
        "seconds": None,
        "_arrays": {"val_eta": val.eta, "val_tip_base": base_val.tip_base,
                    "before_position": base_val.position, "before_angle": base_val.angle,
                    "before_residual": base_val.residual_base,
                    "after_position": final_val.position, "after_angle": final_val.angle,
                    "after_residual": final_val.residual_base,
                    "reduction": (1.0 - after["position_mean_mm"] / base_summary["position_mean_mm"])
                    if base_summary["position_mean_mm"] else None},
    }
