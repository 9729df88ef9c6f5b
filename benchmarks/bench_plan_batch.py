"""Benchmark: many scenarios in one ``ctrplan plan`` process against one process per scenario.

Generates N variants of the shipped task-target and obstacles scenarios (task targets moved by up
to 2 mm, obstacles by up to 3 mm, planner seeds 1..N; fixed generator seed), then plans them
(a) with one ``ctrplan plan VARIANTS/ --out OUT/batch`` process and (b) with N separate
``ctrplan plan VARIANT.toml --out OUT/single/<name>`` processes, both bound-aware only
(``--no-blind``), and prints the wall time of each, the ratio, the per-scenario times of (b)
(mean, median, p90, max) and the load average.

    python benchmarks/bench_plan_batch.py [--variants 20] [--out out/bench-plan-batch]

Run it alone: the two modes are timed one after the other on the same machine.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def make_variants(folder: Path, n: int, seed: int = 20261125) -> list[Path]:
    """N scenario files in ``folder`` (absolute robot and mesh paths)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for k in range(n):
        base = ("task-target", "obstacles")[k % 2]
        text = (ROOT / "scenarios" / f"{base}.toml").read_text()
        text = text.replace('"../model/', f'"{(ROOT / "model").as_posix()}/')
        text = text.replace('file = "meshes/', f'file = "{(ROOT / "scenarios" / "meshes").as_posix()}/')
        text = re.sub(r"(?m)^seed = .*$", f"seed = {k + 1}", text)
        text = re.sub(r"(?m)^(\[output\][^\[]*)", "", text)

        def shift(m, scale):
            vals = [float(v) + rng.uniform(-scale, scale) for v in m.group(2).split(",")]
            return f"{m.group(1)}[{', '.join(f'{v:.5f}' for v in vals)}]"

        text = re.sub(r"(?m)^(tip_position_m = )\[([^\]]*)\]", lambda m: shift(m, 2e-3), text)
        text = re.sub(r"(?m)^((?:center_m|translation_m) = )\[([^\]]*)\]", lambda m: shift(m, 3e-3), text)
        path = folder / f"{base}-{k + 1:02d}.toml"
        path.write_text(text)
        out.append(path)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", type=int, default=20)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench-plan-batch"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    files = make_variants(out / "variants", args.variants)
    exe = [str(Path(sys.executable).with_name("ctrplan"))]          # the entry point of this environment
    print(f"{len(files)} variants; load average {os.getloadavg()[0]:.2f}", flush=True)
    t0 = time.perf_counter()
    r = subprocess.run(exe + ["plan", str(out / "variants"), "--out", str(out / "batch"), "--no-blind"],
                       capture_output=True, text=True)
    batch = time.perf_counter() - t0
    print(r.stdout.strip().splitlines()[-1] if r.stdout.strip() else r.stderr[-500:])
    singles = []
    for f in files:
        t = time.perf_counter()
        subprocess.run(exe + ["plan", str(f), "--out", str(out / "single" / f.stem), "--no-blind", "--jobs", "1"],
                       capture_output=True, text=True)
        singles.append(time.perf_counter() - t)
    s = np.array(singles)
    print(f"one process for {len(files)} scenarios: {batch:.1f} s wall")
    print(f"{len(files)} processes: {s.sum():.1f} s wall in total; per scenario mean {s.mean():.2f}, median "
          f"{np.median(s):.2f}, p90 {np.percentile(s, 90):.2f}, max {s.max():.2f} s")
    print(f"ratio separate / batch: {s.sum() / batch:.2f}; load average {os.getloadavg()[0]:.2f}")
    return 0 if r.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
