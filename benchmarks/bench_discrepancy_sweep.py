"""Benchmark: what the discrepancy workflow names on synthetic data with one hidden effect, over seeds.

For each seed and each truth (drive backlash, tracker time offset, torsional friction, gradually
developing friction, off-plane precurvature, noise only), synthesizes a continuous trajectory of
the Table I tube pair (500 samples at 10 Hz, 0.5 mm / 0.3 deg noise, standard model at ds = 6 mm
or the friction model for the friction truths) with the effect's size drawn uniformly from 30 to
100 % of its typical range (random sign where the range is two-sided), runs the workflow with
every registered candidate from the base file without the effect, and prints the confusion
matrix: truth x {named (right), ambiguous with the truth, named wrong, ambiguous without the
truth, nothing}.

    python benchmarks/bench_discrepancy_sweep.py [--seeds 5] [--first-seed 1000] [--jobs 2]
                                                 [--out out/bench-discrepancy-sweep]
                                                 [--results benchmarks/results/discrepancy-sweep.json]

Each case is a separate run folder under ``--out`` (its stages are reused when the sweep is run
again after an interruption) and one line of ``cases.jsonl`` there; finished cases are not run
again. ``--results`` receives the matrix and the cases (derived numbers only).

Targets: no wrong name; the truth named or in the ambiguous pair in at least 90 % of the cases
with an effect; nothing named on noise only.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
TRUTHS = ("backlash", "time_offset", "friction", "gradual_friction", "offplane", "none")
OUTCOMES = ("named", "ambiguous with truth", "named wrong", "ambiguous without truth", "nothing")
SAMPLES = 500


def draw_effects(truth: str, robot, rng) -> dict:
    """The hidden effects of a case: ``{effect: {parameter: value}}`` [SI], sizes drawn from 30 to
    100 % of each parameter's typical range."""
    from ctrplan.effects import REGISTRY

    def size(spec):
        lo, hi = spec.typical
        if lo < 0 < hi:
            return float(rng.choice((-1.0, 1.0)) * rng.uniform(0.3, 1.0) * min(-lo, hi))
        return float(lo + rng.uniform(0.3, 1.0) * (hi - lo))

    specs = {e: {p.name: p for p in REGISTRY[e].parameters(robot)} for e in REGISTRY}
    if truth == "none":
        return {}
    if truth == "backlash":
        return {"backlash": {"backlash_2": size(specs["backlash"]["backlash_2"])}}
    if truth == "time_offset":
        return {"time_offset": {"time_offset": size(specs["time_offset"]["time_offset"])}}
    if truth == "friction":
        return {"friction": {"mu_1": size(specs["friction"]["mu_1"])}}
    if truth == "gradual_friction":
        return {"friction": {"mu_1": size(specs["friction"]["mu_1"])},
                "gradual_friction": {"friction_angle": size(specs["gradual_friction"]["friction_angle"])}}
    if truth == "offplane":
        return {"offplane": {n: size(p) for n, p in specs["offplane"].items()}}
    raise ValueError(truth)


def outcome(truth: str, res: dict) -> str:
    """One of :data:`OUTCOMES` for a run's results."""
    named, other, verdict = res["named_effect"], res["ambiguous_with"], res["verdict"]
    if verdict == "none":
        return "nothing"
    if verdict == "ambiguous":
        return "ambiguous with truth" if truth in (named, other) else "ambiguous without truth"
    return "named" if named == truth else "named wrong"


def run_case(truth: str, seed: int, out: Path) -> dict:
    import numpy as np

    from ctrplan.discrepancy import Noise, synthesize, write_synth
    from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy
    from ctrplan.io.robot_file import load_robot, robot_to_toml
    from ctrplan.mechanics import ModelSettings

    rng = np.random.default_rng(seed)
    pair = load_robot(PAIR)
    base = pair.replace(friction_coefficients=(0.0,))
    effects = draw_effects(truth, base, rng)
    folder = out / f"{truth}-{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    model = folder / "pair.toml"
    model.write_text(robot_to_toml(base, header="Table I tube pair, friction off (sweep base file)"))
    data = folder / "data.csv"
    t0 = time.perf_counter()
    if not data.exists():
        write_synth(data, synthesize(base, effects, protocol="trajectory", samples=SAMPLES,
                                     noise=Noise(position_rms=0.5e-3, angle_rms=float(np.deg2rad(0.3))), seed=seed,
                                     settings=ModelSettings(ds=6e-3)))
    opts = DiscrepancyOptions(ds=6e-3, n_permutations=199, max_evaluations=200, n_jobs=1, seed=seed)
    res = run_discrepancy(model, data, folder / "report", opts, echo=lambda s: None, progress=False)
    fitted = {e: res["candidates"][e]["parameters"] for e in (res["named_effect"], res["ambiguous_with"]) if e}
    return {"truth": truth, "seed": seed, "hidden": effects, "verdict": res["verdict"], "named": res["named_effect"],
            "ambiguous_with": res["ambiguous_with"], "named_effects": res["named_effects"],
            "outcome": outcome(truth, res), "fitted": fitted,
            "noise_consistent": res["noise"]["consistent"],
            "test_mean_mm": [res["test_split"]["before"]["position_mean_mm"],
                             res["test_split"]["after"]["position_mean_mm"]],
            "seconds": time.perf_counter() - t0}


def matrix(cases: list) -> dict:
    """``{truth: {outcome: count}}``."""
    m = {t: {o: 0 for o in OUTCOMES} for t in TRUTHS}
    for c in cases:
        m[c["truth"]][c["outcome"]] += 1
    return m


def markdown(m: dict) -> str:
    lines = ["| truth | " + " | ".join(OUTCOMES) + " |", "| --- |" + " --- |" * len(OUTCOMES)]
    for t in TRUTHS:
        lines.append(f"| {t} | " + " | ".join(str(m[t][o]) for o in OUTCOMES) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=2, help="cases run at once")
    ap.add_argument("--truths", default=",".join(TRUTHS))
    ap.add_argument("--out", default=str(ROOT / "out" / "bench-discrepancy-sweep"))
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "discrepancy-sweep.json"))
    args = ap.parse_args(argv)
    from joblib import Parallel, delayed

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "cases.jsonl"
    done = {}
    if log.exists():
        for line in log.read_text().splitlines():
            if line.strip():
                c = json.loads(line)
                done[(c["truth"], c["seed"])] = c
    todo = [(t, args.first_seed + k) for k in range(args.seeds) for t in args.truths.split(",")
            if (t, args.first_seed + k) not in done]
    print(f"{len(done)} cases finished earlier, {len(todo)} to run, {args.jobs} at once; load average "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    t0 = time.perf_counter()
    for case in Parallel(n_jobs=args.jobs, return_as="generator_unordered")(
            delayed(run_case)(t, s, out) for t, s in todo):
        done[(case["truth"], case["seed"])] = case
        with log.open("a") as fh:
            fh.write(json.dumps(case) + "\n")
        print(f"  {case['truth']:17s} seed {case['seed']}: {case['outcome']:24s} named {case['named']} "
              f"(or {case['ambiguous_with']}); hidden {case['hidden']}; fitted {case['fitted']}; "
              f"{case['seconds']:.0f} s", flush=True)
    cases = sorted((c for c in done.values() if c["seed"] < args.first_seed + args.seeds),
                   key=lambda c: (TRUTHS.index(c["truth"]), c["seed"]))
    m = matrix(cases)
    with_effect = [c for c in cases if c["truth"] != "none"]
    found = sum(c["outcome"] in ("named", "ambiguous with truth") for c in with_effect)
    wrong = sum(c["outcome"] == "named wrong" for c in cases) + sum(
        c["outcome"] != "nothing" for c in cases if c["truth"] == "none")
    summary = {"cases": len(cases), "truth_found": found, "cases_with_effect": len(with_effect),
               "truth_found_fraction": found / len(with_effect) if with_effect else None, "wrong_names": wrong}
    print()
    print(markdown(m))
    print(f"\ntruth named or in the ambiguous pair: {found} of {len(with_effect)} cases with an effect; wrong names "
          f"(including any name on noise only): {wrong}; {time.perf_counter() - t0:.0f} s this run; load average "
          f"{os.getloadavg()[0]:.2f}")
    results = Path(args.results)
    results.parent.mkdir(parents=True, exist_ok=True)
    results.write_text(json.dumps({"command": "python benchmarks/bench_discrepancy_sweep.py "
                                              f"--seeds {args.seeds} --first-seed {args.first_seed}",
                                   "samples": SAMPLES, "robot": PAIR.name, "matrix": m, "summary": summary,
                                   "cases": cases}, indent=1) + "\n")
    print(f"wrote {results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
