"""Benchmark: does a designed experiment settle what a short recording left open?

Each case hides one effect (the truth) in data of a robot, with a second effect that a short
recording confuses with it (the alternative):

- off-plane precurvature against a rotation of the tracker frame (``registration``);
- drive backlash against torsional friction;
- a tracker lag (``time_offset``) against gradually developing friction.

Per case: a 20-s pilot recording (200 samples at 10 Hz) of tube rotations at the home insertion
(the reference synthesizer's seeded motion with its translation steps removed) is synthesized with
the truth. Such a recording leaves each pair open: what the registry's ``separated_by`` names for
them (translations after rotations, tips near and far from the base, rests and passes at several
speeds) is missing or scarce in it. ``ctrplan discrepancy`` fits both candidates
(``--effects truth,alternative``); from its ``results.json`` ``ctrplan.design`` plans a follow-up
motion of :data:`BUDGET_S` (three times the pilot) that separates the two fitted hypotheses. The
truth is then synthesized along three follow-ups of that budget: the designed motion, a random one
(random primitives within the same limits, drawn by the design's own comparison) and three
repetitions of the pilot (new noise each), and ``ctrplan discrepancy`` runs on the pilot and each
follow-up together (``--data`` once per recording). A run names the truth when its verdict names
the truth alone.

The data are made by the reference synthesizer of ``tests/ctrplan_reference`` (independent of the code
that fits), along the given motions: its ``reference_motion`` is replaced by the designed, random
or recorded motion (each segment a minimum-jerk move with the duration ruckig gave it). The truth
robots are built by ``bench_discrepancy_sweep._truth_robot`` (no ``ctrplan.discrepancy`` or
``ctrplan.effects``).

Usage::

    python benchmarks/bench_design.py [--cases 10] [--jobs 2] [--out out/bench-design]
                                      [--results benchmarks/results/design.json]

Cases are stored one per line in ``<out>/cases.jsonl``; a rerun skips the cases there.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the frozen reference ctrplan_reference (tests/, not installed)

#: The cases: robot, truth, alternative, hidden values (SI), seed. Two robots (the Table I tube pair
#: and the Table VII three-tube robot), three confusable pairs.
CASES = (
    ("pair", "offplane", "registration", {"offplane": {"precurvature_x_1": 1.0, "precurvature_x_2": 1.0}}, 101),
    ("pair", "backlash", "friction", {"backlash": {"backlash_2": np.deg2rad(3.0)}}, 102),
    ("pair", "time_offset", "gradual_friction", {"time_offset": {"time_offset": 0.15}}, 103),
    ("three-tube", "offplane", "registration", {"offplane": {"precurvature_x_3": 1.5}}, 104),
    ("pair", "offplane", "registration", {"offplane": {"precurvature_x_1": 0.6, "precurvature_x_2": 0.6}}, 105),
    ("pair", "backlash", "friction", {"backlash": {"backlash_2": np.deg2rad(2.0)}}, 106),
    ("pair", "time_offset", "gradual_friction", {"time_offset": {"time_offset": 0.10}}, 107),
    ("three-tube", "backlash", "friction", {"backlash": {"backlash_2": np.deg2rad(2.0),
                                                         "backlash_3": np.deg2rad(2.0)}}, 108),
    ("pair", "offplane", "registration", {"offplane": {"precurvature_x_1": -0.8, "precurvature_x_2": 0.8}}, 109),
    ("three-tube", "time_offset", "gradual_friction", {"time_offset": {"time_offset": 0.12}}, 110),
)
SAMPLES = 200
RATE_HZ = 10.0
#: Budget of the follow-up experiment [s]: three times the pilot recording.
BUDGET_S = 3 * SAMPLES / RATE_HZ
REPEATS = 3
NOISE_M = 0.5e-3


def _synthesize(truth_robot, hidden: dict, seed: int, motion=None):
    """The reference synthesizer's record of ``truth_robot`` with ``hidden`` (along ``motion`` when
    given, else its own seeded motion of SAMPLES samples)."""
    import ctrplan_reference.synth_reference as sr

    kw = {}
    if "backlash" in hidden:
        kw["backlash"] = tuple(hidden["backlash"].get(f"backlash_{i + 1}", 0.0) for i in range(truth_robot.n_tubes))
    if "time_offset" in hidden:
        kw["time_offset"] = hidden["time_offset"]["time_offset"]
    if motion is None:
        return sr.synthesize_reference(truth_robot, samples=SAMPLES, rate_hz=RATE_HZ, seed=seed,
                                       noise_position_rms=NOISE_M, **kw)
    with mock.patch.object(sr, "reference_motion", lambda robot, **_: motion):
        return sr.synthesize_reference(truth_robot, samples=len(motion.times), rate_hz=RATE_HZ, seed=seed,
                                       noise_position_rms=NOISE_M, **kw)


def _pilot_motion(truth_robot, seed: int):
    """The reference synthesizer's seeded motion of SAMPLES samples with every translation step
    removed: rotations of the tubes at the home insertion."""
    import dataclasses

    import ctrplan_reference.synth_reference as sr

    m = sr.reference_motion(truth_robot, samples=SAMPLES, rate_hz=RATE_HZ, seed=seed)
    steps = np.where(m.rotation[None, :], m.steps, 0.0)
    return dataclasses.replace(m, steps=steps)


def _reference_motion(robot, traj, sample_times):
    """The reference synthesizer's motion object for a ruckig trajectory: one minimum-jerk move per
    segment, with its start and duration."""
    from ctrplan_reference.synth_reference import ReferenceMotion

    segs = traj.segments
    return ReferenceMotion(joint_names=tuple(robot.joint_names),
                           rotation=np.array([j.kind == "rotation" for j in robot.joints]),
                           q0=np.asarray(traj.position[0], float),
                           starts=np.array([s.t_start for s in segs]), durations=np.array([s.duration for s in segs]),
                           steps=np.array([s.q_end - s.q_start for s in segs]), times=np.asarray(sample_times, float),
                           end_time=float(traj.duration))


def _discrepancy(model, data_files, out, effects, jobs, seed) -> dict:
    from click.testing import CliRunner

    from ctrplan.cli import main

    if (Path(out) / "results.json").exists():
        return json.loads((Path(out) / "results.json").read_text())
    args = ["-q", "discrepancy", "--robot", str(model), "--out", str(out), "--effects", ",".join(effects),
            "--jobs", str(jobs), "--seed", str(seed), "--no-progress"]
    for f in data_files:
        args += ["--data", str(f)]
    r = CliRunner().invoke(main, args, catch_exceptions=False)
    if r.exit_code != 0:
        raise RuntimeError(f"ctrplan discrepancy failed ({r.exit_code}): {r.output[-2000:]}")
    return json.loads((Path(out) / "results.json").read_text())


def _comparison(res: dict, truth: str, alternative: str) -> dict | None:
    """The run's out-of-fold comparison of the truth against the alternative: the ratio of their
    folds' mean errors (alternative over truth), its interval, the one-sided p-value, the folds."""
    c = ((res.get("decision") or {}).get("comparisons") or {}).get(f"{truth} vs {alternative}")
    if not c:
        return None
    return {k: c.get(k) for k in ("ratio", "ratio_ci", "p_value", "n_folds", "positive_folds")}


def _named_right(res: dict, truth: str) -> bool:
    return res.get("verdict") == "named" and list(res.get("named_effects") or []) == [truth]


def run_case(index: int, out: Path, jobs: int) -> dict:
    """Case ``index`` of :data:`CASES`, its line of ``cases.jsonl``."""
    from bench_discrepancy_sweep import _truth_robot

    from ctrplan.design import (DesignSearch, ExperimentLimits, SensorNoise, design_experiment, result_hypotheses,
                                sample, trajectory)
    from ctrplan.discrepancy import load_measured_data
    from ctrplan.io.robot_file import robot_to_toml

    robot_key, truth_e, alt_e, hidden, seed = CASES[index]
    folder = out / f"case-{index}"
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    base, truth_robot = _truth_robot({"robot": robot_key, "tube_errors": {}, "hidden": hidden})
    model = folder / "base.toml"
    model.write_text(robot_to_toml(base, header="design benchmark base file: candidate effects off"))
    recorded = folder / "recorded.csv"
    frame, rec_truth = _synthesize(truth_robot, hidden, seed, _pilot_motion(truth_robot, seed))
    frame.to_csv(recorded, index=False)
    # gradual friction is fitted on top of friction (Effect.after): its run needs both
    effects = (truth_e, alt_e) + (("friction",) if "gradual_friction" in (truth_e, alt_e) else ())
    first = _discrepancy(model, [recorded], folder / "recorded", effects, jobs, seed)
    hyps = result_hypotheses(first, [truth_e, alt_e])
    data = load_measured_data(recorded, base)
    noise = first["noise"]["noise"]
    t1 = time.perf_counter()
    design = design_experiment(base, data, hyps,
                               noise=SensorNoise.from_estimate(noise),
                               limits=ExperimentLimits(duration=BUDGET_S), search=DesignSearch(n_random=1, seed=seed))
    design_s = time.perf_counter() - t1
    runs, files = {}, {}
    motions = {"designed": design.primitives, "random": design.random_primitives[0]}
    drive = None
    for key, prims in motions.items():
        from ctrplan.design import drive_from_data

        drive = drive or drive_from_data(base, data)
        traj = trajectory(base, list(prims), drive)
        times, _ = sample(traj, 1.0 / RATE_HZ)
        new, _ = _synthesize(truth_robot, hidden, seed + 1000, _reference_motion(base, traj, times))
        path = folder / f"{key}.csv"
        new.to_csv(path, index=False)
        files[key] = [path]
        runs[key] = {"duration_s": float(traj.duration), "samples": int(len(new))}
    rep = rec_truth["motion"]
    files["repeated"] = []
    for r in range(REPEATS):
        new, _ = _synthesize(truth_robot, hidden, seed + 2000 + r, rep)
        files["repeated"].append(folder / f"repeated-{r + 1}.csv")
        new.to_csv(files["repeated"][-1], index=False)
    runs["repeated"] = {"duration_s": REPEATS * float(rep.end_time), "samples": REPEATS * int(len(new))}
    for key in runs:
        res = _discrepancy(model, [recorded, *files[key]], folder / key, effects, jobs, seed)
        runs[key].update(verdict=res["verdict"], named=res["named_effect"], named_effects=res["named_effects"],
                         ambiguous_with=res["ambiguous_with"], right=_named_right(res, truth_e),
                         comparison=_comparison(res, truth_e, alt_e))
    sep = design.separation
    return {"index": index, "robot": robot_key, "truth": truth_e, "alternative": alt_e, "hidden": hidden,
            "seed": seed, "budget_s": BUDGET_S,
            "recorded": {"verdict": first["verdict"], "named": first["named_effect"],
                                       "named_effects": first["named_effects"],
                                       "ambiguous_with": first["ambiguous_with"],
                                       "right": _named_right(first, truth_e),
                                       "comparison": _comparison(first, truth_e, alt_e)},
            "predicted_separation": {k: (min(v.values()) if isinstance(v, dict) else [min(x.values()) for x in v])
                                     for k, v in sep.items()},
            "runs": runs, "primitives": [p.describe(base.joint_names) for p in design.primitives],
            "design_seconds": design_s, "seconds": time.perf_counter() - t0}


def summarize(cases: list) -> dict:
    from bench_discrepancy_sweep import clopper_pearson

    n = len(cases)
    out = {"n_cases": n}
    for key in ("designed", "random", "repeated"):
        k = sum(1 for c in cases if c["runs"][key]["right"])
        out[f"{key}_right"] = k
        out[f"{key}_right_interval_90"] = clopper_pearson(k, n, 0.90) if n else None
    out["recorded_right"] = sum(1 for c in cases if c["recorded"]["right"])
    out["recorded_ambiguous"] = sum(1 for c in cases if c["recorded"]["verdict"] == "ambiguous")
    # the cases the pilot recording left open (not named right by it alone)
    open_cases = [c for c in cases if not c["recorded"]["right"]]
    out["n_open"] = len(open_cases)
    for key in ("designed", "random", "repeated"):
        k = sum(1 for c in open_cases if c["runs"][key]["right"])
        out[f"open_{key}_right"] = k
        out[f"open_{key}_right_interval_90"] = clopper_pearson(k, len(open_cases), 0.90) if open_cases else None
    for key in ("recorded", "designed", "random", "repeated"):
        ratios = [(c["recorded"] if key == "recorded" else c["runs"][key]).get("comparison") for c in cases]
        ratios = [r["ratio"] for r in ratios if r and r.get("ratio") is not None]
        out[f"{key}_ratio_median"] = float(np.median(ratios)) if ratios else None
    return out


def main(argv=None):
    from _records import run_record

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=len(CASES))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench-design"))
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "design.json"))
    args = ap.parse_args(argv)
    logging.getLogger("ctrplan").setLevel(logging.WARNING)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    store = out / "cases.jsonl"
    done = {}
    if store.exists():
        for line in store.read_text().splitlines():
            c = json.loads(line)
            done[c["index"]] = c
    load0 = os.getloadavg()
    for i in range(min(args.cases, len(CASES))):
        if i in done:
            continue
        c = run_case(i, out, args.jobs)
        done[i] = c
        with store.open("a") as f:
            f.write(json.dumps(c) + "\n")
        print(f"case {i}: {c['robot']} {c['truth']} vs {c['alternative']}: recorded {c['recorded']['verdict']} "
              f"{c['recorded']['named_effects']}; designed {c['runs']['designed']['right']}, random "
              f"{c['runs']['random']['right']}, repeated {c['runs']['repeated']['right']} ({c['seconds']:.0f} s)",
              flush=True)
    cases = [done[i] for i in sorted(done)]
    results = {"summary": summarize(cases), "cases": cases,
               "run": run_record("python benchmarks/bench_design.py " + " ".join(argv or sys.argv[1:]), load0,
                                 os.getloadavg())}
    Path(args.results).write_text(json.dumps(results, indent=1, default=float) + "\n")
    print(json.dumps(results["summary"], indent=1))


if __name__ == "__main__":
    main()
