"""First run against warm run, of this checkout and of another commit, side by side.

A fresh clone has no compiled kernels: numba compiles each on its first call and caches it on
disk. Each run here gets an empty numba cache (``NUMBA_CACHE_DIR`` pointed at a new folder,
which is what a fresh clone has), runs a command cold, then once more warm with that cache:

- the Quick start main job, ``ctrplan plan scenarios/obstacles.toml``;
- ``ctrplan evaluate --model friction`` on 10 random configurations of the Table II robot
  (the full bound: clearance and all friction solutions), default jobs;
- ``ctrplan evaluate --model standard`` on the same configurations.

The two codes alternate (``--rounds`` times each), so a drift of the machine's speed hits both.
Printed: wall times [s] per command, code and round, their mean, median, p90 and max, the ratio
this / base of the cold medians, and the load average at the start and the end. The machines
are shared: the ratio is the figure to trust, the absolute times drift 2-3x between runs.

Run:  python benchmarks/first_run_ab_timing.py --base REV [--rounds 2]
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _checkouts import ROOT, child_env, cli_command, worktree  # noqa: E402


def _configurations(path, n=10, seed=2026):
    """``n`` random configurations of the Table II robot at its home translations, as the CSV of
    ``ctrplan evaluate`` (alpha [rad], beta [m])."""
    sys.path.insert(0, str(ROOT))
    from ctrplan.io.robot_file import load_robot
    robot = load_robot(ROOT / "model" / "ha2019-table2-nominal.toml")
    rng = np.random.default_rng(seed)
    k = robot.n_tubes
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([f"alpha_{i + 1}" for i in range(k)] + [f"beta_{i + 1}" for i in range(k)])
        for _ in range(n):
            alpha = np.concatenate([[0.0], rng.uniform(-np.pi, np.pi, k - 1)])
            w.writerow([*alpha, *robot.home_beta])


def _commands(configs, out):
    robot = ROOT / "model" / "ha2019-table2-nominal.toml"
    return {
        "plan obstacles": ["plan", ROOT / "scenarios" / "obstacles.toml", "--out", out / "plan"],
        "evaluate friction (10)": ["evaluate", "--robot", robot, "--configs", configs, "--model", "friction",
                                   "--out", out / "friction.csv", "--no-progress"],
        "evaluate standard (10)": ["evaluate", "--robot", robot, "--configs", configs, "--model", "standard",
                                   "--out", out / "standard.csv", "--no-progress"],
    }


def _time(code, args, cache):
    t0 = time.perf_counter()
    subprocess.run(cli_command(code, *args), check=True, env=child_env(code, cache), cwd=str(code),
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _stats(x):
    x = np.asarray(x)
    return (f"mean {x.mean():6.1f}  median {np.median(x):6.1f}  p90 {np.percentile(x, 90):6.1f}  "
            f"max {x.max():6.1f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="git revision to compare against")
    ap.add_argument("--rounds", type=int, default=1, help="cold + warm runs of each code, alternated")
    args = ap.parse_args(argv)
    print(f"load average at the start: {os.getloadavg()}", flush=True)
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        configs = tmp / "configs.csv"
        _configurations(configs)
        with worktree(args.base, tmp / "base") as base:
            for r in range(args.rounds):
                for name, code in (("base", base), ("this", ROOT)):
                    out = tmp / f"out-{name}-{r}"
                    for cmd, cli in _commands(configs, out).items():
                        cache = tmp / f"cache-{name}-{r}-{len(times)}"   # empty: a fresh clone
                        cold = _time(code, cli, cache)
                        warm = _time(code, cli, cache)
                        times.setdefault((cmd, name), []).append((cold, warm))
                        print(f"  round {r + 1} {name:4s} {cmd:24s} cold {cold:6.1f} s  warm {warm:5.1f} s",
                              flush=True)
    print(f"load average at the end: {os.getloadavg()}")
    for cmd in _commands(Path("."), Path(".")):
        print(f"\n{cmd} [s]:")
        for name in ("base", "this"):
            t = np.array(times[(cmd, name)])
            print(f"  {name:4s} cold {_stats(t[:, 0])}")
            print(f"  {name:4s} warm {_stats(t[:, 1])}")
        c = {n: np.median(np.array(times[(cmd, n)])[:, 0]) for n in ("base", "this")}
        w = {n: np.median(np.array(times[(cmd, n)])[:, 1]) for n in ("base", "this")}
        print(f"  this / base: cold {c['this'] / c['base']:.2f}, warm {w['this'] / w['base']:.2f}")


if __name__ == "__main__":
    main()
