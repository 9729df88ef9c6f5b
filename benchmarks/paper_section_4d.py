"""Reproduce Section IV-D of Ha, Fagogenis & Dupont 2019 (three-tube robot of Table II).

A 4x4x4 uniform grid over (alpha_2, alpha_3, beta_3), clearances 0.0425 and 0.0625 mm,
mu = 0.2. Prints mean (std) and max tip-position [mm] and tip-tangent [deg] differences of the
clearance model and of the friction model (all four directions) against the zero-clearance
model, and the median evaluation time per configuration of each model next to the paper's
Table VIII MATLAB times.

Run:  python benchmarks/paper_section_4d.py [--ds 0.003] [--robot model/ha2019-table2-nominal.toml]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ctrplan.io.robot_file import load_robot  # noqa: E402
from ctrplan.mechanics import ModelSettings, all_eta, solve_clearance, solve_friction, solve_standard  # noqa: E402
from ctrplan.mechanics._lie import angle_between  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the frozen reference ctrplan_reference (tests/, not installed)

from ctrplan_reference.paper_grids import PAPER_TIMES_S, grid_4x4x4  # noqa: E402
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default=str(ROOT / "model" / "ha2019-table2-nominal.toml"))
    ap.add_argument("--ds", type=float, default=3e-3, help="arc-length step [m]")
    args = ap.parse_args(argv)
    robot = load_robot(args.robot)
    settings = ModelSettings(ds=args.ds)
    names, Q = grid_4x4x4(robot)
    rows = {"clearance": ([], []), "friction": ([], [])}
    times = {"standard": [], "clearance": [], "friction": []}
    skipped = []
    for q in Q:
        alpha, beta = robot.configuration(q)
        t0 = time.perf_counter()
        std = solve_standard(robot, alpha, beta, settings)
        times["standard"].append(time.perf_counter() - t0)
        if not std.diagnostics.ok:
            skipped.append((q, std.diagnostics.message))
            continue
        t0 = time.perf_counter()
        cl = solve_clearance(robot, alpha, beta, settings, standard=std)
        times["clearance"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        fr = [solve_friction(robot, alpha, beta, eta, settings, standard=std, warm_start=cl)
              for eta in all_eta(robot.n_tubes)]
        # per configuration, as the paper: clearance solve plus all friction directions
        times["friction"].append(time.perf_counter() - t0 + times["clearance"][-1])
        for model, sols in (("clearance", [cl]), ("friction", fr)):
            for s in sols:
                if not s.diagnostics.converged:
                    skipped.append((q, s.diagnostics.message))
                rows[model][0].append(np.linalg.norm(s.tip_position - std.tip_position) * 1e3)
                rows[model][1].append(np.degrees(angle_between(s.tip_tangent, std.tip_tangent)))
    print(f"Section IV-D reproduction: {robot.name}, {len(Q)} configurations "
          f"({' x '.join(names)} = 4x4x4), ds = {args.ds * 1e3:.2f} mm, "
          f"clearances {', '.join(f'{c * 1e3:.4f}' for c in robot.clearances)} mm, "
          f"mu {', '.join(f'{m:.2f}' for m in robot.friction_coefficients)}")
    print(f"{'model':<10} {'n':>4} {'pos mean (std) [mm]':>22} {'pos max [mm]':>13} "
          f"{'tan mean (std) [deg]':>22} {'tan max [deg]':>14}")
    for model, (dp, dt) in rows.items():
        dp, dt = np.asarray(dp), np.asarray(dt)
        print(f"{model:<10} {dp.size:>4} {f'{dp.mean():.2f} ({dp.std():.2f})':>22} {dp.max():>13.2f} "
              f"{f'{dt.mean():.2f} ({dt.std():.2f})':>22} {dt.max():>14.2f}")
    print()
    print(f"{'model':<10} {'median time / configuration [s]':>32} {'paper Table VIII [s]':>22} {'speed-up':>9}")
    for model, ts in times.items():
        med = float(np.median(ts))
        print(f"{model:<10} {med:>32.4f} {PAPER_TIMES_S[model]:>22.2f} {PAPER_TIMES_S[model] / med:>8.0f}x")
    print("(friction: clearance solve plus all four friction solutions; machine: this one, 1 BLAS thread)")
    if skipped:
        print(f"\n{len(skipped)} flagged solves (unstable or not converged):")
        for q, msg in skipped:
            print(f"  q = {np.round(q, 4)}: {msg}")


if __name__ == "__main__":
    main()
