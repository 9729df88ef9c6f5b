"""Benchmark: ``ctrplan evaluate --jobs 1`` against the C++ standard-model solver of Ha and Dupont
(github.com/hjhdog1/ConcentricTubes, ``MechanicsBasedKinematics``), in interleaved rounds.

That repository has no licence: nothing of it is in this one. Given a checkout (``--checkout``;
without one, or without ``g++``, the benchmark says so and exits 0), this script copies the
sources it needs into a build folder outside the repository (``--build-dir``, default a
temporary folder), makes them compile with g++ on Linux without changing what they compute
(:data:`COMPAT`: an empty ``Windows.h``, include names as Linux spells them, ``typename`` where
C++11 needs it, the one Windows-only string function left out), and compiles a driver written
here (:data:`DRIVER`) against them with ``-O2``. The driver builds the paper's three-tube robot as
the C++ code hard-codes it (``CTRFactory::buildCTR``), with ``--grid-points`` arc-length points
and the IVP Jacobian switched on (the authors' own setting for sampling configurations), and
times ``ComputeKinematics`` (the standard model's boundary-value solve, each from the previous
solution) on a 4x4x4 grid over its joint space (rotations of tubes 2 and 3 over a full turn,
the translation over its limits), reporting the median time per solve.

Each round then times, with the command line as a user runs it (process start subtracted, from
a one-row run of the same round, as ``bench_speed.py`` section 4 does):

- ``friction``: ``ctrplan evaluate --model friction --jobs 1`` on the paper's 4x4x4 grid (Table II
  robot; every one of the 2^(n-1) friction solutions and the clearance solution, i.e. the full
  bound), per configuration;
- ``standard``: ``ctrplan evaluate --model standard --jobs 1`` on the measured trajectory's rows
  (``../shared/data/ha-three-tube-trajectory``, read ``--tile`` times over; skipped without the
  data), per row,

and each as a ratio to the C++ median solve of the same round. Prints every round, mean, median,
p90 and max of the ratios, and the load average before and after.

    python benchmarks/bench_cpp_peer.py --checkout PATH [--rounds 5] [--grid-points 100] [--tile 8]
                                        [--build-dir DIR] [--results benchmarks/results/cpp-peer.json]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

#: Folders of the checkout the solver needs.
SOURCES = ("MechanicsBasedKinematics", "LieGroup", "Utilities", "Lib")
#: Translation units linked into the driver.
UNITS = ("MechanicsBasedKinematics/CTR", "MechanicsBasedKinematics/CTRFactory",
         "MechanicsBasedKinematics/MechanicsBasedKinematics", "MechanicsBasedKinematics/Part",
         "MechanicsBasedKinematics/Section", "MechanicsBasedKinematics/Tube", "LieGroup/LieGroup",
         "LieGroup/utils", "Utilities/Utilities")
#: What the build changes so that the Visual Studio sources compile with g++ on Linux (none of it
#: touches the mechanics): headers named as Linux spells them, an empty ``Windows.h``,
#: ``typename`` before two dependent iterator types, and ``s2ws`` (a Windows string conversion
#: the solver never calls) left out.
COMPAT = ("shim/Eigen/dense and shim/Dense include <Eigen/Dense>", "shim/Windows.h is empty",
          "Utilities.h: typename ::std::vector<T>::const_iterator", "Utilities.cpp: s2ws left out")
FLAGS = ("-O2", "-std=c++11", "-w", "-fpermissive", "-include", "cstring", "-include", "string",
         "-include", "cmath")

#: The timing driver (this project's code): the robot of ``CTRFactory::buildCTR``, the grid of
#: the module docstring, ``rounds`` passes over it; one JSON line out.
DRIVER = r"""
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include "CTRFactory.h"
#include "MechanicsBasedKinematics.h"

int main(int argc, char** argv) {
  const int n = 4;
  const int grid = argc > 1 ? std::atoi(argv[1]) : 100;
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 1;
  CTR* robot = CTRFactory::buildCTR("");
  MechanicsBasedKinematics kin(robot, grid);
  kin.ActivateIVPJacobian();
  const double collar = robot->GetTubes()[0].GetCollarLength();
  const double lo = robot->GetLowerTubeJointLimits()[2] + 1e-3;
  const double hi = robot->GetUpperTubeJointLimits()[2] - 1e-3;
  std::vector<double> times;
  int converged = 0;
  for (int r = 0; r < rounds; ++r)
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        for (int k = 0; k < n; ++k) {
          double rotation[3] = {0.0, 2.0 * M_PI * i / n, 2.0 * M_PI * j / n};
          double translation[3] = {0.0, -collar, lo + (hi - lo) * k / (n - 1)};
          auto t0 = std::chrono::steady_clock::now();
          bool ok = kin.ComputeKinematics(rotation, translation);
          auto t1 = std::chrono::steady_clock::now();
          times.push_back(std::chrono::duration<double>(t1 - t0).count());
          converged += ok ? 1 : 0;
        }
  std::vector<double> sorted(times);
  std::sort(sorted.begin(), sorted.end());
  double sum = 0.0;
  for (double t : times) sum += t;
  const size_t m = sorted.size();
  std::printf("{\"solves\": %zu, \"converged\": %d, \"grid_points\": %d, \"mean_s\": %.9g, \"median_s\": %.9g, "
              "\"max_s\": %.9g}\n", m, converged, grid, sum / m, sorted[m / 2], sorted[m - 1]);
  return 0;
}
"""


def build(checkout: Path, folder: Path) -> Path:
    """The driver compiled against the checkout's solver in ``folder`` (outside the repository).

    Raises
    ------
    ValueError
        ``folder`` is inside the repository.
    FileNotFoundError
        The checkout lacks one of :data:`SOURCES`.
    subprocess.CalledProcessError
        A compile or link step failed (its output is printed).
    """
    folder = folder.resolve()
    if folder == ROOT or ROOT in folder.parents:
        raise ValueError(f"build folder {folder} is inside the repository: the peer's code has no licence")
    src = folder / "src"
    shutil.rmtree(src, ignore_errors=True)
    for name in SOURCES:
        if not (checkout / name).is_dir():
            raise FileNotFoundError(f"{checkout}: no folder {name}/ (expected a checkout of hjhdog1/ConcentricTubes)")
        shutil.copytree(checkout / name, src / name)
    shim = folder / "shim"
    (shim / "Eigen").mkdir(parents=True, exist_ok=True)
    (shim / "Eigen" / "dense").write_text("#include <Eigen/Dense>\n")
    (shim / "Dense").write_text("#include <Eigen/Dense>\n")
    (shim / "Windows.h").write_text("")
    header = src / "Utilities" / "Utilities.h"
    text = header.read_text(encoding="utf-8-sig", errors="replace")
    header.write_text(re.sub(r"\(\s*::std::vector<T>::const_iterator", "(typename ::std::vector<T>::const_iterator", text))
    unit = src / "Utilities" / "Utilities.cpp"
    text = unit.read_text(encoding="utf-8-sig", errors="replace")
    unit.write_text(re.sub(r"std::wstring s2ws\(const std::string& s\)\s*\{.*?return r;\s*\}", "", text, flags=re.S))
    (folder / "driver.cpp").write_text(DRIVER)
    includes = [f"-I{p}" for p in (shim, src / "Lib", src / "LieGroup", src / "Utilities",
                                   src / "MechanicsBasedKinematics")]
    objects = []
    for u in UNITS:
        obj = folder / "obj" / (u.replace("/", "_") + ".o")
        obj.parent.mkdir(exist_ok=True)
        _compile(["g++", *FLAGS, *includes, "-c", str(src / f"{u}.cpp"), "-o", str(obj)])
        objects.append(str(obj))
    exe = folder / "driver"
    _compile(["g++", *FLAGS, *includes, str(folder / "driver.cpp"), *objects, "-o", str(exe)])
    return exe


def _compile(cmd):
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        print(res.stdout + res.stderr, file=sys.stderr)
        raise subprocess.CalledProcessError(res.returncode, cmd)


def cpp_round(exe: Path, grid_points: int) -> dict:
    """One pass of the driver over its grid: ``{"solves", "converged", "median_s", ...}``."""
    out = subprocess.run([str(exe), str(grid_points), "1"], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _stats(values) -> dict:
    v = np.asarray(values, dtype=float)
    return {"mean": float(v.mean()), "median": float(np.median(v)), "p90": float(np.percentile(v, 90)),
            "max": float(v.max()), "min": float(v.min())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkout", type=Path, default=None, help="a checkout of hjhdog1/ConcentricTubes")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--grid-points", type=int, default=100, help="arc-length points of the C++ solver")
    ap.add_argument("--tile", type=int, default=8, help="times the trajectory's rows are read over")
    ap.add_argument("--build-dir", type=Path, default=None)
    ap.add_argument("--results", type=Path, default=ROOT / "benchmarks" / "results" / "cpp-peer.json")
    args = ap.parse_args(argv)
    if args.checkout is None or not args.checkout.is_dir():
        print(f"skipped: no checkout of hjhdog1/ConcentricTubes given ({args.checkout}); pass --checkout PATH")
        return 0
    if shutil.which("g++") is None:
        print("skipped: no g++ on this machine")
        return 0
    import bench_speed
    from ctrplan_reference.paper_grids import grid_4x4x4

    from ctrplan.io.robot_file import load_robot
    from ctrplan.io.tables import load_ha_trajectory

    tmp = tempfile.TemporaryDirectory(prefix="ctrplan-cpp-peer-")
    build_dir = args.build_dir or Path(tmp.name) / "build"
    exe = build(args.checkout, build_dir)
    robot_file = ROOT / "model" / "ha2019-table2-nominal.toml"
    robot = load_robot(robot_file)
    _, Q = grid_4x4x4(robot)
    A = np.array([robot.configuration(q)[0] for q in Q])
    B = np.array([robot.configuration(q)[1] for q in Q])
    work = Path(tmp.name)
    bench_speed._write_configs(work / "one.csv", A[:1], B[:1])
    bench_speed._write_configs(work / "grid.csv", A, B)
    data = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"
    n_rows = 0
    if data.exists():
        frame = load_ha_trajectory(data)
        TA = frame[[f"alpha_{i}" for i in (1, 2, 3)]].to_numpy()
        TB = frame[[f"beta_{i}" for i in (1, 2, 3)]].to_numpy()
        bench_speed._write_configs(work / "rows.csv", np.tile(TA, (args.tile, 1)), np.tile(TB, (args.tile, 1)))
        n_rows = args.tile * len(TA)
    else:
        print(f"no measured trajectory at {data}: the standard-model rows are skipped")
    load_before = os.getloadavg()
    print(f"load average {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}; C++ solver: "
          f"{args.grid_points} arc-length points, IVP Jacobian", flush=True)
    bench_speed._cli(robot_file, work / "one.csv", "friction", 1, work / "w.csv")     # compiled cache warm
    rounds = []
    for r in range(args.rounds):
        cpp = cpp_round(exe, args.grid_points)
        start = bench_speed._cli(robot_file, work / "one.csv", "standard", 1, work / "o.csv")
        friction = (bench_speed._cli(robot_file, work / "grid.csv", "friction", 1, work / "f.csv") - start) / len(Q)
        row = {"cpp_median_s": cpp["median_s"], "cpp_converged": f"{cpp['converged']} of {cpp['solves']}",
               "process_start_s": start, "friction_per_configuration_s": friction,
               "friction_ratio": friction / cpp["median_s"]}
        if n_rows:
            standard = (bench_speed._cli(robot_file, work / "rows.csv", "standard", 1, work / "s.csv") - start) / n_rows
            row.update(standard_per_row_s=standard, standard_ratio=standard / cpp["median_s"])
        rounds.append(row)
        print(f"  round {r + 1}: C++ {cpp['median_s'] * 1e3:.3f} ms a solve ({row['cpp_converged']} converged); "
              f"friction {friction * 1e3:.1f} ms a configuration = {row['friction_ratio']:.0f}x"
              + (f"; standard {row['standard_per_row_s'] * 1e3:.3f} ms a row = {row['standard_ratio']:.2f}x"
                 if n_rows else ""), flush=True)
    summary = {k: _stats([r[k] for r in rounds]) for k in ("cpp_median_s", "friction_ratio", "standard_ratio")
               if k in rounds[0]}
    load_after = os.getloadavg()
    for k, s in summary.items():
        print(f"{k:16s} mean {s['mean']:.4g}  median {s['median']:.4g}  p90 {s['p90']:.4g}  max {s['max']:.4g}")
    print(f"load average at the end {load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f}")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    peer = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=args.checkout, capture_output=True,
                          text=True).stdout.strip() or None
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps({
        "command": f"python benchmarks/bench_cpp_peer.py --checkout PATH --rounds {args.rounds} "
                   f"--grid-points {args.grid_points} --tile {args.tile}",
        "commit": commit, "peer_commit": peer, "grid_points": args.grid_points, "tile": args.tile,
        "rows_per_run": n_rows, "configurations": len(Q), "compat": list(COMPAT),
        "load_average": {"before": list(load_before), "after": list(load_after)},
        "summary": summary, "rounds": rounds}, indent=1) + "\n")
    print(f"wrote {args.results}")
    tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
