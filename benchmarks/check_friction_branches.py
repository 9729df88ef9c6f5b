"""Is every friction solution of a grid the one friction builds up from the clearance solution?

For each configuration of the paper's 4x4x4 grid or the 8x8x8 grid (Table II robot)
whose standard solution is stable and whose clearance solve converged, every friction solution
of ``evaluate_bound`` (all 2^(n-1) directions eta) is compared with the same solution followed in
mu from the clearance solution (``continue_friction``, docs/mechanics.md Sec. 5):

- a solve that converged directly should end where the branch ends, at the robot's mu (printed if
  the branch stops short or ends more than ``--tol-um`` away);
- a solve that did not converge is printed with where its branch ends: a fold below the robot's mu
  (no equilibrium near the branch under maximal friction) or, if the branch reaches mu, a solver
  failure of the direct solve.

Then a summary and the time of the bounds and of the continuations [ms], and the slowest bounds
with how nonlinear their branches are: the largest, over eta, ratio of the tip's rate per unit mu
on the branch's last step to that on its first, or its inverse if larger (1 on a straight branch;
infinite where a branch ends at a fold; NaN where the configuration was skipped).

Exits with status 1 if a direct solve that did not converge has a branch that reaches mu (a
solver failure).

Run:  OPENBLAS_NUM_THREADS=1 python benchmarks/check_friction_branches.py [--grid 4|8] [--ds 3e-3] [--tol-um 10]
(about 10 s on the 4x4x4 grid and 1 min on the 8x8x8 grid at the default step, one thread)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from paper_section_4d import grid_4x4x4, grid_8x8x8  # noqa: E402

from ctrplan.io.robot_file import load_robot  # noqa: E402
from ctrplan.mechanics import ModelSettings, continue_friction, evaluate_bound  # noqa: E402

ROBOT = ROOT / "model" / "ha2019-table2-nominal.toml"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", choices=("4", "8"), default="8",
                    help="4x4x4 (paper, Sec. IV-D) or 8x8x8 (paper_section_4d.grid_8x8x8)")
    ap.add_argument("--ds", type=float, default=3e-3, help="largest arc-length step [m]")
    ap.add_argument("--tol-um", type=float, default=10.0,
                    help="largest distance [um] of a directly converged tip from its branch's end")
    args = ap.parse_args(argv)
    robot = load_robot(ROBOT)
    settings = ModelSettings(ds=args.ds)
    if args.grid == "4":
        _, q = grid_4x4x4(robot)
        configs = [robot.configuration(x) for x in q]
    else:
        configs = grid_8x8x8()
    # compile or load the kernels once, untimed
    b0 = evaluate_bound(robot, *configs[0], settings)
    continue_friction(robot, *configs[0], (1,) * (robot.n_tubes - 1), settings, standard=b0.standard)
    print(f"load average at the start: {os.getloadavg()}")
    t_bound, t_cont, growth, outer = [], [], [], []
    direct_ok, on_branch, far, folds, solver_failures, skipped = 0, 0, [], [], [], 0
    for i, (alpha, beta) in enumerate(configs):
        t0 = time.perf_counter()
        b = evaluate_bound(robot, alpha, beta, settings)
        t_bound.append(time.perf_counter() - t0)
        outer.append(b.diagnostics.iterations)
        growth.append(np.nan)
        if b.standard.diagnostics.unstable or not b.clearance.diagnostics.converged:
            skipped += 1
            continue
        growth[-1] = 0.0
        for eta, f in b.friction.items():
            t0 = time.perf_counter()
            br = continue_friction(robot, alpha, beta, eta, settings, standard=b.standard, clearance=b.clearance)
            t_cont.append(time.perf_counter() - t0)
            d_um = np.linalg.norm(br.solution.tip_position - f.tip_position) * 1e6
            rate = br.tip_sensitivity
            r = rate[-1] / rate[0] if br.reached and rate[0] > 0 and rate[-1] > 0 else np.inf
            growth[-1] = max(growth[-1], r, 1.0 / r)
            where = (f"configuration {i}, alpha {np.round(np.degrees(alpha), 1)} deg, "
                     f"beta {np.round(np.asarray(beta) * 1e3, 2)} mm, eta {eta}")
            if f.diagnostics.converged:
                direct_ok += 1
                if br.reached and d_um <= args.tol_um:
                    on_branch += 1
                else:
                    far.append(d_um)
                    print(f"converged off its branch: {where}: {br.message}; direct tip {d_um / 1e3:.3f} mm "
                          f"from the branch's end ({f.diagnostics.iterations} outer iterations)")
            elif br.reached:
                solver_failures.append(where)
                print(f"SOLVER FAILURE: {where}: the branch reaches mu ({br.solves} solves) but the direct "
                      f"solve did not converge ({f.diagnostics.message})")
            else:
                folds.append(where)
                print(f"fold: {where}: {br.message}")
    print(f"load average at the end: {os.getloadavg()}")
    print(f"\n{len(configs)} configurations, {skipped} skipped (standard model unstable or clearance "
          f"not converged); {direct_ok} friction solves converged directly, {on_branch} of them at their "
          f"branch's end within {args.tol_um:g} um, {len(far)} off it"
          + (f" (up to {max(far) / 1e3:.3f} mm)" if far else ""))
    print(f"unconverged solves: {len(folds)} at a fold of their branch below mu, {len(solver_failures)} "
          f"solver failures (branch reaches mu)")
    for name, t in (("bound", t_bound), ("continuation", t_cont)):
        t = np.array(t) * 1e3
        print(f"{name:12s} [ms]: mean {t.mean():.1f}  median {np.median(t):.1f}  p90 {np.percentile(t, 90):.1f}  "
              f"max {t.max():.1f}  (n = {t.size})")
    _slow_tail(configs, np.array(t_bound) * 1e3, np.array(growth), np.array(outer))
    return 1 if solver_failures else 0


def _slow_tail(configs, t_ms, growth, outer, n=10):
    """The slowest bounds with their branches' nonlinearity, and how the two go together."""
    from scipy.stats import spearmanr
    print(f"\n{n} slowest bounds (median {np.median(t_ms):.1f} ms):")
    for i in np.argsort(t_ms)[::-1][:n]:
        alpha, beta = configs[i]
        change = (f"{growth[i]:.2f}x" if np.isfinite(growth[i]) else
                  "infinite (a fold)" if np.isinf(growth[i]) else "- (skipped)")
        print(f"  configuration {i}: alpha {np.round(np.degrees(alpha), 1)} deg, beta_n {beta[-1] * 1e3:.2f} mm: "
              f"{t_ms[i]:.1f} ms, {outer[i]} outer iterations, branch rate change {change}")
    ok = np.isfinite(growth)
    rho_t, rho_o = spearmanr(t_ms[ok], growth[ok])[0], spearmanr(outer[ok], growth[ok])[0]
    print(f"Spearman correlation with the rate change, over the {ok.sum()} configurations whose branches "
          f"all reach mu: time {rho_t:.2f}, outer iterations {rho_o:.2f}")
    for q in (1.5, 2.0):
        sel = ok & (growth > q)
        if sel.any():
            print(f"  rate change > {q:g}x: {sel.sum()} configurations, median {np.median(t_ms[sel]):.1f} ms "
                  f"against {np.median(t_ms[ok & ~sel]):.1f} ms for the others")


if __name__ == "__main__":
    sys.exit(main())
