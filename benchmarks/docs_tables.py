"""The tables of docs/discrepancy.md, made from the results files of the benchmarks that measure them.

    python benchmarks/docs_tables.py          # rewrite the tables between their markers
    python benchmarks/docs_tables.py --check  # exit 1 when the docs differ from the results files

Each table sits between ``<!-- NAME -->`` and ``<!-- /NAME -->`` in docs/discrepancy.md:

- ``sweep-table``: ``benchmarks/results/discrepancy-sweep.json``
  (``benchmarks/bench_discrepancy_sweep.py``);
- ``ha-table``: ``benchmarks/results/ha-trajectory-discrepancy.json``
  (``benchmarks/ha_trajectory_discrepancy.py``);
- ``robot-files-table``: ``benchmarks/results/ha-robot-files.json`` (``benchmarks/ha_robot_files.py``).
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
           "robot-files-table": RESULTS / "ha-robot-files.json"}
OUTCOMES = ("named", "ambiguous with truth", "named wrong", "ambiguous without truth", "nothing")


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


def sweep_table(res: dict) -> str:
    """Confusion matrix and per-case sizes of the sweep."""
    m, s = res["matrix"], res["summary"]
    lines = ["| truth | " + " | ".join(OUTCOMES) + " |", "|---|" + "---|" * len(OUTCOMES)]
    for t, row in m.items():
        lines.append(f"| {t} | " + " | ".join(str(row[o]) for o in OUTCOMES) + " |")
    lines += ["", f"Truth named or in the ambiguous pair: {s['truth_found']} of {s['cases_with_effect']} cases with an "
                  f"effect; wrong names (including any name on noise only): {s['wrong_names']}.", "",
              "| truth | seed | hidden [SI] | verdict | fitted [SI] |", "|---|---|---|---|---|"]
    for c in res["cases"]:
        hidden = "; ".join(f"{k} = {v:.4g}" for e in c["hidden"].values() for k, v in e.items()) or "-"
        fitted = "; ".join(f"{k} = {v:.4g}" for e in c["fitted"].values() for k, v in e.items()) or "-"
        verdict = c["verdict"] + ("" if c["verdict"] == "none" else f": {c['named']}")
        if c["ambiguous_with"]:
            verdict += f" or {c['ambiguous_with']}"
        lines.append(f"| {c['truth']} | {c['seed']} | {hidden} | {verdict} | {fitted} |")
    return "\n".join(lines)


def ha_table(res: dict) -> str:
    """Verdict, candidates, test-split shrink next to Table VIII, noise, baseline changes."""
    verdict = res["verdict"] + ("" if res["verdict"] == "none" else f": {res['named']}")
    if res["ambiguous_with"]:
        verdict += f" or {res['ambiguous_with']}"
    lines = [f"Data: {res['n_samples']} samples ({res['data_file']}, SHA-256 {res['data_sha256'][:12]}...); "
             f"{res['split']}.", "", f"**Verdict: {verdict}.**"]
    if res.get("separated_by") and res["ambiguous_with"]:
        lines.append(f" Data that would separate them: {res['separated_by']}.")
    n = res["noise"]
    lines += ["", f"Noise: {n['description']}; out-of-fold baseline rms {n['out_of_fold_rms_mm']:.3f} mm; consistent "
                  f"with noise: {n['consistent']}" + (f" (F = {n['statistic']:.3g}, threshold {n['threshold']:.3g})"
                                                      if n["statistic"] is not None else "") + ".", "",
              "| candidate | fitted (95 % interval) | out-of-fold mean / max [mm] | improvement [mm + deg] (95 % CI) | p | "
              "eligible |", "|---|---|---|---|---|---|"]
    for e, c in res["candidates"].items():
        params = "; ".join(f"{k} = {_pm(p['value'], p['stderr'], p['unit'])}"
                           + (" (atypical)" if not p["in_typical_range"] else "")
                           + (" (at bound)" if p["at_bound"] else "") for k, p in c["parameters"].items()) or "nominal"
        ci = c["improvement_ci"]
        lines.append(f"| {c['label']} | {params} | {c['out_of_fold_mean_mm']:.2f} / {c['out_of_fold_max_mm']:.2f} | "
                     f"{c['improvement_mm_deg']:.3f} ({ci[0]:.3f}..{ci[1]:.3f}) | {c['p_value']:.4f} | "
                     f"{'yes' if c['eligible'] else 'no'} |")
    t = res["test_split"]
    lines += ["", f"Test split ({t['n_samples']} samples in {t['n_units']} units, untouched until the end; "
                  f"{t['label']}):", "",
              "| tip position error | before [mm] | after [mm] | shrink (95 % interval) | Ha et al. Table VIII (grid data) |",
              "|---|---|---|---|---|"]
    for stat, paper in (("mean", res["table_viii_shrink"]["mean"]), ("p95", None), ("max", res["table_viii_shrink"]["max"])):
        b, a, s = t["before"][f"{stat}_mm"], t["after"][f"{stat}_mm"], t["shrink"][stat]
        lines.append(f"| {stat} | {b['value']:.2f} ({b['ci'][0]:.2f}..{b['ci'][1]:.2f}) | {a['value']:.2f} "
                     f"({a['ci'][0]:.2f}..{a['ci'][1]:.2f}) | {100 * s['value']:.0f} % ({100 * s['ci'][0]:.0f}.."
                     f"{100 * s['ci'][1]:.0f} %) | {'-' if paper is None else f'{100 * paper:.0f} %'} |")
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
        lines += ["", "The history-aware prediction " + ("beats" if pc["history_beats_standard"] else "does not beat")
                  + " the standard model in mean and max on the test split: the written robot file's "
                  "[prediction_validation] " + ("lets" if pc["history_beats_standard"] else "does not let")
                  + " `ctrplan plan` aim with it."]
    b = res.get("bound")
    if b:
        raw, cal = b["raw_test"], b["test"]
        lines += ["", f"Friction bound of the written robot file on the test split ({raw['n']} samples): "
                      f"{100 * raw['covered']:.0f} % ({100 * raw['ci'][0]:.0f}..{100 * raw['ci'][1]:.0f} %) of the measured "
                      f"tips within b + {b['margin_mm']:.2f} mm, median e / (b + m) {raw['ratio']['median']:.2f}; calibrated "
                      f"bound {b['factor']:.3g} x (b + m) (target {100 * b['target']:.0f} %): "
                      f"{100 * cal['covered']:.0f} % ({100 * cal['ci'][0]:.0f}..{100 * cal['ci'][1]:.0f} %), {b['status']}, "
                      f"median size {cal['bound_median_m'] * 1e3:.2f} mm."]
    if res["cautions"]:
        lines += [""] + [f"- caution: {c}" for c in res["cautions"]]
    return "\n".join(lines)


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
                     f"{c['median_size_mm']:.2f} mm, {100 * c['test_coverage']:.0f} % ({100 * ci[0]:.0f}..{100 * ci[1]:.0f} %), "
                     f"{c['status']} |")
    lines += ["", "Standard-model mean error [mm] with one file's value(s) put into the other:", "",
              "| parameters | Table II value(s) | Table VII value(s) | Table II file with Table VII values | Table VII file "
              "with Table II values |", "|---|---|---|---|---|"]
    for w in res["swaps"]:
        lines.append(f"| {', '.join(w['parameters'])} | {', '.join(f'{v:.4g}' for v in w['table2'])} | "
                     f"{', '.join(f'{v:.4g}' for v in w['table7'])} | {w['table2_with_table7_values']['mean_mm']:.2f} | "
                     f"{w['table7_with_table2_values']['mean_mm']:.2f} |")
    return "\n".join(lines)


MAKERS = {"sweep-table": sweep_table, "ha-table": ha_table, "robot-files-table": robot_files_table}


def render(doc: str) -> str:
    """``doc`` with every table whose results file exists rewritten between its markers."""
    for name, make in MAKERS.items():
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
    doc = DOC.read_text()
    new = render(doc)
    if args.check:
        if new != doc:
            print(f"{DOC} differs from the results files; run python benchmarks/docs_tables.py")
            return 1
        return 0
    DOC.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
