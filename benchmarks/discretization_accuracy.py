"""Accuracy and cost of arc-length discretizations of the contact models, against a converged
reference.

On the Table II robot (mu = 0.2) of Ha, Fagogenis & Dupont 2019, at the configurations of the
paper's 4x4x4 grid (Section IV-D) and of the 8x8x8 grid (``paper_section_4d.grid_8x8x8``), every
discretization named below is run through :func:`ctrplan.mechanics.evaluate_bound` and compared
with a **converged reference**: the default grading refined to ds / 4 and ds / 8 and extrapolated
to ds -> 0 by Richardson's rule for a second-order method, ref = u8 + (u8 - u4) / 3 (the contact
discretization is second order, docs/mechanics.md Sec. 9). Its own uncertainty at a configuration
is the largest |u8 - u4| / 3 over its tips and bounds. Where that exceeds ``--reference-tol``
(default 0.025 mm, a tenth of the 0.25 mm accuracy budget) the reference has not converged in the
step (near a fold, Sec. 5: the two fine solutions sit on different sides of it) and the
configuration is left out of the statistics; how many are left out is printed.

Measured per discretization, over every configuration where both it and the reference converged
and the reference is converged in the step:

- clearance-model tip position error [mm] (median, max);
- friction-model tip position error [mm], every direction eta of every configuration;
- error of the bound (``position``) and of the translation-last bound [mm];
- configurations whose flags differ from the reference's: not converged (a fold or a failed
  solve), elastically unstable standard solution;
- median time per bound in this run (informative only: the ratio of two discretizations is
  measured by ``--timing``).

``--timing R`` then times today's default and every other discretization alternately, R rounds,
one bound at a time in CPU time, and prints the per-configuration minimum over the rounds (mean,
median, p90, max), the ratio of the medians to the default's and the median of the
per-configuration ratios, with the load average. Run it alone on the machine.

    OPENBLAS_NUM_THREADS=1 python benchmarks/discretization_accuracy.py [--grid 4|8|both]
        [--candidate NAME:KEY=VALUE,KEY=VALUE ...] [--timing 5] [--jobs 2]
        [--out out/bench-discretization] [--results benchmarks/results/discretization-accuracy.json]

A candidate is a set of :class:`ctrplan.mechanics.ModelSettings` fields, for example
``coarse:ds=0.006,refine_ratio=0.125``. Reference solutions are cached under ``--out`` (keyed by
the mechanics version, the robot file and the settings), so a second run only solves the
candidates.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the frozen reference ctrplan_reference (tests/, not installed)

from ctrplan_reference.paper_grids import grid_4x4x4, grid_8x8x8  # noqa: E402

from ctrplan.cache import content_key, file_hash  # noqa: E402
from ctrplan.constants import MECHANICS_VERSION  # noqa: E402
from ctrplan.io.robot_file import load_robot  # noqa: E402
from ctrplan.mechanics import ModelSettings, all_eta, evaluate_bound  # noqa: E402
from ctrplan.parallel import Executor  # noqa: E402

ROBOT_FILE = ROOT / "model" / "ha2019-table2-nominal.toml"
#: Discretizations compared when none is given: today's default, and gradings with a larger step
#: away from the breakpoints and the same or a finer step at them.
DEFAULT_CANDIDATES = ("default:", "ds4.5mm-h0.75mm:ds=0.0045,refine_ratio=0.1667",
                      "ds6mm-h0.75mm:ds=0.006,refine_ratio=0.125", "ds6mm-h1.5mm:ds=0.006",
                      "ds8mm-h0.75mm:ds=0.008,refine_ratio=0.09375")
FIELDS = ("clearance", "friction", "bound", "translation_last", "converged", "unstable", "friction_converged",
          "seconds", "nodes")


def parse_candidate(text: str) -> tuple[str, dict]:
    """``NAME:KEY=VALUE,...`` -> (name, ModelSettings keywords). Raises ValueError on a bad field."""
    name, _, body = text.partition(":")
    fields = {f.name: f.type for f in ModelSettings.__dataclass_fields__.values()}
    kw = {}
    for item in filter(None, body.split(",")):
        key, _, value = item.partition("=")
        if key not in fields:
            raise ValueError(f"candidate {name!r}: {key!r} is not a ModelSettings field ({', '.join(fields)})")
        kw[key] = int(value) if fields[key] in (int, "int") else float(value)
    ModelSettings(**kw)
    return name, kw


def configurations(robot, grid: str) -> list:
    """(alpha (3,) [rad], beta (3,) [m]) of the 4x4x4 or the 8x8x8 grid."""
    if grid == "4":
        _, Q = grid_4x4x4(robot)
        return [robot.configuration(q) for q in Q]
    return grid_8x8x8()


def _solve(robot, alpha, beta, settings):
    etas = all_eta(robot.n_tubes)
    t0 = time.process_time()
    r = evaluate_bound(robot, alpha, beta, settings)
    seconds = time.process_time() - t0
    nan3 = np.full(3, np.nan)
    return {"clearance": r.clearance.tip_position,
            "friction": np.array([r.friction[e].tip_position if e in r.friction else nan3 for e in etas]),
            "bound": r.position, "translation_last": r.translation_last_position,
            "converged": r.diagnostics.converged, "unstable": r.diagnostics.unstable,
            "friction_converged": np.array([e in r.friction and r.friction[e].diagnostics.converged for e in etas]),
            "seconds": seconds, "nodes": len(r.standard.s)}


def solve_all(robot, cfgs, settings, jobs: int, cache: Path | None = None) -> dict:
    """Every configuration solved with ``settings``: arrays of :data:`FIELDS`. Cached in ``cache``
    (an .npz) when given."""
    if cache is not None and cache.exists():
        with np.load(cache) as z:
            return {k: z[k] for k in FIELDS}
    with Executor(jobs) as ex:
        done = dict(ex.run(_solve, [(k, (robot, a, b, settings)) for k, (a, b) in enumerate(cfgs)]))
    rows = [done[k] for k in range(len(cfgs))]
    out = {k: np.array([r[k] for r in rows]) for k in FIELDS}
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache.with_suffix(".tmp.npz")
        np.savez(tmp, **out)
        tmp.replace(cache)
    return out


def reference(robot, cfgs, grid: str, jobs: int, out: Path) -> tuple[dict, dict]:
    """Richardson extrapolation of the default grading at ds / 4 and ds / 8 (second order).
    Returns (reference fields with ``uncertainty`` [m] per configuration, its largest uncertainty
    [m] per quantity over the configurations where both fine solutions converged)."""
    base = ModelSettings()
    key = content_key([MECHANICS_VERSION, file_hash(ROBOT_FILE), asdict(base)])[:12]
    fine = {}
    for factor in (4, 8):
        settings = replace(base, ds=base.ds / factor)
        print(f"reference: ds = {settings.ds * 1e3:.3g} mm on the {grid}x{grid}x{grid} grid "
              f"({len(cfgs)} configurations) ...", flush=True)
        fine[factor] = solve_all(robot, cfgs, settings, jobs, out / f"reference-g{grid}-ds{factor}-{key}.npz")
    a, b = fine[4], fine[8]
    ref = dict(b)
    spread = {}
    per_config = np.zeros(len(cfgs))
    converged = a["converged"] & b["converged"]
    for k in ("clearance", "friction", "bound", "translation_last"):
        ref[k] = b[k] + (b[k] - a[k]) / 3.0
        diff = np.abs(b[k] - a[k]) / 3.0
        size = (np.linalg.norm(diff, axis=-1) if diff.ndim > 1 else diff).reshape(len(cfgs), -1)
        spread[k] = float(np.nanmax(size[converged]))
        per_config = np.fmax(per_config, np.nanmax(size, axis=1))
    ref["uncertainty"] = per_config
    ref["converged"] = converged
    ref["unstable"] = b["unstable"]
    ref["flags_agree"] = (a["converged"] == b["converged"]) & (a["unstable"] == b["unstable"])
    return ref, spread


def errors(sol: dict, ref: dict, tol: float) -> dict:
    """Error statistics of one discretization against the reference [m], over the configurations
    whose reference uncertainty is at most ``tol`` [m]; flag mismatches over all."""
    both = sol["converged"] & ref["converged"] & (ref["uncertainty"] <= tol)
    fr_ok = both[:, None] & sol["friction_converged"]
    e_clr = np.linalg.norm(sol["clearance"] - ref["clearance"], axis=-1)[both]
    e_fr = np.linalg.norm(sol["friction"] - ref["friction"], axis=-1)[fr_ok]
    e_b = np.abs(sol["bound"] - ref["bound"])[both]
    e_tl = np.abs(sol["translation_last"] - ref["translation_last"])[both]

    def stats(e):
        return {"median": float(np.median(e)), "p90": float(np.percentile(e, 90)), "max": float(np.max(e)),
                "n": int(e.size)}
    return {"clearance_tip": stats(e_clr), "friction_tip": stats(e_fr), "bound": stats(e_b),
            "translation_last_bound": stats(e_tl),
            "converged_differs": int(np.sum(sol["converged"] != ref["converged"])),
            "unstable_differs": int(np.sum(sol["unstable"] != ref["unstable"])),
            "median_seconds": float(np.median(sol["seconds"])), "median_nodes": float(np.median(sol["nodes"]))}


def timing(robot, cfgs, candidates: dict, rounds: int) -> dict:
    """Per-configuration minimum CPU time of each discretization over ``rounds`` alternated rounds."""
    names = list(candidates)
    best = {n: np.full(len(cfgs), np.inf) for n in names}
    settings = {n: ModelSettings(**kw) for n, kw in candidates.items()}
    for n in names:  # compile and warm the caches of every code path once
        evaluate_bound(robot, *cfgs[0], settings[n])
    for r in range(rounds):
        order = names if r % 2 == 0 else names[::-1]
        for i, (a, b) in enumerate(cfgs):
            for n in order:
                t0 = time.process_time()
                evaluate_bound(robot, a, b, settings[n])
                best[n][i] = min(best[n][i], time.process_time() - t0)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", choices=("4", "8", "both"), default="both")
    ap.add_argument("--candidate", action="append", default=None,
                    help="NAME:KEY=VALUE,... (ModelSettings fields); repeatable; default: a built-in set")
    ap.add_argument("--timing", type=int, default=0, metavar="ROUNDS",
                    help="also time the candidates against the default, alternated, ROUNDS rounds (run alone)")
    ap.add_argument("--reference-tol", type=float, default=0.025,
                    help="largest reference uncertainty of a configuration in the statistics [mm]")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench-discretization")
    ap.add_argument("--results", type=Path, default=None, help="write the figures to this JSON file")
    args = ap.parse_args(argv)
    try:
        candidates = dict(parse_candidate(c) for c in (args.candidate or DEFAULT_CANDIDATES))
    except ValueError as exc:
        ap.error(str(exc))
    if "default" not in candidates:
        candidates = {"default": {}, **candidates}
    robot = load_robot(ROBOT_FILE)
    print(f"{ROBOT_FILE.name}, mechanics {MECHANICS_VERSION}; load average {os.getloadavg()[0]:.2f}", flush=True)
    results = {"robot": ROBOT_FILE.name, "mechanics_version": MECHANICS_VERSION,
               "candidates": candidates, "grids": {}}
    for grid in (("4", "8") if args.grid == "both" else (args.grid,)):
        cfgs = configurations(robot, grid)
        ref, spread = reference(robot, cfgs, grid, args.jobs, args.out)
        tol = args.reference_tol * 1e-3
        settled = ref["converged"] & (ref["uncertainty"] <= tol)
        g = {"configurations": len(cfgs), "reference_uncertainty_mm": {k: v * 1e3 for k, v in spread.items()},
             "reference_converged": int(ref["converged"].sum()), "reference_tol_mm": args.reference_tol,
             "reference_settled": int(settled.sum()),
             "left_out": [int(i) for i in np.flatnonzero(ref["converged"] & ~settled)],
             "reference_flags_agree_ds4_ds8": bool(ref["flags_agree"].all()), "candidates": {}}
        print(f"\n{grid}x{grid}x{grid} grid: {len(cfgs)} configurations, reference converged at "
              f"{g['reference_converged']}; reference uncertainty |u8 - u4| / 3 at most: "
              + ", ".join(f"{k} {v:.4f} mm" for k, v in g["reference_uncertainty_mm"].items())
              + f"; {len(g['left_out'])} converged configurations left out (uncertainty above {args.reference_tol} mm): "
              + (", ".join(map(str, g["left_out"])) or "none"), flush=True)
        print(f"{'discretization':22s} {'nodes':>5s} {'ms':>6s} | {'clearance tip':>15s} | {'friction tip':>15s} | "
              f"{'bound':>15s} | {'transl.-last':>15s} | flags differ (conv., unstable)")
        print(f"{'':22s} {'':>5s} {'':>6s} | {'median    max':>15s} | {'median    max':>15s} | "
              f"{'median    max':>15s} | {'median    max':>15s} |")
        for name, kw in candidates.items():
            sol = solve_all(robot, cfgs, ModelSettings(**kw), args.jobs)
            e = errors(sol, ref, tol)
            g["candidates"][name] = e

            def cell(q):
                return f"{e[q]['median'] * 1e3:7.4f} {e[q]['max'] * 1e3:7.4f}"
            print(f"{name:22s} {e['median_nodes']:5.0f} {e['median_seconds'] * 1e3:6.1f} | {cell('clearance_tip')} | "
                  f"{cell('friction_tip')} | {cell('bound')} | {cell('translation_last_bound')} | "
                  f"{e['converged_differs']}, {e['unstable_differs']}", flush=True)
        if args.timing:
            load0 = os.getloadavg()
            best = timing(robot, cfgs, candidates, args.timing)
            load1 = os.getloadavg()
            base = best["default"]
            g["timing"] = {"rounds": args.timing, "load_average": [load0[0], load1[0]], "candidates": {}}
            print(f"\ntiming, {args.timing} alternated rounds, per-configuration minimum CPU time [ms]; "
                  f"load average {load0[0]:.2f} -> {load1[0]:.2f}")
            for name, t in best.items():
                st = {"mean": float(t.mean()), "median": float(np.median(t)), "p90": float(np.percentile(t, 90)),
                      "max": float(t.max()), "speedup_of_medians": float(np.median(base) / np.median(t)),
                      "median_speedup": float(np.median(base / t))}
                g["timing"]["candidates"][name] = st
                print(f"{name:22s} mean {st['mean'] * 1e3:6.1f} median {st['median'] * 1e3:6.1f} "
                      f"p90 {st['p90'] * 1e3:6.1f} max {st['max'] * 1e3:6.1f}; default / this: "
                      f"{st['speedup_of_medians']:.2f}x (medians), {st['median_speedup']:.2f}x (per configuration)")
        results["grids"][grid] = g
    if args.results:
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(results, indent=1) + "\n")
        print(f"wrote {args.results}")


if __name__ == "__main__":
    main()
