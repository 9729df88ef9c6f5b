"""Benchmark: does a designed follow-up settle what a short pilot recording left open, where a random
follow-up or more of the same recording does not?

**The rule, fixed before any case is drawn.** Candidate case k (k = 0, 1, ...) is seeded by
``FIRST_SEED + k``; its robot and pair of confusable effects are ``COMBOS[k % 7]``: three robots
(the Table I tube pair, the Table II robot with six joints, whose outer tube rotates, the Table VII
three-tube robot) and three pairs (off-plane precurvature against a rotation of the tracker frame,
``registration``; drive backlash against torsional friction; a tracker lag, ``time_offset``,
against gradually developing friction), every pair on every robot except off-plane precurvature
against a registration where the outer tube does not rotate: there no motion of the drive tells a
tilted bending plane of the fixed outer tube from a tracker frame turned about the base axis, and
the workflow calls them not separable on any recording. The first effect of the pair is hidden in
the data (the truth), each of its parameters log-uniform in :data:`SHARE_RANGE` of the effect
registry's typical range. Its
pilot is a 20-s recording (200 samples at 10 Hz) of rotations of the inner tubes at the home
insertion, the outer tube held (the reference synthesizer's seeded motion with its translation
steps and the outer tube's steps removed), on which ``ctrplan
discrepancy`` fits both effects (``--effects truth,alternative``). A case is **kept** when the pilot
leaves it open: it does not name the truth alone (its verdict is ambiguous, it names an effect
other than the truth, or it names nothing). Candidates are
drawn until :data:`OPEN_CASES` are kept (at most :data:`MAX_DRAWS`).

**The follow-ups.** For each kept case, from the pilot's ``results.json``, ``ctrplan.design`` plans a
follow-up of half the pilot's duration (:data:`FOLLOW_UP_S`) that separates the two fitted
hypotheses, twice: with today's greedy search (``designed``) and with the two-step primitives
offered too (``compound``, ``DesignSearch(compound=True)``: a move, then a reversal about the new
value). The truth is synthesized along four follow-ups of that duration: the two designed motions,
a random one (random primitives within the same drive limits and budget, the design's own
comparison) and the pilot's first half repeated (new noise). ``ctrplan discrepancy`` runs on the
pilot and each follow-up together (``--data`` once per recording). A run names the truth when its
verdict names the truth alone. Beside each verdict stands the comparison's strength: the ratio of
the alternative's out-of-fold error to the truth's, its interval and p-value.

**Calibration.** Beside each follow-up's verdict stand two predictions, computed alike on every
follow-up as synthesized (:func:`predict`): that the workflow's comparison prefers the truth over
the alternative after it (``ctrplan.design.predicted_preference``), and that the workflow names the
truth alone (``ctrplan.design.predicted_naming``: also below the pilot's calibrated baseline at
Holm's first step over the pilot's candidates). :func:`calibration` sets
the first against the comparison's significance and the second against the verdict, over every
follow-up run, and ``--figure`` draws both.

**Targets** (:func:`summarize`, for each designed follow-up): the truth named alone after it in at
least :data:`TARGET_RIGHT` of the kept cases, and in at least :data:`TARGET_MARGIN` more of them than
after the random follow-up or the repetition.

The data are made by the reference synthesizer of ``tests/ctrplan_reference`` (independent of the code
that fits), along the given motions: its ``reference_motion`` is replaced by the designed, random
or recorded motion (each segment a minimum-jerk move with the duration ruckig gave it). The truth
robots are built by ``bench_discrepancy_sweep._truth_robot`` (no ``ctrplan.discrepancy`` or
``ctrplan.effects``); the sizes are drawn from the effect registry's typical ranges as the sweep
draws them.

Usage::

    python benchmarks/bench_design.py [--open-cases 10] [--jobs 2] [--out out/bench-design]
                                      [--results benchmarks/results/design.json]
                                      [--figure docs/images/design-calibration.png] [--results-only]

Every candidate is one line of ``<out>/draws.jsonl`` (its pilot's verdict; kept or not) and every
kept case one line of ``<out>/cases.jsonl``; a rerun goes on from them, and each ``ctrplan
discrepancy`` run is reused from its ``results.json``; ``--results-only`` writes the results of
what is recorded without running anything.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import os
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the frozen reference ctrplan_reference (tests/, not installed)
sys.path.insert(0, str(ROOT / "benchmarks"))

#: Robot files of the candidates, in the order of the cycle.
ROBOT_FILES = {"pair": ROOT / "model" / "ha2019-table1-tube-pair.toml",
               "six-joint": ROOT / "model" / "ha2019-table2-six-joint.toml",
               "three-tube": ROOT / "model" / "ha2019-table7-calibrated.toml"}
ROBOTS = ("pair", "six-joint", "three-tube")
#: Confusable pairs (truth, alternative).
PAIRS = (("offplane", "registration"), ("backlash", "friction"), ("time_offset", "gradual_friction"))
#: Candidate k's robot and pair: COMBOS[k % len(COMBOS)].
COMBOS = (("six-joint", PAIRS[0]), ("pair", PAIRS[1]), ("three-tube", PAIRS[2]), ("six-joint", PAIRS[1]),
          ("pair", PAIRS[2]), ("three-tube", PAIRS[1]), ("six-joint", PAIRS[2]))
#: Size of each hidden parameter: log-uniform in this share of its typical range (of the half-width
#: for a range symmetric about zero, with a random sign).
SHARE_RANGE = (0.2, 1.5)
FIRST_SEED = 3000
OPEN_CASES = 10
MAX_DRAWS = 60
SAMPLES = 200
RATE_HZ = 10.0
#: Duration of every follow-up [s]: half the pilot's.
FOLLOW_UP_S = 0.5 * SAMPLES / RATE_HZ
NOISE_M = 0.5e-3
#: Targets over the kept cases: right after the designed follow-up in at least this many ...
TARGET_RIGHT = 8
#: ... and in at least this many more than after the random follow-up or the repetition.
TARGET_MARGIN = 3
FOLLOW_UPS = ("designed", "compound", "random", "repeated")
#: The follow-ups the targets are judged for (each against the random one and the repetition).
DESIGNED = ("designed", "compound")


def draw(k: int) -> dict:
    """Candidate ``k`` by the rule of the module docstring: ``{"draw", "seed", "robot", "truth",
    "alternative", "hidden" (SI), "shares"}``."""
    from bench_discrepancy_sweep import _draw_size

    from ctrplan.effects import REGISTRY
    from ctrplan.io.robot_file import load_robot

    seed = FIRST_SEED + k
    rng = np.random.default_rng(seed)
    robot_key, (truth, alternative) = COMBOS[k % len(COMBOS)]
    robot = load_robot(ROBOT_FILES[robot_key])
    specs = {p.name: p for p in REGISTRY[truth].parameters(robot)}
    if truth == "backlash":
        rotating = sorted({j.tube for j in robot.joints if j.kind == "rotation"})
        specs = {f"backlash_{i + 1}": specs[f"backlash_{i + 1}"] for i in rotating if f"backlash_{i + 1}" in specs}
    lo, hi = SHARE_RANGE
    shares = {n: float(math.exp(rng.uniform(math.log(lo), math.log(hi)))) for n in specs}
    hidden = {truth: {n: _draw_size(spec, shares[n], rng) for n, spec in specs.items()}}
    return {"draw": k, "seed": seed, "robot": robot_key, "truth": truth, "alternative": alternative,
            "hidden": hidden, "shares": shares}


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
    and every step of the outer tube (tube 1) removed: rotations of the inner tubes at the home
    insertion, the outer tube held."""
    import ctrplan_reference.synth_reference as sr

    m = sr.reference_motion(truth_robot, samples=SAMPLES, rate_hz=RATE_HZ, seed=seed)
    inner = np.array([j.kind == "rotation" and j.tube > 0 for j in truth_robot.joints])
    return dataclasses.replace(m, steps=np.where(inner[None, :], m.steps, 0.0))


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


def _verdict(res: dict, truth: str, alternative: str) -> dict:
    """What a run says: its verdict, the named effects, the rival of an ambiguous verdict, whether it
    names the truth alone, and the comparison of the truth against the alternative."""
    return {"verdict": res["verdict"], "named_effects": list(res.get("named_effects") or []),
            "ambiguous_with": res.get("ambiguous_with"), "right": _named_right(res, truth),
            "comparison": _comparison(res, truth, alternative)}


def _is_open(pilot: dict, truth: str) -> bool:
    """The pilot leaves the case open: it does not name the truth alone (an ambiguous verdict, an
    effect named that is not the truth, or nothing named)."""
    return not pilot["right"]


def _truth_and_base(cand: dict):
    import bench_discrepancy_sweep as sweep

    sweep.ROBOTS.update(ROBOT_FILES)      # the six-joint robot beside the sweep's
    return sweep._truth_robot({"robot": cand["robot"], "tube_errors": {}, "hidden": cand["hidden"]})


def _effects(truth: str, alternative: str) -> tuple:
    # gradual friction is fitted on top of friction (Effect.after): its run needs both
    return (truth, alternative) + (("friction",) if "gradual_friction" in (truth, alternative) else ())


def run_pilot(cand: dict, out: Path, jobs: int) -> dict:
    """Candidate ``cand``'s pilot: its data, the discrepancy run on it, whether the case is kept;
    ``cand`` with ``pilot`` (duration of motion [s], samples, verdict) and ``kept``."""
    from ctrplan.io.robot_file import robot_to_toml

    t0 = time.perf_counter()
    folder = out / f"draw-{cand['draw']}"
    folder.mkdir(parents=True, exist_ok=True)
    base, truth_robot = _truth_and_base(cand)
    model = folder / "base.toml"
    model.write_text(robot_to_toml(base, header="design benchmark base file: candidate effects off"))
    pilot = folder / "pilot.csv"
    motion = _pilot_motion(truth_robot, cand["seed"])
    if not pilot.exists():
        frame, _ = _synthesize(truth_robot, cand["hidden"], cand["seed"], motion)
        frame.to_csv(pilot, index=False)
    res = _discrepancy(model, [pilot], folder / "pilot", _effects(cand["truth"], cand["alternative"]), jobs,
                       cand["seed"])
    verdict = _verdict(res, cand["truth"], cand["alternative"])
    return {**cand, "pilot": {"duration_s": float(motion.times[-1] - motion.times[0]), "samples": SAMPLES, **verdict},
            "kept": _is_open(verdict, cand["truth"]), "pilot_seconds": time.perf_counter() - t0}


def run_follow_ups(cand: dict, out: Path, jobs: int) -> dict:
    """A kept case's four follow-ups of :data:`FOLLOW_UP_S` and the discrepancy run on the pilot
    with each; its line of ``cases.jsonl``."""
    from ctrplan.design import (DesignSearch, ExperimentLimits, SensorNoise, design_experiment, drive_from_data,
                                result_hypotheses, sample, trajectory)
    from ctrplan.discrepancy import load_measured_data

    t0 = time.perf_counter()
    truth_e, alt_e, seed = cand["truth"], cand["alternative"], cand["seed"]
    folder = out / f"draw-{cand['draw']}"
    base, truth_robot = _truth_and_base(cand)
    model, pilot = folder / "base.toml", folder / "pilot.csv"
    effects = _effects(truth_e, alt_e)
    first = _discrepancy(model, [pilot], folder / "pilot", effects, jobs, seed)
    hyps = result_hypotheses(first, [truth_e, alt_e])
    data = load_measured_data(pilot, base)
    t1 = time.perf_counter()
    noise = SensorNoise.from_estimate(first["noise"]["noise"])
    design = design_experiment(base, data, hyps, noise=noise, limits=ExperimentLimits(duration=FOLLOW_UP_S),
                               search=DesignSearch(n_random=1, seed=seed))
    design_s = time.perf_counter() - t1
    t1 = time.perf_counter()
    compound = design_experiment(base, data, hyps, noise=noise, limits=ExperimentLimits(duration=FOLLOW_UP_S),
                                 search=DesignSearch(n_random=0, seed=seed, compound=True))
    compound_s = time.perf_counter() - t1
    # the predictions for every follow-up, computed alike on it as synthesized, are predict's
    drive = drive_from_data(base, data)
    runs, files = {}, {}
    for key, prims in (("designed", design.primitives), ("compound", compound.primitives),
                       ("random", design.random_primitives[0])):
        path = folder / f"{key}.csv"
        traj = trajectory(base, list(prims), drive)
        times, _ = sample(traj, 1.0 / RATE_HZ)
        if not path.exists():
            new, _ = _synthesize(truth_robot, cand["hidden"], seed + 1000, _reference_motion(base, traj, times))
            new.to_csv(path, index=False)
        files[key] = path
        runs[key] = {"duration_s": float(traj.duration), "samples": int(len(times))}
    # the pilot's first half again, with new noise
    whole = _pilot_motion(truth_robot, seed)
    half = dataclasses.replace(whole, times=whole.times[: SAMPLES // 2],
                               end_time=float(whole.times[SAMPLES // 2 - 1]))
    path = folder / "repeated.csv"
    if not path.exists():
        new, _ = _synthesize(truth_robot, cand["hidden"], seed + 2000, half)
        new.to_csv(path, index=False)
    files["repeated"] = path
    runs["repeated"] = {"duration_s": float(half.times[-1] - half.times[0]), "samples": SAMPLES // 2}
    for key in FOLLOW_UPS:
        res = _discrepancy(model, [pilot, files[key]], folder / key, effects, jobs, seed)
        runs[key].update(_verdict(res, truth_e, alt_e))
    def smallest(sep):
        return {k: (min(v.values()) if isinstance(v, dict) else [min(x.values()) for x in v]) for k, v in sep.items()}

    return {**cand, "follow_up_s": FOLLOW_UP_S, "predicted_separation": smallest(design.separation),
            "predicted_power": design.power, "predicted_preference": design.preference,
            "compound": {"predicted_separation": smallest(compound.separation), "predicted_power": compound.power,
                         "predicted_preference": compound.preference, "seconds": compound_s,
                         "primitives": [p.describe(base.joint_names) for p in compound.primitives]},
            "noise_lower_bound": design.noise_lower_bound, "runs": runs,
            "primitives": [p.describe(base.joint_names) for p in design.primitives],
            "design_seconds": design_s, "seconds": cand["pilot_seconds"] + time.perf_counter() - t0}


#: What the predictions of :func:`predict` simulate; a case recorded with other predictions is
#: predicted again.
PREDICTIONS = "workflow split, naming"


def predict(case: dict, out: Path, jobs: int) -> dict:
    """``case`` with two predictions for every follow-up, computed alike on the follow-up as
    synthesized: ``runs[key]["predicted"]``, that the workflow's comparison prefers the truth over
    the alternative (:func:`ctrplan.design.predicted_preference`), and
    ``runs[key]["predicted_named"]``, that the workflow names the truth alone
    (:func:`ctrplan.design.predicted_naming`: also below the pilot's calibrated baseline at Holm's
    first step over the pilot's candidates)."""
    from ctrplan.design import SensorNoise, predicted_naming, predicted_preference, result_hypotheses
    from ctrplan.discrepancy import load_measured_data

    folder = out / f"draw-{case['draw']}"
    base, _ = _truth_and_base(case)
    first = json.loads((folder / "pilot" / "results.json").read_text())
    hyps = result_hypotheses(first, [case["truth"], case["alternative"]])
    baseline = result_hypotheses(first, ["baseline"])[0]
    family = first["decision"].get("family") or [case["truth"], case["alternative"]]
    data = load_measured_data(folder / "pilot.csv", base)
    noise = SensorNoise.from_estimate(first["noise"]["noise"])
    pair = f"{case['truth']}>{case['alternative']}"
    for key in FOLLOW_UPS:
        follow_up = load_measured_data(folder / f"{key}.csv", base)
        run = case["runs"][key]
        run["predicted"] = predicted_preference(base, data, hyps, follow_up, noise=noise, level=LEVEL, n_jobs=jobs,
                                                seed=case["seed"])[pair]
        run["predicted_named"] = predicted_naming(
            base, data, hyps, baseline, follow_up, noise=noise, level=LEVEL, n_candidates=len(family), n_jobs=jobs,
            seed=case["seed"])[case["truth"]]
    case["pilot_predicted"] = predicted_preference(base, data, hyps, noise=noise, level=LEVEL, seed=case["seed"])[pair]
    case["n_candidates"], case["predictions"] = len(family), PREDICTIONS
    return case


def summarize(draws: list, cases: list) -> dict:
    """Counts of the draws and the kept cases, the right verdicts after each follow-up with their 90 %
    intervals, the median comparison ratio per follow-up, and the targets."""
    from bench_discrepancy_sweep import clopper_pearson

    n = len(cases)
    out = {"n_draws": len(draws), "n_kept": n,
           "kept_by_robot": {r: sum(c["robot"] == r for c in cases) for r in ROBOTS},
           "kept_by_pair": {f"{t} vs {a}": sum(c["truth"] == t for c in cases) for t, a in PAIRS},
           "pilot_verdicts_kept": {v: sum(c["pilot"]["verdict"] == v for c in cases)
                                   for v in sorted({c["pilot"]["verdict"] for c in cases})}}
    right = {}
    for key in FOLLOW_UPS:
        right[key] = sum(1 for c in cases if c["runs"][key]["right"])
        out[f"{key}_right"] = right[key]
        out[f"{key}_right_interval_90"] = clopper_pearson(right[key], n, 0.90) if n else None
        ratios = [c["runs"][key]["comparison"]["ratio"] for c in cases
                  if c["runs"][key].get("comparison") and c["runs"][key]["comparison"].get("ratio") is not None]
        out[f"{key}_ratio_median"] = float(np.median(ratios)) if ratios else None
    out["calibration"] = calibration(cases)
    out["targets"] = {}
    for key in DESIGNED:
        out["targets"][f"{key} right in >= {TARGET_RIGHT} of the kept cases"] = bool(n and right[key] >= TARGET_RIGHT)
        out["targets"][f"{key} right in >= {TARGET_MARGIN} more than random and repeated"] = \
            bool(n and right[key] >= max(right["random"], right["repeated"]) + TARGET_MARGIN)
    return out


#: Bins of the predicted probability in the calibration [-].
CALIBRATION_BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
#: Level of the comparison a prediction is checked against [-] (the workflow's default).
LEVEL = 0.01


#: The predictions checked, each against the outcome it predicts: ``(name, prediction key of a run,
#: outcome)``. The comparison's preference against the comparison's significance at LEVEL; the
#: naming probability against the truth named alone.
CALIBRATIONS = (("comparison", "predicted", "comparison significant"),
                ("naming", "predicted_named", "truth named alone"))


def _calibration_points(cases: list, prediction: str) -> list:
    """Per follow-up run with the prediction ``prediction``: ``(predicted, outcome)``, the outcome
    the comparison significant at LEVEL (``"predicted"``) or the truth named alone
    (``"predicted_named"``)."""
    out = []
    for c in cases:
        for key in FOLLOW_UPS:
            r = c["runs"][key]
            p = r.get(prediction)
            if p is None or not math.isfinite(p):
                continue
            if prediction == "predicted":
                comp = r.get("comparison") or {}
                outcome = comp.get("p_value") is not None and comp["p_value"] < LEVEL
            else:
                outcome = r["right"]
            out.append((float(p), bool(outcome)))
    return out


def calibration(cases: list) -> dict:
    """Each prediction of :data:`CALIBRATIONS` against its outcome over every follow-up run: the
    Brier score, the Brier score of the outcome's base rate, and per bin of
    :data:`CALIBRATION_BINS` the runs, the mean prediction and the observed share with its 90 %
    Clopper-Pearson interval."""
    from bench_discrepancy_sweep import clopper_pearson

    result = {}
    for name, prediction, outcome in CALIBRATIONS:
        pts = _calibration_points(cases, prediction)
        if not pts:
            result[name] = {"n_runs": 0, "outcome": outcome}
            continue
        p, y = (np.array(v, float) for v in zip(*pts))
        bins = []
        edges = CALIBRATION_BINS
        for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
            m = (p >= lo) & ((p < hi) if i < len(edges) - 2 else (p <= hi))
            n = int(m.sum())
            if n:
                hits = int(y[m].sum())
                bins.append({"from": lo, "to": hi, "n_runs": n, "mean_predicted": float(p[m].mean()),
                             "observed": hits, "observed_interval_90": clopper_pearson(hits, n, 0.90)})
        result[name] = {"outcome": outcome, "n_runs": len(pts), "brier": float(np.mean((p - y) ** 2)),
                        "brier_at_base_rate": float(np.mean((y.mean() - y) ** 2)), "bins": bins}
    return result


def calibration_figure(cases: list, path: Path) -> None:
    """Reliability diagram of :func:`calibration`: per bin, the observed share of each prediction's
    outcome against the mean prediction, with its 90 % interval; the marker's area grows with the
    runs in the bin."""
    from ctrplan.plots import new_figure, save_figure

    cal = calibration(cases)
    fig = new_figure((5.0, 4.2))
    ax = fig.add_subplot(111)
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="perfect calibration")
    for (name, _, outcome), marker, color, dx in zip(CALIBRATIONS, "so", ("C1", "C0"), (0.008, -0.008)):
        label = {"comparison": "comparison's preference: significant", "naming": "naming: truth named alone"}[name]
        for b in cal[name].get("bins", []):
            x, n = b["mean_predicted"] + dx, b["n_runs"]
            lo, hi = b["observed_interval_90"]
            y = b["observed"] / n
            ax.errorbar([x], [y], yerr=[[y - lo], [hi - y]], fmt=marker, ms=4 + 2 * math.sqrt(n), capsize=3,
                        color=color, label=label if b is cal[name]["bins"][0] else None)
    ax.set_xlim(-0.03, 1.03)
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlabel("predicted probability")
    ax.set_ylabel("observed share of follow-up runs")
    n_runs = max(c["n_runs"] for c in cal.values())
    ax.set_title(f"{n_runs} follow-up runs of {len(cases)} kept case{'s' if len(cases) != 1 else ''}", fontsize=9)
    ax.legend(fontsize=8, loc="upper left", markerscale=0.5)
    save_figure(fig, path)


#: Short names of the effects in the table of :func:`markdown_table`.
SHORT = {"offplane": "off-plane", "registration": "registration", "backlash": "backlash", "friction": "friction",
         "time_offset": "lag", "gradual_friction": "gradual friction"}


def _size(hidden: dict) -> str:
    """The hidden effect's values in report units (deg for angles, s, 1/m)."""
    parts = []
    for values in hidden.values():
        for name, v in values.items():
            if name.startswith("backlash"):
                parts.append(f"{math.degrees(v):.1f} deg")
            elif name == "time_offset":
                parts.append(f"{v:+.2f} s")
            else:
                parts.append(f"{v:+.2f} 1/m")
    return ", ".join(parts)


def _cell(run: dict) -> str:
    """A run's verdict (the named effects, bold when the truth alone), its comparison ratio and the
    predicted probability of naming the truth alone."""
    v = run["verdict"]
    text = ("ambiguous" if v == "ambiguous" else "nothing" if v == "none" else
            " + ".join(SHORT.get(e, e) for e in run["named_effects"]))
    if run.get("right"):
        text = f"**{text}**"
    ratio = (run.get("comparison") or {}).get("ratio")
    pred = run.get("predicted_named")
    return (text + (f", {ratio:.2f}" if ratio is not None else "")
            + (f" ({pred:.2f})" if pred is not None and math.isfinite(pred) else ""))


def markdown_table(cases: list) -> str:
    """The kept cases as a markdown table: robot, truth against the alternative with the hidden
    values, the pilot's verdict and each follow-up's (:func:`_cell`), the greedy design's seconds."""
    lines = ["| case | robot | truth (hidden) vs alternative | pilot | + designed | + compound | + random | "
             "+ repeated | design [s] |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for c in cases:
        cells = [_cell(c["runs"][k]) for k in FOLLOW_UPS]
        pilot = _cell({**c["pilot"], "predicted_named": None})
        lines.append(f"| {c['draw']} | {c['robot']} | {SHORT[c['truth']]} ({_size(c['hidden'])}) vs "
                     f"{SHORT[c['alternative']]} | {pilot} | " + " | ".join(cells) + f" | {c['design_seconds']:.0f} |")
    return "\n".join(lines)


def _read(path: Path, key: str) -> dict:
    out = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                c = json.loads(line)
                out[c[key]] = c
    return out


def main(argv=None):
    from _records import run_record

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--open-cases", type=int, default=OPEN_CASES, help="kept cases to reach")
    ap.add_argument("--max-draws", type=int, default=MAX_DRAWS)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench-design"))
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "design.json"))
    ap.add_argument("--results-only", action="store_true",
                    help="write the results from the draws and cases recorded in --out, running nothing")
    ap.add_argument("--figure", default=str(ROOT / "docs" / "images" / "design-calibration.png"),
                    help="the calibration plot of the predictions against the follow-ups' verdicts")
    args = ap.parse_args(argv)
    logging.getLogger("ctrplan").setLevel(logging.WARNING)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    draws_file, cases_file = out / "draws.jsonl", out / "cases.jsonl"
    draws, cases = _read(draws_file, "draw"), _read(cases_file, "draw")
    load0 = os.getloadavg()
    k = 0
    while not args.results_only and sum(d["kept"] for d in draws.values()) < args.open_cases and k < args.max_draws:
        if k not in draws:
            d = run_pilot(draw(k), out, args.jobs)
            draws[k] = d
            with draws_file.open("a") as f:
                f.write(json.dumps(d) + "\n")
            print(f"draw {k}: {d['robot']} {d['truth']} vs {d['alternative']}: pilot {d['pilot']['verdict']} "
                  f"{d['pilot']['named_effects']} -> {'kept' if d['kept'] else 'not kept'} "
                  f"({d['pilot_seconds']:.0f} s)", flush=True)
        k += 1
    for k in sorted(draws):
        d = draws[k]
        if d["kept"] and k not in cases and not args.results_only:
            c = run_follow_ups(d, out, args.jobs)
            cases[k] = c
            with cases_file.open("a") as f:
                f.write(json.dumps(c, default=float) + "\n")
            print(f"case {k}: " + ", ".join(f"{key} {c['runs'][key]['verdict']} {c['runs'][key]['named_effects']}"
                                            for key in FOLLOW_UPS) + f" ({c['seconds']:.0f} s)", flush=True)
    for k in sorted(cases):
        if not args.results_only and cases[k].get("predictions") != PREDICTIONS:
            cases[k] = predict(cases[k], out, args.jobs)
            cases_file.write_text("".join(json.dumps(cases[j], default=float) + "\n" for j in sorted(cases)))
            print(f"case {k}: predicted (comparison, naming) " + ", ".join(
                f"{key} {cases[k]['runs'][key]['predicted']:.2f}, {cases[k]['runs'][key]['predicted_named']:.2f}"
                for key in FOLLOW_UPS), flush=True)
    kept = [cases[k] for k in sorted(cases)]
    if args.results_only:       # what was recorded: the candidates up to the last kept case run
        last = max(cases, default=-1)
        draws = {k: d for k, d in draws.items() if k <= last}
    results = {"summary": summarize(list(draws.values()), kept), "draws": [draws[k] for k in sorted(draws)],
               "cases": kept,
               "run": run_record("python benchmarks/bench_design.py " + " ".join(argv or sys.argv[1:]), load0,
                                 os.getloadavg())}
    Path(args.results).write_text(json.dumps(results, indent=1, default=float) + "\n")
    if kept:
        calibration_figure(kept, Path(args.figure))
    print(json.dumps(results["summary"], indent=1))
    print(markdown_table(kept))


if __name__ == "__main__":
    main()
