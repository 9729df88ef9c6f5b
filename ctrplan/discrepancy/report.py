"""Report folder of the discrepancy workflow: ``report.md``, ``results.json`` and PNG plots.

The report formats a run's typed results (:class:`~ctrplan.discrepancy.workflow.DiscrepancyResult`,
SI units) for people, who read millimetres and degrees; it computes no figure of its own. This is
the one module of the workflow that turns results into report units: ``results.json`` keeps SI
values where the key says so (``_m``, ``_rad``, or no unit suffix) and millimetres / degrees
where the key says ``_mm`` / ``_deg`` (:func:`results_dict`).
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..effects import REGISTRY
from ..io.atomic import atomic_write_text
from ..io.ros2 import describe_bag_summary
from .coverage import BOUND_DEFINITION
from .decision import no_effect_sentence
from .envelope import PREDICTION_DESCRIPTION
from .estimates import display_value
from .evaluation import ErrorFigures
from .provenance import provenance

__all__ = ["write_report", "results_dict", "candidate_dict", "noise_dict", "error_dict", "bound_dict", "TABLE_VIII"]

#: The paper's gain with its friction model on its own grid data (Table VIII of Ha et al. 2019):
#: relative fall of the mean and of the maximum tip position error.
TABLE_VIII = {"mean": 0.46, "max": 0.49}


def _fmt(x, nd=2):
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.{nd}f}"


def _ci(d, nd=2, scale=1.0, unit=""):
    """``value (low..high)`` of a ``{"value", "ci"}`` dict."""
    lo, hi = d["ci"]
    return f"{_fmt(d['value'] * scale, nd)}{unit} ({_fmt(lo * scale, nd)}..{_fmt(hi * scale, nd)})"


def _pct(cmp: dict) -> str:
    """The reduction of a :func:`~ctrplan.discrepancy.statistics.cv_comparison` in % with its interval."""
    lo, hi = cmp["reduction_ci"]
    return f"{_fmt(100 * cmp['reduction'], 0)} % ({_fmt(100 * lo, 0)}..{_fmt(100 * hi, 0)} %)"


def _value(row) -> str:
    """A parameter row of a parameter table, with its standard error, in report units."""
    text = display_value(row["name"], row["value"], row["unit"])
    se = row.get("stderr")
    if se is not None:
        if not np.isfinite(se):
            text += " (not determined by the data)"
        else:
            s = np.rad2deg(se) if row["unit"] == "rad" else se * 1e3 if row["unit"] == "m" else se
            text += f" +- {s:.2g}"
    if row.get("at_bound"):
        text += " **at bound**"
    if not row.get("in_typical_range", True):
        text += " **atypical**"
    return text


def _tangential(residual, tip):
    """Residual component along e_z x tip direction (rotation about the base axis) [m]."""
    t = np.column_stack([-tip[:, 1], tip[:, 0], np.zeros(len(tip))])
    t /= np.linalg.norm(t, axis=1, keepdims=True) + 1e-300
    return np.einsum("ij,ij->i", residual, t)


def _errors_arrays(e) -> dict:
    return {"position": e.position, "angle": e.angle, "residual": e.residual_base, "tip_base": e.tip_base}


def _arrays(result) -> dict:
    """The arrays the plots draw [SI]."""
    split, data, final = result.split, result.setup.data, result.final
    return {"dev_eta": data.take(split.dev_rows).eta, "test_eta": data.take(split.test_rows).eta,
            "oof": _errors_arrays(result.baseline.oof),
            "oof_final": None if final is None else _errors_arrays(final.oof),
            "test_before": _errors_arrays(result.test.baseline), "test_after": _errors_arrays(result.test.final),
            "test_file": _errors_arrays(result.test.file)}


def _plots(result, out: Path) -> list[str]:
    from ..plots import _figure, _save

    a = _arrays(result)
    files = []
    fig = _figure((10, 3.8))
    axes = fig.subplots(1, 2)
    before, after = a["test_before"]["position"] * 1e3, a["test_after"]["position"] * 1e3
    top = np.nanmax(np.concatenate([before, after]))
    bins = np.linspace(0, top if np.isfinite(top) and top > 0 else 1.0, 40)
    final = result.test.label
    axes[0].hist(before[np.isfinite(before)], bins, alpha=0.6, label="baseline (standard, calibrated)")
    axes[0].hist(after[np.isfinite(after)], bins, alpha=0.6, label=final)
    axes[0].set_xlabel("test-split tip position error [mm]")
    axes[0].set_ylabel("samples")
    axes[0].legend(fontsize=8)
    ab, aa = np.rad2deg(a["test_before"]["angle"]), np.rad2deg(a["test_after"]["angle"])
    if np.isfinite(ab).any():
        top = np.nanmax(np.concatenate([ab, aa]))
        bins = np.linspace(0, top, 40)
        axes[1].hist(ab[np.isfinite(ab)], bins, alpha=0.6, label="baseline")
        axes[1].hist(aa[np.isfinite(aa)], bins, alpha=0.6, label="final")
        axes[1].legend(fontsize=8)
    axes[1].set_xlabel("test-split tip tangent error [deg]")
    fig.suptitle("Error histograms on the untouched test split, before and after")
    files.append(_save(fig, out / "error_histograms.png").name)

    eta = np.asarray(a["dev_eta"], int)
    combos = sorted({tuple(e) for e in eta}, reverse=True)
    fig = _figure((10, 3.8))
    axes = fig.subplots(1, 2, sharey=True)
    panels = [(axes[0], a["oof"], "baseline"), (axes[1], a["oof_final"] or a["oof"], "final model")]
    for ax, arr, title in panels:
        tang = _tangential(np.asarray(arr["residual"]), np.asarray(arr["tip_base"])) * 1e3
        data = [tang[np.all(eta == np.array(c), axis=1) & np.isfinite(tang)] for c in combos]
        ax.boxplot(data, showfliers=False)
        ax.set_xticks(range(1, len(combos) + 1))
        ax.set_xticklabels([",".join("+" if v > 0 else "-" if v < 0 else "0" for v in c) for c in combos])
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("direction of the last relative rotation eta (pair 1, pair 2, ...)")
        ax.set_title(title)
    axes[0].set_ylabel("out-of-fold residual about the base axis [mm]")
    fig.suptitle("Out-of-fold residual (tangential component) by direction of the last relative rotation")
    files.append(_save(fig, out / "residuals_by_direction.png").name)
    return files


def _verdict_lines(results: dict, result) -> list[str]:
    d = results["decision"]
    ts = results["test_split"]
    f = ts["figures"]
    cal = f["calibration_shrink"]["mean"]
    gain = (f"On the untouched test split ({f['n_samples']} samples, {f['n_units']} units) the mean tip position error "
            f"is {_ci(f['file']['mean_mm'])} mm with the robot file and a registration, {_ci(f['before']['mean_mm'])} mm "
            f"with the calibrated baseline (shrink {_ci(cal, 0, 100, ' %')}) and {_ci(f['after']['mean_mm'])} mm with "
            f"{ts['label']} (shrink {_ci(f['shrink']['mean'], 0, 100, ' %')}); the p95 {_fmt(f['before']['p95_mm'])} -> "
            f"{_fmt(f['after']['p95_mm'])} mm and the maximum {_fmt(f['before']['max_mm'])} -> {_fmt(f['after']['max_mm'])} "
            f"mm; {100 * f['confidence']:.0f} % intervals: {f['method']}. Table VIII of Ha et al. 2019 (friction, grid "
            f"data): mean -{100 * TABLE_VIII['mean']:.0f} %, max -{100 * TABLE_VIII['max']:.0f} %.")
    if d["verdict"] == "none":
        sentence = no_effect_sentence(result.naming.decision, result.noise, result.naming.candidates)
        return [f"**No effect named.** {sentence}.", "", gain, ""]
    comb = results.get("combination") or {}
    caution = "".join(f" **Caution:** {c}." for c in d.get("cautions") or [])
    if d["verdict"] == "ambiguous":
        a, b = results["candidates"][d["named"]]["label"], results["candidates"][d["ambiguous_with"]]["label"]
        head = (f"**Ambiguous: {a} or {b}.** Both lower the cross-validated error, and the data cannot tell them apart "
                f"within their uncertainty. Data that would separate them: {d['separated_by']}. The updated model "
                f"file carries {ts['label']} (the lower out-of-fold error of the two).{caution}")
    elif comb.get("replaced_by"):
        head = (f"**Named missing effect: {ts['label']}** ({comb['first_label']} was the best alone, but adds nothing "
                f"once {ts['label']} is fitted with it).{caution}")
    else:
        head = f"**Named missing effect{'s' if comb.get('named') else ''}: {ts['label']}.**{caution}"
    return [head + " " + gain, ""]


def _split_lines(results: dict) -> list[str]:
    s = results["split"]
    source = results.get("data_source")
    bag = [] if not source else [f"- {line}" for line in describe_bag_summary(source)]
    return ["## Samples", "", *bag,
            f"- {results['n_samples']} samples in the {results['frame']} frame; {s['how']}.",
            f"- Folds: {s['n_folds']} of {', '.join(map(str, s['fold_samples']))} samples ({', '.join(map(str, s['fold_units']))} "
            f"units); each fold is predicted by models fitted on the others, from the same cold start as the fit on "
            f"all development samples (fits use {', '.join(map(str, s['fit_samples']))} samples, at most "
            f"{s['max_fit_samples']}).",
            f"- Buffer: {s['buffer_note']}; left out of every fit on each side of the blocks it is judged on "
            f"(validation and test).",
            "- Chosen once on the development samples and reused by every fold: the buffer and the prior's scale "
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
        imp = c["improvement_eq49"]
        if c.get("fit_note"):
            notes.append(f"- {c['label']}: {c['fit_note']}.")
        if c.get("widened"):
            notes.append(f"- {c['label']}: widened because a fit ended at them: {'; '.join(c['widened'])}.")
        lines.append(f"| {c['label']} | {params} | {_fmt(c['out_of_fold']['position_mean_mm'], 3)} / "
                     f"{_fmt(c['out_of_fold']['position_max_mm'], 3)} | {_pct(imp)} | {imp['p_value']:.2g} | "
                     f"{yes(c.get('improvement_significant'))} | {yes(c.get('eligible'))} |")
    lines += ["", f"Rule: {d['rule']}.", ""]
    lines += [f"- {n}." for n in d["notes"]]
    if notes:
        lines += ["", "Fits:", ""] + notes
    return lines + [""]


def _strength(t) -> str:
    if t == 0:
        return "0 (the robot file's tube parameters, a registration only)"
    return "inf (no prior)" if t is None or not np.isfinite(t) else f"{t:g}"


def _baseline_lines(results: dict) -> list[str]:
    b = results["baseline"]
    lines = ["## Baseline parameters", "",
             "Prior toward the robot file's tube parameters, strength tau chosen by the out-of-fold error (a relative "
             f"change tau costs one squared residual of {b['residual_scale']:.3g} mm + deg, the pilot fit's rms):", "",
             "| tau | out-of-fold mean tip error [mm] | out-of-fold Eq. (49) [mm + deg] | error lower than the robot "
             "file's by (95 % interval), p |", "|---|---|---|---|"]
    for c in b["prior_choices"]:
        cmp = c["against_file"]
        lines.append(f"| {_strength(c['strength'])}{' (chosen)' if c['strength'] == b['prior_strength'] else ''} | "
                     f"{1e3 * c['mean_position_m']:.3f} | {c['mean_eq49']:.3f} | "
                     + ("-" if c["strength"] == 0 else f"{_pct(cmp)}, {cmp['p_value']:.2g}") + " |")
    lines += ["", f"Fit on the development samples: {b['fit']['message']}" + ("" if b["fit"]["converged"] else
                                                                             " (**not converged**)") + ".", "",
             "| parameter | value +- standard error | robot file | change | typical range |", "|---|---|---|---|---|"]
    for r in b["parameter_table"]:
        ref = "-" if r.get("reference") is None else f"{r['reference']:.4g}"
        change = "-" if r.get("relative_change") is None else f"{100 * r['relative_change']:+.0f} %"
        rng = "-" if r["typical"] is None else f"{r['typical'][0]:.4g}..{r['typical'][1]:.4g}"
        lines.append(f"| {r['name']} | {_value(r).split(' = ', 1)[-1]} | {ref} | {change} | {rng} |")
    corr = b["fit"].get("correlation")
    if corr is not None:
        names = list(b["fit"]["parameters"])
        strong = [(names[i], names[j], corr[i][j]) for i in range(len(names)) for j in range(i + 1, len(names))
                  if corr[i][j] is not None and np.isfinite(corr[i][j]) and abs(corr[i][j]) >= 0.9]
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
        lines.append(f"| {t['label']} | {t['effect_size_mm']:.3f} | {t['p_value']:.4f} | {t['statistic']:.4g} | "
                     f"{t['n_units']} | {t['description']} |")
    for e, why in (results.get("skipped_effects") or {}).items():
        lines.append(f"| {e} | - | - | - | - | not tried, because {why} |")
    return lines + ["", "The signature tests are evidence for a reader; the verdict rests on the cross-validated "
                        "improvement.", ""]


def _noise_lines(results: dict) -> list[str]:
    n = results["noise"]
    t = n.get("test")
    text = (f"Sensor noise (development samples): {n['noise']['description']} (source: {n['noise']['source'] or 'none'}); "
            f"out-of-fold baseline rms position error {n['rms_mm']:.3f} mm")
    if t:
        dof = "" if t.get("dof_residual") is None else (f", {t['dof_residual']:.0f} and "
                                                        + ("inf" if t.get("dof_noise") is None else f"{t['dof_noise']:.0f}")
                                                        + " effective degrees of freedom")
        text += (f" = {n['ratio']:.2f} x the noise; {'consistent' if t['consistent'] else '**not consistent**'} with noise "
                 f"(F = {t['statistic']:.3g}, threshold {t['threshold']:.3g} at false-alarm rate "
                 f"{t['false_alarm_rate']:g}, allowing {100 * (t['inflation'] - 1):.0f} % for the fitted parameters{dof}).")
    return [text, ""]


def _combination_lines(results: dict) -> list[str]:
    comb = results.get("combination")
    if not comb:
        return []
    lines = ["## A second effect fitted with the named one", "", f"Rule: {comb['rule']}.", ""]
    if comb["tried"]:
        lines += ["| pair (fitted jointly) | fitted parameters | out-of-fold mean [mm] | error lower than the named "
                  "effect's alone by (95 % interval), p | than the second effect's alone by, p | named |",
                  "|---|---|---|---|---|---|"]
        for e, c in comb["tried"].items():
            imp, rev = c["improvement_eq49"], c.get("reverse") or {}
            lines.append(f"| {c['label']} | {'; '.join(_value(r) for r in c['parameter_table'])} | "
                         f"{_fmt(c['out_of_fold']['position_mean_mm'], 3)} | {_pct(imp)}, {imp['p_value']:.2g} | "
                         f"{_pct(rev) if rev else '-'}, {rev.get('p_value', float('nan')):.2g} | "
                         f"{'yes' if e == comb['named'] else 'no'} |")
        lines.append("")
    if comb.get("dropped"):
        lines += [f"{comb['first_label']} goes to zero when fitted with "
                  f"{results['candidates'][comb['replaced_by']]['label']}: the pair is no better than the latter alone, "
                  f"which is the final model.", ""]
    lines += [f"- not tried: {results['candidates'][e]['label']}, because {why}." for e, why in comb["not_tried"].items()]
    return lines + [""]


def _prediction_lines(results: dict) -> list[str]:
    pred = results.get("prediction")
    if not pred:
        return []
    lines = ["## Prediction with the motion history (test split)", "", pred["description"], "",
             "| model | samples | mean [mm] | p95 [mm] | max [mm] |", "|---|---|---|---|---|"]
    for row in pred["rows"]:
        lines.append(f"| {row['label']} | {row['n']} | {_fmt(row['mean_mm'])} | {_fmt(row['p95_mm'])} | "
                     f"{_fmt(row['max_mm'])} |")
    for env in pred.get("envelopes") or []:
        coeff = ", ".join(f"{k} = {v:.3g}" for k, v in env.get("coefficients", {}).items())
        lines += ["", f"Envelope coverage ({env.get('label', 'fitted')} coefficients {coeff}; {env['description']}): "
                      f"{env['inside']} of {env['n']} measured tips ({100 * env['fraction_inside']:.0f} %) lie inside "
                      f"the envelope of the bounding solutions plus {env['margin_mm']:.2f} mm of sensor noise; the "
                      f"others lie outside by median {_fmt(env['outside_median_mm'])} mm, p95 "
                      f"{_fmt(env['outside_p95_mm'])} mm, max {_fmt(env['outside_max_mm'])} mm. Median envelope size: "
                      f"{_fmt(env['size_median_mm'])} mm."]
    return lines + [""]


def _prediction_check_lines(results: dict) -> list[str]:
    pc = results.get("prediction_check")
    if not pc:
        return []
    lines = [f"Measured prediction error on the test split ({pc['n_samples']} samples in {pc['n_units']} units; "
             f"{100 * pc['confidence']:.0f} % intervals: {pc['method']}):", "",
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

    def share(d):
        return "-" if d["covered"] is None else (f"{100 * d['covered']:.0f} % ({100 * d['ci'][0]:.0f}.."
                                                 f"{100 * d['ci'][1]:.0f} %)")

    def ratio(d):
        r = d["ratio"]
        return " / ".join(_fmt(r[k]) for k in ("median", "p90", "max"))

    lines = ["## The friction bound against the measured tips (test split)", "", f"Definition: {b['definition']} "
             f"(m = {b['margin_mm']:.2f} mm from {b['noise_rms_mm']:.3f} mm rms noise).", "",
             "| bound | samples | covered (95 % interval) | e / (b + m): median / p90 / max | median size [mm] |",
             "|---|---|---|---|---|",
             f"| friction bound b + m | {raw['n']} | {share(raw)} | {ratio(raw)} | "
             f"{_fmt(None if raw['bound_median_m'] is None else raw['bound_median_m'] * 1e3 + b['margin_mm'])} |",
             f"| calibrated bound {b['factor']:.3g} x (b + m) | {cal['n']} | {share(cal)} | {ratio(cal)} | "
             f"{_fmt(cal.get('bound_median_mm'))} |"]
    if tl:
        lines.append(f"| translation-last bound + m (after a final translation of every pair) | {tl['n']} | {share(tl)} | "
                     f"{ratio(tl)} | {_fmt(None if tl['bound_median_m'] is None else tl['bound_median_m'] * 1e3 + b['margin_mm'])} |")
    lines += ["", f"Calibrated bound: {b['method']}; target {100 * b['target']:.0f} %: "
                  + {"failing": "**FAILING** on the test split (its coverage falls short of the target).",
                     "conservative": "conservative on the test split (its coverage exceeds the target by more than "
                                     "5 points).",
                     "met": "met on the test split within its interval or 5 points."}[b.get("status", "met")], ""]
    return lines


def write_report(result, out_dir) -> dict:
    """Write ``report.md``, ``results.json`` (:func:`results_dict`) and the plots into ``out_dir``
    (atomically).

    Parameters
    ----------
    result : DiscrepancyResult
        From :func:`ctrplan.discrepancy.workflow.run_discrepancy`.
    out_dir : path

    Returns
    -------
    dict
        Paths written: ``markdown``, ``json``, ``plots`` (list).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plots = _plots(result, out)
    results = results_dict(result)
    results["plots"] = plots
    atomic_write_text(out / "results.json", json.dumps(results, indent=2, default=_plain))
    lines = [f"# Discrepancy report: {Path(results['robot_file']).name} on {Path(results['data_file']).name}", ""]
    lines += _verdict_lines(results, result)
    if results.get("cautions"):
        lines += ["Cautions:", ""] + [f"- {c}." for c in results["cautions"]] + [""]
    lines += _noise_lines(results)
    lines += _split_lines(results)
    lines += _candidate_lines(results)
    lines += _combination_lines(results)
    lines += _baseline_lines(results)
    lines += _signature_lines(results)
    lines += _prediction_lines(results)
    lines += _prediction_check_lines(results)
    lines += _bound_lines(results)
    lines += ["## Updated model file", "",
              f"`{Path(results['updated_model_file']).name}` (evaluate with the {results['updated_model']} model); loaded "
              f"back, it reproduces the test split's errors: {'yes' if results['reproduced'] else '**NO**'} "
              f"(mean {results['reproduced_position_mean_mm']:.3f} mm over {results['reproduced_samples']} samples). "
              f"Total time {results['seconds']:.0f} s.", "", "## Plots", ""]
    lines += [f"![{p}]({p})" for p in plots]
    atomic_write_text(out / "report.md", "\n".join(lines) + "\n")
    return {"markdown": str(out / "report.md"), "json": str(out / "results.json"), "plots": plots}


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
    """:class:`~ctrplan.discrepancy.output.ModelFigures` in mm."""
    return {"mean_mm": m.mean.scaled(1e3).as_dict(), "p95_mm": _mm(m.p95), "max_mm": _mm(m.max)}


def candidate_dict(c) -> dict:
    """A :class:`~ctrplan.discrepancy.fitting.Candidate` as ``results.json`` stores it (mm in
    ``out_of_fold``; SI in ``parameters`` and ``parameter_table``; Eq. (49) units in
    ``improvement_eq49``)."""
    out = {"effects": list(c.effects), "label": c.label, "model": c.model, "fit": c.fit.as_dict(),
           "folds": [f.as_dict() for f in c.cv.folds], "parameters": c.shown, "units": c.units,
           "parameter_table": [p.as_dict() for p in c.parameters], "atypical": [a.as_dict() for a in c.atypical],
           "typical": c.typical, "at_bound": list(c.at_bound), "widened": list(c.widened), "converged": c.cv.converged,
           "n_parameters": c.n_parameters, "bic": c.bic, "delta_bic": c.delta_bic,
           "out_of_fold": error_dict(c.out_of_fold_figures), "mean_eq49": c.mean_error,
           "improvement_eq49": c.improvement.as_dict(), "improvement_position": c.improvement_position.as_dict(),
           "fit_note": c.fit_note}
    for key in ("improvement_significant", "eligible", "significant"):
        if getattr(c, key) is not None:
            out[key] = getattr(c, key)
    if c.reverse is not None:
        out["reverse"] = c.reverse.as_dict()
    return out


def noise_dict(check) -> dict:
    """A :class:`~ctrplan.discrepancy.decision.NoiseCheck` as ``results.json`` stores it (mm)."""
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
    """A :class:`~ctrplan.discrepancy.coverage.BoundCalibration` as ``results.json`` stores it (mm
    where the key says so)."""
    return {"definition": BOUND_DEFINITION, "method": b.method, "target": b.target, "factor": b.factor,
            "margin_mm": b.margin_m * 1e3, "noise_multiple": b.noise_multiple, "noise_rms_mm": b.noise_rms_m * 1e3,
            "n_calibration": b.n_calibration, "test": _coverage_dict(b.test, error_median=True),
            "raw_test": _coverage_dict(b.raw_test, error_median=False),
            "translation_last": None if b.translation_last is None else b.translation_last.as_dict(),
            "failing": b.failing, "status": b.status}


def _envelope_dict(env) -> dict:
    return {"n": env.n, "inside": env.inside, "fraction_inside": env.fraction_inside, "margin_mm": env.margin_m * 1e3,
            "outside_median_mm": _mm(env.outside_median_m), "outside_p95_mm": _mm(env.outside_p95_m),
            "outside_max_mm": _mm(env.outside_max_m), "size_median_mm": _mm(env.size_median_m),
            "description": env.description, "coefficients": env.coefficients, "label": env.label}


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
            "not_tried": dict(combination.not_tried), "family": list(combination.family), "rule": combination.rule,
            "dropped": combination.dropped, "replaced_by": combination.replaced_by}


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
        "cautions": list(result.cautions), "significance": options.significance, "options": opts,
        "seconds": result.seconds, "provenance": provenance(options),
    }


def _plain(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return str(x)
