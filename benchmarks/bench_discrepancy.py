"""Benchmark: the whole discrepancy workflow on the paper-protocol synthetic data.

Generates the paper's protocol (8 x 8 x 8 joint grid x 4 approach directions, 4 x 4 x 4
calibration subset) from the Table VII robot with friction mu = (0.22, 0.12) and the EM-sensor
noise, then runs ``ctrplan discrepancy`` on it with the friction-free model, and prints where the
time goes (each step's wall time, from the workflow's own log lines) and the outcome.

    python benchmarks/bench_discrepancy.py [--grid 8] [--jobs 2] [--out out/bench-discrepancy]
                                           [--data FILE]

``--data`` reuses data written earlier by ``ctrplan synth --robot model/ha2019-table7-calibrated.toml
--grid 8 --mu 0.22,0.12`` instead of generating it.

Target: the whole workflow within 30 minutes on a 2-core machine.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=8)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench-discrepancy"))
    ap.add_argument("--data", default=None, help="paper-protocol CSV from `ctrplan synth` (default: generate)")
    args = ap.parse_args(argv)

    from ctrplan.discrepancy import SynthProtocol, synthesize, write_synth
    from ctrplan.discrepancy.outputs.report import write_report
    from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy
    from ctrplan.io.robot_file import load_robot, robot_to_toml

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    robot = load_robot(ROOT / "model" / "ha2019-table7-calibrated.toml")
    t0 = time.perf_counter()
    if args.data is None:
        res = synthesize(robot, {"friction": {"mu_1": 0.22, "mu_2": 0.12}}, protocol=SynthProtocol.paper(args.grid),
                         seed=0, n_jobs=args.jobs)
        data = out / "paper-protocol-friction.csv"
        write_synth(data, res)
        n_rows = len(res.frame)
    else:
        data = Path(args.data)
        with data.open() as fh:
            n_rows = sum(1 for _ in fh) - 1
    t_synth = time.perf_counter() - t0
    model = out / "table7-without-friction.toml"
    model.write_text(robot_to_toml(robot.replace(friction_coefficients=(0.0, 0.0)),
                                   header="Table VII robot with friction switched off (benchmark input)"))

    marks = []

    class Marks(logging.Handler):
        """Each message of the workflow with the time it came."""

        def emit(self, record):
            line = record.getMessage()
            marks.append((time.perf_counter(), line))
            print(f"[{time.perf_counter() - t1:7.1f} s] {line}", flush=True)

    package = logging.getLogger("ctrplan")
    package.addHandler(Marks(logging.INFO))
    package.setLevel(logging.INFO)
    t1 = time.perf_counter()
    result = run_discrepancy(model, data, out / "report", DiscrepancyOptions(n_jobs=args.jobs), progress=False)
    write_report(result, out / "report")
    results = result.to_dict()
    total = time.perf_counter() - t1

    print()
    print(f"synthetic data: {n_rows} samples {'in %.0f s' % t_synth if args.data is None else 'from ' + str(data)} "
          f"(not part of the workflow)")
    print(f"workflow total: {total:.0f} s = {total / 60:.1f} min (target 30 min), {args.jobs} jobs")
    print("where the time goes (wall time until the next step starts):")
    for (ta, line), (tb, _) in zip(marks, marks[1:] + [(t1 + total, "")]):
        if tb - ta > 1.0:
            print(f"  {tb - ta:7.1f} s  {line[:110]}")
    b, a = results["test_split"]["before"], results["test_split"]["after"]
    print(f"verdict: {results['verdict']}; named: {results['named_label']}; test-split tip error mean {b['position_mean_mm']:.2f} -> "
          f"{a['position_mean_mm']:.2f} mm, max {b['position_max_mm']:.2f} -> {a['position_max_mm']:.2f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
