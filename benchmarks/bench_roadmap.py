"""Interactive planning on a roadmap (``ctrplan.Planner``) against a single-query plan per goal.

Per shipped scenario (``scenarios/*.toml``), in this process:

1. the roadmap is built from nothing on ``--jobs`` processes (its build time; nothing read from
   the cache);
2. ``--goals`` random goals are drawn (seeded, uniformly from the joint box, kept when valid for
   the search's checker: limits, elastic stability, the map's valid region, obstacles) and
   planned one after another from the current configuration with ``Planner.plan_to``: goal,
   roadmap search, ordering and final check with the exact standard model, exact friction bound at
   the ordered waypoints, drive trajectory (the query time: mean, median, p90, max);
3. each goal is planned again from the same start with the scenario's single-query planner
   (``ctrplan.planning.plan_route``: RRT*, the scenario's iterations and seed), ordered, checked and
   bounded the same way: the ratio of the largest exact bound at the waypoints given the last
   motion, roadmap over single query (median and worst), and the single query's time.

Timings on a shared 2-core machine are noisy: run alone; the load average is printed before and
after.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_roadmap.py [--goals 20] [--jobs 2] [--results benchmarks/results/roadmap.json]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_roadmap.py scenarios/obstacles.toml --goals 5
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from _records import REPO, figures, run_record


def random_goals(planner, n: int, seed: int) -> list:
    """``n`` valid joint vectors drawn uniformly from the joint box [rad or m]."""
    js = planner.joint_space
    lo = np.where(js.periodic, -np.pi, js.lower)
    hi = np.where(js.periodic, np.pi, js.upper)
    rng = np.random.default_rng(seed)
    goals = []
    while len(goals) < n:
        q = lo + rng.random(len(lo)) * (hi - lo)
        if planner.checks.search(q):
            goals.append(q)
    return goals


def single_query(planner, q0, q1) -> tuple[float, float]:
    """(largest exact bound at the ordered waypoints given the last motion [m], seconds) of the
    scenario's single-query plan from ``q0`` to ``q1``."""
    from ctrplan.mechanics import evaluate_bound
    from ctrplan.planning import BoundCostObjective, SearchSettings, bounds_given_last_motion
    from ctrplan.planning.approach import end_with
    from ctrplan.planning.route import plan_route

    sc = planner.setup.scenario
    p = sc.planner
    t0 = time.perf_counter()
    route = plan_route(planner.robot, q0, [q1], planner.checks,
                       BoundCostObjective.factory(planner.field, bound_weight=planner.bound_weight),
                       SearchSettings.from_scenario(p), joint_space=planner.joint_space)
    ordered, _ = end_with(route.ordered, len(route.ordered.q) - 1, p.final_motion, planner.checks.final.check)
    bounds = bounds_given_last_motion(ordered, planner.robot, evaluate_bound, planner.setup.settings)
    return float(np.nanmax(bounds.position)), time.perf_counter() - t0


def run(path: Path, n_goals: int, seed: int, compare: bool, jobs: int) -> dict:
    from ctrplan.errors import CtrplanError
    from ctrplan.planning.interactive import Planner

    t0 = time.perf_counter()
    planner = Planner.from_scenario(path, store=False, n_jobs=jobs)
    setup_s = time.perf_counter() - t0
    rm = planner.roadmap
    goals = random_goals(planner, n_goals, seed)
    rows = []
    for k, g in enumerate(goals):
        q0 = planner.current.copy()
        row = {"goal": k + 1}
        try:
            plan = planner.plan_to(g)
        except CtrplanError as exc:
            row.update(status="failed", reason=str(exc).splitlines()[0])
            rows.append(row)
            print(f"  {path.stem} goal {k + 1}: FAILED {row['reason']}", file=sys.stderr, flush=True)
            continue
        row.update(status="planned", via=plan.via, times_s=plan.times_s, max_bound_m=plan.max_bound_m,
                   final_bound_m=plan.final_bound_m, waypoints=len(plan.ordered.q))
        if compare:
            try:
                b, s = single_query(planner, q0, plan.goal)
                row.update(single_max_bound_m=b, single_seconds=s, bound_ratio=plan.max_bound_m / b)
            except CtrplanError as exc:
                row.update(single_failed=str(exc).splitlines()[0])
        rows.append(row)
        print(f"  {path.stem} goal {k + 1}: {plan.times_s['total']:.3f} s via {plan.via}, max bound "
              f"{plan.max_bound_m * 1e3:.2f} mm" + (f" (single query {row['single_max_bound_m'] * 1e3:.2f} mm, "
                                                    f"{row['single_seconds']:.1f} s)" if "bound_ratio" in row else ""),
              file=sys.stderr, flush=True)
    done = [r for r in rows if r["status"] == "planned"]
    out = {"scenario": path.name, "joints": planner.joint_space.n_joints,
           "roadmap": {"states": rm.n_nodes, "motions": rm.n_edges, "neighbours": rm.neighbours,
                       "build_s": rm.build_seconds, "draws": rm.draws},
           "setup_s": setup_s, "goals": len(goals), "planned": len(done),
           "via_search": sum(1 for r in done if r["via"] == "search"),
           "query_s": figures([r["times_s"]["total"] for r in done]) if done else None,
           "query_split_median_s": {k: float(np.median([r["times_s"][k] for r in done]))
                                    for k in ("goal", "search", "order_and_check", "exact_bound", "trajectory")}
           if done else None,
           "rows": rows}
    ratios = [r["bound_ratio"] for r in done if "bound_ratio" in r]
    if ratios:
        out["bound_ratio"] = figures(ratios)
        out["single_query_s"] = figures([r["single_seconds"] for r in done if "single_seconds" in r])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenarios", nargs="*", help="scenario files (default: scenarios/*.toml)")
    ap.add_argument("--goals", type=int, default=20, help="random goals per scenario")
    ap.add_argument("--seed", type=int, default=2026, help="seed of the random goals")
    ap.add_argument("--no-compare", action="store_true", help="skip the single-query plans")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="processes that build the roadmap")
    ap.add_argument("--results", type=Path, help="write the figures to this JSON file")
    args = ap.parse_args(argv)
    paths = [Path(p).resolve() for p in args.scenarios] or sorted((REPO / "scenarios").glob("*.toml"))
    start_load = os.getloadavg()
    print(f"load average before: {start_load}")
    results = [run(p, args.goals, args.seed, not args.no_compare, args.jobs) for p in paths]
    end_load = os.getloadavg()
    print(f"load average after: {end_load}")
    print("\nscenario       joints  roadmap (states / motions / build s)  query s: mean / median / p90 / max   "
          "bound ratio roadmap/single: median / worst   planned")
    for r in results:
        q, rm = r["query_s"], r["roadmap"]
        ratio = r.get("bound_ratio")
        print(f"{r['scenario']:<15}{r['joints']:>6}  {rm['states']:>6} / {rm['motions']:>6} / {rm['build_s']:6.1f}        "
              + (f"{q['mean']:.3f} / {q['median']:.3f} / {q['p90']:.3f} / {q['max']:.3f}" if q else "-")
              + (f"        {ratio['median']:.3f} / {ratio['max']:.3f}" if ratio else "        -")
              + f"        {r['planned']}/{r['goals']} ({r['via_search']} by search)")
    if args.results:
        doc = {**run_record("OPENBLAS_NUM_THREADS=1 python benchmarks/bench_roadmap.py " + " ".join(argv or sys.argv[1:]),
                            start_load, end_load),
               "goals": args.goals, "jobs": args.jobs, "seed": args.seed, "scenarios": results}
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {args.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
