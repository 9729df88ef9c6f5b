"""The tables of the docs made from the results files of the benchmarks that measure them.

    python benchmarks/docs_tables.py          # rewrite the tables between their markers
    python benchmarks/docs_tables.py --check  # exit 1 when the docs differ from the results files

Each table sits between ``<!-- NAME -->`` and ``<!-- /NAME -->`` in its page:

- docs/discrepancy.md, ``sweep-table``: ``benchmarks/results/discrepancy-sweep.json``
  (``benchmarks/bench_discrepancy_sweep.py``);
- docs/discrepancy.md, ``ha-table``: ``benchmarks/results/ha-trajectory-discrepancy.json``
  (``benchmarks/ha_trajectory_discrepancy.py``);
- docs/discrepancy.md, ``robot-files-table``: ``benchmarks/results/ha-robot-files.json``
  (``benchmarks/ha_robot_files.py``);
- docs/mechanics.md, ``discretization-table``: ``benchmarks/results/discretization-accuracy.json``
  (``benchmarks/discretization_accuracy.py``);
- docs/mechanics.md, ``speed-table``: ``benchmarks/results/speed.json``
  (``benchmarks/bench_speed.py``).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "discrepancy.md"
RESULTS = ROOT / "benchmarks" / "results"
SOURCES = {"sweep-table": RESULTS / "discrepancy-sweep.json", "ha-table": RESULTS / "ha-trajectory-discrepancy.json",
           "robot-files-table": RESULTS / "ha-robot-files.json",
           "discretization-table": RESULTS / "discretization-accuracy.json", "speed-table": RESULTS / "speed.json"}
#: The page each table is in.
DOCS = {"sweep-table": DOC, "ha-table": DOC, "robot-files-table": DOC,
        "discretization-table": ROOT / "docs" / "mechanics.md", "speed-table": ROOT / "docs" / "mechanics.md"}
OUTCOMES = ("right", "right name, value off", "partly right", "ambiguous", "wrong", "nothing")
KIND_LABELS = {"control": "controls (no effect)", "one": "one effect", "two": "two effects"}


def _value(name: str, value: float, unit: str) -> str:
    if unit == "rad":
        return f"{np.rad2deg(value):.3g} deg"
    if unit == "m":
        return f"{value * 1e3:.3g} mm"
    return f"{value:.3g}" + ("" if unit in ("-", "") else f" {unit}")


def _pm(value: float, stderr, unit: str) -> str:
    if stderr is None or not np.isfinite(stderr):
        return _value("", value, unit) + (" (undetermined)" if stderr is not None else "")
    scale = np.rad2deg(1.0) if unit == "rad" else 1e3 if unit == "m" else 1.0
    return _value("", value, unit) + f" +- {1.96 * stderr * scale:.2g}"


def _ci90(ci) -> str:
    return "-" if ci[0] is None else f"{100 * ci[0]:.0f}..{100 * ci[1]:.0f} %"


def sweep_table(res: dict) -> str:
    """Outcome counts by kind, robot and truth, their rates with 90 % Clopper-Pearson intervals,
    the targets met or not, and the cases with their written values against the truth."""
    s = res["summary"]
    n = s["cases"]
    planned = res.get("cases_planned", n)
    per_robot = ", ".join(f"{k}: {sum(c[o] for o in OUTCOMES)}" for k, c in s["by_robot"].items())
    lines = [f"{n} cases" + (f" of the {planned} planned, seeds {_seed_ranges([c['seed'] for c in res['cases']])}"
                             if planned != n else "") + f" ({per_robot}); "
             f"cost {res['case_seconds']['total'] / 3600:.1f} h of workflow runs (a case: mean "
             f"{res['case_seconds']['mean']:.0f} s, median {res['case_seconds']['median']:.0f} s, p90 "
             f"{res['case_seconds']['p90']:.0f} s, max {res['case_seconds']['max']:.0f} s"
             + (f"; median load average {res['case_seconds']['load_average_median']:.1f}"
                if res['case_seconds'].get('load_average_median') is not None else "") + ").", "",
             "| cases | " + " | ".join(OUTCOMES) + " |", "|---|" + "---|" * len(OUTCOMES)]
    lines.append("| all | " + " | ".join(str(s["by_outcome"][o]) for o in OUTCOMES) + " |")
    lines.append("| rate (90 % interval) | " + " | ".join(
        f"{100 * s['rates'][o]['rate']:.0f} % ({_ci90(s['rates'][o]['ci90'])})" if n else "-" for o in OUTCOMES) + " |")
    for k, row in s["by_kind"].items():
        lines.append(f"| {KIND_LABELS[k]} | " + " | ".join(str(row[o]) for o in OUTCOMES) + " |")
    for r, row in s["by_robot"].items():
        lines.append(f"| {r} | " + " | ".join(str(row[o]) for o in OUTCOMES) + " |")
    for t, row in s["by_truth"].items():
        if sum(row.values()):
            lines.append(f"| {_truth_label(t)} | " + " | ".join(str(row[o]) for o in OUTCOMES) + " |")
    t = s["targets"]
    rule = s["value_rule"]
    w, one, two = t["wrong"], t["clear_one_named"], t["clear_two_both_named"]
    clear = (f"every hidden effect's signal-to-noise ratio (rms tip displacement over the noise's rms length) at "
             f"least {s['clear_snr']:g}")
    lines += ["", f"A written value is right within {rule['stderrs']:g} standard errors (of the final model's "
                  f"development fit) or {100 * rule['share']:.0f} % of the true value. Targets:", "",
              f"- wrong names (a named effect not in the truth, an ambiguous verdict that writes an effect not in it, "
              f"any name on a control): {_share(w)}; target below {100 * w['rate_below']:.0f} %, interval's upper end "
              f"below {100 * w['upper_below']:.0f} %: {_met(w['met'])};",
              f"- the truth named alone (right, or right name with a value off) in the one-effect cases with {clear}: "
              f"{_share(one)}; target at least {100 * one['at_least']:.0f} %: {_met(one['met'])};",
              f"- both effects named (right, or right names with a value off) in the two-effect cases with {clear}: "
              f"{_share(two)}; target at least {100 * two['at_least']:.0f} %: {_met(two['met'])}.", "",
              f"Clear cases: {s['clear_cases']['one']} with one effect, {s['clear_cases']['two']} with two.", "",
              "| seed | robot | truth (size, share of the typical range) | signal-to-noise | noise | verdict | written to "
              "the robot file (against the truth) | why a hidden effect is not named |", "|---|---|---|---|---|---|---|---|"]
    for c in res["cases"]:
        hidden = "; ".join(f"{k} = {_value('', v, _unit(k))} ({100 * c['size_shares'][e][k]:.0f} %)"
                           for e, group in c["hidden"].items() for k, v in group.items()) or "-"
        snr = ", ".join(f"{e} {v:.1f}" for e, v in c["snr"].items()) + (" (clear)" if c["clear"] else "") or "-"
        noise = "white" if not c["ar1"] else f"AR(1) {c['ar1']:g}"
        if c["verdict"] == "ambiguous":     # an ambiguous verdict writes neither effect: say the pair
            verdict = f"{c['outcome']}: {c['named']} or {c['ambiguous_with']}, neither written"
        else:
            verdict = c["outcome"] + ": " + (c["verdict"] if c["verdict"] == "none" else ", ".join(c["named_effects"]))
        if c.get("cautions"):
            verdict += " (caution)"
        checks = c.get("value_check", {})
        written = ("(its robot file is missing)" if c["written"] is None else
                   "; ".join(f"{k} = {_value('', v, _unit(k))}" + _against(checks.get(k))
                             for e in c["written"].values() for k, v in e.items()) or "-")
        lines.append(f"| {c['seed']} | {c['robot']} | {hidden} | {snr} | {noise} | {verdict} | {written} | "
                     f"{_why(c)} |")
    return "\n".join(lines)


def _why(case: dict) -> str:
    """Why each hidden effect that the written model lacks was not named (the case's decision
    record): its first reason with its figure (p value, the candidates that beat it, the limit),
    or that the pair was not separable (with the correlation of the two displacement fields)."""
    rec = case.get("decision")
    if not rec:
        return "-"
    out = []
    for e in case["truth"]:
        if e in case["named_effects"]:
            continue
        reasons = rec["why_not"].get(e) or []
        if case["verdict"] == "ambiguous" and e in (case["named"], case["ambiguous_with"]):
            pair = {case["named"], case["ambiguous_with"]}
            rho = [v["correlation"] for k, v in rec.get("separability", {}).items() if set(k.split(" vs ")) == pair]
            out.append(f"{e}: not separable" + (f" (rho {rho[0]:.3f})" if rho else ""))
        elif not reasons:
            out.append(f"{e}: eligible, another named" if e in rec["eligible"] else f"{e}: -")
        else:
            r = reasons[0]
            detail = {"not significant": lambda: f"p {r['p_value']:.2g} at level {rec['level']:.2g}",
                      "outperformed": lambda: "by " + ", ".join(sorted(r["outperformed_by"])),
                      "at limit": lambda: "; ".join(r["limits"][:1])}.get(r["reason"], lambda: "")()
            out.append(f"{e}: {r['reason']}" + (f" ({detail})" if detail else ""))
    return "; ".join(out) or "-"


def _truth_label(truth: str) -> str:
    """A row label of the sweep's ``by_truth`` key: ``"none"``, an effect, or ``"a+b"``."""
    if truth == "none":
        return "control"
    effects = truth.split("+")
    return f"one effect: {truth}" if len(effects) == 1 else "two effects: " + " + ".join(effects)


def _share(rate: dict) -> str:
    """``"3 of 12 (25 %, 90 % interval 7..52 %)"`` of a sweep target's figures."""
    if not rate["cases"]:
        return "no such cases"
    return (f"{rate['count']} of {rate['cases']} ({100 * rate['rate']:.0f} %, 90 % Clopper-Pearson interval "
            f"{_ci90(rate['ci90'])})")


def _met(met) -> str:
    return "not judged (no such cases)" if met is None else "**met**" if met else "**not met**"


def _against(check) -> str:
    """A written value's check against the truth: its relative error, and in standard errors
    where the fit gave one."""
    if not check or check["written"] is None:
        return ""
    diff = check["written"] - check["true"]
    se = check["stderr"]
    in_se = f", {abs(diff) / se:.1f} se" if se is not None and np.isfinite(se) and se > 0 else ""
    return f" ({100 * diff / abs(check['true']):+.1f} %{in_se})"


def _seed_ranges(seeds) -> str:
    """``[2000, 2001, 2002, 2035]`` -> ``"2000-2002, 2035"``."""
    seeds, parts = sorted(seeds), []
    start = prev = seeds[0]
    for s in seeds[1:] + [None]:
        if s is not None and s == prev + 1:
            prev = s
            continue
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
        start = prev = s
    return ", ".join(parts)


def _unit(name: str) -> str:
    if name.startswith(("backlash", "friction_angle", "registration_r")):
        return "rad"
    if name == "time_offset":
        return "s"
    if name.startswith("precurvature"):
        return "1/m"
    return "-"


def ha_table(res: dict) -> str:
    """Verdict, candidates, baseline prior, test-split figures next to Table VIII, noise, bound."""
    verdict = res["verdict"] + ("" if res["verdict"] == "none" else f": {', '.join(res['named_effects'])}")
    if res["ambiguous_with"]:     # an ambiguous verdict writes neither effect: say the pair
        verdict = f"ambiguous: {res['named']} or {res['ambiguous_with']}, neither written"
    lines = [f"Data: {res['n_samples']} samples ({res['data_file']}, SHA-256 {res['data_sha256'][:12]}...); "
             f"{res['split']}; buffer {res['buffer']}.", "", f"**Verdict: {verdict}.**"]
    if res.get("separated_by") and res["ambiguous_with"]:
        lines.append(f" Data that would separate them: {res['separated_by']}.")
    lines += [f"- caution: {c}" for c in res.get("decision_cautions") or []]
    n = res["noise"]
    lines += ["", f"Noise (development samples): {n['description']}; out-of-fold baseline rms "
                  f"{n['out_of_fold_rms_mm']:.3f} mm; consistent with noise: {n['consistent']}"
              + (f" (F = {n['statistic']:.3g}, threshold {n['threshold']:.3g})" if n["statistic"] is not None else "")
              + ".", ""]
    b = res["baseline"]
    lines += ["Baseline prior strength tau (out-of-fold mean tip error): " + ", ".join(
        f"{_tau(c['strength'])} {1e3 * c['mean_position_m']:.2f} mm" for c in b["prior_choices"])
              + f"; chosen: {_strength(b['prior_strength'])}.",
              "", "| candidate | fitted (95 % interval) | out-of-fold mean / max [mm] | error lower than the baseline's by "
                  "(95 % interval) | p | Holm | eligible |", "|---|---|---|---|---|---|---|"]
    for e, c in res["candidates"].items():
        params = "; ".join(f"{k} = {_pm(p['value'], p['stderr'], p['unit'])}"
                           + (" (atypical)" if not p["in_typical_range"] else "")
                           + (" (at its limit)" if p["at_bound"] else "") for k, p in c["parameters"].items()) or "nominal"
        lo, hi = c["reduction_ci"]
        lines.append(f"| {c['label']} | {params} | {c['out_of_fold_mean_mm']:.2f} / {c['out_of_fold_max_mm']:.2f} | "
                     f"{100 * c['reduction']:.0f} % ({100 * lo:.0f}..{100 * hi:.0f} %) | {c['p_value']:.2g} | "
                     f"{'yes' if c['holm'] else 'no'} | {'yes' if c['eligible'] else 'no'} |")
    if res.get("pairs"):
        lines += ["", "| pair (fitted jointly) | out-of-fold mean [mm] | error lower than the named effect's by, p | "
                      "the named effect still adds (p) | named |", "|---|---|---|---|---|"]
        for e, p in res["pairs"].items():
            lines.append(f"| {p['label']} | {p['out_of_fold_mean_mm']:.2f} | {100 * p['reduction']:.0f} %, "
                         f"{p['p_value']:.2g} | {p['reverse_p_value']:.2g} | {'yes' if e in res['named_effects'] else 'no'} |")
    t = res["test_split"]
    lines += ["", f"Test split ({t['n_samples']} samples in {t['n_units']} units, untouched until the end; "
                  f"{t['label']}; {t['method']}):", "",
              "| tip position error | robot file with a registration [mm] | calibrated baseline [mm] | final model [mm] "
              "| shrink of the final model (95 % interval) | Ha et al. Table VIII (grid data) |",
              "|---|---|---|---|---|---|"]
    m = lambda d: f"{d['value']:.2f} ({d['ci'][0]:.2f}..{d['ci'][1]:.2f})"
    s = t["shrink"]["mean"]
    lines.append(f"| mean | {m(t['file']['mean_mm'])} | {m(t['before']['mean_mm'])} | {m(t['after']['mean_mm'])} | "
                 f"{100 * s['value']:.0f} % ({100 * s['ci'][0]:.0f}..{100 * s['ci'][1]:.0f} %) | "
                 f"{100 * res['table_viii_shrink']['mean']:.0f} % |")
    for stat in ("p95", "max"):
        paper = res["table_viii_shrink"].get(stat)
        lines.append(f"| {stat} | {t['file'][f'{stat}_mm']:.2f} | {t['before'][f'{stat}_mm']:.2f} | "
                     f"{t['after'][f'{stat}_mm']:.2f} | {100 * (1 - t['after'][f'{stat}_mm'] / t['before'][f'{stat}_mm']):.0f} % | "
                     f"{'-' if paper is None else f'{100 * paper:.0f} %'} |")
    c = t["calibration_shrink"]["mean"]
    lines += ["", f"The calibrated baseline against the robot file with only a registration: mean lower by "
                  f"{100 * c['value']:.0f} % ({100 * c['ci'][0]:.0f}..{100 * c['ci'][1]:.0f} %)."]
    changed = [p for p in res["baseline"]["parameters"] if p.get("relative_change") is not None]
    if changed:
        lines += ["", "Baseline parameters (change from the robot file): " + "; ".join(
            f"{p['name']} = {_pm(p['value'], p['stderr'], p['unit'])} ({100 * p['relative_change']:+.0f} %"
            + ("" if p["in_typical_range"] else ", atypical") + ")" for p in changed) + "."]
    pred = res.get("prediction")
    if pred and pred.get("rows"):
        lines += ["", "History-aware prediction on the test split:", "", "| model | mean / p95 / max [mm] |", "|---|---|"]
        for r in pred["rows"]:
            lines.append(f"| {r['label']} | {r['mean_mm']:.2f} / {r['p95_mm']:.2f} / {r['max_mm']:.2f} |")
    pc = res.get("prediction_check")
    if pc:
        d = pc["difference_mm"]
        lines += ["", f"History-aware minus standard, mean: {d['value']:+.2f} mm ({d['ci'][0]:+.2f}..{d['ci'][1]:+.2f} "
                      f"mm over {pc['n_units']} units): it " + ("beats" if pc["history_beats_standard"] else
                                                               "does not beat")
                  + " the standard model; the written robot file's [prediction_validation] "
                  + ("lets" if pc["history_beats_standard"] else "does not let") + " `ctrplan plan` aim with it."]
    b = res.get("bound")
    if b:
        raw, cal = b["raw_test"], b["test"]
        lines += ["", f"Friction bound of the written robot file on the test split ({raw['n']} samples): "
                      f"{100 * raw['covered']:.0f} % ({_ci90(raw['ci'])}) of the measured tips within b + "
                      f"{b['margin_mm']:.2f} mm, median e / (b + m) {raw['ratio']['median']:.2f}; calibrated bound "
                      f"{b['factor']:.3g} x (b + m) (target {100 * b['target']:.0f} %): {100 * cal['covered']:.0f} % "
                      f"({_ci90(cal['ci'])}), {b['status']}, median size {cal['bound_median_m'] * 1e3:.2f} mm."]
    if res["cautions"]:
        lines += [""] + [f"- caution: {c}" for c in res["cautions"]]
    return "\n".join(lines)


def _tau(t) -> str:
    return "file" if t == 0 else "none" if t is None or t == float("inf") else f"{t:g}"


def _strength(t) -> str:
    if t == 0:
        return "the robot file's tube parameters with only a registration"
    return "no prior" if t is None or t == float("inf") else f"tau = {t:g}"


def robot_files_table(res: dict) -> str:
    """Standard model, prediction, bound and calibrated bound per robot file; the parameter swaps."""
    lines = [f"Data: {res['data_file']} (SHA-256 {res['data_sha256'][:12]}...), ds = {res['ds_m'] * 1e3:g} mm; "
             f"registration fitted on the first {res['files'][0]['rows_registered']} rows, errors on the other "
             f"{res['files'][0]['rows_evaluated']}.", "",
             "| robot file (mu) | standard model mean / p95 / max [mm] | history-aware prediction mean / p95 / max [mm] "
             "| bound mean / max [mm] | error <= bound + 0.6 mm | calibrated bound (target 90 %): factor, median size, "
             "test coverage (95 % interval) |", "|---|---|---|---|---|---|"]
    for f in res["files"]:
        s, p, c = f["standard"], f["prediction"], f["calibrated_bound"]
        ci = c["test_coverage_ci"]
        lines.append(f"| `{f['robot_file']}` ({', '.join(f'{m:g}' for m in f['friction_coefficients'])}) | "
                     f"{s['mean_mm']:.2f} / {s['p95_mm']:.2f} / {s['max_mm']:.2f} | {p['mean_mm']:.2f} / {p['p95_mm']:.2f} "
                     f"/ {p['max_mm']:.2f} | {f['bound_mean_mm']:.2f} / {f['bound_max_mm']:.2f} | "
                     f"{100 * f['within_bound_plus_0_6_mm']:.1f} % | {c['factor']:.3g} x (b + {c['margin_mm']:.2f} mm), "
                     f"{c['median_size_mm']:.2f} mm, {100 * c['test_coverage']:.0f} % ("
                     + ("interval undefined" if ci[0] is None or ci[1] is None else
                        f"{100 * ci[0]:.0f}..{100 * ci[1]:.0f} %") + "), "
                     f"{c['status']} |")
    lines += ["", "Standard-model mean error [mm] with one file's value(s) put into the other:", "",
              "| parameters | Table II value(s) | Table VII value(s) | Table II file with Table VII values | Table VII file "
              "with Table II values |", "|---|---|---|---|---|"]
    for w in res["swaps"]:
        lines.append(f"| {', '.join(w['parameters'])} | {', '.join(f'{v:.4g}' for v in w['table2'])} | "
                     f"{', '.join(f'{v:.4g}' for v in w['table7'])} | {w['table2_with_table7_values']['mean_mm']:.2f} | "
                     f"{w['table7_with_table2_values']['mean_mm']:.2f} |")
    return "\n".join(lines)


def discretization_table(res: dict) -> str:
    """Accuracy against the converged reference (and speed, where timed) of each discretization,
    per grid: medians and maxima [mm] of the tips and the bound, configurations flagged otherwise."""
    names = list(res["candidates"])
    lines = ["| grid | discretization | nodes | clearance tip, median / max [mm] | friction tip, median / max [mm] "
             "| bound, median / max [mm] | flags differ (not converged, unstable) | bound time, default / this |",
             "|---|---|---|---|---|---|---|---|"]
    for grid, g in res["grids"].items():
        timing = g.get("timing", {}).get("candidates", {})
        for n in names:
            e = g["candidates"][n]
            kw = res["candidates"][n]
            label = n if not kw else f"{n} (" + ", ".join(f"{k} {v:g}" for k, v in kw.items()) + ")"

            def cell(q):
                return f"{e[q]['median'] * 1e3:.3f} / {e[q]['max'] * 1e3:.3f}"
            speed = f"{timing[n]['speedup_of_medians']:.2f}x" if n in timing else "-"
            lines.append(f"| {grid}x{grid}x{grid} ({g['reference_settled']} of {g['configurations']}) | {label} | {e['median_nodes']:.0f} | "
                         f"{cell('clearance_tip')} | {cell('friction_tip')} | {cell('bound')} | "
                         f"{e['converged_differs']}, {e['unstable_differs']} | {speed} |")
    return "\n".join(lines)


def _ms(x: float) -> str:
    return f"{x * 1e3:.3g}"


def speed_table(res: dict) -> str:
    """Times per configuration or row: mean, median, p90, max [ms], the median as a multiple of one
    standard solve measured in the same run, the paper's Table VIII times and the frozen reference."""
    r = res["ratios"]
    unit = float(np.median(r["single_standard_s"]))
    lines = [f"Measured {res['date']} at {res['commit']} (mechanics {res['mechanics_version']}), {res['cpu']}, "
             f"{res['cores']} cores, OPENBLAS_NUM_THREADS={res['openblas_threads']}; load average (1, 5, 15 min) "
             f"{', '.join(f'{x:.2f}' for x in res['load_average_start'])} at the start, "
             f"{', '.join(f'{x:.2f}' for x in res['load_average_end'])} at the end. "
             f"Command: `{res['command']}`.", "",
             "| quantity (Table II robot, ds = 3 mm) | n | mean / median / p90 / max [ms] | median / one standard solve "
             "| paper's Table VIII (MATLAB) | frozen reference / this, medians |", "|---|---|---|---|---|---|"]

    def row(name, ts, paper=None, ref=None):
        t = np.asarray(ts, dtype=float)
        stats = " / ".join(_ms(v) for v in (t.mean(), np.median(t), np.percentile(t, 90), t.max()))
        speed = "-" if not ref else f"{np.median(ref) / np.median(t):.0f}x"
        lines.append(f"| {name} | {t.size} | {stats} | {np.median(t) / unit:.3g} | "
                     f"{'-' if paper is None else f'{paper * 1e3:.0f} ms'} | {speed} |")

    row("one standard solve, determinant test only (the unit), 4x4x4", r["single_standard_s"])
    for name, m in res.get("per_configuration", {}).get("models", {}).items():
        row(f"{name}, 4x4x4", m["seconds"], m["paper_s"], m["reference_seconds"])
    for name, ts in r["rows"].items():
        row(name, ts)
    notes = []
    if "cli_scaling_runs" in r:
        runs = r["cli_scaling_runs"]
        notes.append(f"whole-command scaling of `ctrplan evaluate --model standard`, default jobs over `--jobs 1`: "
                     f"{np.median(runs):.2f}x (run by run {', '.join(f'{x:.2f}' for x in runs)}); process start "
                     f"subtracted {r['process_start_s']['jobs_1']:.2f} s (`--jobs 1`), "
                     f"{r['process_start_s']['default_jobs']:.2f} s (default jobs)")
    if "batch_scaling" in r:
        notes.append(f"the batch call alone (`solve_standard_batch` with the stability screen), 2 threads over 1: "
                     f"{r['batch_scaling']:.2f}x")
    b8 = r["rows"].get("full bound, in-process, 8x8x8")
    if b8:
        notes.append(f"8x8x8 bound, slowest over median: {np.max(b8) / np.median(b8):.1f}")
    bt = res.get("batch_throughput")
    if bt:
        notes.append(f"`solve_standard_batch` on {bt['configurations']} random configurations, no multistart: "
                     + ", ".join(f"{np.median(v):.0f} configurations/s on {k} thread(s)"
                                 for k, v in bt["rates_per_s"].items()))
    lines += [""] + [f"- {n}." for n in notes]
    return "\n".join(lines)


MAKERS = {"sweep-table": sweep_table, "ha-table": ha_table, "robot-files-table": robot_files_table,
          "discretization-table": discretization_table, "speed-table": speed_table}


def render(doc: str, names=None) -> str:
    """``doc`` with every table of ``names`` (default all) whose results file exists rewritten
    between its markers."""
    for name, make in MAKERS.items():
        if names is not None and name not in names:
            continue
        if not SOURCES[name].exists():
            continue
        table = make(json.loads(SOURCES[name].read_text()))
        block = f"<!-- {name} -->\n{table}\n<!-- /{name} -->"
        pattern = re.compile(rf"<!-- {name} -->.*?<!-- /{name} -->|<!-- {name} -->", re.S)
        doc = pattern.sub(lambda _: block, doc, count=1)
    return doc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args(argv)
    status = 0
    for page in dict.fromkeys(DOCS.values()):
        doc = page.read_text()
        new = render(doc, [n for n, p in DOCS.items() if p == page])
        if args.check:
            if new != doc:
                print(f"{page} differs from the results files; run python benchmarks/docs_tables.py")
                status = 1
        elif new != doc:
            page.write_text(new)
    return status


if __name__ == "__main__":
    sys.exit(main())
