"""The command line's cost per configuration in units of Ha's C++ standard solve.

Measured by timing, beside this checkout, a reference commit whose cost in that unit is known.
The unit is one standard-model solve of the C++ implementation of hjhdog1/ConcentricTubes,
which is not in this project (no licence). The cost of commit 10e8828 (the last commit before
``evaluate`` solved the standard model in batch, 90fc8e6) is known in that unit, measured on
another machine: ``ctrplan evaluate --model friction --jobs 1`` on the 4x4x4 grid took 1269x the
C++ solve per configuration, and ``ctrplan evaluate --model standard --jobs 1`` on the 1307 rows
of the measured trajectory 45x (that commit solves one configuration at a time with the multistart
stability search and pays joblib and JSON checkpoint overhead per row). This script times that
commit and this checkout side by side, alternately, in separate processes, and converts:

    this checkout in C++ solves = (reference figure) x (this checkout's time / reference commit's time).

The two conversions (friction, standard) are independent estimates of the C++ solve's time on
this machine; both are printed, with the project's own single standard solve (determinant test
only) in the same unit for each (stated as 4-7x for the reference commit: a check of the
calibration). The conversion assumes that both codes slow down alike from one machine to another.
The printed targets are the project's speed goals in this unit: at most 300x (friction) and 2x
(standard).

Each command's time per configuration is (T(K rows) - T(1 row)) / (K - 1), both runs of the same
command and code, wall time: the process start, imports and loading of compiled kernels cancel.
Each T is the shortest of ``--repeat`` commands. The standard model reads the 1307 trajectory
rows ``--tile`` (4) times over for the reference commit and ``--this-tile`` (32) times over for
this checkout: once, they are 0.15 s of work behind about 1.1 s of process start, which alone
varies by 0.1 s (one such run gave -0.07 ms per row). At 4 times over, this checkout's rows are
still only about 0.35 s of work (the same code measured 0.063 and 0.076 ms per row in two runs);
the reference commit needs no more, with about 8 s of work at 4 times over. The passes after the
first cost what it did (only each pass's first row follows a distant row, the last one). Figures
are medians over ``--runs`` runs of each code, alternated (per-run values printed).

Run:  OPENBLAS_NUM_THREADS=1 python benchmarks/bench_issue_units.py [--issue-commit 10e8828] [--runs 3] [--repeat 3]
      [--tile 4] [--this-tile 32]
Needs ../shared/data/ha-three-tube-trajectory/ for the standard-model row (skipped without it).
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
from _checkouts import ROOT, child_env, cli_command, worktree  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"
ROBOT = ROOT / "model" / "ha2019-table2-nominal.toml"
# the reference commit's cost, in C++ standard solves per configuration (measured on another machine)
ISSUE_FRICTION_X = 1269.0
ISSUE_STANDARD_X = 45.0
# the project's speed goals, in the same unit
TARGET_FRICTION_X = 300.0
TARGET_STANDARD_X = 2.0


_SINGLE = """
import sys, time, numpy as np, ctrplan
root = sys.argv[1]
if not ctrplan.__file__.startswith(root):
    raise RuntimeError(f'ctrplan imported from {ctrplan.__file__}, not from {root}')
sys.path.insert(0, sys.argv[2])
from paper_section_4d import grid_4x4x4
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, solve_standard
robot = load_robot(sys.argv[3])
_, Q = grid_4x4x4(robot)
settings = ModelSettings().replace(multistart=0)
solve_standard(robot, *robot.configuration(Q[0]), settings)
best = []
for q in Q:
    a, b = robot.configuration(q)
    t = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        solve_standard(robot, a, b, settings)
        t = min(t, time.perf_counter() - t0)
    best.append(t)
print(float(np.median(best)))
"""


def _cli_time(code, cache, configs, model, out):
    """Wall time [s] of ``ctrplan evaluate --jobs 1`` of the checkout ``code`` (run from it)."""
    for f in (out, out.with_name(out.name + ".partial.jsonl")):
        f.unlink(missing_ok=True)
    cmd = cli_command(code, "evaluate", "--robot", ROBOT, "--configs", configs, "--model", model, "--out", out,
                      "--jobs", 1, "--no-progress")
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=child_env(code, cache), cwd=str(code))
    return time.perf_counter() - t0


def _single(code, cache):
    """Median over the 4x4x4 grid of the best-of-5 single standard solve [s] of checkout ``code``."""
    r = subprocess.run([sys.executable, "-c", _SINGLE, str(code), str(ROOT / "benchmarks"), str(ROBOT)],
                       check=True, capture_output=True, text=True, env=child_env(code, cache), cwd=str(code))
    return float(r.stdout.split()[-1])


def _write_configs(path, alpha, beta):
    """Configurations (K, n) [rad], [m] as a CSV that ``evaluate --configs`` reads
    (``ctrplan.io.tables.write_table``, the project's schema)."""
    import pandas as pd
    from ctrplan.io.tables import write_table
    n = alpha.shape[1]
    write_table(path, pd.DataFrame({**{f"alpha_{i + 1}": alpha[:, i] for i in range(n)},
                                    **{f"beta_{i + 1}": beta[:, i] for i in range(n)}}))


def _inputs(tmp, tile, this_tile):
    """Config files: the 4x4x4 grid, the trajectory ``tile`` times over (``traj``, for the
    reference commit) and ``this_tile`` times over (``traj_this``, for this checkout), left out if
    absent, and their first rows."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from paper_section_4d import grid_4x4x4
    from ctrplan.io.robot_file import load_robot
    robot = load_robot(ROBOT)
    _, Q = grid_4x4x4(robot)
    A, B = (np.array(x) for x in zip(*(robot.configuration(q) for q in Q)))
    files = {"grid": (tmp / "grid.csv", len(Q)), "grid1": (tmp / "grid1.csv", 1)}
    _write_configs(files["grid"][0], A, B)
    _write_configs(files["grid1"][0], A[:1], B[:1])
    if DATA.exists():
        from ctrplan.io.tables import load_ha_trajectory
        frame = load_ha_trajectory(DATA)
        TA = frame[[f"alpha_{i}" for i in (1, 2, 3)]].to_numpy()
        TB = frame[[f"beta_{i}" for i in (1, 2, 3)]].to_numpy()
        files["traj"] = (tmp / "traj.csv", tile * len(TA))
        files["traj1"] = (tmp / "traj1.csv", 1)
        _write_configs(files["traj"][0], np.tile(TA, (tile, 1)), np.tile(TB, (tile, 1)))
        _write_configs(files["traj1"][0], TA[:1], TB[:1])
        files["traj_this"] = (tmp / "traj_this.csv", this_tile * len(TA))
        files["traj_this1"] = files["traj1"]
        _write_configs(files["traj_this"][0], np.tile(TA, (this_tile, 1)), np.tile(TB, (this_tile, 1)))
    return files


def _per_configuration(code, cache, files, key, model, tmp, repeat):
    """(T(K rows) - T(1 row)) / (K - 1) [s], each T the shortest of ``repeat`` commands."""
    out = tmp / "out.csv"
    (f, K), (f1, _) = files[key], files[key + "1"]
    t = min(_cli_time(code, cache, f, model, out) for _ in range(repeat))
    t1 = min(_cli_time(code, cache, f1, model, out) for _ in range(repeat))
    return (t - t1) / (K - 1)


def _measure(code, cache, traj, files, tmp, repeat):
    """Per-configuration times [s] of one run of checkout ``code``, its standard model on the
    trajectory file ``files[traj]``."""
    r = {"friction": _per_configuration(code, cache, files, "grid", "friction", tmp, repeat)}
    if traj in files:
        r["standard"] = _per_configuration(code, cache, files, traj, "standard", tmp, repeat)
    r["single"] = _single(code, cache)
    return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--issue-commit", default="10e8828",
                    help="reference commit whose cost in C++ standard solves is known (default 10e8828)")
    ap.add_argument("--runs", type=int, default=3, help="runs of each code, alternated")
    ap.add_argument("--repeat", type=int, default=3,
                    help="commands per figure in a run (the shortest counts: the process start is noisy)")
    ap.add_argument("--tile", type=int, default=4,
                    help="the trajectory's rows this many times over in the reference commit's standard-model command")
    ap.add_argument("--this-tile", type=int, default=32,
                    help="the same for this checkout's command, whose rows cost a twentieth")
    args = ap.parse_args(argv)
    print(f"load average at the start: {os.getloadavg()}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = _inputs(tmp, args.tile, args.this_tile)
        if "traj" not in files:
            print(f"   ({DATA} not found: the standard-model conversion is skipped)")
        with worktree(args.issue_commit, tmp / "issue") as old:
            codes = {"ref": (old, tmp / "cache-issue", "traj"), "this": (ROOT, tmp / "cache-this", "traj_this")}
            for code, cache, _ in codes.values():      # compile or cache every kernel once, untimed
                _cli_time(code, cache, files["grid1"][0], "friction", tmp / "out.csv")
                if "traj" in files:
                    _cli_time(code, cache, files["traj"][0], "standard", tmp / "out.csv")
            runs = {name: [] for name in codes}
            for k in range(args.runs):
                order = list(codes) if k % 2 == 0 else list(codes)[::-1]
                for name in order:
                    runs[name].append(_measure(*codes[name], files, tmp, args.repeat))
                    print(f"  run {k + 1} {name:5s} " + "  ".join(f"{m} {v * 1e3:.3f} ms" for m, v in
                                                               runs[name][-1].items()), flush=True)
    print(f"load average at the end: {os.getloadavg()}")
    med = {name: {m: float(np.median([r[m] for r in rs])) for m in rs[0]} for name, rs in runs.items()}
    print(f"\nmedians over {args.runs} runs [ms per configuration]:")
    for name in codes:
        print(f"  {name:5s} " + "  ".join(f"{m} {v * 1e3:.3f}" for m, v in med[name].items()))
    conversions = [("friction", ISSUE_FRICTION_X, TARGET_FRICTION_X)]
    if "standard" in med["this"]:
        conversions.append(("standard", ISSUE_STANDARD_X, TARGET_STANDARD_X))
    for model, issue_x, _ in conversions:
        cpp = med["ref"][model] / issue_x
        print(f"\nC++ solve estimated from the reference commit's {model} figure ({issue_x:.0f}x): {cpp * 1e6:.1f} us")
        for m, _, target in conversions:
            x = med["this"][m] / cpp
            print(f"  this checkout, CLI {m:8s} --jobs 1: {x:7.1f}x the C++ solve (target <= {target:.0f}x; "
                  f"reference commit {med['ref'][m] / cpp:.1f}x)")
        print(f"  own single standard solve: this {med['this']['single'] / cpp:.2f}x, reference commit "
              f"{med['ref']['single'] / cpp:.2f}x (stated for it: 4-7x)")


if __name__ == "__main__":
    main()
