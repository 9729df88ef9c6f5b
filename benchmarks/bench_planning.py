"""``ctrplan plan`` on every shipped scenario, as a new user runs it, and how far the bound the
planner uses is from the exact model.

Part 1, per scenario (``scenarios/*.toml``): the command ``ctrplan plan SCENARIO --out DIR`` in a
fresh process (so the wall time includes process start and imports; compiled numba code comes
from its on-disk cache, warm after the first run), then from its ``summary.json``:

- wall [s]: the whole command; bound map [s]: finding (or computing) the map; planner [s]: the
  bound-aware plan (search, ordering, final check, repairs), and the bound-blind plan;
- validity calls, standard-model solves (search, repairs and final check) and collision time [s]
  (both plans and the goals' checks);
- max exact bound at the ordered waypoints [mm] (given the last motion, bound-aware plan) and the
  bound-aware joint path length [mm of the weighted metric].

Part 2, the bound maps of the shipped scenarios against the exact model
(:func:`ctrplan.boundmap.interpolation_error`): 200 configurations drawn uniformly from each
robot's joint box and valid in the exact model (seed 0), per quantity: median, p95, mean and max
of |map - exact| [mm], and how many of them the map refuses (exact valid, map invalid).

Part 3, per scenario: the bound the planner used at each waypoint (``planned_bound_m`` of
``path.csv``) against the exact one (``bound_position_m``), the same quantity.

Timings on a shared 2-core machine are noisy: run alone; the load average is printed before and
after.

Usage::

    python benchmarks/bench_planning.py                              # all shipped scenarios
    python benchmarks/bench_planning.py scenarios/obstacles.toml --skip-accuracy
    python benchmarks/bench_planning.py --repeat 3                   # 3 runs per scenario
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def run_scenario(path: Path, out: Path, blind: bool) -> tuple[float, dict, list]:
    """(wall [s], summary, path.csv rows) of ``ctrplan plan`` in a new process."""
    entry = Path(sys.executable).with_name("ctrplan")   # the console script of this environment
    cmd = ([str(entry)] if entry.exists() else [sys.executable, "-c", "from ctrplan.cli import run; run()"]) + \
        ["plan", str(path), "--out", str(out)] + ([] if blind else ["--no-blind"])
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO,
                          env=dict(os.environ, CTRPLAN_CACHE_DIR=str(REPO / ".cache")))
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    with open(out / "path.csv") as fh:
        rows = list(csv.DictReader(fh))
    return wall, summary, rows


def stats(x) -> str:
    x = np.asarray(x, dtype=float)
    return (f"mean {x.mean():8.2f}, median {np.median(x):8.2f}, p90 {np.percentile(x, 90):8.2f}, "
            f"max {x.max():8.2f}")


def accuracy(scenarios, n, jobs):
    from ctrplan.boundmap import interpolation_error, load_or_compute_bound_map
    from ctrplan.io.scenario import load_scenario
    from ctrplan.mechanics import ModelSettings, evaluate_bound
    from ctrplan.planning import map_spec

    seen = {}
    for path in scenarios:
        sc = load_scenario(path)
        settings = ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()
        field, source, _ = load_or_compute_bound_map(sc.robot_file, sc.robot, map_spec(sc), settings)
        if field.key in seen:
            continue
        t = time.perf_counter()
        errs = interpolation_error(field, sc.robot, evaluate_bound, n=n, seed=0, settings=settings,
                                   quantity=("position", "translation_last_position"), n_jobs=jobs, valid_only=True)
        seen[field.key] = (sc.robot.name, field, source, errs, time.perf_counter() - t)
    print(f"\nBound map versus the exact model, {n} random valid configurations per robot (seed 0) [mm]")
    print(f"{'robot':<28} {'map':<22} {'quantity':<26} {'median':>7} {'p95':>7} {'mean':>7} {'max':>7} "
          f"{'refused':>7} {'exact [s]':>9}")
    for robot, field, source, errs, secs in seen.values():
        grid = "x".join(map(str, field.shape)) + f" {field.metadata.get('spec', {}).get('placement', '')}"
        for q, e in errs.items():
            print(f"{robot:<28} {grid:<22} {q:<26} {e.median * 1e3:7.3f} {e.p95 * 1e3:7.3f} {e.mean * 1e3:7.3f} "
                  f"{e.max * 1e3:7.3f} {e.n_refused:7d} {secs:9.1f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenarios", nargs="*", help="scenario files (default: scenarios/*.toml)")
    ap.add_argument("--no-blind", action="store_true", help="skip the bound-blind comparison plan")
    ap.add_argument("--repeat", type=int, default=1, help="runs per scenario")
    ap.add_argument("--skip-accuracy", action="store_true", help="skip part 2 (the exact model at random states)")
    ap.add_argument("--n-random", type=int, default=200, help="random valid configurations per map (part 2)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="workers of the exact model in part 2")
    args = ap.parse_args(argv)
    paths = [Path(p).resolve() for p in args.scenarios] or sorted((REPO / "scenarios").glob("*.toml"))
    print(f"load average before: {os.getloadavg()}")
    results = {}
    with tempfile.TemporaryDirectory(prefix="ctrplan-bench-plan-") as tmp:
        for path in paths:
            for k in range(args.repeat):
                out = Path(tmp) / f"{path.stem}-{k}"
                wall, s, rows = run_scenario(path, out, not args.no_blind)
                results.setdefault(path.stem, []).append((wall, s, rows))
                print(f"{path.name} run {k + 1}: {wall:.1f} [s]", file=sys.stderr, flush=True)
    print(f"load average after: {os.getloadavg()}")

    print("\nctrplan plan per scenario (times in s; path in mm of the weighted joint metric)")
    head = ("scenario", "wall", "map", "IK", "aware", "blind", "valid. calls", "model solves", "collision",
            "max bound mm", "path mm", "repairs")
    print(f"{head[0]:<14}" + "".join(f"{h:>13}" for h in head[1:]))
    for name, runs in results.items():
        for wall, s, _ in runs:
            me = s["model_evaluations"]
            a = s["bound_aware"]
            b = s.get("bound_blind", {})
            vals = (wall, s["times_s"]["bound_map"], s["times_s"]["inverse_kinematics"], a["planning_time_s"],
                    b.get("planning_time_s", float("nan")), me["validity_calls"], me["standard_model_solves"],
                    me["collision_time_s"], a["max_bound_at_waypoints_mm"], a["joint_path_length_m"] * 1e3,
                    a["final_check"]["repairs"])
            print(f"{name:<14}" + "".join(f"{v:>13.0f}" if isinstance(v, int) else f"{v:>13.2f}" for v in vals))
        if len(runs) > 1:
            print(f"{'':<14}wall: {stats([r[0] for r in runs])}")
            print(f"{'':<14}bound-aware planner: {stats([r[1]['bound_aware']['planning_time_s'] for r in runs])}")
            same = all(r[2] == runs[0][2] for r in runs[1:])
            print(f"{'':<14}same path.csv in all {len(runs)} runs (same seed): {'yes' if same else 'NO'}")
        if "bound_blind" in runs[0][1]:
            b = runs[0][1]["bound_blind"]
            print(f"{'':<14}bound-blind: max bound {b['max_bound_at_waypoints_mm']:.2f} mm, path "
                  f"{b['joint_path_length_m'] * 1e3:.1f} mm")

    print("\nPlanned versus exact bound at the ordered waypoints (bound-aware plan; given the last motion) [mm]")
    print(f"{'scenario':<14} {'waypoints':>9} {'max exact':>10} {'max planned':>12} {'median |diff|':>14} "
          f"{'max |diff|':>11}")
    for name, runs in results.items():
        rows = runs[0][2]
        exact = np.array([float(r["bound_position_m"]) for r in rows]) * 1e3
        planned = np.array([float(r["planned_bound_m"]) if r["planned_bound_m"] else np.nan for r in rows]) * 1e3
        diff = np.abs(planned - exact)
        print(f"{name:<14} {len(rows):>9d} {np.nanmax(exact):>10.2f} {np.nanmax(planned):>12.2f} "
              f"{np.nanmedian(diff):>14.3f} {np.nanmax(diff):>11.3f}")

    if not args.skip_accuracy:
        accuracy(paths, args.n_random, args.jobs)
        print(f"load average at the end: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
