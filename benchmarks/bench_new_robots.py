"""New robots from nothing precomputed to a checked bound-aware plan: ``ctrplan plan`` on robot
files no map was made for.

The robots: the six-joint robot of ``model/ha2019-table2-six-joint.toml`` with tube 1's
precurvature changed to 4.0 1/m, then robots made from the shipped files by scaling each tube's
precurvatures and bending stiffness k_xy (``k_xy_N_m2`` or ``k_xy_relative``) by factors drawn uniformly from [0.8, 1.25] (seeded, each
tube and quantity on its own), in turn: the six-joint robot (scenario ``six-joint.toml``) and the
calibrated Table VII robot (scenarios ``obstacles.toml`` and ``task-target.toml``). A scaled
robot's task-space goal is the tip it reaches at the joints that reach the shipped goal on the
shipped robot (inside its workspace by construction; ``--shipped-goals`` asks the shipped goal,
which a robot with shorter reach may not reach: that case ends in one line naming the closest
tip). Each runs as
a new user runs it, ``ctrplan plan SCENARIO --out DIR --no-full-map`` in a new process whose
working folder has an empty cache (the preview map is computed, the plan refines it where it goes),
with a time limit. A robot succeeds when the command exits 0 within the limit and its output
passes :func:`ctrplan.testing.assert_trajectory_within_limits`,
:func:`~ctrplan.testing.assert_rotations_before_translations` and
:func:`~ctrplan.testing.assert_collision_free`; otherwise its first error line is recorded.

Timings on a shared 2-core machine are noisy: run alone; the load average is printed before and
after.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_new_robots.py [--robots 20] [--seed 0] [--limit 300]
        [--results benchmarks/results/new-robots.json]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _records import REPO, figures, run_record

#: (robot file, scenario) pairs the scaled robots cycle through.
BASES = (("ha2019-table2-six-joint.toml", "six-joint.toml"),
         ("ha2019-table7-calibrated.toml", "obstacles.toml"),
         ("ha2019-table7-calibrated.toml", "task-target.toml"))


def scaled_robot_text(text: str, rng, low: float = 0.8, high: float = 1.25) -> tuple[str, list]:
    """The robot file ``text`` with each tube's precurvatures and k_xy scaled by its own factors
    drawn from U(low, high); returns the text and the factors ``[(tube, quantity, factor)]``."""
    out, factors, tube, kappa_scale = [], [], 0, None
    for line in text.splitlines(keepends=True):
        if line.strip() == "[[tubes]]":
            tube += 1
            kappa_scale = float(rng.uniform(low, high))
            factors.append((tube, "precurvature", kappa_scale))
        m = re.match(r"(\s*k_xy_(?:N_m2|relative)\s*=\s*)([0-9.eE+-]+)(.*)", line, re.S)
        if m and tube:
            f = float(rng.uniform(low, high))
            factors.append((tube, "k_xy", f))
            line = f"{m.group(1)}{float(m.group(2)) * f!r}{m.group(3)}"
        m = re.match(r"(\s*precurvature_per_m\s*=\s*\[)([^\]]*)(\].*)", line, re.S)
        if m and tube:
            values = [float(v) * kappa_scale for v in m.group(2).split(",")]
            line = f"{m.group(1)}{', '.join(repr(v) for v in values)}{m.group(3)}"
        out.append(line)
    return "".join(out), factors


def issue_robot_text(text: str) -> str:
    """The six-joint robot with tube 1's precurvature 4.0 1/m."""
    first = text.index("precurvature_per_m")
    end = text.index("\n", first)
    return text[:first] + "precurvature_per_m = [0.0, 4.0]" + text[end:]


def scenario_text(scenario: Path, robot_file: Path, *, reachable: bool = False) -> str:
    """The shipped scenario pointed at ``robot_file``, its mesh files by absolute path.

    ``reachable``: each task-space goal moved to the tip the new robot reaches at the joints that
    reach the shipped goal on the shipped robot (its inverse kinematics,
    :func:`ctrplan.planning.goals.resolve_goal`), so that a scaled robot is asked a goal inside
    its workspace; a goal the new robot is unstable at there is kept as shipped."""
    text = scenario.read_text()
    if reachable:
        text = _reachable_task_goals(text, scenario, robot_file)
    text = re.sub(r'(?m)^robot\s*=\s*".*"', f'robot = "{robot_file.as_posix()}"', text)
    return re.sub(r'file\s*=\s*"([^"]+)"', lambda m: f'file = "{(scenario.parent / m.group(1)).as_posix()}"', text)


def _reachable_task_goals(text: str, scenario: Path, robot_file: Path) -> str:
    from ctrplan.io.robot_file import load_robot
    from ctrplan.io.scenario import load_scenario
    from ctrplan.mechanics import solve_standard
    from ctrplan.planning.goals import resolve_goal

    shipped = load_scenario(scenario)
    new = load_robot(robot_file)
    goals = [g for g in shipped.goals if getattr(g, "tip_position", None) is not None]
    matches = list(re.finditer(r"tip_position_m\s*=\s*\[[^\]]*\]", text))
    if len(matches) != len(goals):
        raise ValueError(f"{scenario}: {len(matches)} tip_position_m keys for {len(goals)} task-space goals")
    out, last = [], 0
    for m, goal in zip(matches, goals):
        q = resolve_goal(goal, shipped.robot).q
        sol = solve_standard(new, *new.configuration(q))
        moved = "tip_position_m = [" + ", ".join(repr(float(v)) for v in sol.tip_position) + "]"
        out += [text[last:m.start()], moved if sol.diagnostics.ok else m.group(0)]
        last = m.end()
    return "".join(out) + text[last:]


def check_outputs(out: Path) -> str | None:
    """None when the plan's outputs pass the checks, else the first failure's line."""
    from ctrplan.testing import (assert_collision_free, assert_rotations_before_translations,
                                 assert_trajectory_within_limits)

    for check in (assert_trajectory_within_limits, assert_rotations_before_translations, assert_collision_free):
        try:
            check(out)
        except AssertionError as exc:
            return f"{check.__name__}: {str(exc).splitlines()[0] if str(exc) else 'failed'}"
    return None


def run_one(index: int, robot_text: str, scenario: Path, limit: float, jobs: int, reachable: bool = False) -> dict:
    with tempfile.TemporaryDirectory(prefix="ctrplan-new-robot-") as tmp:
        tmp = Path(tmp)
        robot_file = tmp / f"robot-{index}.toml"
        robot_file.write_text(robot_text)
        sc = tmp / f"scenario-{index}.toml"
        sc.write_text(scenario_text(scenario, robot_file, reachable=reachable))
        entry = Path(sys.executable).with_name("ctrplan")
        cmd = ([str(entry)] if entry.exists() else [sys.executable, "-c", "from ctrplan.cli import run; run()"]) + \
            ["plan", str(sc), "--out", str(tmp / "out"), "--no-full-map", "--jobs", str(jobs)]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp, timeout=limit,
                                  env=dict(os.environ, CTRPLAN_CACHE_DIR=str(tmp / ".cache")))   # empty cache
            wall = time.perf_counter() - t0
        except subprocess.TimeoutExpired:
            return {"status": "failed", "wall_s": limit, "reason": f"no plan within {limit:.0f} s"}
        if proc.returncode != 0:
            lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
            reason = next((ln for ln in lines if "rror" in ln), lines[-1] if lines else f"exit {proc.returncode}")
            return {"status": "failed", "wall_s": wall, "reason": reason.strip()}
        failure = check_outputs(tmp / "out")
        summary = json.loads((tmp / "out" / "summary.json").read_text())
        return {"status": "failed" if failure else "planned", "wall_s": wall, "reason": failure,
                "times_s": summary.get("times_s"),
                "max_bound_mm": summary.get("comparison", {}).get("max_bound_at_waypoints_mm", {}).get("bound aware")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", type=int, default=20, help="robots, the first the six-joint case with 4.0 1/m")
    ap.add_argument("--seed", type=int, default=0, help="seed of the scale factors")
    ap.add_argument("--limit", type=float, default=300.0, help="time limit per robot [s]")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes of ctrplan plan")
    ap.add_argument("--results", type=Path, help="write the figures to this JSON file")
    ap.add_argument("--shipped-goals", action="store_true",
                    help="ask the scaled robots the shipped task-space goals (default: the tip each reaches at the "
                         "joints that reach the shipped goal on the shipped robot)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    start_load = os.getloadavg()
    print(f"load average before: {start_load}")
    rows = []
    for k in range(args.robots):
        if k == 0:
            base, scen = BASES[0]
            text, factors = issue_robot_text((REPO / "model" / base).read_text()), [(1, "precurvature", 4.0 / 3.7735849056603774)]
        else:
            base, scen = BASES[(k - 1) % len(BASES)]
            text, factors = scaled_robot_text((REPO / "model" / base).read_text(), rng)
        row = {"robot": k + 1, "base": base, "scenario": scen, "factors": factors}
        row.update(run_one(k + 1, text, REPO / "scenarios" / scen, args.limit, args.jobs,
                           reachable=k > 0 and not args.shipped_goals))
        rows.append(row)
        print(f"robot {k + 1:2d} ({base}, {scen}): {row['status']} in {row['wall_s']:.1f} s"
              + (f" -- {row['reason']}" if row.get("reason") else ""), flush=True)
    end_load = os.getloadavg()
    print(f"load average after: {end_load}")
    planned = [r for r in rows if r["status"] == "planned"]
    walls = np.array([r["wall_s"] for r in planned]) if planned else np.zeros(0)
    print(f"\nplanned {len(planned)} of {len(rows)} within {args.limit:.0f} s"
          + (f"; wall s mean {walls.mean():.1f}, median {np.median(walls):.1f}, p90 {np.percentile(walls, 90):.1f}, "
             f"max {walls.max():.1f}" if planned else ""))
    if args.results:
        doc = {**run_record("OPENBLAS_NUM_THREADS=1 python benchmarks/bench_new_robots.py "
                            + " ".join(argv or sys.argv[1:]), start_load, end_load),
               "limit_s": args.limit, "planned": len(planned), "robots": len(rows),
               "wall_s": {k: figures(walls)[k] for k in ("mean", "median", "p90", "max")} if planned else None,
               "rows": rows}
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {args.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
