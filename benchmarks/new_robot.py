"""A new robot to its first bound-aware plan: the time split, and the map against the exact bound
where the plan goes.

The six-joint robot of Table II (``model/ha2019-table2-six-joint.toml``) with tube 1's
precurvature scaled by ``--scale`` (default 1.1), so that no map of it is shipped or cached, is
planned for the six-joint scenario (``scenarios/six-joint.toml``: its start, goal, obstacles,
planner and ``[bound_field]``) from an empty map cache in ``--out``, with ``--jobs`` workers:

1. the first plan (``ctrplan.plan``, bound-blind comparison included): the preview map
   (computed), the plans and the refinement (exact nodes, re-plans) with their times, and per
   plan the map's bound against the exact bound given the last motion at its waypoints
   (median, max); the last plan's figures are what the plan reports;
2. the same scenario planned again (the preview map and the refinement read from the cache);
3. with ``--full-map``: the full map (``ctrplan.planning.complete_bound_map``), its
   interpolation error against the exact bound at ``--n`` random configurations valid in the
   exact model (``ctrplan.boundmap.interpolation_error``, seed ``--seed``) beside the shipped
   six-joint map's on its own robot with the same draw, and a third plan, which reads it.

Beside the waypoints, the first plan's path is sampled at ``--path-samples`` configurations
(between the waypoints too), where the preview map, the refined map and (with ``--full-map``)
the full map are compared with the exact friction bound.

Run it alone, with the compiled cache warm (any plan run once before), and print the load
average with the figures:

    OPENBLAS_NUM_THREADS=1 python benchmarks/new_robot.py [--jobs 2] [--full-map] [--n 200]
        [--out out/bench-new-robot] [--results benchmarks/results/new-robot.json]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "model" / "ha2019-table2-six-joint.toml"
SCENARIO = ROOT / "scenarios" / "six-joint.toml"


def _new_robot(folder: Path, scale: float) -> Path:
    """The six-joint robot file with tube 1's precurvature scaled (its first ``precurvature_per_m``
    line, the curved section of tube 1)."""
    text = ROBOT.read_text()
    m = re.search(r"^precurvature_per_m = \[([^,\]]+), ([^\]]+)\].*$", text, flags=re.M)
    if m is None:
        raise SystemExit(f"{ROBOT}: no precurvature_per_m line")
    kx, ky = float(m.group(1)), float(m.group(2))
    new = (f"precurvature_per_m = [{kx * scale!r}, {ky * scale!r}]   # tube 1's, scaled by {scale:g} "
           f"(benchmarks/new_robot.py)")
    path = folder / f"six-joint-tube1-x{scale:g}.toml"
    path.write_text(text[:m.start()] + new + text[m.end():])
    return path


def _scenario(folder: Path, robot: Path) -> Path:
    text = SCENARIO.read_text()
    text = re.sub(r'^robot = ".*"$', f'robot = "{robot.as_posix()}"', text, count=1, flags=re.M)
    text = text.replace('file = "meshes/', f'file = "{(SCENARIO.parent / "meshes").as_posix()}/')
    path = folder / "six-joint-new-robot.toml"
    path.write_text(text)
    return path


def _plan_figures(run, wall: float) -> dict:
    ref = run.refinement
    t = run.timings_s
    out = {"wall_s": wall, "bound_map_s": t["bound_map"], "bound_map_source": run.bound_map.source,
           "preview": run.bound_map.preview, "resolution": list(run.bound_map.field.shape),
           "inverse_kinematics_s": t["inverse_kinematics"], "compensation_s": t["compensation"],
           "prediction_at_waypoints_s": t["prediction_at_waypoints"], "plans_wall_s": t["plans_wall"],
           "refinement_s": t["refinement"], "total_s": t["total"]}
    out["other_s"] = t["total"] - sum(t[k] for k in ("bound_map", "inverse_kinematics", "compensation", "plans_wall"))
    if ref is not None:
        out.update(refinement_plans=len(ref.rounds), converged=ref.converged, exact_nodes=ref.n_nodes,
                   node_evaluations=ref.node_evaluations, node_time_s=ref.node_time_s, exact_samples=ref.samples.n,
                   refined_resolution=list(ref.field.shape),
                   rounds=[{"max_mm": r.max_error * 1e3, "median_mm": r.median_error * 1e3,
                            "waypoints": r.n_waypoints, "plan_s": r.time_s} for r in ref.rounds])
    b = run.plans.aware.bounds
    ok = np.asarray(b.exact.valid, bool) & np.isfinite(b.exact.position) & np.isfinite(b.planned)
    err = np.abs(np.asarray(b.planned) - np.asarray(b.exact.position))[ok] * 1e3
    out.update(planned_minus_exact_median_mm=float(np.median(err)) if err.size else None,
               planned_minus_exact_max_mm=float(err.max()) if err.size else None, waypoints=int(err.size),
               max_exact_bound_at_waypoints_mm=float(np.nanmax(b.exact.position) * 1e3))
    return out


def _along_path(run, fields: dict, n: int, jobs: int) -> dict:
    """Friction bound of each map in ``fields`` against the exact bound at ``n`` configurations
    spread along the bound-aware plan's ordered path (between its waypoints too) [mm]."""
    from ctrplan.boundmap import sample_exact
    from ctrplan.mechanics import evaluate_bound

    q = run.plans.aware.bounds.dense_q
    q = q[np.unique(np.linspace(0, len(q) - 1, min(n, len(q))).round().astype(int))]
    exact, ok = sample_exact(run.setup.robot, evaluate_bound, q, run.setup.settings, jobs)
    out = {}
    for label, field in fields.items():
        err = np.abs(np.asarray(field(q, "position")) - exact[:, 0])[ok & np.asarray(field.is_valid(q))] * 1e3
        out[label] = {"n": int(err.size), "median_mm": float(np.median(err)), "p95_mm": float(np.percentile(err, 95)),
                      "max_mm": float(err.max())}
        print(f"  along the plan's path, {label}: map - exact friction bound at {err.size} configurations: median "
              f"{out[label]['median_mm']:.3f}, p95 {out[label]['p95_mm']:.3f}, max {out[label]['max_mm']:.3f} mm")
    return out


def _print_plan(label: str, f: dict) -> None:
    print(f"\n{label}: {f['wall_s']:.1f} s wall (bound map {f['bound_map_s']:.1f} s, {f['bound_map_source']}"
          f"{', preview ' + 'x'.join(map(str, f['resolution'])) if f['preview'] else ''}; plans "
          f"{f['plans_wall_s']:.1f} s, of which refinement {f['refinement_s']:.1f} s and the bound-aware plan's "
          f"prediction at its waypoints {f['prediction_at_waypoints_s']:.1f} s; goals' inverse kinematics "
          f"{f['inverse_kinematics_s']:.1f} s; compensation {f['compensation_s']:.1f} s; set-up, trajectory and "
          f"the rest {f['other_s']:.1f} s)")
    for k, r in enumerate(f.get("rounds", [])):
        print(f"  plan {k + 1}: map - exact at {r['waypoints']} waypoints: median {r['median_mm']:.3f} mm, "
              f"max {r['max_mm']:.3f} mm; {r['plan_s']:.1f} s")
    if "rounds" in f:
        print(f"  exact nodes {f['exact_nodes']} ({f['node_evaluations']} evaluated in {f['node_time_s']:.1f} s), "
              f"exact samples {f['exact_samples']}, refined grid {'x'.join(map(str, f['refined_resolution']))}, "
              f"converged: {f['converged']}")
    print(f"  the plan: map - exact bound at its {f['waypoints']} waypoints: median "
          f"{f['planned_minus_exact_median_mm']:.3f} mm, max {f['planned_minus_exact_max_mm']:.3f} mm; largest exact "
          f"bound {f['max_exact_bound_at_waypoints_mm']:.2f} mm")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scale", type=float, default=1.1, help="factor on tube 1's precurvature")
    ap.add_argument("--full-map", action="store_true", help="also compute the full map and plan with it")
    ap.add_argument("--n", type=int, default=200, help="random valid configurations for the map error")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--path-samples", type=int, default=60,
                    help="configurations along the first plan's path where the maps meet the exact bound")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench-new-robot")
    ap.add_argument("--results", type=Path, default=None)
    args = ap.parse_args(argv)
    args.out = args.out.resolve()
    if args.results is not None:
        args.results = args.results.resolve()

    import ctrplan
    from ctrplan.boundmap import find_bound_map, interpolation_error
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import evaluate_bound
    from ctrplan.planning import complete_bound_map

    if args.out.exists():
        shutil.rmtree(args.out)
    args.out.mkdir(parents=True)
    robot_file = _new_robot(args.out, args.scale)
    scenario = _scenario(args.out, robot_file)
    os.chdir(args.out)                  # the map cache (.cache/boundmaps) starts empty here
    os.environ["CTRPLAN_CACHE_DIR"] = str(Path(args.out).resolve() / ".cache")
    load0 = os.getloadavg()
    print(f"robot {robot_file.name}, scenario {scenario.name}, {args.jobs} workers; load average {load0}")
    from bench_speed import _commit, _cpu
    from ctrplan.constants import MECHANICS_VERSION

    results = {"command": "OPENBLAS_NUM_THREADS=1 python benchmarks/new_robot.py " + " ".join(
                   sys.argv[1:] if argv is None else argv),
               "mechanics_version": MECHANICS_VERSION, "commit": _commit(), "date": datetime.date.today().isoformat(),
               "cores": os.cpu_count(), "cpu": _cpu(), "robot": robot_file.name, "scale": args.scale,
               "jobs": args.jobs, "load_average_start": load0}

    t0 = time.perf_counter()
    first = ctrplan.plan(scenario, n_jobs=args.jobs, compare_blind=True).run
    results["first_plan"] = _plan_figures(first, time.perf_counter() - t0)
    _print_plan("first plan", results["first_plan"])
    maps = {"preview map": first.bound_map.field}
    if first.refinement is not None:
        maps["refined map"] = first.refinement.field
    results["first_plan"]["along_path"] = _along_path(first, maps, args.path_samples, args.jobs)

    t0 = time.perf_counter()
    second = ctrplan.plan(scenario, n_jobs=args.jobs, compare_blind=True).run
    results["second_plan"] = _plan_figures(second, time.perf_counter() - t0)
    _print_plan("second plan (warm)", results["second_plan"])

    if args.full_map:
        t0 = time.perf_counter()
        full = complete_bound_map(first.setup, args.jobs)
        results["full_map"] = {"wall_s": time.perf_counter() - t0, "resolution": list(full.field.shape)}
        print(f"\nfull map: {results['full_map']['wall_s']:.1f} s wall, {'x'.join(map(str, full.field.shape))}")
        shipped_robot = load_robot(ROBOT)
        found = find_bound_map(ROBOT, shipped_robot, first.setup.spec, first.setup.settings)
        for label, field, robot in (("new robot, full map", full.field, first.setup.robot),
                                    ("shipped six-joint map", None if found is None else found[0], shipped_robot)):
            if field is None:
                print(f"  {label}: not found")
                continue
            e = interpolation_error(field, robot, evaluate_bound, n=args.n, seed=args.seed,
                                    settings=first.setup.settings, n_jobs=args.jobs, valid_only=True)
            results.setdefault("map_error", {})[label] = {
                "n": int(e.errors.size), "refused": e.n_refused, "median_mm": e.median * 1e3, "p95_mm": e.p95 * 1e3,
                "max_mm": e.max * 1e3}
            print(f"  {label}: map - exact bound at {e.errors.size} random valid configurations: median "
                  f"{e.median * 1e3:.3f}, p95 {e.p95 * 1e3:.3f}, max {e.max * 1e3:.3f} mm ({e.n_refused} refused)")
        t0 = time.perf_counter()
        third = ctrplan.plan(scenario, n_jobs=args.jobs, compare_blind=True).run
        results["third_plan"] = _plan_figures(third, time.perf_counter() - t0)
        _print_plan("plan with the full map", results["third_plan"])
        results["first_plan"]["along_path"].update(
            _along_path(first, {"full map": full.field}, args.path_samples, args.jobs))

    results["load_average_end"] = os.getloadavg()
    print(f"\nload average at the end: {results['load_average_end']}")
    if args.results is not None:
        args.results.write_text(json.dumps(results, indent=2) + "\n")
        print(f"results in {args.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
