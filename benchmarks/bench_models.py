"""Model evaluation times and bound-map interpolation error, side by side in one run.

- median / 90th percentile time per configuration of the standard model (with and without the
  multistart equilibrium search), the clearance model, one friction solution and the full bound
  (clearance + all 2^(n-1) friction solutions), over the 4x4x4 grid of Section IV-D on the
  Table II robot, next to the paper's Table VIII MATLAB times;
- where the time of one full bound goes (profile of the contact solver);
- the interpolation error of the shipped bound map of the Table VII robot against the exact
  model at 100 random configurations (median and 95th percentile [mm]).

Run:  python benchmarks/bench_models.py [--ds 0.003] [--n-random 100] [--skip-map]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from ctrplan.io.robot_file import load_robot  # noqa: E402
from ctrplan.mechanics import (ModelSettings, evaluate_bound, solve_clearance, solve_friction,  # noqa: E402
                               solve_standard)
from paper_section_4d import PAPER_TIMES_S, grid_4x4x4  # noqa: E402


def _timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def model_times(robot, settings):
    _, Q = grid_4x4x4(robot)
    no_ms = settings.replace(multistart=0)
    rows = {"standard (stability: det + multistart)": [], "standard (stability: det only)": [],
            "clearance": [], "one friction solution": [], "full bound (clearance + 4 friction)": []}
    solve_standard(robot, *robot.configuration(Q[0]), settings)  # compile numba kernels
    for q in Q:
        a, b = robot.configuration(q)
        std, t = _timed(solve_standard, robot, a, b, settings)
        rows["standard (stability: det + multistart)"].append(t)
        _, t = _timed(solve_standard, robot, a, b, no_ms)
        rows["standard (stability: det only)"].append(t)
        if not std.diagnostics.ok:
            continue
        cl, t = _timed(solve_clearance, robot, a, b, settings, standard=std)
        rows["clearance"].append(t)
        _, t = _timed(solve_friction, robot, a, b, (1, -1), settings, standard=std, warm_start=cl)
        rows["one friction solution"].append(t)
        _, t = _timed(evaluate_bound, robot, a, b, settings)
        rows["full bound (clearance + 4 friction)"].append(t)
    paper = {"standard (stability: det + multistart)": PAPER_TIMES_S["standard"],
             "clearance": PAPER_TIMES_S["clearance"],
             "full bound (clearance + 4 friction)": PAPER_TIMES_S["friction"]}
    print(f"Model evaluation time per configuration: {robot.name}, 4x4x4 grid of Section IV-D, "
          f"ds = {settings.ds * 1e3:.1f} mm, 1 BLAS thread")
    print(f"{'model':<42} {'n':>3} {'median [ms]':>12} {'p90 [ms]':>10} {'max [ms]':>10} {'paper [ms]':>11}")
    for name, ts in rows.items():
        ts = np.asarray(ts) * 1e3
        p = f"{paper[name] * 1e3:.0f}" if name in paper else "-"
        print(f"{name:<42} {ts.size:>3} {np.median(ts):>12.2f} {np.percentile(ts, 90):>10.2f} "
              f"{ts.max():>10.2f} {p:>11}")
    return rows


def profile_bound(robot, settings):
    a, b = robot.configuration([2.0, 1.0, -0.06])
    pr = cProfile.Profile()
    pr.enable()
    for _ in range(3):
        evaluate_bound(robot, a, b, settings)
    pr.disable()
    s = io.StringIO()
    pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(8)
    print("\nWhere the time of a full bound goes (3 evaluations, by own time):")
    print("\n".join(line for line in s.getvalue().splitlines() if line.strip())[:3000])


def map_error(n_random, seed=0):
    from ctrplan.boundmap import MapSpec, interpolation_error, load_or_compute_bound_map

    robot_path = ROOT / "model" / "ha2019-table7-calibrated.toml"
    robot = load_robot(robot_path)
    settings = ModelSettings(ds=3e-3)
    res = MapSpec((16, 16, 14), "adaptive")     # the shipped map of scenarios/*.toml
    field, source, secs = load_or_compute_bound_map(robot_path, robot, res, settings)
    t0 = time.perf_counter()
    err = interpolation_error(field, robot, evaluate_bound, n=n_random, seed=seed, settings=settings)
    dt = time.perf_counter() - t0
    e = np.asarray(err.errors) * 1e3
    print(f"\nBound map of {robot.name} ({source}, resolution {res}, "
          f"{int(field.valid.sum())}/{field.valid.size} nodes valid):")
    print(f"  interpolation error of the friction bound at {e.size} random valid configurations "
          f"(seed {seed}): median {np.median(e):.3f} mm, 95th percentile {np.percentile(e, 95):.3f} mm, "
          f"max {e.max():.3f} mm ({err.n_invalid} invalid draws skipped; {dt:.0f} s)")
    meta = field.metadata or {}
    if "compute_time_s" in meta:
        print(f"  map computed in {meta['compute_time_s']:.0f} s")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ds", type=float, default=3e-3)
    ap.add_argument("--n-random", type=int, default=100)
    ap.add_argument("--skip-map", action="store_true")
    args = ap.parse_args(argv)
    robot = load_robot(ROOT / "model" / "ha2019-table2-nominal.toml")
    settings = ModelSettings(ds=args.ds)
    model_times(robot, settings)
    profile_bound(robot, settings)
    if not args.skip_map:
        map_error(args.n_random)


if __name__ == "__main__":
    main()
