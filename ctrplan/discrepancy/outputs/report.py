"""Report folder of the discrepancy workflow: ``report.md``, ``results.json`` and PNG plots.

The report formats a run's typed results (:class:`~ctrplan.discrepancy.workflow.DiscrepancyResult`,
SI units) for people, who read millimetres and degrees; it computes no figure of its own. This is
the one module of the workflow that turns results into report units: ``results.json`` keeps SI
values where the key says so (``_m``, ``_rad``, or no unit suffix) and millimetres / degrees
where the key says ``_mm`` / ``_deg`` (:func:`ctrplan.discrepancy.outputs.results.results_dict`).

``report.md`` is formatted from ``results.json`` alone, which is written first: a report that
could not be written is written again from it (:func:`write_report_from_results`,
``ctrplan discrepancy-report OUT``). A figure the data leave undefined (an interval over one
unit, a mean over no samples, a comparison over one fold, a failed fit's parameter) is null or
NaN in ``results.json`` and printed as "undefined", with the reason where the results give one.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np

from ...errors import DataFileError
from ...io.atomic import atomic_write_text
from ...io.ros2 import describe_bag_summary
from ..verdict.coverage import COVERAGE_TOLERANCE, MIN_UNITS
from ..fits.estimates import display_value
from .logtext import UNDEFINED, defined  # how the report prints a figure the data leave undefined (null or NaN)
from ..options import CONFIDENCE
from .results import json_default, results_dict
from .report_plots import write_plots as _plots
from . import words

__all__ = ["write_report", "write_report_from_results", "report_markdown", "undetermined_parameters", "TABLE_VIII",
           "UNDEFINED"]

logger = logging.getLogger(__name__)

#: The paper's gain with its friction model on its own grid data (Table VIII of Ha et al. 2019):
#: relative fall of the mean and of the maximum tip position error.
TABLE_VIII = {"mean": 0.46, "max": 0.49}


#: The command that writes ``report.md`` again from ``results.json`` (``{out}``: the report folder).
REWRITE_COMMAND = "ctrplan discrepancy-report {out}"


def _number(x) -> float | None:
    """``x`` as a float (infinities kept), or None where it is no number or NaN (an undefined figure)."""
    return defined(x, finite=False)


def _undefined(reason: str | None = None) -> str:
    """``undefined`` or ``undefined (reason)``."""
    return UNDEFINED if not reason else f"{UNDEFINED} ({reason})"


def _count_reason(n, what: str) -> str | None:
    """Why a figure over ``n`` units (or folds, ...) is undefined: none, or one (``n`` < 2)."""
    n = _number(n)
    if n is None or n >= 2:
        return None
    return f"no {what}s" if n < 1 else f"one {what}"


def _num(x, spec: str = ".2f", reason: str | None = None) -> str:
    """``x`` formatted by ``spec``; :data:`UNDEFINED` (with ``reason``) for None or NaN, ``inf``
    for an infinite value."""
    v = _number(x)
    return _undefined(reason) if v is None else format(v, spec)


def _fmt(x, nd=2, reason: str | None = None):
    """A figure with ``nd`` decimals (:func:`_num`)."""
    return _num(x, f".{nd}f", reason)


def _ends(ci) -> tuple:
    """The finite ends ``(low, high)`` of an interval ``[low, high]``; (None, None) where either
    is missing, null or not finite."""
    try:
        lo, hi = (_number(v) for v in ci)
    except (TypeError, ValueError):
        return None, None
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return None, None
    return lo, hi


def _interval_text(lo, hi, scale: float, nd: int, reason: str | None, suffix: str = "") -> str:
    """``(low..high)`` times ``scale``, or ``(interval undefined: reason)`` without finite ends."""
    if lo is None:
        return f"(interval {UNDEFINED}: {reason})" if reason else f"(interval {UNDEFINED})"
    return f"({lo * scale:.{nd}f}..{hi * scale:.{nd}f}{suffix})"


def _ci(d, nd=2, scale=1.0, unit=""):
    """``value (low..high)`` of a ``{"value", "ci", "n_units"}`` dict; an undefined value or
    interval says so, and why where its unit count tells (none, or one unit)."""
    d = d or {}
    why = _count_reason(d.get("n_units"), "unit")
    value = _number(d.get("value"))
    if value is None or not math.isfinite(value):
        return _undefined("no samples" if _number(d.get("n_units")) == 0 else why)
    lo, hi = _ends(d.get("ci"))
    return f"{value * scale:.{nd}f}{unit} {_interval_text(lo, hi, scale, nd, why)}"


def _pct(cmp: dict) -> str:
    """The reduction of a :func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison` in % with its interval."""
    cmp = cmp or {}
    why = _count_reason(cmp.get("n_folds"), "fold")
    value = _number(cmp.get("reduction"))
    if value is None or not math.isfinite(value):
        return _undefined(why)
    lo, hi = _ends(cmp.get("reduction_ci"))
    return f"{100 * value:.0f} % {_interval_text(lo, hi, 100, 0, why, ' %')}"


def _coverage_reason(d) -> str | None:
    """Why a :class:`~ctrplan.discrepancy.verdict.coverage.Coverage` dict's interval is undefined: none,
    no samples, or too few units for the bootstrap (fewer than
    :data:`~ctrplan.discrepancy.verdict.coverage.MIN_UNITS`)."""
    if not d.get("n"):
        return "no samples"
    n = _number(d.get("n_units"))
    if n is None or n >= MIN_UNITS:
        return None
    return "no units" if n < 1 else "one unit" if n < 2 else f"{n:.0f} units, fewer than {MIN_UNITS}"


def _share(d) -> str:
    """A :class:`~ctrplan.discrepancy.verdict.coverage.Coverage` dict's covered share in % with its
    interval (ends None over fewer than :data:`~ctrplan.discrepancy.verdict.coverage.MIN_UNITS` units)."""
    d = d or {}
    why = _coverage_reason(d)
    value = _number(d.get("covered"))
    if value is None:
        return _undefined("no samples" if not d.get("n") else why)
    lo, hi = _ends(d.get("ci"))
    return f"{100 * value:.0f} % {_interval_text(lo, hi, 100, 0, why, ' %')}"


def _coverage_verdict(b: dict) -> str:
    """The calibrated bound's test coverage with its interval, units and status, e.g.
    ``89 % (95 % interval 81-95 %, 12 units): shown (...)``; an undefined interval says why."""
    d = b.get("test") or {}
    confidence = _number(b.get("confidence"))
    level = "" if confidence is None else f"{100 * confidence:.0f} % "
    tolerance = _number(b.get("tolerance"))
    floor = f"the target less {100 * (COVERAGE_TOLERANCE if tolerance is None else tolerance):.0f} points"
    value = _number(d.get("covered"))
    lo, hi = _ends(d.get("ci"))
    why = _coverage_reason(d)
    units = _number(d.get("n_units"))
    if value is None:
        text = _undefined(why)
    elif lo is None:
        text = f"{100 * value:.0f} % (interval {UNDEFINED}{': ' + why if why else ''})"
    else:
        text = (f"{100 * value:.0f} % ({level}interval {100 * lo:.0f}-{100 * hi:.0f} %, {_num(units, '.0f')} "
                f"units)")
    status = b.get("status")
    if status == "shown":
        text += f": shown (the interval's lower end is at or above {floor})"
    elif status == "failed":
        text += f": **failed** (the interval's upper end is below {floor})"
    elif status == "not shown":
        text += (f": not shown (the interval reaches below {floor})" if lo is not None else
                 ": not shown (without an interval)")
    else:
        text += f": {status} (as judged by an earlier version)" if status else ": status not recorded"
    if b.get("conservative"):
        text += (f"; conservative: the interval lies wholly above the target plus "
                 f"{100 * (COVERAGE_TOLERANCE if tolerance is None else tolerance):.0f} points (the bound is wider "
                 "than it needs to be)")
    return text


def _factor_spread_text(b: dict) -> str | None:
    """The factor's spread over resampled development units, or None where results.json has none."""
    c = b.get("calibration")
    if not c:
        return None
    n = _number(c.get("n_units"))
    why = _coverage_reason({"n": 1, "n_units": n})
    ends = list(c.get("factor_ci") or [None, None])
    f_lo, f_hi = _number(ends[0]), _number(ends[-1])
    c_lo, c_hi = _ends(c.get("coverage_ci"))
    if why or f_lo is None or c_lo is None:
        return f"Over resampled development units the factor's spread is {_undefined(why or 'no finite factor')}."
    factor = f"{f_lo:.3g}-{'inf' if f_hi is None else format(f_hi, '.3g')}"
    return (f"Over resampled development units ({n:.0f} units) the factor ranges {factor}, and a factor "
            f"calibrated on another draw of such units covers {100 * c_lo:.0f}-{100 * c_hi:.0f} % of the "
            f"development tips (the conformal guarantee assumes exchangeable scores; out-of-fold errors along a "
            f"motion are serially correlated).")


def _value(row) -> str:
    """A parameter row of a parameter table, with its standard error, in report units."""
    value = _number(row.get("value"))
    text = f"{row['name']} = {UNDEFINED}" if value is None else display_value(row["name"], value, row["unit"])
    se = row.get("stderr")
    if se is not None:
        se = _number(se)
        if se is None:
            text += f" (standard error {_undefined('fewer than two clusters of units')})"
        elif not math.isfinite(se):
            text += " (not determined by the data)"
        else:
            s = np.rad2deg(se) if row["unit"] == "rad" else se * 1e3 if row["unit"] == "m" else se
            text += f" +- {s:.2g}"
    if row.get("at_bound"):
        text += " **at bound**"
    if not row.get("in_typical_range", True):
        text += " **atypical**"
    return text


def _label(results: dict, effect) -> str:
    """The report label of a candidate effect of ``results`` (its name where it has none)."""
    c = (results.get("candidates") or {}).get(effect) or {}
    return c.get("label") or str(effect)


def _verdict_lines(results: dict) -> list[str]:
    d = results["decision"]
    ts = results["test_split"]
    f = ts["figures"]
    cal = f["calibration_shrink"]["mean"]
    gain = (f"On the untouched test split ({f['n_samples']} samples, {f['n_units']} units) the mean tip position error "
            f"is {_ci(f['file']['mean_mm'])} mm with the robot file and a registration, {_ci(f['before']['mean_mm'])} mm "
            f"with the calibrated baseline (shrink {_ci(cal, 0, 100, ' %')}) and {_ci(f['after']['mean_mm'])} mm with "
            f"{ts['label']} (shrink {_ci(f['shrink']['mean'], 0, 100, ' %')}); the p95 {_fmt(f['before']['p95_mm'])} -> "
            f"{_fmt(f['after']['p95_mm'])} mm and the maximum {_fmt(f['before']['max_mm'])} -> {_fmt(f['after']['max_mm'])} "
            f"mm; {_num(100 * f['confidence'], '.0f')} % intervals: {f['method']}. Table VIII of Ha et al. 2019 "
            f"(friction, grid data): mean -{100 * TABLE_VIII['mean']:.0f} %, max -{100 * TABLE_VIII['max']:.0f} %.")
    if d["verdict"] == "none":
        # a results.json from an earlier ctrplan stored the sentence
        why = results.get("no_effect_sentence") or words.no_effect(d, results.get("noise") or {},
                                                                   results.get("candidates"))
        return [f"**No effect named.** {why}.", "", gain, ""]
    comb = results.get("combination") or {}
    caution = "".join(f" **Caution:** {words.caution(c)}." for c in d.get("cautions") or [])
    if d["verdict"] == "ambiguous":
        a, b = _label(results, d["named"]), _label(results, d["ambiguous_with"])
        why = ("their fitted tip displacement fields on this motion are collinear, so the motion cannot tell them "
               "apart" if d.get("inseparable") else "the data cannot tell them apart within their uncertainty")
        design = f" A motion that separates them: {_design_command(results)}."
        head = (f"**Ambiguous: {a} or {b}.** Both lower the cross-validated error, and {why}. Data that would "
                f"separate them: {words.separated_by(d, words.labels_of(results.get('candidates')))}.{design} The "
                f"updated model file carries neither ({ts['label']}).{caution}")
    elif comb.get("replaced_by"):
        head = (f"**Named missing effect: {ts['label']}** ({comb['first_label']} was the best alone, but adds nothing "
                f"once {ts['label']} is fitted with it).{caution}")
    else:
        head = f"**Named missing effect{'s' if comb.get('named') else ''}: {ts['label']}.**{caution}"
    return [head + " " + gain, ""]


def _design_command(results: dict) -> str:
    """The ``ctrplan design`` command that plans a follow-up from this report's folder."""
    folder = Path(results["updated_model_file"]).parent if results.get("updated_model_file") else "DIR"
    return f"`ctrplan design --result {folder} --out DESIGN_DIR`"


def _written_fit(results: dict) -> tuple[dict, dict]:
    """The fit of the model the updated robot file carries (the named pair, the named effect, else
    the baseline) and the parameter table beside it."""
    comb, named = results.get("combination") or {}, results.get("named_effect")
    entry = ((comb.get("tried") or {}).get(comb["named"]) if comb.get("named") else
             (results.get("candidates") or {}).get(named) if named else results.get("baseline")) or {}
    return entry.get("fit") or {}, entry


def undetermined_parameters(results: dict) -> dict:
    """Free parameters of the written model that the recording leaves undetermined: a standard
    error that is infinite, or a 95 % interval (+-1.96 standard errors) wider than the parameter's
    typical range (the rule of :meth:`ctrplan.design.Hypothesis.undetermined`).

    Parameters
    ----------
    results : dict
        ``results.json`` of ``ctrplan discrepancy``; an ambiguous verdict writes no effect and
        gives ``{}``.

    Returns
    -------
    dict
        ``{name: "not determined" | "wider than typical"}``, in the fit's order.
    """
    if results["decision"]["verdict"] == "ambiguous":
        return {}
    fit, entry = _written_fit(results)
    rows = [*(results.get("baseline") or {}).get("parameter_table", ()), *entry.get("parameter_table", ())]
    typical = {r["name"]: r.get("typical") for r in rows}
    out = {}
    for name in fit.get("parameters") or {}:
        se, rng = _number((fit.get("stderr") or {}).get(name)), typical.get(name)
        if se is not None and not math.isfinite(se):
            out[name] = "not determined"
        elif se is not None and rng and 2 * 1.96 * se > abs(rng[1] - rng[0]):
            out[name] = "wider than typical"
    return out


def _follow_up_lines(results: dict) -> list[str]:
    loose = undetermined_parameters(results)
    if not loose:
        return []
    why = {"not determined": "not determined by the data",
           "wider than typical": "its 95 % interval is wider than its typical range"}
    return [f"**Left undetermined by this recording:** {'; '.join(f'{n} ({why[k]})' for n, k in loose.items())}. "
            f"A motion that determines them (the follow-up that shrinks their standard errors most within the drive's "
            f"limits): {_design_command(results)}.", ""]


def _split_lines(results: dict) -> list[str]:
    s = results["split"]
    source = results.get("data_source")
    bag = [] if not source else [f"- {line}" for line in describe_bag_summary(source)]
    return ["## Samples", "", *bag,
            f"- {results['n_samples']} samples in the {results['frame']} frame; {words.split_text(s)}.",
            f"- Folds: {s['n_folds']} of {', '.join(map(str, s['fold_samples']))} samples ({', '.join(map(str, s['fold_units']))} "
            f"units); each fold is predicted by models fitted on the others, from the same cold start as the fit on "
            f"all development samples (fits use {', '.join(map(str, s['fit_samples']))} samples, at most "
            f"{s['max_fit_samples']}).",
            f"- Buffer: {words.buffer_text(s)}; left out of every fit on each side of the blocks it is judged on "
            f"(validation and test).",
            "- Chosen once on the development samples and reused by every fold: the buffer, the development "
            "blocks' length and the prior's scale "
            "(from the pilot fit), and the prior's strength (by the baseline's out-of-fold error); everything else "
            "each fold fit does again from the same cold start.",
            f"- Test split: {s['n_test']} samples in {s['n_test_units']} units (units "
            f"{', '.join(map(str, s['test_units']))}), evaluated once, after the verdict.", ""]


def _candidate_lines(results: dict) -> list[str]:
    yes = (lambda b: "yes" if b else "no")
    d = results["decision"]
    lines = ["## Candidate effects (cross-validated on the development samples)", "",
             "| effect | fitted parameters (+- standard error) | out-of-fold mean / max [mm] | error lower than the "
             "baseline's by (95 % interval) | p | Holm | eligible |", "|---|---|---|---|---|---|---|"]
    notes = []
    base = results["baseline"]["out_of_fold"]
    lines.append(f"| baseline (standard, calibrated) | - | {_fmt(base['position_mean_mm'], 3)} / "
                 f"{_fmt(base['position_max_mm'], 3)} | - | - | - | - |")
    for e, c in results["candidates"].items():
        params = "; ".join(_value(r) for r in c["parameter_table"]) or "none (nominal)"
        imp = c.get("improvement_eq49") or {}
        # a results.json from an earlier ctrplan stored "fit_note", one sentence
        said = [words.fit_note(n) for n in c.get("fit_notes") or ()] or ([c["fit_note"]] if c.get("fit_note") else [])
        if said:
            notes.append(f"- {c['label']}: {'; '.join(said)}.")
        if c.get("widened"):
            notes.append(f"- {c['label']}: widened because a fit ended at them: {'; '.join(c['widened'])}.")
        lines.append(f"| {c['label']} | {params} | {_fmt(c['out_of_fold']['position_mean_mm'], 3)} / "
                     f"{_fmt(c['out_of_fold']['position_max_mm'], 3)} | {_pct(imp)} | "
                     f"{_num(imp.get('p_value'), '.2g')} | "
                     f"{yes(c.get('improvement_significant'))} | {yes(c.get('eligible'))} |")
    labels = words.labels_of(results.get("candidates"))
    lines += ["", f"Rule: {words.rule(d['rule'])}.", ""]
    lines += [f"- {words.note(n, d, labels)}." for n in d.get("notes") or []]
    if notes:
        lines += ["", "Fits:", ""] + notes
    return lines + [""]


def _strength(t) -> str:
    if t == 0:
        return "0 (the robot file's tube parameters, a registration only)"
    t = _number(t)
    return "inf (no prior)" if t is None or not math.isfinite(t) else f"{t:g}"


def _baseline_lines(results: dict) -> list[str]:
    b = results["baseline"]
    lines = ["## Baseline parameters", "",
             "Prior toward the robot file's tube parameters, strength tau chosen by the out-of-fold error (a relative "
             f"change tau costs one squared residual of {_num(b.get('residual_scale'), '.3g')} mm + deg, the pilot "
             f"fit's rms):", "",
             "| tau | out-of-fold mean tip error [mm] | out-of-fold Eq. (49) [mm + deg] | error lower than the robot "
             "file's by (95 % interval), p |", "|---|---|---|---|"]
    for c in b["prior_choices"]:
        cmp = c.get("against_file") or {}
        mean = _number(c.get("mean_position_m"))
        lines.append(f"| {_strength(c['strength'])}{' (chosen)' if c['strength'] == b['prior_strength'] else ''} | "
                     f"{_fmt(None if mean is None else 1e3 * mean, 3)} | {_fmt(c.get('mean_eq49'), 3)} | "
                     + ("-" if c["strength"] == 0 else f"{_pct(cmp)}, {_num(cmp.get('p_value'), '.2g')}") + " |")
    lines += ["", f"Fit on the development samples: {b['fit']['message']}" + ("" if b["fit"].get("converged") else
                                                                             " (**not converged**)") + ".", "",
             "| parameter | value +- standard error | robot file | change | typical range |", "|---|---|---|---|---|"]
    for r in b["parameter_table"]:
        ref = "-" if r.get("reference") is None else _num(r["reference"], ".4g")
        change = "-" if r.get("relative_change") is None else _num(100 * r["relative_change"], "+.0f") + " %"
        rng = "-" if not r.get("typical") else f"{_num(r['typical'][0], '.4g')}..{_num(r['typical'][1], '.4g')}"
        lines.append(f"| {r['name']} | {_value(r).split(' = ', 1)[-1]} | {ref} | {change} | {rng} |")
    corr = b["fit"].get("correlation")
    names = list(b["fit"].get("parameters") or [])
    if corr is not None and len(corr) == len(names):
        strong = [(names[i], names[j], corr[i][j]) for i in range(len(names)) for j in range(i + 1, len(names))
                  if _number(corr[i][j]) is not None and abs(corr[i][j]) >= 0.9]
        if strong:
            lines += ["", "Strongly correlated (|r| >= 0.9; the data determine their combination better than each): "
                      + ", ".join(f"{a} and {c} ({r:+.2f})" for a, c, r in strong) + "."]
    return lines + [""]


def _signature_lines(results: dict) -> list[str]:
    lines = ["## Signature tests (out-of-fold residuals of the baseline)", "",
             "| effect | effect size [mm] | p-value | statistic | units | test |", "|---|---|---|---|---|---|"]
    for e, t in results["signature_tests"].items():
        if not t.get("testable", True):
            lines.append(f"| {t['label']} | - | - | - | - | {t['description']} |")
            continue
        lines.append(f"| {t['label']} | {_num(t.get('effect_size_mm'), '.3f')} | {_num(t.get('p_value'), '.4f')} | "
                     f"{_num(t.get('statistic'), '.4g')} | {t['n_units']} | {t['description']} |")
    for e, why in (results.get("skipped_effects") or {}).items():
        lines.append(f"| {e} | - | - | - | - | not tried, because {why} |")
    return lines + ["", "The signature tests are evidence for a reader; the verdict rests on the cross-validated "
                        "improvement.", ""]


def _noise_lines(results: dict) -> list[str]:
    n = results["noise"]
    t = n.get("test")
    text = (f"Sensor noise (development samples): {words.noise_text(n['noise'])} (source: {n['noise']['source'] or 'none'}); "
            f"out-of-fold baseline rms position error {_num(n.get('rms_mm'), '.3f')} mm")
    if t:
        dof = "" if t.get("dof_residual") is None else (f", {_num(t['dof_residual'], '.0f')} and "
                                                        + ("inf" if t.get("dof_noise") is None else
                                                           _num(t["dof_noise"], ".0f"))
                                                        + " effective degrees of freedom")
        inflation = _number(t.get("inflation"))
        text += (f" = {_num(n.get('ratio'), '.2f')} x the noise; "
                 f"{'consistent' if t['consistent'] else '**not consistent**'} with noise "
                 f"(F = {_num(t.get('statistic'), '.3g')}, threshold {_num(t.get('threshold'), '.3g')} at false-alarm "
                 f"rate {_num(t.get('false_alarm_rate'), 'g')}, allowing "
                 f"{_num(None if inflation is None else 100 * (inflation - 1), '.0f')} % for the fitted "
                 f"parameters{dof}).")
    return [text, ""]


def _combination_lines(results: dict) -> list[str]:
    comb = results.get("combination")
    if not comb:
        return []
    title = ("## Two effects fitted together (neither named alone)" if comb.get("joint")
             else "## A second effect fitted with the named one")
    lines = [title, "", f"Rule: {words.pair_rule(comb)}.", ""]
    if comb["tried"]:
        against = comb.get("against_baseline") or {}
        first = "first" if comb.get("joint") else "named"
        lines += ["| pair (fitted jointly) | fitted parameters | out-of-fold mean [mm] | error lower than the "
                  f"{first} effect's alone by (95 % interval), p | than the second effect's alone by, p | "
                  + ("than the baseline by, p | " if against else "") + "named |",
                  "|---|---|---|---|---|" + ("---|" if against else "") + "---|"]
        for e, c in comb["tried"].items():
            imp, rev = c.get("improvement_eq49") or {}, c.get("reverse") or {}
            reverse = f"{_pct(rev)}, {_num(rev.get('p_value'), '.2g')}" if rev else "-"
            base = against.get(e)
            base = (f"{_pct(base)}, {_num(base.get('p_value'), '.2g')} | " if base else "- | ") if against else ""
            lines.append(f"| {c['label']} | {'; '.join(_value(r) for r in c['parameter_table'])} | "
                         f"{_fmt(c['out_of_fold']['position_mean_mm'], 3)} | {_pct(imp)}, "
                         f"{_num(imp.get('p_value'), '.2g')} | {reverse} | {base}{'yes' if e == comb['named'] else 'no'} |")
        lines.append("")
    if comb.get("dropped"):
        lines += [f"{comb['first_label']} goes to zero when fitted with "
                  f"{_label(results, comb['replaced_by'])}: the pair is no better than the latter alone, "
                  f"which is the final model.", ""]
    lines += [f"- not tried: {_label(results, e)}, because {words.not_paired(why, comb['first_label'])}."
              for e, why in (comb.get("not_tried") or {}).items()]
    return lines + [""]


def _prediction_lines(results: dict) -> list[str]:
    pred = results.get("prediction")
    if not pred:
        return []
    lines = ["## Prediction with the motion history (test split)", "", pred["description"], "",
             "| model | samples | mean [mm] | p95 [mm] | max [mm] |", "|---|---|---|---|---|"]
    for row in pred["rows"]:
        why = "no samples" if not row.get("n") else None
        lines.append(f"| {row['label']} | {row['n']} | {_fmt(row['mean_mm'], reason=why)} | "
                     f"{_fmt(row['p95_mm'], reason=why)} | {_fmt(row['max_mm'], reason=why)} |")
    for env in pred.get("envelopes") or []:
        coeff = ", ".join(f"{k} = {_num(v, '.3g')}" for k, v in (env.get("coefficients") or {}).items())
        inside = _number(env.get("fraction_inside"))
        how = words.envelope_text(env, results["noise"]["noise"])
        lines += ["", f"Envelope coverage ({env.get('label', 'fitted')} coefficients {coeff}; {how}): "
                      f"{env['inside']} of {env['n']} measured tips "
                      f"({_undefined('no samples') if inside is None else f'{100 * inside:.0f} %'}) lie inside "
                      f"the envelope of the bounding solutions plus {_num(env.get('margin_mm'), '.2f')} mm of sensor "
                      f"noise; the "
                      f"others lie outside by median {_fmt(env['outside_median_mm'])} mm, p95 "
                      f"{_fmt(env['outside_p95_mm'])} mm, max {_fmt(env['outside_max_mm'])} mm. Median envelope size: "
                      f"{_fmt(env['size_median_mm'])} mm."]
    return lines + [""]


def _prediction_check_lines(results: dict) -> list[str]:
    pc = results.get("prediction_check")
    if not pc:
        return []
    lines = [f"Measured prediction error on the test split ({pc['n_samples']} samples in {pc['n_units']} units; "
             f"{_num(100 * pc['confidence'], '.0f')} % intervals: {pc['method']}):", "",
             "| model | mean [mm] | p95 [mm] | max [mm] |", "|---|---|---|---|"]
    for side, label in (("standard", "standard model, the written robot file"), ("history", pc["history_label"])):
        f = pc[side]
        lines.append(f"| {label} | {_ci(f['mean_mm'])} | {_fmt(f['p95_mm'])} | {_fmt(f['max_mm'])} |")
    lines += ["", f"History-aware minus standard, mean: {_ci(pc['difference_mm'])} mm. "
              + ("Its interval lies below zero: planning may aim with the history-aware prediction."
                 if pc["history_beats_standard"] else
                 "Its interval does not lie below zero: planning aims with the standard model with this robot file."),
              ""]
    return lines


def _bound_lines(results: dict) -> list[str]:
    b = results.get("bound")
    if not b:
        return []
    raw, cal, tl = b["raw_test"], b["test"], b.get("translation_last")

    def ratio(d):
        r = d.get("ratio") or {}
        why = "no samples" if not d.get("n") else None
        return " / ".join(_fmt(r.get(k), reason=why) for k in ("median", "p90", "max"))

    def size(d):
        """Median size of the raw or translation-last bound plus the margin [mm]."""
        median = _number(d.get("bound_median_m"))
        margin = _number(b.get("margin_mm")) or 0.0
        return _fmt(None if median is None else median * 1e3 + margin, reason="no samples" if not d.get("n") else None)

    confidence = _number(b.get("confidence"))
    level = f"{100 * (CONFIDENCE if confidence is None else confidence):.0f} %"
    lines = ["## The friction bound against the measured tips (test split)", "", f"Definition: {b['definition']} "
             f"(m = {_num(b.get('margin_mm'), '.2f')} mm from {_num(b.get('noise_rms_mm'), '.3f')} mm rms noise).", "",
             f"| bound | samples | covered ({level} interval) | e / (b + m): median / p90 / max | median size [mm] |",
             "|---|---|---|---|---|",
             f"| friction bound b + m | {raw['n']} | {_share(raw)} | {ratio(raw)} | {size(raw)} |",
             f"| calibrated bound {_num(b.get('factor'), '.3g')} x (b + m) | {cal['n']} | {_share(cal)} | "
             f"{ratio(cal)} | {_fmt(cal.get('bound_median_mm'), reason='no samples' if not cal.get('n') else None)} |"]
    if tl:
        lines.append(f"| translation-last bound + m (after a final translation of every pair) | {tl['n']} | "
                     f"{_share(tl)} | {ratio(tl)} | {size(tl)} |")
    target = _number(b.get("target"))
    lines += ["", f"Calibrated bound: {b['method']}; target {_num(None if target is None else 100 * target, '.0f')} %; "
                  f"coverage of the test split's tips {_coverage_verdict(b)}.", ""]
    spread = _factor_spread_text(b)
    if spread:
        lines += [spread, ""]
    return lines


def _cautions_lines(results: dict) -> list[str]:
    cautions = results.get("cautions")
    return ["Cautions:", ""] + [f"- {words.caution(c)}." for c in cautions] + [""] if cautions else []


def _updated_model_lines(results: dict) -> list[str]:
    seconds = _number(results.get("seconds"))
    return ["## Updated model file", "",
            f"`{Path(results['updated_model_file']).name}` (evaluate with the {results['updated_model']} model); loaded "
            f"back, it reproduces the test split's errors: {'yes' if results['reproduced'] else '**NO**'} "
            f"(mean {_num(results.get('reproduced_position_mean_mm'), '.3f')} mm over {results['reproduced_samples']} "
            f"samples). Total time {_num(seconds, '.0f')} s.", ""]


#: Report names of the stages of ``results.json["stage_seconds"]``
#: (:data:`ctrplan.discrepancy.workflow.STAGES`); a candidate's stage is ``candidate:<effect>``.
STAGE_LABELS = {
    "setup": "setup: robot, data, effects, stage store", "split": "split: test split and folds",
    "baseline": "pilot fit and baseline calibration", "signature_tests": "signature tests",
    "noise_check": "noise check", "contact_baseline": "clearance-model refit of the tube parameters",
    "naming": "naming", "second_effect": "second effect (pairs)", "test_split": "test split",
    "prediction": "history-aware prediction and its check", "bound": "friction bound and its calibration",
    "updated_model": "updated robot file and its reproduction", "cautions": "cautions",
}


def _stage_label(results: dict, stage: str) -> str:
    effect = stage.partition("candidate:")[2]
    return f"candidate {_label(results, effect)}" if effect else STAGE_LABELS.get(stage, stage)


def _time_lines(results: dict) -> list[str]:
    """The table "Where the time went": each stage's wall time [s] and share of the run's total
    (``results["stage_seconds"]``); nothing for a ``results.json`` written without it."""
    stages = results.get("stage_seconds")
    if not stages:
        return []
    total = _number(results.get("seconds"))
    reused = results.get("stage_reused") or {}

    def share(x):
        x = _number(x)
        return _undefined() if x is None or not total else f"{100 * x / total:.1f} %"

    def wall(x):
        """Seconds: three decimals under one second, one above."""
        x = _number(x)
        return _num(x, ".3f" if x is not None and abs(x) < 1.0 else ".1f")

    lines = ["## Where the time went", "",
             "Wall time of each stage of the run; a candidate's runs from the end of the one before it to its "
             "out-of-fold errors. 'From an earlier run': the stage read stored results of a run with the same "
             "inputs and options (`.stages` in the report folder) instead of computing them.", "",
             "| stage | wall time [s] | share of the total | from an earlier run |", "|---|---|---|---|"]
    for stage, seconds in stages.items():
        lines.append(f"| {_stage_label(results, stage)} | {wall(seconds)} | {share(seconds)} | "
                     f"{reused.get(stage, '-')} |")
    rest = None if total is None else total - sum(_number(v) or 0.0 for v in stages.values())
    if rest is not None:
        lines.append(f"| between the stages | {wall(max(rest, 0.0))} | {share(max(rest, 0.0))} | - |")
    lines.append(f"| total | {wall(total)} | {'100 %' if total else _undefined()} | - |")
    return lines + [""]


def _plot_lines(results: dict, out: Path) -> list[str]:
    """The plots ``results["plots"]`` names that are in ``out``, and why the others are not."""
    lines = ["## Plots", ""]
    plots = list(results.get("plots") or [])
    if results.get("plots_error"):
        lines += [f"No plots: they could not be made ({results['plots_error']}). They are made from the run's "
                  f"arrays, which results.json does not hold: the same `ctrplan discrepancy` command makes them "
                  f"again (its finished stages are reused).", ""]
    missing = [p for p in plots if not (out / p).exists()]
    lines += [f"![{p}]({p})" for p in plots if p not in missing]
    if missing:
        lines += ["", f"Not in the report folder: {', '.join(missing)} (made from the run's arrays, which "
                      f"results.json does not hold: the same `ctrplan discrepancy` command makes them again)."]
    return lines


#: The report's sections after its title, in order; each formats ``results.json`` alone.
_SECTIONS = (_verdict_lines, _follow_up_lines, _cautions_lines, _noise_lines, _split_lines, _candidate_lines,
             _combination_lines, _baseline_lines, _signature_lines, _prediction_lines, _prediction_check_lines, _bound_lines,
             _updated_model_lines, _time_lines)


def _title(results: dict) -> list[str]:
    robot, data = results.get("robot_file"), results.get("data_file")
    return [f"# Discrepancy report: {Path(str(robot)).name} on {Path(str(data)).name}", ""]


def report_markdown(results: dict, out_dir) -> str:
    """``report.md``: the text of :func:`write_report`, formatted from ``results`` alone.

    A figure that is null or NaN prints as :data:`UNDEFINED`, with the reason where the results
    give one ("one unit", "no samples", "one fold"). A section whose figures do not have the
    form the formatters expect is replaced by a line that says so (logged as a warning); the
    others are written.

    Parameters
    ----------
    results : dict
        As ``results.json`` holds it (:func:`results_dict` after a JSON round trip).
    out_dir : path
        The report folder (the plots are looked for there).

    Returns
    -------
    str
    """
    lines = []
    for section in (_title, *_SECTIONS):
        try:
            lines += section(results)
        except Exception as exc:  # noqa: BLE001 - one unexpected figure must not lose the rest of the report
            logger.warning(f"report.md: section {section.__name__.strip('_')} not written ({type(exc).__name__}: "
                           f"{exc}); its figures are in results.json", exc_info=logger.isEnabledFor(logging.DEBUG))
            lines += [f"*This section could not be written ({type(exc).__name__}: {exc}); its figures are in "
                      f"results.json.*", ""]
    lines += _plot_lines(results, Path(out_dir))
    return "\n".join(lines) + "\n"


def _json_text(results: dict) -> str:
    return json.dumps(results, indent=2, default=json_default)


def write_report(result, out_dir) -> dict:
    """Write ``results.json`` (:func:`results_dict`), the plots and ``report.md`` into ``out_dir``,
    in this order and each atomically.

    ``results.json`` is on disk before anything else is made; ``report.md`` is formatted from what
    it holds (:func:`report_markdown`), so :func:`write_report_from_results` writes the same
    report again from the folder. Plots that cannot be made are left out with a warning and a
    note in the report.

    Parameters
    ----------
    result : DiscrepancyResult
        From :func:`ctrplan.discrepancy.workflow.run_discrepancy`.
    out_dir : path
        Report folder (made if missing).

    Returns
    -------
    dict
        Paths written: ``markdown``, ``json``, ``plots`` (list of file names in ``out_dir``).

    Raises
    ------
    OSError
        A file cannot be written (``results.json`` first: then nothing is written).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = results_dict(result)
    results["plots"], results["plots_error"] = [], None
    atomic_write_text(out / "results.json", _json_text(results))
    try:
        results["plots"] = _plots(result, out)
    except Exception as exc:  # noqa: BLE001 - the plots illustrate; the figures are in results.json
        logger.warning(f"plots not made ({type(exc).__name__}: {exc}); results.json and report.md are written",
                       exc_info=logger.isEnabledFor(logging.DEBUG))
        results["plots_error"] = f"{type(exc).__name__}: {exc}"
    text = _json_text(results)
    atomic_write_text(out / "results.json", text)
    atomic_write_text(out / "report.md", report_markdown(json.loads(text), out))
    return {"markdown": str(out / "report.md"), "json": str(out / "results.json"), "plots": results["plots"]}


def write_report_from_results(out_dir) -> dict:
    """Write ``report.md`` again from the ``results.json`` of a report folder (e.g. after the
    report of a run could not be written; ``ctrplan discrepancy-report OUT``).

    The text is that :func:`write_report` writes from the same ``results.json``. The plots are
    not made again (they need the run's arrays, which ``results.json`` does not hold): the report
    shows those still in the folder and names the missing ones.

    Parameters
    ----------
    out_dir : path
        A report folder written by :func:`write_report` (``results.json`` in it).

    Returns
    -------
    dict
        Paths: ``markdown``, ``json``, ``plots`` (file names listed in ``results.json`` and present).

    Raises
    ------
    DataFileError
        ``out_dir/results.json`` is missing or is not a JSON object.
    """
    out = Path(out_dir)
    path = out / "results.json"
    try:
        results = json.loads(path.read_text())
    except FileNotFoundError:
        raise DataFileError(f"{path}: not found; a report folder of `ctrplan discrepancy` holds it") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataFileError(f"{path}: not readable as JSON ({exc})") from None
    if not isinstance(results, dict) or "decision" not in results:
        raise DataFileError(f"{path}: not the results of `ctrplan discrepancy` (no 'decision' key)")
    atomic_write_text(out / "report.md", report_markdown(results, out))
    return {"markdown": str(out / "report.md"), "json": str(path),
            "plots": [p for p in results.get("plots") or [] if (out / p).exists()]}


