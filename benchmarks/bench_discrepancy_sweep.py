"""Benchmark: how often the discrepancy workflow names the right effect, a wrong one or nothing, on
hard synthetic cases made independently of the code that fits them.

Every case is a continuous trajectory of 500 samples at 10 Hz made by the reference synthesizer of
``tests/reference`` (an analytic motion, the history rules written again from their definitions,
the frozen reference solvers; none of it imports ``ctrplan.history``, ``ctrplan.effects`` or
``ctrplan.discrepancy``), on one of three robots: the Table I tube pair (most cases), the
three-tube robot of Table VII and the path-history pair of Table V (Ha, Fagogenis & Dupont, IEEE
T-RO 35(2) 2019). The truth's tube parameters (in-plane precurvatures and bending-stiffness
ratios) are 5-15 % away from the base file's, the way a real tube set differs from its drawing;
the tracker noise is 0.5 mm rms, white or AR(1) (phi 0.6 or 0.85 per sample); the hidden effects
are none (a control), one, or two at once, drawn from drive backlash, tracker time offset,
torsional friction, gradually developing friction and off-plane precurvature, each with a size
from 10 to 150 % of its typical range (:data:`SIZE_RANGE`). The workflow runs with its default
options (every registered candidate) from the base file without the effects.

    python benchmarks/bench_discrepancy_sweep.py [--cases 50] [--first-seed 2000] [--jobs 2]
                                                 [--run-first SEED ...]
                                                 [--scheduler tcp://host:8786]
                                                 [--out out/bench-discrepancy-sweep]
                                                 [--results benchmarks/results/discrepancy-sweep.json]
                                                 [--synthesize-only | --results-only]

Each case is a folder under ``--out`` (the workflow's log in ``workflow.log``; its stages are reused when the sweep is run again
after an interruption) and a line of ``cases.jsonl`` there; finished cases are not run again. The
results file is rewritten after every case with the cases finished so far (``cases`` of
``cases_planned``). ``--synthesize-only`` makes every case's data (``data.csv`` in its folder; the
reference synthesizer takes up to half an hour for a three-tube case) and stops, so that another
process or machine can make the data while the cases run; a case whose data exists does not make
it again.
With ``--scheduler`` the cases run on the Dask workers of that cluster (each with ``--jobs``
processes), else one after the other here. ``--run-first`` runs the cases of the given seeds
before the others (the cases themselves do not change): until all planned cases are finished,
the results file holds a chosen subset, and the docs table names its seeds.

Outcomes: **right** (the named effects are the truth), **partly right** (of two hidden effects,
one is named and nothing else), **ambiguous with truth** (the truth is one of an ambiguous pair),
**wrong** (a named effect, or both of an ambiguous pair, not in the truth; any name on a control),
**nothing**. A name that carries a caution counts like any other. Rates with Clopper-Pearson
intervals (two-sided 90 %, whose upper end is the one-sided 95 % bound). Targets: wrong names
below 5 %, the interval's upper end below 15 %; the truth named (right, partly right) or in the
ambiguous pair in at least 85 % of the cases whose hidden effects are all above 30 % of their
typical range.
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = {"pair": ROOT / "model" / "ha2019-table1-tube-pair.toml",
          "three-tube": ROOT / "model" / "ha2019-table7-calibrated.toml",
          "table5-pair": ROOT / "model" / "ha2019-table5-path-history-pair.toml"}
#: The robot of case i is ROBOT_CYCLE[i % 5] and its kind KIND_CYCLE[(i // 5) % 5]: 60 % of the
#: cases on the tube pair, 20 % on each of the others; 60 % with one effect, 20 % with two, 20 %
#: controls, every robot with every kind; the first 15 cases hold five of each of one effect,
#: control and one effect again, so that a shorter run still sees controls.
ROBOT_CYCLE = ("pair", "pair", "pair", "three-tube", "table5-pair")
KIND_CYCLE = ("one", "control", "one", "two", "one")
KINDS = ("control", "one", "two")
EFFECTS = ("backlash", "time_offset", "friction", "gradual_friction", "offplane")
#: Size of a hidden effect: uniform in this share of its typical range (of the half-width for a
#: range symmetric about zero, with a random sign).
SIZE_RANGE = (0.1, 1.5)
#: Relative error of every baseline tube parameter of the truth against the base file.
MISSPECIFICATION = (0.05, 0.15)
NOISE_M = 0.5e-3
AR1 = (0.0, 0.6, 0.85)
SAMPLES = 500
OUTCOMES = ("right", "partly right", "ambiguous with truth", "wrong", "nothing")
#: Cases whose hidden effects are all above this share of their typical range count for the
#: target on finding the truth.
CLEAR_SIZE = 0.3


def _draw_size(spec, share, rng) -> float:
    lo, hi = spec.typical
    if lo < 0 < hi:
        return float(rng.choice((-1.0, 1.0)) * share * min(-lo, hi))
    return float(lo + share * (hi - lo))


def plan_case(seed: int, index: int) -> dict:
    """The truth of case ``index`` (seeded by ``seed``): robot, hidden effects with their sizes (SI
    and as a share of the typical range), tube-parameter errors, noise."""
    import numpy as np

    from ctrplan.discrepancy.parameters import parameter
    from ctrplan.effects import REGISTRY
    from ctrplan.io.robot_file import load_robot

    rng = np.random.default_rng(seed)
    robot_key = ROBOT_CYCLE[index % len(ROBOT_CYCLE)]
    robot = load_robot(ROBOTS[robot_key])
    kind = KIND_CYCLE[(index // len(ROBOT_CYCLE)) % len(KIND_CYCLE)]
    n = {"control": 0, "one": 1, "two": 2}[kind]
    if n == 1:        # every effect on every robot in turn
        chosen = [EFFECTS[(index // len(ROBOT_CYCLE) + index) % len(EFFECTS)]]
    elif n == 2:      # gradual friction carries its friction coefficients: never with friction
        pairs = [p for p in itertools.combinations(EFFECTS, 2) if set(p) != {"friction", "gradual_friction"}]
        chosen = list(pairs[int(rng.integers(len(pairs)))])
    else:
        chosen = []
    hidden, shares = {}, {}
    rotating = sorted({j.tube for j in robot.joints if j.kind == "rotation"})
    for e in chosen:
        share = float(rng.uniform(*SIZE_RANGE))
        shares[e] = share
        specs = {p.name: p for p in REGISTRY[e].parameters(robot)}
        if e == "backlash":
            hidden[e] = {f"backlash_{i + 1}": _draw_size(specs[f"backlash_{i + 1}"], share, rng) for i in rotating}
        elif e == "time_offset":
            hidden[e] = {"time_offset": _draw_size(specs["time_offset"], share, rng)}
        elif e == "offplane":
            hidden[e] = {k: _draw_size(s, share, rng) for k, s in specs.items()}
        elif e == "friction":
            fs = {p.name: p for p in REGISTRY["friction"].parameters(robot)}
            hidden[e] = {k: _draw_size(s, share, rng) for k, s in fs.items()}
        elif e == "gradual_friction":
            fs = {p.name: p for p in REGISTRY["friction"].parameters(robot)}
            hidden["friction"] = {k: _draw_size(s, float(rng.uniform(0.3, 1.0)), rng) for k, s in fs.items()}
            hidden[e] = {"friction_angle": _draw_size(specs["friction_angle"], share, rng)}
    from ctrplan.discrepancy.setup import default_baseline_parameters

    names = default_baseline_parameters(robot, register=False)
    errors = {nm: float(rng.choice((-1.0, 1.0)) * rng.uniform(*MISSPECIFICATION)) for nm in names}
    for nm in names:
        parameter(robot, nm)               # validates
    return {"seed": int(seed), "index": int(index), "robot": robot_key, "kind": kind, "truth": sorted(chosen), "hidden": hidden,
            "size_shares": shares, "tube_errors": errors, "ar1": float(rng.choice(AR1)), "noise_m": NOISE_M}


def _truth_robot(plan: dict):
    import numpy as np

    from ctrplan.discrepancy.parameters import apply_parameters, read_parameters
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(ROBOTS[plan["robot"]])
    robot = robot.replace(friction_coefficients=(0.0,) * (robot.n_tubes - 1))
    names = tuple(plan["tube_errors"])
    values = read_parameters(robot, names) * (1.0 + np.array([plan["tube_errors"][n] for n in names]))
    truth = apply_parameters(robot, names, values)
    if "offplane" in plan["hidden"]:
        off = plan["hidden"]["offplane"]
        truth = apply_parameters(truth, tuple(off), tuple(off.values()))
    if "friction" in plan["hidden"]:
        mu = plan["hidden"]["friction"]
        truth = truth.replace(friction_coefficients=tuple(mu[f"mu_{k + 1}"] for k in range(robot.n_tubes - 1)))
    return robot, truth


def outcome(truth: list, res: dict) -> str:
    """One of :data:`OUTCOMES` for a run's results."""
    named = set(res["named_effects"])
    if res["verdict"] == "none":
        return "nothing"
    if res["verdict"] == "ambiguous":
        pair = {res["named_effect"], res["ambiguous_with"]}
        return "ambiguous with truth" if pair & set(truth) else "wrong"
    if not truth or not named <= set(truth):
        return "wrong"
    return "right" if named == set(truth) else "partly right"


def synthesize_case(seed: int, index: int, out: str) -> tuple:
    """The base file and the data of case ``index`` (seeded by ``seed``; reference synthesizer) in
    its folder under ``out``, the data made unless an earlier run made it: ``(plan, base file,
    data file, seconds spent making the data)``."""
    sys.path.insert(0, str(ROOT / "tests"))
    from reference.synth_reference import synthesize_reference

    from ctrplan.io.robot_file import robot_to_toml

    plan = plan_case(seed, index)
    folder = Path(out) / f"case-{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    base, truth = _truth_robot(plan)
    model = folder / "base.toml"
    model.write_text(robot_to_toml(base, header="sweep base file: nominal tube parameters, candidate effects off"))
    data = folder / "data.csv"
    t0 = time.perf_counter()
    hidden = plan["hidden"]
    if not data.exists():
        kw = {}
        if "backlash" in hidden:
            kw["backlash"] = tuple(hidden["backlash"].get(f"backlash_{i + 1}", 0.0) for i in range(base.n_tubes))
        if "time_offset" in hidden:
            kw["time_offset"] = hidden["time_offset"]["time_offset"]
        if "friction" in hidden:
            kw["mu"] = truth.friction_coefficients
        if "gradual_friction" in hidden:
            kw["friction_angle"] = hidden["gradual_friction"]["friction_angle"]
        frame, _ = synthesize_reference(truth, samples=SAMPLES, seed=seed, noise_position_rms=plan["noise_m"],
                                        noise_ar1=plan["ar1"], **kw)
        tmp = data.with_suffix(".tmp")
        frame.to_csv(tmp, index=False)
        tmp.replace(data)
    return plan, model, data, time.perf_counter() - t0


def run_case(seed: int, index: int, out: str, jobs: int) -> dict:
    """Case ``index`` (seeded by ``seed``): its data (:func:`synthesize_case`), then the workflow
    on it; the case's line of ``cases.jsonl`` (``seconds`` counts the data's making where this
    call made it, ``synth_seconds``)."""
    from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy

    t0 = time.perf_counter()
    plan, model, data, synth_s = synthesize_case(seed, index, out)
    folder = model.parent
    opts = DiscrepancyOptions(n_jobs=jobs, seed=seed)
    log = logging.FileHandler(folder / "workflow.log")
    log.setFormatter(logging.Formatter("%(asctime)s %(message)s", "%H:%M:%S"))
    package = logging.getLogger("ctrplan")
    level = package.level
    package.addHandler(log)
    package.setLevel(logging.INFO)
    try:
        res = run_discrepancy(model, data, folder / "report", opts, progress=False).to_dict()
    finally:
        package.removeHandler(log)
        package.setLevel(level)
        log.close()
    final = res["named_effects"]
    fitted = {e: res["candidates"][e]["parameters"] for e in final if e in res["candidates"]}
    return {**plan, "verdict": res["verdict"], "named": res["named_effect"], "ambiguous_with": res["ambiguous_with"],
            "named_effects": final, "outcome": outcome(plan["truth"], res), "fitted": fitted,
            "written": written_values(res["updated_model_file"], final, fitted),
            "cautions": res["decision"].get("cautions", []), "noise_consistent": res["noise"]["consistent"],
            "noise_mm": res["noise"]["noise_rms_mm"],
            "test_mean_mm": {k: res["test_split"]["figures"][k]["mean_mm"]["value"] for k in ("file", "before", "after")},
            "prior_strength": res["baseline"]["prior_strength"], "synth_seconds": synth_s,
            "seconds": time.perf_counter() - t0, "stage_seconds": res.get("stage_seconds", {}),
            "source_sha256": res["provenance"]["source_sha256"]}


def written_values(model_file, named, fitted) -> dict:
    """``{effect: {parameter: value}}`` of the named effects as the written robot file holds them
    (fitted jointly where two are named); the registration, which a robot file does not hold, as
    ``fitted`` gives it (each named effect fitted alone)."""
    from ctrplan.discrepancy.parameters import read_parameters
    from ctrplan.discrepancy.setup import reported_parameters
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(model_file)
    out = {}
    for e in named:
        if e == "registration":
            out[e] = dict(fitted.get(e, {}))
            continue
        names = reported_parameters(robot, e)
        out[e] = {n: float(v) for n, v in zip(names, read_parameters(robot, names))}
    return out


def clopper_pearson(k: int, n: int, level: float = 0.90) -> list:
    """Two-sided Clopper-Pearson interval of k successes in n (``scipy.stats.binomtest``)."""
    from scipy.stats import binomtest

    if n == 0:
        return [None, None]
    ci = binomtest(k, n).proportion_ci(confidence_level=level, method="exact")
    return [float(ci.low), float(ci.high)]


def summarize(cases: list) -> dict:
    """Counts per outcome (all cases, per robot, per kind) and the rates of the targets."""
    def counts(sub):
        return {o: sum(c["outcome"] == o for c in sub) for o in OUTCOMES}

    clear = [c for c in cases if c["truth"] and min(c["size_shares"].values()) > CLEAR_SIZE]
    found = sum(c["outcome"] in ("right", "partly right", "ambiguous with truth") for c in clear)
    wrong = sum(c["outcome"] == "wrong" for c in cases)
    return {"cases": len(cases), "by_outcome": counts(cases),
            "by_robot": {r: counts([c for c in cases if c["robot"] == r]) for r in ROBOTS},
            "by_kind": {k: counts([c for c in cases if c["kind"] == k]) for k in KINDS},
            "by_truth": {e: counts([c for c in cases if c["truth"] == [e]]) for e in ("none",) + EFFECTS},
            "wrong": wrong, "wrong_rate": wrong / len(cases) if cases else None,
            "wrong_ci90": clopper_pearson(wrong, len(cases)),
            "clear_cases": len(clear), "clear_found": found,
            "clear_found_rate": found / len(clear) if clear else None,
            "clear_found_ci90": clopper_pearson(found, len(clear)),
            "targets": {"wrong_rate_below": 0.05, "wrong_upper_below": 0.15, "clear_found_at_least": 0.85}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=50)
    ap.add_argument("--first-seed", type=int, default=2000)
    ap.add_argument("--jobs", type=int, default=2, help="worker processes within a case")
    ap.add_argument("--scheduler", default=None, help="address of a Dask scheduler to run the cases on")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench-discrepancy-sweep"))
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "discrepancy-sweep.json"))
    ap.add_argument("--run-first", type=int, nargs="+", default=(), metavar="SEED",
                    help="run the cases of these seeds (of the planned ones) before the others")
    ap.add_argument("--synthesize-only", action="store_true",
                    help="make the data of the planned cases not made yet, run no workflow, write no results")
    ap.add_argument("--results-only", action="store_true",
                    help="rewrite the results file from the finished cases without running any")
    args = ap.parse_args(argv)
    from ctrplan.discrepancy.provenance import provenance

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "cases.jsonl"
    done = {}
    if log.exists():
        for line in log.read_text().splitlines():
            if line.strip():
                c = json.loads(line)
                if "written" not in c:   # a case recorded before the written values were: read its file
                    files = sorted((out / f"case-{c['seed']}" / "report").glob("*.toml"))
                    c["written"] = written_values(files[-1], c["named_effects"], c["fitted"]) if files else None
                done[c["seed"]] = c
    seeds = [args.first_seed + k for k in range(args.cases)]
    unknown = sorted(set(args.run_first) - set(seeds))
    if unknown:
        ap.error(f"--run-first: seeds {unknown} are not among the planned {seeds[0]}..{seeds[-1]}")
    first = [s for s in args.run_first if s not in done]
    todo = first + [s for s in seeds if s not in done and s not in first]
    print(f"{len(seeds) - len(todo)} of {len(seeds)} cases finished earlier, {len(todo)} to run; load average "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    t0 = time.perf_counter()
    results = Path(args.results)

    def write_results():
        """The results file of the cases finished so far (rewritten after every case)."""
        cases = [done[s] for s in seeds if s in done]
        if not cases:
            return cases
        results.parent.mkdir(parents=True, exist_ok=True)
        results.write_text(json.dumps({
            "command": f"python benchmarks/bench_discrepancy_sweep.py --cases {args.cases} --first-seed {args.first_seed}",
            "cases_planned": len(seeds), "samples": SAMPLES, "robots": {k: v.name for k, v in ROBOTS.items()},
            "summary": summarize(cases),
            "case_seconds": {"total": sum(c["seconds"] for c in cases),
                             "median": sorted(c["seconds"] for c in cases)[len(cases) // 2]},
            "provenance": {**provenance(), "cases_source_sha256": sorted({c["source_sha256"] for c in cases})},
            "cases": cases}, indent=1) + "\n")
        return cases

    def record(case):
        done[case["seed"]] = case
        with log.open("a") as fh:
            fh.write(json.dumps(case) + "\n")
        write_results()
        print(f"  {case['seed']} {case['robot']:11s} truth {','.join(case['truth']) or 'none':28s} -> "
              f"{case['outcome']:20s} ({case['verdict']}: {','.join(case['named_effects']) or '-'}"
              + (f" or {case['ambiguous_with']}" if case["ambiguous_with"] else "") + f"); {case['seconds']:.0f} s",
              flush=True)

    if args.synthesize_only:
        for s in todo:
            t = synthesize_case(s, s - args.first_seed, str(out))[3]
            print(f"  {s} data made in {t:.0f} s", flush=True)
        return 0
    if args.results_only:
        todo = []
    if args.scheduler and todo:
        from dask.distributed import Client, as_completed

        with Client(args.scheduler) as client:
            futures = client.map(run_case, todo, [s - args.first_seed for s in todo], out=str(out), jobs=args.jobs,
                                 pure=False)
            for fut in as_completed(futures):
                record(fut.result())
    else:
        for s in todo:
            record(run_case(s, s - args.first_seed, str(out), args.jobs))
    cases = write_results()
    summary = summarize(cases)
    wall = time.perf_counter() - t0
    print(json.dumps({k: summary[k] for k in ("by_outcome", "wrong", "wrong_ci90", "clear_cases", "clear_found",
                                              "clear_found_ci90")}, indent=1))
    print(f"{wall:.0f} s this run, {sum(c['seconds'] for c in cases):.0f} s of cases in all; load average "
          f"{os.getloadavg()[0]:.2f}")
    print(f"wrote {results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
