"""Report folder of the discrepancy workflow: ``report.md``, ``results.json`` and PNG plots.

People read millimetres and degrees; the JSON keeps SI values where the key says so (``_m``,
``_rad``) and millimetres / degrees where the key says ``_mm`` / ``_deg``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write_text

__all__ = ["write_report"]


def _fmt(x, nd=2):
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.{nd}f}"


def _row(name, s):
    return (f"| {name} | {_fmt(s['position_mean_mm'])} +- {_fmt(s['position_std_mm'])} | "
            f"{_fmt(s['position_max_mm'])} | {_fmt(s['tangent_mean_deg'])} | {_fmt(s['tangent_max_deg'])} | "
            f"{_fmt(s['evaluation_ms_per_sample'], 1)} |")


def _tangential(residual, tip):
    """Residual component along e_z x tip direction (rotation about the base axis) [m]."""
    t = np.column_stack([-tip[:, 1], tip[:, 0], np.zeros(len(tip))])
    t /= np.linalg.norm(t, axis=1, keepdims=True) + 1e-300
    return np.einsum("ij,ij->i", residual, t)


def _plots(results: dict, out: Path) -> list[str]:
    from ..plots import _figure, _save

    a = results["_arrays"]
    files = []
    # error histograms before / after
    fig = _figure((10, 3.8))
    axes = fig.subplots(1, 2)
    before, after = a["before_position"] * 1e3, a["after_position"] * 1e3
    top = np.nanmax(np.concatenate([before, after]))
    bins = np.linspace(0, top if np.isfinite(top) and top > 0 else 1.0, 40)
    axes[0].hist(before[np.isfinite(before)], bins, alpha=0.6, label="baseline (standard, calibrated)")
    axes[0].hist(after[np.isfinite(after)], bins, alpha=0.6,
                 label=f"with {results['named_label']}" if results["named_effect"] else "after (no effect named)")
    axes[0].set_xlabel("held-out tip position error [mm]")
    axes[0].set_ylabel("samples")
    axes[0].legend(fontsize=8)
    ab, aa = np.rad2deg(a["before_angle"]), np.rad2deg(a["after_angle"])
    if np.isfinite(ab).any():
        top = np.nanmax(np.concatenate([ab, aa]))
        bins = np.linspace(0, top, 40)
        axes[1].hist(ab[np.isfinite(ab)], bins, alpha=0.6, label="baseline")
        axes[1].hist(aa[np.isfinite(aa)], bins, alpha=0.6, label="after")
        axes[1].legend(fontsize=8)
    axes[1].set_xlabel("held-out tip tangent error [deg]")
    fig.suptitle("Error histograms before and after adding the named effect")
    files.append(_save(fig, out / "error_histograms.png").name)

    # residuals by approach direction
    eta = np.asarray(a["val_eta"], int)
    combos = sorted({tuple(e) for e in eta}, reverse=True)
    fig = _figure((10, 3.8))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, key, title in ((axes[0], "before_residual", "baseline"), (axes[1], "after_residual", "after")):
        tang = _tangential(a[key], a["val_tip_base"]) * 1e3
        data = [tang[np.all(eta == np.array(c), axis=1) & np.isfinite(tang)] for c in combos]
        ax.boxplot(data, showfliers=False)
        ax.set_xticks(range(1, len(combos) + 1))
        ax.set_xticklabels([",".join("+" if v > 0 else "-" if v < 0 else "0" for v in c) for c in combos])
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("approach direction eta (pair 1, pair 2, ...)")
        ax.set_title(title)
    axes[0].set_ylabel("residual about the base axis [mm]")
    fig.suptitle("Held-out residual (tangential component) by approach direction")
    files.append(_save(fig, out / "residuals_by_direction.png").name)
    return files


def write_report(results: dict, out_dir) -> dict:
    """Write ``report.md``, ``results.json`` and the plots into ``out_dir``.

    Parameters
    ----------
    results : dict
        From :func:`ctrplan.discrepancy.workflow.run_discrepancy`.
    out_dir : path

    Returns
    -------
    dict
        Paths written: ``markdown``, ``json``, ``plots`` (list).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plots = _plots(results, out)
    public = {k: v for k, v in results.items() if not k.startswith("_")}
    public["plots"] = plots
    atomic_write_text(out / "results.json", json.dumps(public, indent=2, default=_plain))

    base, after = results["baseline"]["held_out"], results["after"]
    named = results["named_effect"]
    lines = [f"# Discrepancy report: {Path(results['robot_file']).name} on {Path(results['data_file']).name}", ""]
    if named:
        red = 1.0 - after["position_mean_mm"] / base["position_mean_mm"]
        redmax = 1.0 - after["position_max_mm"] / base["position_max_mm"]
        change = (f"lowers the maximum by {100 * redmax:.0f}%" if redmax >= 0
                  else f"raises the maximum by {-100 * redmax:.0f}%")
        comb = results.get("combination") or {}
        label = (comb["tried"][comb["named"]]["label"] if comb.get("named") else results["named_label"])
        lines += [f"**Named missing effect{'s' if comb.get('named') else ''}: {label}.** Adding "
                  f"{'them' if comb.get('named') else 'it'} "
                  f"{'lowers' if red >= 0 else 'raises'} the held-out mean tip position error by "
                  f"{100 * abs(red):.0f}% and {change}.", ""]
    else:
        lines += [_no_effect_paragraph(results), ""]
    lines += _combination_lines(results)
    decision = results.get("decision") or {}
    if named and decision.get("notes"):
        lines += ["Decision:", ""] + [f"- {n}." for n in decision["notes"]] + [""]
    noise = results.get("noise")
    if noise:
        ratio = "" if noise["ratio"] is None else f" = {noise['ratio']:.2f} x the noise"
        lines += [f"Sensor noise: {noise['noise']['description']}; held-out baseline rms position error "
                  f"{noise['rms_mm']:.3f} mm{ratio} (consistent with noise when <= {noise['threshold_ratio']}).", ""]
    if results.get("cautions"):
        lines += ["Cautions:", ""] + [f"- {c}." for c in results["cautions"]] + [""]
    lines += [f"- data: {results['n_samples']} samples in the {results['frame']} frame; split {results['split']};",
              f"- calibration fit on {results['n_fit']} samples, errors on {results['n_validation']} held-out samples;",
              f"- baseline parameters: {', '.join(results['baseline_parameters'])};",
              f"- updated model file: `{Path(results['updated_model_file']).name}` (evaluate with the "
              f"{results['updated_model']} model); loaded back, it reproduces the held-out errors: "
              f"{'yes' if results['reproduced'] else 'NO'} on {results['reproduced_samples']} samples (mean {results['reproduced_position_mean_mm']:.3f} mm);",
              f"- total time {results['seconds']:.0f} s.", "",
              "## Held-out error (in the form of Table VIII of Ha et al. 2019)", "",
              "| model | tip position mean +- std [mm] | max [mm] | tangent mean [deg] | max [deg] | "
              "evaluation [ms/sample] |",
              "|---|---|---|---|---|---|",
              _row("baseline: standard, calibrated", base)]
    for e, c in results["candidates"].items():
        lines.append(_row(f"+ {c['label']} ({c['model']} model)" + (" **named**" if e == named else ""),
                          c["held_out"]))
    lines += ["", "## Signature tests (held-out residuals of the baseline)", "",
              "| effect | effect size [mm] | p-value | statistic | units | test |", "|---|---|---|---|---|---|"]
    for e, t in results["signature_tests"].items():
        if not t.get("testable", True):
            lines.append(f"| {t['label']} | - | - | - | - | {t['description']} |")
            continue
        lines.append(f"| {t['label']} | {t['effect_size_mm']:.3f} | {t['p_value']:.4f} | {t['statistic']:.4g} | "
                     f"{t['n_units']} | {t['description']} |")
    for e, why in (results.get("skipped_effects") or {}).items():
        lines.append(f"| {e} | - | - | - | - | not tried, because {why} |")
    lines += ["", f"Significance level {results['significance']}; permutation p-values are bounded below by "
              f"1 / (permutations + 1).", "", "## Candidate effects", "",
              "| effect | fitted parameters | dBIC | held-out mean change [mm] | improvement p | signature | "
              "improvement | BIC | eligible |", "|---|---|---|---|---|---|---|---|---|"]
    notes = []
    for e, c in results["candidates"].items():
        params = ", ".join(f"{k} = {v:.4g}" + (" (implausible)" if any(b["name"] == k for b in c.get("implausible", []))
                                               else "") for k, v in c["parameters"].items()) or "none (nominal)"
        if c.get("fit_note"):
            notes.append(f"- {c['label']}: {c['fit_note']}.")
        dm = c["held_out"]["position_mean_mm"] - base["position_mean_mm"]
        yes = (lambda b: "yes" if b else "no")
        lines.append(f"| {c['label']} | {params} | {c['delta_bic']:.1f} | {dm:+.3f} | "
                     f"{c['improvement_eq49']['p_value']:.4f} | {yes(c['signature_significant'])} | "
                     f"{yes(c['improvement_significant'])} | {yes(c['bic_better'])} | {yes(c['eligible'])} |")
    base_fit = results["baseline"]["fit"]
    lines += ["", f"Baseline fit: {base_fit['message']}" + ("" if base_fit.get("converged", True) else
                                                            " (**not converged**)") + "."]
    cfit = results.get("contact_baseline")
    if cfit:
        lines += ["", f"Clearance-model refit of the tube parameters (shared by the clearance and friction candidates): "
                      f"cost {cfit['cost']:.4g}; {cfit['message']}" + ("" if cfit.get("converged", True) else
                                                                     " (**not converged**)") + "."]
    if notes:
        lines += ["", "Fits:", ""] + notes
    lines += ["", "Rule: an effect is eligible when its signature test is significant, its held-out improvement "
              "(Eq. (49) residual, paired sign-flip test over held-out configurations or time blocks) is "
              f"significant, and its BIC is lower than the baseline's by more than {results['bic_margin']}. "
              "Among the eligible effects whose fitted values are plausible (all eligible ones if none is), the "
              "largest held-out improvement is named; eligible effects whose held-out residual does not differ "
              "significantly from the named one's are listed as equally good.", ""]
    lines += _prediction_section(results)
    lines += ["## Plots", ""]
    lines += [f"![{p}]({p})" for p in plots]
    atomic_write_text(out / "report.md", "\n".join(lines) + "\n")
    return {"markdown": str(out / "report.md"), "json": str(out / "results.json"), "plots": plots}


def _combination_lines(results: dict) -> list[str]:
    """The second effect tried on top of the named one: steps of a named pair, every pair tried,
    fitted values in deg / mm (SI in the JSON)."""
    from .fitting import display_value

    comb = results.get("combination")
    if not comb:
        return []
    lines = ["## Combination of effects", "",
             f"Rule for a second effect: {comb['rule']}.", ""]
    if comb["named"]:
        c = comb["tried"][comb["named"]]
        lines += [f"**Named combination: {c['label']}** ({c['model']} model). Steps (held-out):", ""]
        for k, st in enumerate(comb["steps"], 1):
            imp = st["improvement_eq49"]
            lines.append(f"{k}. {st['label']}: mean {st['held_out_mean_mm']:.3f} mm, max {st['held_out_max_mm']:.3f} mm; "
                         f"Eq. (49) improvement over {'the baseline' if st['over'] == 'baseline' else 'step 1'} "
                         f"{imp['mean_difference']:.3f} (mm + deg), p = {imp['p_value']:.4f}")
        lines.append("")
    if comb["tried"]:
        lines += ["| pair | fitted parameters | held-out mean [mm] | max [mm] | improvement over the first p | "
                  "dBIC over the first | converged | named |", "|---|---|---|---|---|---|---|---|"]
        for e, c in comb["tried"].items():
            params = ", ".join(display_value(n, v, c["units"][n]) for n, v in c["parameters"].items())
            lines.append(f"| {c['label']} | {params} | {_fmt(c['held_out']['position_mean_mm'], 3)} | "
                         f"{_fmt(c['held_out']['position_max_mm'], 3)} | {c['improvement_eq49']['p_value']:.4f} | "
                         f"{c['delta_bic']:.1f} | {'yes' if c['converged'] else '**no**'} | "
                         f"{'yes' if e == comb['named'] else 'no'} |")
        lines.append("")
    lines += [f"- {n}." for n in comb["notes"]]
    return lines + ([""] if comb["notes"] else [])


def _no_effect_paragraph(results: dict) -> str:
    case = (results.get("decision") or {}).get("no_effect_case")
    noise = results.get("noise") or {}
    head = ("**No effect named.** No candidate had a significant residual signature, a significant held-out "
            "improvement and a better BIC together. ")
    if case == "noise":
        return head + (f"The held-out residual of the calibrated baseline (rms {noise['rms_mm']:.3f} mm) is "
                       f"consistent with the sensor noise ({noise['noise']['description']}).")
    if case == "unexplained":
        return head + (f"The held-out residual of the calibrated baseline (rms {noise['rms_mm']:.3f} mm, "
                       f"{noise['ratio']:.1f} times the sensor noise, {noise['noise']['description']}) is **not** "
                       f"consistent with noise: the model misses something that none of the candidates explains.")
    return head + ("Whether the residual is noise cannot be said: the sensor noise is unknown (give "
                   "`--noise-position-mm`).")


def _prediction_section(results: dict) -> list[str]:
    """History-aware prediction and friction-envelope coverage (issue 13, Sec. 3)."""
    pred = results.get("prediction")
    if not pred:
        return []
    lines = ["## Prediction with the motion history (held-out data)", "",
             pred["description"], "",
             "| model | samples | mean [mm] | p95 [mm] | max [mm] |", "|---|---|---|---|---|"]
    for row in pred["rows"]:
        lines.append(f"| {row['label']} | {row['n']} | {_fmt(row['mean_mm'])} | {_fmt(row['p95_mm'])} | "
                     f"{_fmt(row['max_mm'])} |")
    for env in pred.get("envelopes") or ([pred["envelope"]] if pred.get("envelope") else []):
        coeff = ", ".join(f"{k} = {v:.3g}" for k, v in env.get("coefficients", {}).items())
        lines += ["", f"Envelope coverage ({env.get('label', 'fitted')} coefficients {coeff}; {env['description']}): "
                      f"{env['inside']} of {env['n']} measured tips ({100 * env['fraction_inside']:.0f} %) lie inside "
                      f"the envelope of the bounding solutions plus {env['margin_mm']:.2f} mm of sensor noise; the "
                      f"others lie outside by median {_fmt(env['outside_median_mm'])} mm, p95 "
                      f"{_fmt(env['outside_p95_mm'])} mm, max {_fmt(env['outside_max_mm'])} mm. Median envelope size "
                      f"(largest distance between two bounding tips): {_fmt(env['size_median_mm'])} mm."]
    return lines + [""]


def _plain(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return str(x)
