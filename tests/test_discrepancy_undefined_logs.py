"""Log lines of the discrepancy workflow's stages never stop a run at a figure the data leave
undefined: the test split with no finite sample or in one unit, a prediction row with no finite
error, a bound's coverage over one unit or no sample. Each prints "undefined" (never "nan" and
never a made-up 0 %), and the stage returns its result with the figure carried as None or NaN.

The stages are called with constructed inputs (their model evaluations replaced by errors made
here), so nothing is simulated; a run of the workflow is in tests/test_discrepancy_workflow.py.
"""

from __future__ import annotations

import logging
import re
from types import SimpleNamespace

import numpy as np
import pytest

from ctrplan.discrepancy.outputs import output
from ctrplan.discrepancy.verdict import coverage, envelope
from ctrplan.discrepancy.fits.evaluation import Errors
from ctrplan.discrepancy.outputs.logtext import figure, interval

NAN = float("nan")


def _errors(position) -> Errors:
    """Errors at ``len(position)`` test samples [m] (angles equal to them, residuals zero)."""
    p = np.asarray(position, float)
    return Errors(rows=np.arange(p.size), position=p, angle=p.copy(), residual_base=np.zeros((p.size, 3)),
                  tip_base=np.zeros((p.size, 3)), seconds=0.0)


def _no_nan(text: str) -> bool:
    return not re.search(r"\bnan\b", text, re.IGNORECASE)


def test_figures_and_intervals_print_undefined_for_none_and_nan():
    """The formatting helpers: a finite figure in the printed unit, None / NaN / inf as
    "undefined", an interval with a missing end as "undefined"."""
    assert figure(0.00123, ".3f", 1e3, " mm") == "1.230 mm"
    assert figure(None, ".3f", 1e3, " mm") == figure(NAN, ".3f") == figure(float("inf"), ".2f") == "undefined"
    assert interval(0.3, 0.5, ".0f", 100, " %") == "30..50 %"
    assert interval(None, 0.5, ".0f", 100, " %") == interval(NAN, NAN, ".0f") == "undefined"


@pytest.fixture
def test_split_stage(monkeypatch):
    """``evaluate_test_split`` with nothing named, on test samples in ``units`` whose models'
    errors are ``errors`` (the robot file's and the baseline's, which is the final model; one array
    each, [m])."""
    def run(errors, units):
        it = iter(errors)
        monkeypatch.setattr(output, "evaluate_rows", lambda *a, **k: _errors(next(it)))
        test = np.ones(len(units), bool)
        split = SimpleNamespace(test_rows=test, units=np.asarray(units), n_test=int(test.sum()))
        baseline = SimpleNamespace(file_cv=SimpleNamespace(params={}), params={})
        naming = SimpleNamespace(named=None, verdict="none", candidates={})
        return output.evaluate_test_split(None, split, baseline, naming, None, SimpleNamespace(n_jobs=1))

    return run


def test_a_test_split_without_a_finite_sample_logs_undefined_and_returns(test_split_stage, caplog):
    """Every test sample failed for the robot file (NaN errors): the means and maxima are
    undefined, the stage logs "undefined" and returns its figures with them None / NaN. Catches
    the log line that multiplied the maximum (None) by 1e3 and ended the run before results.json
    was written."""
    nan4 = np.full(4, NAN)
    with caplog.at_level(logging.INFO, logger="ctrplan.discrepancy"):
        res = test_split_stage([nan4, np.full(4, 1e-3)], [0, 0, 1, 1])
    assert res.figures.n_samples == 0 and res.figures.before.max is None
    assert np.isnan(res.figures.after.mean.value)
    line = next(m for m in caplog.messages if m.startswith("test split"))
    assert "robot file with a registration undefined" in line and "max undefined -> undefined" in line
    assert _no_nan(line), line


def test_a_test_split_in_one_unit_logs_an_undefined_interval(test_split_stage, caplog):
    """All test samples in one unit: the means are defined, their intervals are not; the line
    says "interval undefined". Catches the line that printed "nan..nan %"."""
    with caplog.at_level(logging.INFO, logger="ctrplan.discrepancy"):
        res = test_split_stage([np.full(4, 3e-3), np.full(4, 2e-3)], [7, 7, 7, 7])
    assert res.figures.n_units == 1 and np.isnan(res.figures.shrink.low)
    line = next(m for m in caplog.messages if m.startswith("test split"))
    assert "calibrated baseline 2.000 mm (shrink 33 %, interval undefined)" in line
    assert "(nothing named) 2.000 mm (shrink 0 %, 95% interval undefined); max 2.00 mm -> 2.00 mm" in line
    assert _no_nan(line), line


def test_a_prediction_row_without_a_finite_error_logs_undefined_and_is_carried(monkeypatch, caplog):
    """Stage 9 where every history-aware evaluation on the test split failed (NaN errors): the
    rows are returned with their NaN errors (results.json then holds null figures) and the log
    says "undefined". Catches ``np.percentile`` of an empty row, which raised IndexError mid-run."""
    from ctrplan.discrepancy.fits import evaluation

    assert envelope.evaluate_rows is evaluation.evaluate_rows
    monkeypatch.setattr(envelope, "evaluate_rows",
                        lambda setup, rows, stage, model, params, **k: _errors(
                            np.full(3, 1e-3) if model == "standard" else np.full(3, NAN)))
    data = SimpleNamespace(take=lambda rows: SimpleNamespace(n_samples=int(np.sum(rows))))
    setup = SimpleNamespace(data=data, robot=SimpleNamespace(friction_coefficients=(0.2,), n_tubes=2))
    friction = SimpleNamespace(shown={"mu_1": 0.2}, model="friction", params={"mu_1": 0.2}, label="friction")
    naming = SimpleNamespace(candidates={"friction": friction}, named=None)
    options = SimpleNamespace(n_jobs=1, reference_friction=None, envelope_samples=0)
    split = SimpleNamespace(test_rows=np.ones(3, bool))
    with caplog.at_level(logging.INFO, logger="ctrplan.discrepancy"):
        pred = envelope.predict_with_history(setup, split, SimpleNamespace(params={}), naming, None, options)
    assert len(pred.rows) == 3 and np.isnan(pred.rows[1][1]).all()
    lines = [m for m in caplog.messages if "prediction:" in m]
    assert "mean 1.000, p95 1.000, max 1.000 mm (3 samples)" in lines[0]
    assert lines[1].endswith("mean, p95 and max undefined (no finite error of 3)") and _no_nan(lines[1])
    from ctrplan.discrepancy.outputs.results import _prediction_dict

    assert _prediction_dict(pred)["rows"][1] == {"label": pred.rows[1][0], "n": 0, "mean_mm": None,
                                                 "p95_mm": None, "max_mm": None}


def test_a_bound_coverage_over_one_unit_logs_an_undefined_interval():
    """The bound's test samples all in one unit: the coverage interval's ends are None, and the
    log line says "interval undefined" (not "0..0 %"); with no finite test sample the shares
    are "undefined" (not "0 %"). Catches the ``or 0`` that turned an undefined interval into a
    certain 0 %."""
    rng = np.random.default_rng(3)
    cal_b = rng.uniform(1e-3, 3e-3, 40)
    cal_e = cal_b * rng.uniform(0.2, 1.2, 40)
    test_b = rng.uniform(1e-3, 3e-3, 10)
    cal = coverage.calibrate_bound(coverage.BoundSamples(cal_e, cal_b),
                                   coverage.BoundSamples(test_b * 0.5, test_b, np.zeros(10, int)), noise_rms=0.2e-3)
    assert cal.test.ci == (None, None) and cal.test.covered == 1.0
    line = coverage._bound_line((0.2,), cal)
    assert "covers 100 % (interval undefined, target 90 %" in line and "0..0 %" not in line and _no_nan(line)

    none = coverage.calibrate_bound(coverage.BoundSamples(cal_e, cal_b),
                                    coverage.BoundSamples(np.full(10, NAN), test_b, np.zeros(10, int)), noise_rms=0.2e-3)
    assert none.test.covered is None and none.raw_test.n == 0
    line = coverage._bound_line((0.2,), none)
    assert line.startswith("friction bound (mu = 0.2) on the test split: undefined of 0 measured tips")
    assert "(median e / (b + m) undefined)" in line and "covers undefined (interval undefined" in line
    assert " 0 %" not in line and _no_nan(line)
