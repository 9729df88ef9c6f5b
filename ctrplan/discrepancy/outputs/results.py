"""``results.json`` of the discrepancy workflow: a run's typed results as plain JSON values.

:func:`results_dict` is what the report folder's ``results.json`` holds and what
:meth:`~ctrplan.discrepancy.workflow.DiscrepancyResult.to_dict` returns. Keys say their unit: SI
values where the key has ``_m``, ``_rad`` or no unit suffix, millimetres and degrees where it has
``_mm`` / ``_deg`` (the report reads them in those units). ``report.md`` is formatted from this
dictionary alone (:mod:`ctrplan.discrepancy.outputs.report`).
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from ...effects import REGISTRY
from ..verdict.coverage import BOUND_DEFINITION
from ..verdict.envelope import PREDICTION_DESCRIPTION
from ..fits.evaluation import ErrorFigures
from ..provenance import provenance

__all__ = ["results_dict", "candidate_dict", "noise_dict", "error_dict", "bound_dict", "json_default"]


# --------------------------------------------------------------------------- results.json
def _mm(x):
    return None if x is None else x * 1e3


def error_dict(f: ErrorFigures) -> dict:
    """A row of Table VIII of Ha et al. 2019 in report units: tip position error mean, std, p95,
    max [mm]; tangent mean, max [deg]; evaluation time per sample [ms]."""
    deg = (lambda x: None if x is None else float(np.rad2deg(x)))
    return {"position_mean_mm": _mm(f.position_mean), "position_std_mm": _mm(f.position_std),
            "position_p95_mm": _mm(f.position_p95), "position_max_mm": _mm(f.position_max),
            "tangent_mean_deg": deg(f.tangent_mean), "tangent_max_deg": deg(f.tangent_max),
            "evaluation_ms_per_sample": 1e3 * f.seconds_per_sample, "n_samples": f.n_samples,
            "n_failed": f.n_failed}


def _model_figures(m) -> dict:
    """:class:`~ctrplan.discrepancy.outputs.output.ModelFigures` in mm."""
    return {"mean_mm": m.mean.scaled(1e3).as_dict(), "p95_mm": _mm(m.p95), "max_mm": _mm(m.max)}


def candidate_dict(c) -> dict:
    """A :class:`~ctrplan.discrepancy.fits.fitting.Candidate` as ``results.json`` stores it (mm in
    ``out_of_fold``; SI in ``parameters`` and ``parameter_table``; Eq. (49) units in
    ``improvement_eq49``)."""
    out = {"effects": list(c.effects), "label": c.label, "model": c.model, "fit": c.fit.as_dict(),
           "folds": [f.as_dict() for f in c.cv.folds], "parameters": c.shown, "units": c.units,
           "parameter_table": [p.as_dict() for p in c.parameters], "atypical": [a.as_dict() for a in c.atypical],
           "typical": c.typical, "at_bound": list(c.at_bound), "widened": list(c.widened), "converged": c.cv.converged,
           "n_parameters": c.n_parameters, "bic": c.bic, "delta_bic": c.delta_bic,
           "out_of_fold": error_dict(c.out_of_fold_figures), "mean_eq49": c.mean_error,
           "improvement_eq49": c.improvement.as_dict(), "improvement_position": c.improvement_position.as_dict(),
           "fit_notes": [n.as_dict() for n in c.fit_notes]}
    for key in ("improvement_significant", "eligible", "significant"):
        if getattr(c, key) is not None:
            out[key] = getattr(c, key)
    if c.reverse is not None:
        out["reverse"] = c.reverse.as_dict()
    return out


def noise_dict(check) -> dict:
    """A :class:`~ctrplan.discrepancy.verdict.decision.NoiseCheck` as ``results.json`` stores it (mm)."""
    sigma = check.rms
    return {"rms_mm": check.rms_m * 1e3, "noise_rms_mm": None if sigma is None else sigma * 1e3,
            "ratio": check.ratio, "consistent": check.consistent,
            "test": None if check.test is None else check.test.as_dict(), "noise": check.noise.as_dict()}


def _coverage_dict(c, *, error_median: bool) -> dict:
    out = {**c.as_dict(), "bound_median_mm": _mm(c.bound_median_m)}
    if error_median:
        out["error_median_mm"] = _mm(c.error_median_m)
    return out


def bound_dict(b) -> dict:
    """A :class:`~ctrplan.discrepancy.verdict.coverage.BoundCalibration` as ``results.json`` stores it (mm
    where the key says so): ``status`` one of "shown", "not shown", "failed", ``failing`` True
    exactly when "failed", ``conservative``, the intervals' ``confidence`` and the status's
    ``tolerance``, and ``calibration`` the factor's spread (``{"factor_ci", "coverage_ci",
    "n_units"}``, null without it)."""
    return {"definition": BOUND_DEFINITION, "method": b.method, "target": b.target, "factor": b.factor,
            "margin_mm": b.margin_m * 1e3, "noise_multiple": b.noise_multiple, "noise_rms_mm": b.noise_rms_m * 1e3,
            "n_calibration": b.n_calibration, "test": _coverage_dict(b.test, error_median=True),
            "raw_test": _coverage_dict(b.raw_test, error_median=False),
            "translation_last": None if b.translation_last is None else b.translation_last.as_dict(),
            "failing": b.failing, "status": b.status, "conservative": b.conservative, "confidence": b.confidence,
            "tolerance": b.tolerance, "calibration": None if b.calibration is None else b.calibration.as_dict()}


def _envelope_dict(env) -> dict:
    return {"n": env.n, "inside": env.inside, "fraction_inside": env.fraction_inside, "margin_mm": env.margin_m * 1e3,
            "outside_median_mm": _mm(env.outside_median_m), "outside_p95_mm": _mm(env.outside_p95_m),
            "outside_max_mm": _mm(env.outside_max_m), "size_median_mm": _mm(env.size_median_m),
            "n_samples": env.n_samples, "n_solutions": env.n_solutions, "noise_factor": env.noise_factor,
            "coefficients": env.coefficients, "label": env.label}


def _position_stats(pos) -> dict:
    p = pos[np.isfinite(pos)] * 1e3
    if not p.size:
        return {"n": 0, "mean_mm": None, "p95_mm": None, "max_mm": None}
    return {"n": int(p.size), "mean_mm": float(p.mean()), "p95_mm": float(np.percentile(p, 95)),
            "max_mm": float(p.max())}


def _prediction_dict(prediction) -> dict | None:
    if prediction is None:
        return None
    out = {"description": PREDICTION_DESCRIPTION,
           "rows": [{"label": label, **_position_stats(pos)} for label, pos in prediction.rows]}
    if prediction.envelopes:
        out["envelopes"] = [_envelope_dict(env) for env in prediction.envelopes]
        out["envelope"] = out["envelopes"][0]
    return out


def _prediction_check_dict(pc) -> dict | None:
    if pc is None:
        return None
    return {"n_samples": pc.n_samples, "n_units": pc.n_units, "history_label": pc.history_label,
            "confidence": pc.confidence, "standard": _model_figures(pc.standard),
            "history": _model_figures(pc.history), "difference_mm": pc.difference.scaled(1e3).as_dict(),
            "history_beats_standard": pc.history_beats_standard, "method": pc.method}


def _test_figures_dict(f) -> dict:
    return {"file": _model_figures(f.file), "before": _model_figures(f.before), "after": _model_figures(f.after),
            "shrink": {"mean": f.shrink.as_dict()}, "calibration_shrink": {"mean": f.calibration_shrink.as_dict()},
            "n_samples": f.n_samples, "n_units": f.n_units, "confidence": f.confidence, "method": f.method}


def _combination_dict(combination) -> dict | None:
    if combination is None:
        return None
    return {"first": combination.first, "first_label": combination.first_label, "named": combination.named,
            "tried": {e: candidate_dict(c) for e, c in combination.tried.items()},
            "not_tried": {e: r.as_dict() for e, r in combination.not_tried.items()}, "family": list(combination.family),
            "rule": {"significance": combination.significance, "joint_level": combination.joint_level},
            "dropped": combination.dropped, "replaced_by": combination.replaced_by, "joint": combination.joint,
            "against_baseline": {e: c.as_dict() for e, c in combination.against_baseline.items()}}


def results_dict(result) -> dict:
    """A run's results as ``results.json`` stores them (report units: keys ending ``_mm`` in mm,
    ``_deg`` in degrees, others SI or the Eq. (49) units the key names).

    Parameters
    ----------
    result : DiscrepancyResult

    Returns
    -------
    dict
        JSON-ready (numpy values are converted by :func:`write_report`).
    """
    setup, split, baseline, naming, test = result.setup, result.split, result.baseline, result.naming, result.test
    options = result.options
    opts = asdict(options)
    opts["effects"] = list(setup.effects) if options.effects is None else list(options.effects)
    return {
        "robot_file": str(setup.robot_path), "data_file": str(setup.data_path), "frame": setup.data.frame,
        "data_source": setup.data.source,
        "n_samples": setup.data.n_samples, "split": split.as_dict(), "baseline_parameters": list(setup.base_names),
        "baseline": {"fit": baseline.fit.as_dict(), "folds": [f.as_dict() for f in baseline.cv.folds],
                     "bic": baseline.bic, "parameter_table": [p.as_dict() for p in baseline.parameters],
                     "out_of_fold": error_dict(ErrorFigures.of(baseline.oof)),
                     "prior_strength": baseline.strength,
                     "prior_choices": [{"strength": c.strength, "mean_position_m": c.mean_position,
                                        "mean_eq49": c.mean_eq49, "against_file": c.against_file.as_dict()}
                                       for c in baseline.choices],
                     "residual_scale": baseline.residual_scale, "file_fit": baseline.file_cv.fit.as_dict()},
        "contact_baseline": None if result.contact is None else {"fit": result.contact.fit.as_dict(),
                                                                 "folds": [f.as_dict() for f in result.contact.folds]},
        "signature_tests": {e: {**t.as_dict(), "effect_size_mm": t.effect_size_m * 1e3} for e, t in result.tests.items()},
        "skipped_effects": dict(setup.skipped), "noise": noise_dict(result.noise), "decision": naming.decision.as_dict(),
        "verdict": naming.verdict, "named_effect": naming.named,
        "named_label": REGISTRY[naming.named].label if naming.named else None,
        "ambiguous_with": naming.decision.ambiguous_with,
        "candidates": {e: candidate_dict(c) for e, c in naming.candidates.items()},
        "named_effects": list(result.updated.named_effects),
        "combination": _combination_dict(result.combination),
        "test_split": {"label": test.label, "file": error_dict(ErrorFigures.of(test.file)),
                       "before": error_dict(ErrorFigures.of(test.baseline)),
                       "after": error_dict(ErrorFigures.of(test.final)), "figures": _test_figures_dict(test.figures)},
        "prediction": _prediction_dict(result.prediction),
        "prediction_check": _prediction_check_dict(result.prediction_check),
        "bound": None if result.bound is None else bound_dict(result.bound),
        "updated_model_file": str(result.updated.path), "updated_model": result.updated.model,
        "reproduced": result.reproduction.reproduced, "reproduced_samples": split.n_test,
        "reproduced_position_mean_mm": float(np.nanmean(result.reproduction.position) * 1e3),
        "cautions": [c.as_dict() for c in result.cautions], "significance": options.significance, "options": opts,
        "seconds": result.seconds, "stage_seconds": {k: float(v) for k, v in result.stage_seconds.items()},
        "stage_reused": dict(result.stage_reused), "provenance": provenance(options),
    }


def json_default(x):
    """The ``default`` of ``json.dumps`` for ``results.json``: arrays as lists, numpy scalars as
    Python ones, a non-finite float as null, anything else as its ``str``."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return str(x)
