"""Time of ``ctrplan plan`` on each shipped scenario, split into its phases.

Runs :func:`ctrplan.pipeline.run_plan` (what ``ctrplan plan SCENARIO`` runs) on every
``scenarios/*.toml`` and reads the phase times it reports in its summary
(``summary.json``):

- bound map: loading the shipped map (or computing it if none matches), ``times_s.bound_map``;
- inverse kinematics of the goals, ``times_s.inverse_kinematics``;
- planner: the bound-aware and the bound-blind plans including ordering
  (``bound_aware.planning_time_s`` + ``bound_blind.planning_time_s``);
- exact model at the ordered waypoints (``*.exact_model_time_s``);
- the rest (start check, trajectory, route statistics): total minus the above;
- wall: the whole call, including drawing the figures and writing the files.

Each scenario runs once, in this process, in the order given; the first pays the imports and
numba warm-up. Timings on a shared 2-core machine are noisy.

Usage::

    python benchmarks/bench_planning.py                     # all shipped scenarios
    python benchmarks/bench_planning.py scenarios/obstacles.toml --no-blind
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenarios", nargs="*", help="scenario files (default: scenarios/*.toml)")
    ap.add_argument("--no-blind", action="store_true", help="skip the bound-blind comparison plan")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="workers if a map must be computed")
    ap.add_argument("--out", default=None, help="output folder (default: a temporary folder)")
    args = ap.parse_args(argv)

    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    t0 = time.perf_counter()
    from ctrplan.pipeline import run_plan

    import_s = time.perf_counter() - t0
    paths = [Path(p) for p in args.scenarios] or sorted((REPO / "scenarios").glob("*.toml"))
    rows = []
    with tempfile.TemporaryDirectory(prefix="ctrplan-bench-plan-") as tmp:
        out_root = Path(args.out) if args.out else Path(tmp)
        for path in paths:
            t = time.perf_counter()
            s = run_plan(path, out_dir=out_root / path.stem, n_jobs=args.jobs, compare_blind=not args.no_blind,
                         echo=lambda msg: None)
            wall = time.perf_counter() - t
            plans = [s[m] for m in ("bound_aware", "bound_blind") if m in s]
            planner = sum(p["planning_time_s"] for p in plans)
            exact = sum(p["exact_model_time_s"] for p in plans)
            times = s["times_s"]
            rest = times["total"] - times["bound_map"] - times["inverse_kinematics"] - planner - exact
            rows.append((path.name, s["bound_map"]["source"], times["bound_map"], times["inverse_kinematics"],
                         planner, exact, rest, times["total"], wall))
            print(f"{path.name}: done in {wall:.1f} [s]", file=sys.stderr)
    print(f"imports {import_s:.1f} [s]; plans: {'bound-aware' if args.no_blind else 'bound-aware + bound-blind'}")
    head = ("scenario", "map", "map [s]", "IK [s]", "planner [s]", "exact [s]", "rest [s]", "total [s]", "wall [s]")
    print(f"{head[0]:<18} {head[1]:<8} " + " ".join(f"{h:>11}" for h in head[2:]))
    for name, source, *vals in rows:
        print(f"{name:<18} {source:<8} " + " ".join(f"{v:>11.3f}" for v in vals))
    return 0


if __name__ == "__main__":
    sys.exit(main())
