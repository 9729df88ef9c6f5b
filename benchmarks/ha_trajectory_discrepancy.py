"""The discrepancy workflow on the measured trajectory of Ha et al.'s three-tube robot, with its
figures written to a results file in the repository (derived numbers only, never the data).

    python benchmarks/ha_trajectory_discrepancy.py [--data ../shared/data/ha-three-tube-trajectory/jointTipTrajectory_measured.txt]
                                                   [--robot model/ha2019-table2-nominal.toml] [--jobs 2]
                                                   [--out out/ha-trajectory-discrepancy]
                                                   [--results benchmarks/results/ha-trajectory-discrepancy.json]

It runs ``run_discrepancy`` with the default options (every registered candidate, the default
split, the noise estimated from the data's rests) plus the paper's friction coefficients
(0.22, 0.12, Table VII) as a reference for the history-aware prediction, writes the report to
``--out`` (its stages are reused when run again), and writes to ``--results``: the verdict, every
candidate's parameters with standard errors, out-of-fold figures and comparison with the
baseline, the baseline's prior and parameters with their change from the robot file, the noise
test, the test split's figures (the robot file with only a registration, the calibrated
baseline, the final model) with their t-intervals next to the paper's Table VIII (46 % mean,
49 % max, on grid data), the calibrated bound, the SHA-256 of the data file it came from and the
digest of the code that made it (:mod:`ctrplan.discrepancy.provenance`). ``docs/discrepancy.md``
quotes this file; ``tests/test_docs_results.py`` checks that they agree and that the code has not
changed since.

The data has no licence and is not in the repository: get it from github.com/hjhdog1/ConcentricTubes
(``jointTipTrajectory_measured_short.txt``).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"
#: Table VIII of Ha et al. 2019: the friction model's reduction of the standard model's error on
#: the paper's grid data (mean and max tip position error).
TABLE_VIII_SHRINK = {"mean": 0.46, "max": 0.49}


def summarize(res: dict, data_path: Path, robot_path: Path, seconds: float, command: str) -> dict:
    """The results file's content from a run's results (mm and degrees, as the report)."""
    from ctrplan.discrepancy.outputs import words
    from ctrplan.io.robot_file import file_hash

    def cand(c):
        table = {r["name"]: {"value": r["value"], "stderr": r.get("stderr"), "unit": r["unit"],
                             "in_typical_range": r["in_typical_range"], "at_bound": r["at_bound"]}
                 for r in c["parameter_table"]}
        imp = c["improvement_eq49"]
        return {"label": c["label"], "model": c["model"], "parameters": table,
                "out_of_fold_mean_mm": c["out_of_fold"]["position_mean_mm"],
                "out_of_fold_max_mm": c["out_of_fold"]["position_max_mm"],
                "reduction": imp["reduction"], "reduction_ci": imp["reduction_ci"],
                "improvement_mm_deg": imp["mean_difference"], "p_value": imp["p_value"],
                "holm": c.get("improvement_significant"), "eligible": c.get("eligible"), "typical": c["typical"],
                "at_bound": c["at_bound"], "widened": c.get("widened", [])}

    fig = res["test_split"]["figures"]
    b = res["baseline"]
    d, labels = res["decision"], words.labels_of(res["candidates"])
    comb = res.get("combination") or {}
    return {
        "command": command, "data_file": data_path.name, "data_sha256": file_hash(data_path),
        "robot_file": str(robot_path.relative_to(ROOT)) if robot_path.is_relative_to(ROOT) else str(robot_path),
        "n_samples": res["n_samples"], "split": words.split_text(res["split"]),
        "buffer": words.buffer_text(res["split"]),
        "n_folds": res["split"]["n_folds"], "verdict": res["verdict"], "named": res["named_effect"],
        "ambiguous_with": res["ambiguous_with"], "named_effects": res["named_effects"],
        "separated_by": words.separated_by(d, labels), "notes": [words.note(n, d, labels) for n in d["notes"]],
        "decision_cautions": [words.caution(c) for c in d["cautions"]], "rule": words.rule(d["rule"]),
        "best": res["decision"].get("best"),
        "noise": {"description": words.noise_text(res["noise"]["noise"]), "source": res["noise"]["noise"]["source"],
                  "noise_rms_mm": res["noise"]["noise_rms_mm"], "out_of_fold_rms_mm": res["noise"]["rms_mm"],
                  "consistent": res["noise"]["consistent"],
                  "statistic": (res["noise"]["test"] or {}).get("statistic"),
                  "threshold": (res["noise"]["test"] or {}).get("threshold")},
        "baseline": {"out_of_fold_mean_mm": b["out_of_fold"]["position_mean_mm"],
                     "prior_strength": b["prior_strength"], "prior_choices": b["prior_choices"],
                     "parameters": [{k: r.get(k) for k in ("name", "value", "stderr", "unit", "relative_change",
                                                           "in_typical_range", "at_bound", "fitted")}
                                    for r in b["parameter_table"]]},
        "candidates": {e: cand(c) for e, c in res["candidates"].items()},
        "pairs": {e: {"label": c["label"], "out_of_fold_mean_mm": c["out_of_fold"]["position_mean_mm"],
                      "reduction": c["improvement_eq49"]["reduction"], "p_value": c["improvement_eq49"]["p_value"],
                      "reverse_p_value": (c.get("reverse") or {}).get("p_value"), "significant": c.get("significant"),
                      "parameters": c["parameters"]}
                  for e, c in (comb.get("tried") or {}).items()},
        "dropped": comb.get("dropped"), "replaced_by": comb.get("replaced_by"),
        "test_split": {"label": res["test_split"]["label"], "file": fig["file"], "before": fig["before"],
                       "after": fig["after"], "shrink": fig["shrink"], "calibration_shrink": fig["calibration_shrink"],
                       "n_samples": fig["n_samples"], "n_units": fig["n_units"], "method": fig["method"]},
        "prediction": res["prediction"], "prediction_check": res.get("prediction_check"),
        "bound": None if not res.get("bound") else {k: res["bound"][k] for k in (
            "definition", "method", "target", "factor", "margin_mm", "status", "test", "raw_test", "translation_last")},
        "table_viii_shrink": TABLE_VIII_SHRINK, "cautions": [words.caution(c) for c in res["cautions"]],
        "provenance": res["provenance"],
        "seconds_this_invocation": seconds,     # stages of an earlier invocation are reused
        "stage_seconds": res.get("stage_seconds", {}), "stage_reused": res.get("stage_reused", {}),
        "load_average_end": os.getloadavg()[0],
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument("--robot", default=str(ROOT / "model" / "ha2019-table2-nominal.toml"))
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", default=str(ROOT / "out" / "ha-trajectory-discrepancy"))
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "ha-trajectory-discrepancy.json"))
    args = ap.parse_args(argv)
    data = Path(args.data).resolve()
    if not data.exists():
        print(f"no data at {data}: get jointTipTrajectory_measured_short.txt from github.com/hjhdog1/ConcentricTubes "
              f"and pass --data", file=sys.stderr)
        return 2
    from ctrplan.discrepancy.outputs.report import write_report
    from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy

    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)
    t0 = time.perf_counter()
    opts = DiscrepancyOptions(n_jobs=args.jobs, reference_friction=(0.22, 0.12))
    result = run_discrepancy(Path(args.robot).resolve(), data, args.out, opts, progress=False)
    write_report(result, args.out)
    seconds = time.perf_counter() - t0
    summary = summarize(result.to_dict(), data, Path(args.robot).resolve(), seconds,
                        "python benchmarks/ha_trajectory_discrepancy.py")
    out = Path(args.results)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(summary, indent=1, default=float) + "\n")
    s = summary["test_split"]
    print(f"\nverdict: {summary['verdict']} ({summary['named']}"
          + (f" or {summary['ambiguous_with']}" if summary["ambiguous_with"] else "") + ")")
    print(f"test split: robot file with a registration {s['file']['mean_mm']['value']:.2f} mm, calibrated baseline "
          f"{s['before']['mean_mm']['value']:.2f} mm, {s['label']} {s['after']['mean_mm']['value']:.2f} mm (shrink "
          f"{100 * s['shrink']['mean']['value']:.0f} %, paper Table VIII: 46 %); max {s['before']['max_mm']:.2f} -> "
          f"{s['after']['max_mm']:.2f} mm; {seconds:.0f} s; load average {os.getloadavg()[0]:.2f}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
