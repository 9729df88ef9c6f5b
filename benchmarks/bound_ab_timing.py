"""The full bound of this checkout against another commit, side by side.

Absolute times on the shared machines drift by 2-3x between runs, so a speed change of the
contact solver is measured against the code before it in one run: the other commit is checked
out into a temporary git worktree, and the two codes run alternately in separate processes
(``--runs`` each, one after the other), each timing ``evaluate_bound`` and ``solve_standard``
(with its multistart stability search) at every configuration of the grid in CPU time (``time.process_time``). Each code's figure is the per-configuration
minimum over its runs, which removes most of the load that other processes put on the machine.

Printed: mean, median, p90 and max of those minima for both codes, the ratio of their medians
and the median of the per-configuration ratios, the run medians (to show the noise), outer and
Newton iterations per contact solve, unconverged solves, the largest tip difference between the
two codes [um] (converged solutions) and the load average at the start and the end. Accuracy:
every tip of both codes against a tight solve of this checkout (outer and complementarity
tolerances 1e-9, ``TIGHT``) [um], and whether the two codes leave the same configurations
unconverged and flag the same ones as folds (more than one standard-model equilibrium,
``diagnostics.unstable``).

Run:  OPENBLAS_NUM_THREADS=1 python benchmarks/bound_ab_timing.py --base REV [--runs 6] [--grid 4|8]
Grids: the paper's 4x4x4 grid (Section IV-D, Table II robot) or the 8x8x8 grid
(``paper_section_4d.grid_8x8x8``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _checkouts import ROOT, child_env, worktree  # noqa: E402


def _configurations(robot, grid):
    """(alpha, beta) pairs of the grid [rad], [m]."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from paper_section_4d import grid_4x4x4, grid_8x8x8
    if grid == "4":
        _, Q = grid_4x4x4(robot)
        return [robot.configuration(q) for q in Q]
    return grid_8x8x8()


# The reference of the accuracy check: the same bound solved to 1e-9 [m] centerline change and
# 1e-9 scaled complementarity residual (the defaults are 1e-6).
TIGHT = dict(outer_tol=1e-9, complementarity_tol=1e-9, max_outer_iterations=200)


def child(out, grid, tight=False):
    """Time the bound at every configuration with the ``ctrplan`` on ``PYTHONPATH``; save to ``out``.

    Raises
    ------
    RuntimeError
        If ``ctrplan`` was imported from elsewhere (the comparison would time one code twice)."""
    import ctrplan
    root = Path(os.environ["PYTHONPATH"]).resolve()
    if root not in Path(ctrplan.__file__).resolve().parents:
        raise RuntimeError(f"ctrplan imported from {ctrplan.__file__}, not from {root}")
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import ModelSettings, evaluate_bound, solve_standard
    robot = load_robot(ROOT / "model" / "ha2019-table2-nominal.toml")
    settings = ModelSettings(**TIGHT) if tight else ModelSettings()
    configs = _configurations(robot, grid)
    evaluate_bound(robot, *configs[0], settings)     # compile or load the kernels first
    solve_standard(robot, *configs[0], settings)
    T, tips, iters, T_std, unstable = [], [], [], [], []
    for a, b in configs:
        t0 = time.process_time()
        solve_standard(robot, a, b, settings)        # with the multistart stability search
        T_std.append(time.process_time() - t0)
        t0 = time.process_time()
        r = evaluate_bound(robot, a, b, settings)
        T.append(time.process_time() - t0)
        solves = [r.clearance] + [r.friction[k] for k in sorted(r.friction)]
        tips.append(np.array([s.tip_position for s in solves]))
        iters.append([(s.diagnostics.iterations, s.diagnostics.inner_iterations, s.diagnostics.converged)
                      for s in solves])
        unstable.append(bool(r.diagnostics.unstable))
    np.savez(out, T=np.array(T) * 1e3, T_std=np.array(T_std) * 1e3, tips=np.array(tips), iters=np.array(iters, dtype=float),
             unstable=np.array(unstable))


def _run(code_root, out, grid, cache_dir, tight=False):
    subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", str(out), "--grid", grid]
                   + (["--tight"] if tight else []),
                   check=True, env=child_env(code_root, cache_dir), cwd=str(code_root))
    return np.load(out)


def _stats(x, digits=1):
    return "  ".join(f"{name} {v:7.{digits}f}" for name, v in
                     (("mean", x.mean()), ("median", np.median(x)), ("p90", np.percentile(x, 90)), ("max", x.max())))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="git revision to compare against (e.g. a commit hash); required")
    ap.add_argument("--runs", type=int, default=6, help="runs of each code, alternated")
    ap.add_argument("--grid", choices=("4", "8"), default="4")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--tight", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child, args.grid, args.tight)
        return
    if not args.base:
        ap.error("--base is required (the git revision to compare against)")
    print(f"load average at the start: {os.getloadavg()}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        with worktree(args.base, tmp / "base") as base:
            runs = {"base": [], "this": []}
            for k in range(args.runs):
                for name, code, cache in (("base", base, tmp / "cache-base"), ("this", ROOT, tmp / "cache-this")):
                    runs[name].append(_run(code, tmp / f"{name}{k}.npz", args.grid, cache))
                    print(f"  run {k + 1} {name}: median {np.median(runs[name][-1]['T']):.1f} ms", flush=True)
            print(f"load average at the end of the timed runs: {os.getloadavg()}")
            ref = _run(ROOT, tmp / "tight.npz", args.grid, tmp / "cache-this", tight=True)
    T = {n: np.array([r["T"] for r in v]) for n, v in runs.items()}
    best = {n: t.min(axis=0) for n, t in T.items()}
    print(f"\nfull bound per configuration, {args.grid}x{args.grid}x{args.grid} grid, CPU time [ms], "
          f"per-configuration minimum over {args.runs} runs:")
    for n in ("base", "this"):
        it = runs[n][0]["iters"]
        print(f"  {n:5s} {_stats(best[n])}   outer/solve {it[:, :, 0].mean():.2f}  "
              f"Newton/solve {it[:, :, 1].mean():.1f}  unconverged solves {int((it[:, :, 2] == 0).sum())}")
        print(f"        run medians {np.round(np.median(T[n], axis=1), 1).tolist()}")
    print(f"  this / base: ratio of medians {np.median(best['this']) / np.median(best['base']):.3f}, "
          f"median per-configuration ratio {np.median(best['this'] / best['base']):.3f}")
    if all("T_std" in r for v in runs.values() for r in v):
        S = {n: np.array([r["T_std"] for r in v]).min(axis=0) for n, v in runs.items()}
        print(f"\nstandard model (multistart stability search) per configuration, CPU time [ms], "
              f"per-configuration minimum over {args.runs} runs:")
        for n in ("base", "this"):
            print(f"  {n:5s} {_stats(S[n], 3)}")
        print(f"  this / base: ratio of medians {np.median(S['this']) / np.median(S['base']):.3f}, "
              f"median per-configuration ratio {np.median(S['this'] / S['base']):.3f}")
        print(f"  full bound / own standard solve (this): median {np.median(best['this'] / S['this']):.1f}")
    ok = (runs["base"][0]["iters"][:, :, 2] == 1) & (runs["this"][0]["iters"][:, :, 2] == 1)
    diff = np.linalg.norm(runs["this"][0]["tips"] - runs["base"][0]["tips"], axis=2) * 1e6
    print(f"  tips, this against base, solves converged in both: max {diff[ok].max():.3f} um, "
          f"99th percentile {np.percentile(diff[ok], 99):.3f} um")
    ref_ok = ref["iters"][:, :, 2] == 1
    print(f"\naccuracy against a tight solve of this checkout ({TIGHT}; "
          f"{int((~ref_ok).sum())} solves of {ref_ok.size} without a tight reference):")
    for n in ("base", "this"):
        conv = runs[n][0]["iters"][:, :, 2] == 1
        both = conv & ref_ok
        err = np.linalg.norm(runs[n][0]["tips"] - ref["tips"], axis=2) * 1e6
        print(f"  {n:5s} tips of converged solves: max {err[both].max():.3f} um, "
              f"99th percentile {np.percentile(err[both], 99):.3f} um")
    bad = {n: set(np.nonzero(~np.all(runs[n][0]["iters"][:, :, 2] == 1, axis=1))[0].tolist()) for n in runs}
    fold = {n: set(np.nonzero(runs[n][0]["unstable"])[0].tolist()) if "unstable" in runs[n][0] else None
            for n in runs}
    print(f"  unconverged configurations: base {sorted(bad['base'])}, this {sorted(bad['this'])} "
          f"({'same' if bad['base'] == bad['this'] else 'DIFFERENT'})")
    if fold["base"] is not None:
        print(f"  folds (more than one standard equilibrium): base {len(fold['base'])}, this {len(fold['this'])} "
              f"({'same' if fold['base'] == fold['this'] else 'DIFFERENT'})")


if __name__ == "__main__":
    main()
