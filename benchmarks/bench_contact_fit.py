"""Benchmark: the contact-model fits of the discrepancy workflow, this checkout against another
commit, side by side.

The fits that dominate the workflow on a three-tube robot: on Ha's measured trajectory
(``../shared/data/ha-three-tube-trajectory``, 48 samples evenly chosen, Table II nominal robot
file, Ha, Fagogenis & Dupont 2019), with the code of each checkout,

- ``clearance``: the tube parameters (in-plane precurvatures, bending-stiffness ratios; with the
  registration for data in a tracker frame) fitted with the clearance model (as the workflow's
  contact-baseline refit), from the file's values;
- ``grid``: the friction coefficients by the coarse grid and its refinements
  (:func:`ctrplan.discrepancy.fits.gridsearch.grid_search_friction`, the friction candidate's first
  step);
- ``refine``: the tube parameters and the friction coefficients together with the friction model
  from the grid's point (the candidate's second step),

each within the workflow's default budget of model evaluations. Each run is a child process per
checkout (its own numba cache, warmed by a first run that is not counted), the two checkouts
alternating, so that both see the same machine. Prints every run, mean, median, p90 and max per
fit and checkout, the ratio of medians, the load average, and the fitted values of both
checkouts side by side.

    python benchmarks/bench_contact_fit.py [--base main] [--runs 2]
                                           [--results benchmarks/results/contact-fit.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _checkouts import ROOT, child_env, worktree  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"
ROBOT = ROOT / "model" / "ha2019-table2-nominal.toml"
SAMPLES = 48

# The child: the three fits with the code of the checkout on PYTHONPATH; one JSON line out.
_CHILD = r'''
import json, sys, time
import numpy as np
import ctrplan
root, robot_file, data_file, samples = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
if not ctrplan.__file__.startswith(root):
    raise RuntimeError(f"ctrplan imported from {ctrplan.__file__}, not from {root}")
from ctrplan.io.robot_file import load_robot
from ctrplan.discrepancy.measured.data import load_measured_data
from ctrplan.discrepancy.fits.calibrate import calibrate
from ctrplan.discrepancy.fits.gridsearch import grid_search_friction
from ctrplan.discrepancy.options import DiscrepancyOptions
from ctrplan.discrepancy.setup import default_baseline_parameters
opts = DiscrepancyOptions()
settings = opts.settings()
try:                      # the fits' option objects
    from ctrplan.discrepancy.fits.fitoptions import FitRun, FitStart, GridSpec
    quiet = FitRun(settings=settings, uncertainty=False)

    def fit(model, names, budget, initial=None, register=False, warm=False):
        return calibrate(robot, sub, model, names, start=FitStart(initial, register=register, warm=warm),
                         max_evaluations=budget, run=quiet)

    def grid(fixed):
        return grid_search_friction(robot, sub, fixed, grid=GridSpec(coarse=opts.friction_grid,
                                    search_samples=opts.friction_search_samples, seed=0), run=quiet)
except ImportError:       # a checkout whose fits take every option as a keyword
    def fit(model, names, budget, initial=None, register=False, warm=False):
        return calibrate(robot, sub, model, names, initial=initial, settings=settings, max_evaluations=budget,
                         uncertainty=False, register=register, warm=warm)

    def grid(fixed):
        return grid_search_friction(robot, sub, fixed, settings=settings, coarse=opts.friction_grid,
                                    search_samples=opts.friction_search_samples, seed=0, uncertainty=False)
robot = load_robot(robot_file)
data = load_measured_data(data_file, robot)
sub = data.take(np.linspace(0, data.n_samples - 1, samples).astype(int))
register = data.frame == "tracker"
tubes = default_baseline_parameters(robot, register)
mus = tuple(f"mu_{k + 1}" for k in range(robot.n_tubes - 1))
out = {}
t = time.perf_counter()
c = fit("clearance", tubes, opts.max_contact_evaluations, register=register)
out["clearance"] = {"seconds": time.perf_counter() - t, "evaluations": c.evaluations, "cost": c.cost,
                    "converged": c.converged, "values": dict(zip(c.names, c.values.tolist()))}
fixed = dict(zip(c.names, c.values))
t = time.perf_counter()
g = grid(fixed)
out["grid"] = {"seconds": time.perf_counter() - t, "evaluations": g.evaluations, "cost": g.cost,
               "converged": g.converged, "values": dict(zip(g.names, g.values.tolist()))}
t = time.perf_counter()
names = tubes + mus
init = np.concatenate([c.values, g.values])
r = fit("friction", names, opts.max_contact_evaluations, initial=init, warm=True)
out["refine"] = {"seconds": time.perf_counter() - t, "evaluations": r.evaluations, "cost": r.cost,
                 "converged": r.converged, "values": dict(zip(r.names, r.values.tolist()))}
print(json.dumps(out))
'''

FITS = ("clearance", "grid", "refine")


def _run(code, cache):
    res = subprocess.run([sys.executable, "-c", _CHILD, str(code), str(ROBOT), str(DATA), str(SAMPLES)],
                         env=child_env(code, cache), cwd=str(code), capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def _stats(values):
    v = sorted(values)
    n = len(v)
    return {"mean": sum(v) / n, "median": v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2]),
            "p90": v[min(n - 1, int(round(0.9 * (n - 1))))], "max": v[-1]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default="main", help="git revision to compare with (default main)")
    ap.add_argument("--runs", type=int, default=2, help="counted runs per checkout")
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "contact-fit.json"))
    args = ap.parse_args(argv)
    if not DATA.exists():
        sys.exit(f"{DATA} not found: this benchmark needs Ha's measured trajectory beside the repository")
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    base_rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.base], capture_output=True,
                              text=True, check=True).stdout.strip()
    print(f"load average at start: {os.getloadavg()[0]:.2f}", flush=True)
    with tempfile.TemporaryDirectory() as tmp, worktree(args.base, Path(tmp) / "base") as base:
        codes = {"base": (base, Path(tmp) / "cache-base"), "head": (ROOT, Path(tmp) / "cache-head")}
        for label, (code, cache) in codes.items():
            _run(code, cache)   # compiles the kernels into this checkout's cache; not counted
            print(f"  {label}: warm-up run done", flush=True)
        runs = {label: [] for label in codes}
        for i in range(args.runs):
            for label, (code, cache) in codes.items():
                r = _run(code, cache)
                runs[label].append(r)
                print(f"  run {i + 1} {label}: " + ", ".join(f"{f} {r[f]['seconds']:.1f} s ({r[f]['evaluations']} ev)"
                                                              for f in FITS), flush=True)
    load = os.getloadavg()[0]
    summary = {}
    for f in FITS:
        s = {label: _stats([r[f]["seconds"] for r in runs[label]]) for label in runs}
        summary[f] = {**s, "ratio_of_medians": s["head"]["median"] / s["base"]["median"]}
    total = {label: _stats([sum(r[f]["seconds"] for f in FITS) for r in runs[label]]) for label in runs}
    summary["all three"] = {**total, "ratio_of_medians": total["head"]["median"] / total["base"]["median"]}
    print(f"\nload average at end: {load:.2f}; seconds over {args.runs} runs (mean / median / p90 / max)")
    for f, s in summary.items():
        print(f"  {f:10s} base {args.base} ({base_rev}): " + " / ".join(f"{s['base'][k]:.1f}" for k in
                                                                       ("mean", "median", "p90", "max"))
              + f"; head ({head}): " + " / ".join(f"{s['head'][k]:.1f}" for k in ("mean", "median", "p90", "max"))
              + f"; head / base {s['ratio_of_medians']:.3f}")
    print("\nfitted values (last run): base | head")
    last = {label: runs[label][-1] for label in runs}
    for f in FITS:
        b, h = last["base"][f], last["head"][f]
        print(f"  {f}: cost {b['cost']:.6g} | {h['cost']:.6g}; evaluations {b['evaluations']} | {h['evaluations']}; "
              f"converged {b['converged']} | {h['converged']}")
        for n in b["values"]:
            print(f"    {n:20s} {b['values'][n]:.6g} | {h['values'].get(n, float('nan')):.6g}")
    Path(args.results).write_text(json.dumps({
        "command": "python benchmarks/bench_contact_fit.py" + (f" --base {args.base}" if args.base != "main" else "")
                   + (f" --runs {args.runs}" if args.runs != 2 else ""),
        "base": base_rev, "head": head, "samples": SAMPLES, "robot_file": ROBOT.name, "load_average_end": load,
        "summary": summary, "runs": runs}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
