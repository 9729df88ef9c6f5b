"""The discrepancy report (``ctrplan.discrepancy.outputs.report``) formats ``results.json`` alone, never
stops at a figure the data leave undefined, and can be written again from the report folder.

The results are built here in the form :func:`~ctrplan.discrepancy.outputs.results.results_dict` gives
them (a named friction effect on 240 samples, with every section of the report), and each test
sets some of its figures to what the workflow writes when the data cannot define them: an
interval over one unit (ends None or NaN), a mean over no samples, a comparison over one fold,
a fit that failed (parameters None or NaN), a missing p-value. ``write_report`` is called with
its ``results_dict`` and plots replaced, so the formatting is tested without a run (a run of the
workflow writes a report in tests/test_discrepancy_workflow.py).
"""

from __future__ import annotations

import copy
import json
import logging
import math
import re
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from ctrplan import cli
from ctrplan.discrepancy.outputs import report
from ctrplan.discrepancy.outputs import results as results_json

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
NAN = float("nan")


def _interval(value, low, high, n_units=12):
    """An :class:`~ctrplan.discrepancy.verdict.statistics.Interval` dict."""
    return {"value": value, "se": (high - low) / 4, "ci": [low, high], "dof": n_units - 1, "n_units": n_units}


def _comparison(reduction, low, high, p, n_folds=10):
    """A :class:`~ctrplan.discrepancy.verdict.statistics.Comparison` dict (Eq. (49) units)."""
    return {"n_folds": n_folds, "n_samples": 192, "fold_differences": [0.1] * n_folds,
            "fold_log_ratios": [0.2] * n_folds, "positive_folds": n_folds, "method": "t test of the log ratio",
            "mean_difference": 0.1, "ci": [0.05, 0.15], "ratio": 1 / (1 - reduction),
            "ratio_ci": [1 / (1 - low), 1 / (1 - high)], "reduction": reduction, "reduction_ci": [low, high],
            "se": 0.02, "t": 6.0, "dof": n_folds - 1, "p_value": p, "p_worse": 1 - p}


def _coverage(n, covered, low, high, n_units, bound_median_m=0.004, mm=True):
    """A :class:`~ctrplan.discrepancy.verdict.coverage.Coverage` dict as ``bound_dict`` stores it."""
    out = {"n": n, "covered": covered, "ci": [low, high], "n_units": n_units,
           "ratio": {"median": 0.6, "p90": 0.9, "p95": 1.0, "max": 1.3}, "bound_median_m": bound_median_m,
           "error_median_m": 0.0021}
    if mm:
        out.update(bound_median_mm=None if bound_median_m is None else bound_median_m * 1e3, error_median_mm=2.1)
    return out


def _model(mean, p95, mx, n_units=12):
    return {"mean_mm": _interval(mean, mean - 0.2, mean + 0.2, n_units), "p95_mm": p95, "max_mm": mx}


def _parameter(name, value, unit, stderr, **kw):
    return {"name": name, "unit": unit, "value": value, "stderr": stderr, "ci": None, "typical": [0.0, 0.5],
            "in_typical_range": True, "typical_source": "", "check": "", "at_bound": False, "resolution": None,
            "fitted": True, **kw}


def _results() -> dict:
    """A run's results in the form ``results_dict`` gives them, every figure defined."""
    friction = {"effects": ["friction"], "label": "friction (Coulomb, along the motion)", "model": "friction",
                "parameter_table": [_parameter("mu_1", 0.21, "-", 0.02)], "widened": [], "fit_notes": [],
                "out_of_fold": {"position_mean_mm": 1.1, "position_max_mm": 3.2},
                "improvement_eq49": _comparison(0.42, 0.30, 0.52, 1e-4), "improvement_significant": True,
                "eligible": True}
    offplane = {**copy.deepcopy(friction), "effects": ["offplane"], "label": "off-plane precurvature",
                "model": "standard", "parameter_table": [_parameter("precurvature_x_1", 0.3, "1/m", 0.1)],
                "out_of_fold": {"position_mean_mm": 1.8, "position_max_mm": 4.0},
                "improvement_eq49": _comparison(0.05, -0.02, 0.11, 0.08), "improvement_significant": False,
                "eligible": False}
    clearance = {**copy.deepcopy(offplane), "effects": ["friction", "clearance"], "label": "friction + clearance",
                 "reverse": _comparison(0.30, 0.20, 0.40, 1e-3)}
    return {
        "robot_file": "/data/pair.toml", "data_file": "/data/run.csv", "frame": "robot", "data_source": None,
        "n_samples": 240,
        "split": {"how": "contiguous time blocks of 10 samples", "n_folds": 10, "fold_samples": [19] * 10,
                  "fold_units": [2] * 10, "fit_samples": [190] + [171] * 10, "max_fit_samples": 300,
                  "buffer_note": "2 samples", "n_test": 48, "n_test_units": 5, "test_units": [3, 9, 14, 18, 22]},
        "baseline": {"fit": {"message": "converged", "converged": True, "parameters": {"precurvature_y_1": 5.0},
                             "correlation": [[1.0]]},
                     "parameter_table": [_parameter("precurvature_y_1", 5.0, "1/m", 0.1, reference=4.8,
                                                    relative_change=0.04)],
                     "out_of_fold": {"position_mean_mm": 1.9, "position_max_mm": 4.4}, "prior_strength": 0.03,
                     "prior_choices": [{"strength": 0.0, "mean_position_m": 0.0025, "mean_eq49": 3.1,
                                        "against_file": _comparison(0.0, 0.0, 0.0, 1.0)},
                                       {"strength": 0.03, "mean_position_m": 0.0019, "mean_eq49": 2.4,
                                        "against_file": _comparison(0.2, 0.1, 0.3, 1e-3)}],
                     "residual_scale": 1.7},
        "signature_tests": {"friction": {"effect": "friction", "label": "friction", "testable": True,
                                         "statistic": 4.2, "effect_size_mm": 0.8, "p_value": 0.001,
                                         "n_permutations": 999, "n_units": 24, "description": "sign test"}},
        "skipped_effects": {},
        "noise": {"rms_mm": 1.9, "noise_rms_mm": 0.5, "ratio": 3.8, "consistent": False,
                  "test": {"statistic": 14.4, "threshold": 1.3, "p_value": 0.0, "inflation": 1.05,
                           "dof_residual": 300.0, "dof_noise": None, "consistent": False, "false_alarm_rate": 0.01},
                  "noise": {"description": "0.5 mm rms, stated", "source": "stated"}},
        "decision": {"verdict": "named", "named": "friction", "ambiguous_with": None, "best": "friction",
                     "why_not": {"offplane": [{"reason": "not significant", "p_value": 0.031}]},
                     "separated_by": None, "cautions": [],
                     "notes": [{"kind": "best, not named", "effect": "offplane"}],
                     "rule": {"significance": 0.05, "n_folds": 5, "n_candidates": 2}},
        "verdict": "named", "named_effect": "friction",
        "candidates": {"friction": friction, "offplane": offplane},
        "combination": {"first": "friction", "first_label": friction["label"], "named": None,
                        "tried": {"clearance": clearance}, "not_tried": {"offplane": {"reason": "no improvement alone",
                                                                           "mean_difference": -0.02}},
                        "family": ["clearance", "offplane"], "rule": {"significance": 0.05}, "dropped": None,
                        "replaced_by": None},
        "test_split": {"label": friction["label"],
                       "figures": {"file": _model(3.0, 5.5, 7.0), "before": _model(2.0, 4.0, 5.0),
                                   "after": _model(1.2, 2.5, 3.1),
                                   "shrink": {"mean": _interval(0.4, 0.3, 0.5)},
                                   "calibration_shrink": {"mean": _interval(0.33, 0.2, 0.45)},
                                   "n_samples": 48, "n_units": 12, "confidence": 0.95,
                                   "method": "t-intervals over the test split's units"}},
        "prediction": {"description": "the friction model along the recorded motion",
                       "rows": [{"label": "standard model", "n": 48, "mean_mm": 2.0, "p95_mm": 4.0, "max_mm": 5.0},
                                {"label": "history-aware", "n": 48, "mean_mm": 1.2, "p95_mm": 2.5, "max_mm": 3.1}],
                       "envelopes": [{"n": 20, "inside": 18, "fraction_inside": 0.9, "margin_mm": 1.0,
                                      "outside_median_mm": 0.3, "outside_p95_mm": 0.5, "outside_max_mm": 0.6,
                                      "size_median_mm": 2.2, "description": "every friction direction",
                                      "coefficients": {"mu_1": 0.21}, "label": "fitted"}]},
        "prediction_check": {"n_samples": 48, "n_units": 12, "history_label": "history-aware", "confidence": 0.95,
                             "standard": _model(2.0, 4.0, 5.0), "history": _model(1.2, 2.5, 3.1),
                             "difference_mm": _interval(-0.8, -1.1, -0.5), "history_beats_standard": True,
                             "method": "t-interval of the paired differences"},
        "bound": {"definition": "e <= b + m", "method": "split-conformal", "target": 0.9, "factor": 1.3,
                  "margin_mm": 1.0, "noise_multiple": 2.0, "noise_rms_mm": 0.5, "n_calibration": 60,
                  "test": _coverage(48, 0.9, 0.86, 0.97, 12), "raw_test": _coverage(48, 0.7, 0.55, 0.85, 12),
                  "translation_last": _coverage(30, 0.8, 0.6, 0.95, 8, mm=False), "failing": False, "status": "shown",
                  "conservative": False, "confidence": 0.95, "tolerance": 0.05,
                  "calibration": {"factor_ci": [1.1, 1.6], "coverage_ci": [0.84, 0.95], "n_units": 40}},
        "updated_model_file": "/data/out/pair-friction.toml", "updated_model": "friction", "reproduced": True,
        "reproduced_samples": 48, "reproduced_position_mean_mm": 1.2, "cautions": [], "seconds": 3600.0,
        "stage_seconds": {"setup": 2.0, "split": 0.5, "baseline": 600.0, "signature_tests": 30.0, "noise_check": 1.5,
                          "contact_baseline": 300.0, "candidate:friction": 1800.0, "candidate:offplane": 240.0,
                          "naming": 0.1, "second_effect": 400.0, "test_split": 60.0, "prediction": 90.0,
                          "bound": 50.0, "updated_model": 20.0, "cautions": 0.0},
        "stage_reused": {"baseline": "reused", "candidate:friction": "partly reused"},
    }


def _write(monkeypatch, out, results) -> str:
    """``write_report`` of ``results`` into ``out`` (its ``results_dict`` and plots replaced);
    the text of report.md."""
    monkeypatch.setattr(report, "results_dict", lambda result: copy.deepcopy(results))
    monkeypatch.setattr(report, "_plots", lambda result, out: [])
    report.write_report(object(), out)
    return (out / "report.md").read_text()


def _set(results, path, value):
    """``results`` with the item at ``path`` (keys separated by ``/``; list indices as numbers) set."""
    keys = [int(k) if k.isdigit() else k for k in path.split("/")]
    node = results
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    return results


def test_a_translation_last_coverage_over_one_unit_has_an_undefined_interval(monkeypatch, tmp_path):
    """The translation-last bound's test samples (10) all in one unit: its coverage interval is
    (None, None) (``coverage_figures``). The report says the interval is undefined over one unit,
    prints the rest of the bound's row and of the report, and results.json keeps the ends null.
    Catches the formatter that multiplied the interval's None ends and lost report.md after an
    hour's run."""
    results = _set(_results(), "bound/translation_last", _coverage(10, 0.8, None, None, 1, mm=False))
    text = _write(monkeypatch, tmp_path, results)
    assert ("| translation-last bound + m (after a final translation of every pair) | 10 | "
            "80 % (interval undefined: one unit) | 0.60 / 0.90 / 1.30 | 5.00 |") in text
    assert text.rstrip().endswith("## Plots") and "could not be written" not in text
    assert json.loads((tmp_path / "results.json").read_text())["bound"]["translation_last"]["ci"] == [None, None]


def _bound_verdict(text: str) -> str:
    """The line of report.md that states the calibrated bound's test coverage and status."""
    return next(line for line in text.splitlines() if line.startswith("Calibrated bound:"))


BOUND_STATUSES = [
    # (what, test coverage, status, conservative, text of the status line)
    ("shown", _coverage(48, 0.9, 0.86, 0.97, 12), "shown", False,
     "coverage of the test split's tips 90 % (95 % interval 86-97 %, 12 units): shown (the interval's lower end "
     "is at or above the target less 5 points)."),
    ("not shown", _coverage(48, 0.9, 0.62, 1.0, 5), "not shown", False,
     "90 % (95 % interval 62-100 %, 5 units): not shown (the interval reaches below the target less 5 points)."),
    ("failed", _coverage(48, 0.5, 0.42, 0.58, 20), "failed", False,
     "50 % (95 % interval 42-58 %, 20 units): **failed** (the interval's upper end is below the target less 5 "
     "points)."),
    ("one unit", _coverage(10, 0.9, None, None, 1), "not shown", False,
     "90 % (interval undefined: one unit): not shown (without an interval)."),
    ("no samples", {**_coverage(0, None, None, None, 0), "ratio": dict.fromkeys(("median", "p90", "p95", "max"))},
     "not shown", False, "undefined (no samples): not shown (without an interval)."),
    ("conservative", _coverage(120, 1.0, 1.0, 1.0, 12), "shown", True,
     "100 % (95 % interval 100-100 %, 12 units): shown (the interval's lower end is at or above the target less 5 "
     "points); conservative: the interval lies wholly above the target plus 5 points"),
]


@pytest.mark.parametrize("what, test, status, conservative, expected", BOUND_STATUSES,
                         ids=[b[0] for b in BOUND_STATUSES])
def test_the_calibrated_bound_is_reported_with_its_interval_and_status(monkeypatch, tmp_path, what, test, status,
                                                                       conservative, expected):
    """The calibrated bound's test coverage prints with its interval, level and units, and its
    status ("shown", "not shown" or "failed", with the rule that gave it); an undefined interval
    (one unit, no samples) prints "undefined" with its reason, never "nan" or "0 %". Catches a
    report that prints a status without the interval it rests on, and the former wording ("met")
    for a coverage whose interval reaches far below the target."""
    results = _results()
    results["bound"].update(test=test, status=status, failing=status == "failed", conservative=conservative)
    line = _bound_verdict(_write(monkeypatch, tmp_path, results))
    assert expected in line, line
    assert " met " not in line and not re.search(r"\bnan\b", line)


def test_a_results_json_of_the_former_status_rule_still_makes_a_report(monkeypatch, tmp_path):
    """A results.json written under the former rule (status "met", no confidence, tolerance,
    conservative flag or factor spread): the report is written, says the status is the earlier
    version's, and prints no spread line. Catches a report that needs the new keys."""
    results = _results()
    for key in ("conservative", "confidence", "tolerance", "calibration"):
        del results["bound"][key]
    results["bound"]["status"] = "met"
    text = _write(monkeypatch, tmp_path, results)
    assert "(interval 86-97 %, 12 units): met (as judged by an earlier version)." in _bound_verdict(text)
    assert "resampled development units" not in text and "could not be written" not in text


def test_the_factor_spread_is_reported(monkeypatch, tmp_path):
    """The factor's spread over resampled development units prints with its units, and says the
    conformal guarantee's assumption. Catches a spread that results.json holds and the report
    leaves out."""
    text = _write(monkeypatch, tmp_path, _results())
    assert ("Over resampled development units (40 units) the factor ranges 1.1-1.6, and a factor calibrated on "
            "another draw of such units covers 84-95 % of the development tips (the conformal guarantee assumes "
            "exchangeable scores") in text


def test_bound_dict_keeps_the_former_keys_and_adds_the_new_ones():
    """:func:`~ctrplan.discrepancy.outputs.results.bound_dict` of a calibrated bound: the former keys
    (``failing``, ``status``, ``test`` with ``ci``...) with ``status`` one of the three and
    ``failing`` True exactly when "failed", plus ``conservative``, ``confidence``, ``tolerance``
    and ``calibration``; JSON-serializable without NaN. Catches a renamed key that breaks readers
    of results.json, and a ``failing`` that disagrees with the status."""
    import numpy as np

    from ctrplan.discrepancy.verdict.coverage import BoundSamples, calibrate_bound

    cal_e = np.linspace(0.01, 0.99, 99)
    for covered in (np.arange(200) % 10 < 9, np.arange(200) % 2 == 0, np.arange(200) % 10 < 7):
        b = calibrate_bound(BoundSamples(cal_e, np.ones(99), np.repeat(np.arange(33), 3)),
                            BoundSamples(np.where(covered, 0.5, 0.95), np.ones(200), np.repeat(np.arange(20), 10)),
                            noise_rms=1e-4)
        d = results_json.bound_dict(b)
        assert {"definition", "method", "target", "factor", "margin_mm", "noise_multiple", "noise_rms_mm",
                "n_calibration", "test", "raw_test", "translation_last", "failing", "status"} <= set(d)
        assert d["status"] in ("shown", "not shown", "failed") and d["failing"] == (d["status"] == "failed")
        assert d["confidence"] == 0.95 and d["tolerance"] == 0.05 and d["calibration"]["n_units"] == 33
        assert d["test"]["ci"] == list(b.test.ci) and "NaN" not in json.dumps(d)


UNDEFINED_FIGURES = [
    # (what, path in results.json, value, text of report.md)
    ("test split mean over one unit", "test_split/figures/after/mean_mm", _interval(1.2, NAN, NAN, 1),
     "1.20 (interval undefined: one unit) mm with friction"),
    ("test split shrink over one unit", "test_split/figures/shrink/mean", _interval(0.4, NAN, NAN, 1),
     "(shrink 40 % (interval undefined: one unit))"),
    ("test split without samples", "test_split/figures/after",
     {"mean_mm": _interval(NAN, NAN, NAN, 0), "p95_mm": None, "max_mm": None},
     "undefined (no samples) mm with friction"),
    ("comparison over one fold", "candidates/offplane/improvement_eq49", _comparison(NAN, NAN, NAN, 1.0, 1),
     "| 1.800 / 4.000 | undefined (one fold) | 1 | no | no |"),
    ("p-value missing", "candidates/friction/improvement_eq49/p_value", None, "% (30..52 %) | undefined | yes |"),
    ("parameter of a failed fit", "candidates/friction/parameter_table/0",
     _parameter("mu_1", None, "-", None), "| friction (Coulomb, along the motion) | mu_1 = undefined |"),
    ("NaN parameter and standard error", "candidates/friction/parameter_table/0",
     _parameter("mu_1", NAN, "-", NAN), "mu_1 = undefined (standard error undefined (fewer than two clusters of "
                                        "units)) |"),
    ("infinite standard error", "candidates/friction/parameter_table/0",
     _parameter("mu_1", 0.2, "-", float("inf")), "mu_1 = 0.2 (not determined by the data) |"),
    ("signature test p-value missing", "signature_tests/friction/p_value", None, "| friction | 0.800 | undefined |"),
    ("noise ratio missing", "noise/ratio", None, "1.900 mm = undefined x the noise"),
    ("prior choice mean missing", "baseline/prior_choices/1/mean_position_m", None,
     "| 0.03 (chosen) | undefined | 2.400 |"),
    ("prediction row without samples", "prediction/rows/1",
     {"label": "history-aware", "n": 0, "mean_mm": None, "p95_mm": None, "max_mm": None},
     "| history-aware | 0 | undefined (no samples) | undefined (no samples) | undefined (no samples) |"),
    ("envelope without samples", "prediction/envelopes/0/fraction_inside", NAN,
     "18 of 20 measured tips (undefined (no samples)) lie inside"),
    ("prediction difference over one unit", "prediction_check/difference_mm", _interval(-0.8, NAN, NAN, 1),
     "-0.80 (interval undefined: one unit) mm"),
    ("calibrated coverage over one unit", "bound/test", _coverage(10, 0.9, None, None, 1),
     "| 10 | 90 % (interval undefined: one unit) |"),
    ("calibrated coverage over two units", "bound/test", _coverage(20, 0.9, None, None, 2),
     "| 20 | 90 % (interval undefined: 2 units, fewer than 3) |"),
    ("factor spread over two units", "bound/calibration", {"factor_ci": [None, None], "coverage_ci": [None, None],
                                                           "n_units": 2},
     "the factor's spread is undefined (2 units, fewer than 3)."),
    ("raw coverage without samples", "bound/raw_test",
     {"n": 0, "covered": None, "ci": [None, None], "n_units": 0,
      "ratio": {"median": None, "p90": None, "p95": None, "max": None}, "bound_median_m": None,
      "error_median_m": None, "bound_median_mm": None},
     "| friction bound b + m | 0 | undefined (no samples) | undefined (no samples) / undefined (no samples) / "
     "undefined (no samples) | undefined (no samples) |"),
    ("ratio with undefined quantiles", "bound/test/ratio", {"median": 0.6, "p90": None, "p95": None, "max": None},
     "| 0.60 / undefined / undefined |"),
    ("reverse comparison p-value missing", "combination/tried/clearance/reverse/p_value", None,
     "| 30 % (20..40 %), undefined | no |"),
    ("reproduced mean undefined", "reproduced_position_mean_mm", NAN, "(mean undefined mm over 48 samples)"),
    ("stage time missing", "stage_seconds/naming", None, "| naming | undefined | undefined | - |"),
    ("total time missing", "seconds", None, "| total | undefined | undefined | - |"),
]


@pytest.mark.parametrize("what, path, value, expected", UNDEFINED_FIGURES, ids=[u[0] for u in UNDEFINED_FIGURES])
def test_an_undefined_figure_is_printed_as_undefined(monkeypatch, tmp_path, what, path, value, expected):
    """Each figure the data can leave undefined prints as "undefined" (with the reason where the
    results give one), and the rest of the report is written. Catches a formatter that raises on
    None, or prints "nan", "-" or "- % (-..- %)" where a figure is undefined."""
    text = _write(monkeypatch, tmp_path, _set(_results(), path, value))
    assert expected in text
    assert not re.search(r"\bnan\b", text, re.IGNORECASE) and "could not be written" not in text
    assert text.rstrip().endswith("## Plots")


def test_where_the_time_went_is_a_table_of_seconds_and_shares(monkeypatch, tmp_path):
    """``stage_seconds`` in results.json (seconds, in the run's order) is the table "Where the
    time went": each stage's wall time and share of the run's total, a candidate under its label,
    the stages that read stored results of an earlier run marked, and the rest of the total as
    time between the stages. Catches a table that loses the run's order or takes its shares of
    the stages' sum rather than of the total."""
    text = _write(monkeypatch, tmp_path, _results())
    table = text[text.index("## Where the time went"):text.index("## Plots")]
    rows = [r for r in table.splitlines() if r.startswith("| ") and not r.startswith("| stage")]
    assert rows[0] == "| setup: robot, data, effects, stage store | 2.0 | 0.1 % | - |"
    assert "| pilot fit and baseline calibration | 600.0 | 16.7 % | reused |" in rows
    assert "| naming | 0.100 | 0.0 % | - |" in rows       # under a second: to the millisecond
    assert rows[6:8] == ["| candidate friction (Coulomb, along the motion) | 1800.0 | 50.0 % | partly reused |",
                         "| candidate off-plane precurvature | 240.0 | 6.7 % | - |"]
    assert rows[-2:] == ["| between the stages | 5.9 | 0.2 % | - |", "| total | 3600.0 | 100 % | - |"]
    assert len(rows) == len(_results()["stage_seconds"]) + 2
    assert json.loads((tmp_path / "results.json").read_text())["stage_seconds"]["candidate:friction"] == 1800.0


def test_a_results_json_without_stage_seconds_still_makes_a_report(monkeypatch, tmp_path):
    """A results.json written before it held ``stage_seconds`` and ``stage_reused``: the report
    is written, without the table, and still says the total time. Catches a formatter that
    needs the new keys."""
    results = _results()
    del results["stage_seconds"], results["stage_reused"]
    text = _write(monkeypatch, tmp_path, results)
    assert "Where the time went" not in text and "could not be written" not in text
    assert "Total time 3600 s." in text and text.rstrip().endswith("## Plots")


def test_the_report_is_written_again_from_results_json(monkeypatch, tmp_path):
    """With some figures undefined: ``write_report_from_results`` and ``ctrplan discrepancy-report
    OUT`` write report.md again from results.json alone, the same text; plots listed in
    results.json that left the folder are named as missing. Catches a report that needs the run's
    objects (the no-effect sentence, the plots) and can only be written at the end of a run."""
    results = _results()
    _set(results, "bound/translation_last", _coverage(10, 0.8, None, None, 1, mm=False))
    _set(results, "candidates/offplane/improvement_eq49", _comparison(NAN, NAN, NAN, 1.0, 1))
    _set(results, "decision", {**results["decision"], "verdict": "none", "named": None, "no_effect_case": "noise"})
    _set(results, "noise/test/statistic", 1.1)

    def plots(result, out):
        (out / "error_histograms.png").write_bytes(b"png")
        return ["error_histograms.png"]

    monkeypatch.setattr(report, "_plots", plots)
    monkeypatch.setattr(report, "results_dict", lambda result: copy.deepcopy(results))
    report.write_report(object(), tmp_path)
    first = (tmp_path / "report.md").read_text()
    assert ("**No effect named.** no candidate is eligible, and the out-of-fold residual of the calibrated baseline "
            "(rms 1.900 mm) is consistent with the sensor noise (0.5 mm rms, stated; F = 1.1 <= 1.3") in first
    assert "![error_histograms.png](error_histograms.png)" in first
    (tmp_path / "report.md").unlink()
    paths = report.write_report_from_results(tmp_path)
    assert Path(paths["markdown"]).read_text() == first and paths["plots"] == ["error_histograms.png"]
    (tmp_path / "report.md").unlink()
    res = CliRunner().invoke(cli.main, ["discrepancy-report", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "report.md").read_text() == first and f"report: {tmp_path / 'report.md'}" in res.output
    (tmp_path / "error_histograms.png").unlink()
    again = report.write_report_from_results(tmp_path)
    text = Path(again["markdown"]).read_text()
    assert again["plots"] == [] and "Not in the report folder: error_histograms.png" in text
    assert "![error_histograms.png]" not in text


def test_the_reasons_of_the_verdict_are_put_in_words_from_their_kinds_and_numbers(monkeypatch, tmp_path):
    """results.json stores why nothing was named as kinds and numbers (the noise test's case, its
    F and threshold, the best candidate's reasons with their p values); the report says it in
    words with those figures (mm), the rule with its levels and the notes with their labels; an
    inconclusive noise test (a noise that is only a lower bound) without "the model misses
    something". Catches a report that drops a figure, mixes up the cases or prints an effect's
    name where its label belongs."""
    results = _results()
    _set(results, "decision", {**results["decision"], "verdict": "none", "named": None, "best": "offplane",
                               "no_effect_case": "unexplained"})
    _set(results, "candidates/offplane/fit_notes", [
        {"kind": "not converged", "development": True, "folds": [2, 4]},
        {"kind": "overfits", "cost": 12.5, "baseline_cost": 13.0, "mean_m": 1.9e-3, "baseline_mean_m": 1.8e-3}])
    text = _write(monkeypatch, tmp_path, results)
    assert ("- off-plane precurvature: its fit did not converge (stopped at the evaluation budget): the development "
            "fit, fold 2, fold 4; it fits the calibration data better (cost 12.5 against 13) but the held-out folds "
            "worse (mean 1.900 against 1.800 mm)") in text
    assert ("**No effect named.** the out-of-fold residual of the calibrated baseline (rms 1.900 mm, 3.8 times the "
            "sensor noise: 0.5 mm rms, stated) is NOT consistent with noise (F = 14.4 > 1.3 at false-alarm rate 0.01, "
            "after allowing for the 5 % a fitted model adds): the model misses something that no candidate explains; "
            "the best explanation is off-plane precurvature (out-of-fold mean 1.800 mm), not named: its improvement "
            "over the baseline is not significant (p = 0.031, Holm over 2 candidates at 0.05).") in text
    assert ("Rule: out-of-fold improvement over the baseline significant at 0.05 (corrected resampled t test of the "
            "log ratios over 5 folds, Holm over the 2 candidates tried)") in text
    assert ("- the lowest out-of-fold error is off-plane precurvature's, which cannot be named: its improvement over "
            "the baseline is not significant (p = 0.031, Holm over 2 candidates at 0.05).") in text
    assert ("- not tried: off-plane precurvature, because alone it does not lower the baseline's out-of-fold error "
            "(mean difference -0.02 mm + deg): counted in the family, not fitted.") in text
    assert (f"Rule: out-of-fold Eq. (49) improvement over {results['candidates']['friction']['label']} alone "
            "significant at 0.05 (corrected resampled t test of the log ratios over the folds, Holm over the family of "
            "pairs)") in text
    _set(results, "decision", {**results["decision"], "no_effect_case": "inconclusive"})
    text = _write(monkeypatch, tmp_path, results)
    assert ("**No effect named.** no candidate is eligible; the out-of-fold residual of the calibrated baseline (rms "
            "1.900 mm) exceeds the sensor noise (F = 14.4 > 1.3), but that noise is only a lower bound (0.5 mm rms, "
            "stated): the noise test is inconclusive") in text
    assert "the model misses something that no candidate explains" not in text


def test_a_results_json_of_an_earlier_ctrplan_with_sentences_still_makes_a_report(monkeypatch, tmp_path):
    """A results.json from an earlier ctrplan stored the reasons as sentences (the no-effect
    sentence, notes, rule, cautions): the report prints them as they are. Catches a report that
    can no longer read the results folders its users already have."""
    results = _results()
    results["no_effect_sentence"] = "no candidate is eligible, and the residual is consistent with the sensor noise"
    _set(results, "decision", {**results["decision"], "verdict": "none", "named": None, "no_effect_case": "noise",
                               "notes": ["offplane: not significant"], "rule": "the lowest error among the eligible"})
    results["cautions"] = ["baseline registration_tx = 4 mm: at its bound"]
    text = _write(monkeypatch, tmp_path, results)
    assert "**No effect named.** no candidate is eligible, and the residual is consistent with the sensor noise." in text
    assert "Rule: the lowest error among the eligible." in text and "- offplane: not significant." in text
    assert "- baseline registration_tx = 4 mm: at its bound." in text


def test_plots_that_cannot_be_made_leave_a_note(monkeypatch, tmp_path, caplog):
    """The plots raise: results.json and report.md are written, the report says why there are no
    plots, and a warning is logged. Catches plots made before results.json, whose failure lost
    every file of the report."""
    def broken(result, out):
        raise ValueError("bins must increase monotonically")

    monkeypatch.setattr(report, "results_dict", lambda result: _results())
    monkeypatch.setattr(report, "_plots", broken)
    with caplog.at_level(logging.WARNING, logger="ctrplan.discrepancy.outputs.report"):
        paths = report.write_report(object(), tmp_path)
    assert paths["plots"] == []
    assert json.loads((tmp_path / "results.json").read_text())["plots_error"] == (
        "ValueError: bins must increase monotonically")
    assert "No plots: they could not be made (ValueError: bins must increase monotonically)" in (
        tmp_path / "report.md").read_text()
    assert any("plots not made" in m for m in caplog.messages)


def test_a_missing_results_json_is_a_data_file_error(tmp_path):
    """``ctrplan discrepancy-report`` of a folder without results.json stops with a message that
    names the file (exit status 2, no traceback)."""
    from ctrplan.errors import DataFileError

    with pytest.raises(DataFileError, match="results.json: not found"):
        report.write_report_from_results(tmp_path)
    (tmp_path / "results.json").write_text("{not json")
    with pytest.raises(DataFileError, match="not readable as JSON"):
        report.write_report_from_results(tmp_path)


@pytest.mark.parametrize("fails", ["report.md", "results.json"])
def test_a_report_that_cannot_be_written_says_how_to_write_it(monkeypatch, tmp_path, fails):
    """``ctrplan discrepancy`` after the run: writing ``fails`` raises (a full disk). The command
    ends without a traceback (exit status 1) and says what is written and how to write the report:
    ``ctrplan discrepancy-report OUT`` once results.json is on disk, the same command otherwise.
    Catches a run whose hour of results ends in a traceback, and a retry that needs the run
    again when its results are on disk."""
    from ctrplan.discrepancy import workflow

    out = tmp_path / "out"
    data = tmp_path / "run.csv"
    data.write_text("t\n0\n")
    fake = SimpleNamespace(updated_model_file=out / "pair-friction.toml", seconds=3600.0)
    monkeypatch.setattr(workflow, "run_discrepancy", lambda *a, **k: fake)
    monkeypatch.setattr(report, "results_dict", lambda result: _results())
    monkeypatch.setattr(report, "_plots", lambda result, out: [])
    write = report.atomic_write_text

    def full_disk(path, text):
        if Path(path).name == fails:
            raise OSError(28, "No space left on device")
        write(path, text)

    monkeypatch.setattr(report, "atomic_write_text", full_disk)
    res = CliRunner().invoke(cli.main, ["discrepancy", "--robot", str(PAIR), "--data", str(data), "--out", str(out),
                                        "--no-progress"])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit), res.output
    assert "Traceback" not in res.output
    assert "the report could not be written (OSError: [Errno 28] No space left on device)" in res.output
    if fails == "report.md":
        assert json.loads((out / "results.json").read_text())["seconds"] == 3600.0
        assert f"write the report from it with: ctrplan discrepancy-report {out}" in res.output
    else:
        assert not (out / "results.json").exists()
        assert "run the same command again to write it (finished stages are reused" in res.output


def _with_fit(results, stderr):
    """``results`` whose named friction fit has free parameters with the standard errors ``stderr``."""
    results["candidates"]["friction"]["fit"] = {"model": "friction", "parameters": {n: 0.1 for n in stderr},
                                                "fixed": {}, "stderr": dict(stderr)}
    return results


def test_parameters_the_recording_leaves_undetermined_get_the_design_command(monkeypatch, tmp_path):
    """A written parameter whose standard error is infinite, or whose 95 % interval is wider than
    its typical range (here 0..0.5: a standard error above 0.5 / 3.92 = 0.1276), is listed with
    the ``ctrplan design`` command of the report's folder; one just inside the range is not, nor is
    one without a typical range. Catches a rule that drops the factor 2 x 1.96 (0.127 listed or
    0.13 left out) and a report that stays silent about what the data left open."""
    stderr = {"mu_1": math.inf, "precurvature_y_1": 0.13, "mu_2": 0.127, "registration_rz": 5.0}
    results = _with_fit(_results(), stderr)
    results["candidates"]["friction"]["parameter_table"].append(_parameter("mu_2", 0.1, "-", 0.127))
    assert report.undetermined_parameters(results) == {"mu_1": "not determined",
                                                       "precurvature_y_1": "wider than typical"}
    text = _write(monkeypatch, tmp_path, results)
    line = next(x for x in text.splitlines() if x.startswith("**Left undetermined by this recording:**"))
    assert "mu_1 (not determined by the data)" in line and "precurvature_y_1 (its 95 % interval" in line
    assert "mu_2" not in line and "registration_rz" not in line
    assert "`ctrplan design --result /data/out --out DESIGN_DIR`" in line


def test_the_undetermined_parameters_are_the_written_models(monkeypatch, tmp_path):
    """The parameters listed are those of the model the robot file gets: the named pair's fit when a
    second effect is named, the baseline's when nothing is, none when the verdict is ambiguous (the
    ambiguous verdict prints its own design command). Catches a list taken from a fit that is not
    written."""
    results = _with_fit(_results(), {"mu_1": math.inf})
    results["combination"]["named"] = "clearance"
    results["combination"]["tried"]["clearance"]["fit"] = {"parameters": {"clearance_2": 1e-4}, "fixed": {},
                                                           "stderr": {"clearance_2": math.inf}}
    assert report.undetermined_parameters(results) == {"clearance_2": "not determined"}
    results = _with_fit(_results(), {"mu_1": math.inf})
    results["decision"]["verdict"] = results["verdict"] = "none"
    results["named_effect"] = None
    results["baseline"]["fit"]["stderr"] = {"precurvature_y_1": 1.0}
    assert report.undetermined_parameters(results) == {"precurvature_y_1": "wider than typical"}
    results["decision"]["verdict"] = "ambiguous"
    assert report.undetermined_parameters(results) == {}
    ok = _results()
    assert "Left undetermined" not in _write(monkeypatch, tmp_path, ok)
