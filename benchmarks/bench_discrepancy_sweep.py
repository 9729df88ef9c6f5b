"""Benchmark: how often the discrepancy workflow names the right effect, a wrong one or nothing, on
hard synthetic cases made independently of the code that fits them.

Every case is a continuous trajectory of 500 samples at 10 Hz made by the reference synthesizer of
``tests/ctrplan_reference`` (an analytic motion, the history rules written again from their definitions,
the frozen reference solvers; none of it imports ``ctrplan.history``, ``ctrplan.effects`` or
``ctrplan.discrepancy``), on one of three robots: the Table I tube pair (most cases), the
three-tube robot of Table VII and the path-history pair of Table V (Ha, Fagogenis & Dupont, IEEE
T-RO 35(2) 2019). The truth's tube parameters (in-plane precurvatures and bending-stiffness
ratios) are 5-15 % away from the base file's, the way a real tube set differs from its drawing;
the tracker noise is 0.5 mm rms, white or AR(1) (phi 0.6 or 0.85 per sample); the hidden effects
are none (a control), one, or two at once, drawn from drive backlash, tracker time offset,
torsional friction, gradually developing friction and off-plane precurvature. Every parameter of
a hidden effect (each rotating drive's backlash, each tube's off-plane precurvature, each pair's
friction coefficient) has its own size, log-uniform from 10 % to 5 times its typical range
(:data:`SIZE_RANGE`; of the half-width for a range symmetric about zero, with a random sign), so
that a case can lie far outside the range the workflow calls typical and beyond a fit's limit.
Half the cases hide one effect, a third two and a sixth none (:data:`KIND_CYCLE`). The workflow
runs with its default options (every registered candidate) from the base file without the
effects.

How large each hidden effect is on the record (:func:`effect_displacements`): the reference
synthesizer makes the case's record again without that effect (and without noise; a two-effect
case keeps the other), and the effect's signal-to-noise ratio is the rms over the samples of the
3-D tip displacement between the two noise-free records, over the noise's rms length. Friction
and gradual friction are removed by zero friction coefficients (the clearance model throughout),
so that the ratio is the friction's own and not the clearance model's.

    python benchmarks/bench_discrepancy_sweep.py [--cases 100] [--first-seed 2000] [--jobs 2]
                                                 [--run-first SEED ...]
                                                 [--scheduler tcp://host:8786]
                                                 [--out out/bench-discrepancy-sweep]
                                                 [--results benchmarks/results/discrepancy-sweep.json]
                                                 [--synthesize-only | --results-only]

Each case is a folder under ``--out`` (the workflow's log in ``workflow.log``; its stages are reused when the sweep is run again
after an interruption) and a line of ``cases.jsonl`` there; finished cases are not run again. The
results file is rewritten after every case with the cases finished so far (``cases`` of
``cases_planned``). ``--synthesize-only`` makes every case's data and its effects' signal-to-noise
ratios (``data.csv``, ``snr.json`` and ``plan.json`` in its folder; the reference synthesizer
takes up to half an hour for a three-tube case), the cases on ``--jobs``
processes at once (or on the ``--scheduler``'s workers), and stops, so that another process or
machine can make the data while the cases run; a case whose data exists for its present plan
does not make it again (a case folder or a recorded case of another plan is made and run again).
With ``--scheduler`` the cases run on the Dask workers of that cluster (each with ``--jobs``
processes), else one after the other here, a case whose data is made (by ``--synthesize-only``
beside the run) before one whose data is still to make. ``--run-first`` runs the cases of the given
seeds before the others (the cases themselves do not change): until all planned cases are finished,
the results file holds a chosen subset, and the docs table names its seeds.

What the truth and the reference share with the code under test: the robot description
(``ctrplan.robot``: its dataclasses, joint vector and configuration), the robot files' reader
(``ctrplan.io.robot_file``), and, in the reference solvers, the arc-length grid
(``ctrplan.mechanics.grid``), the rotation helpers (``ctrplan.mechanics._lie``), the discrete tube
chain's kinematics (``ctrplan.mechanics.discrete``, contact model), the solution and settings
records (``ctrplan.mechanics.results``), ``ctrplan.constants`` and ``ctrplan.errors``
(``tests/ctrplan_reference/bound_reference.py``, which the synthesizer does not use, also takes
``ctrplan.mechanics.bound``). What they do not share: the solvers themselves (``ctrplan.mechanics``
standard and contact solves), ``ctrplan.history``, ``ctrplan.effects`` and
``ctrplan.discrepancy``: the truth robot (:func:`_truth_robot`) changes the tube fields itself
rather than through the parameters the workflow fits. Only the drawing of a case
(:func:`plan_case`) reads the effect registry's typical ranges and the workflow's list of
baseline parameters, to choose sizes and which tube parameters are off.

Outcomes (:func:`outcome`; a name that carries a caution counts like any other):

- **right**: verdict "named", the named effects are exactly the hidden ones, and every value the
  written robot file holds for them is within 3 standard errors of the true value or within 20 %
  of it (an effect that follows another, gradual friction after friction, is checked on the other
  one's parameters too, against their hidden values);
- **right name, value off**: the names are the truth but a written value is outside both;
- **partly right**: of two hidden effects, exactly one is named and nothing else;
- **ambiguous**: an ambiguous verdict whose written effects (none: an ambiguous verdict writes
  the recalibrated baseline) are all in the truth (never counted as found);
- **wrong**: a named effect not in the truth, any name on a control, or an ambiguous verdict that
  writes an effect not in the truth;
- **nothing**: verdict "none".

The standard errors are those of the final model's development fit (the named effect's table,
or the named pair's); where one is missing or not finite, only the 20 % rule applies. Every
recorded case is scored again by the present rules when the results file is written
(``--results-only`` does only that); a case recorded without standard errors is judged by the
20 % rule alone. The results file's ``provenance`` holds ``sweep_code_sha256``
(:func:`sweep_code_digest`: this file and the reference synthesizer) beside the digest of the
code under test.

Every outcome's rate has a two-sided 90 % Clopper-Pearson interval. Targets, each ``met`` true,
false or null (no such cases) in the results file: wrong names (controls included) below 5 % and
the interval's upper end below 10 %; the truth named alone (right, or right name with a value off)
in at least 80 % of the clear one-effect cases; both effects named in at least half of the clear
two-effect cases. A case is clear when every hidden effect moves the tip by at least the noise:
signal-to-noise ratio at least 1 (:data:`CLEAR_SNR`, fixed before any case was run).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import logging
import math
import os
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the frozen reference ctrplan_reference (tests/, not installed)
ROBOTS = {"pair": ROOT / "model" / "ha2019-table1-tube-pair.toml",
          "three-tube": ROOT / "model" / "ha2019-table7-calibrated.toml",
          "table5-pair": ROOT / "model" / "ha2019-table5-path-history-pair.toml"}
#: The robot of case i is ROBOT_CYCLE[i % 5] and its kind KIND_CYCLE[(i // 5) % 6]: 60 % of the
#: cases on the tube pair, 20 % on each of the others; of 30 cases 15 with one effect, 10 with
#: two, 5 controls, every robot with every kind; the first 15 cases hold five of each kind, so
#: that a shorter run still sees every kind.
ROBOT_CYCLE = ("pair", "pair", "pair", "three-tube", "table5-pair")
KIND_CYCLE = ("one", "two", "control", "one", "two", "one")
KINDS = ("control", "one", "two")
EFFECTS = ("backlash", "time_offset", "friction", "gradual_friction", "offplane")
#: Size of each parameter of a hidden effect: log-uniform in this share of its typical range (of
#: the half-width for a range symmetric about zero, with a random sign).
SIZE_RANGE = (0.1, 5.0)
#: Relative error of every baseline tube parameter of the truth against the base file.
MISSPECIFICATION = (0.05, 0.15)
NOISE_M = 0.5e-3
AR1 = (0.0, 0.6, 0.85)
SAMPLES = 500
OUTCOMES = ("right", "right name, value off", "partly right", "ambiguous", "wrong", "nothing")
#: Outcomes in which the hidden effects are named, alone, with an unambiguous verdict.
NAMED_ALONE = ("right", "right name, value off")
#: Cases whose hidden effects all reach this signal-to-noise ratio (rms tip displacement of the
#: effect over the noise's rms length, :func:`effect_displacements`) count for the targets on
#: finding the truth.
CLEAR_SNR = 1.0
#: A written value is right within this many standard errors of the true value ...
VALUE_STDERRS = 3.0
#: ... or within this share of it.
VALUE_SHARE = 0.2
#: Targets: wrong names below this rate, and the upper end of their 90 % interval below the next.
WRONG_RATE_BELOW = 0.05
WRONG_UPPER_BELOW = 0.10
#: The truth named alone in at least this share of the clear one-effect cases ...
ONE_NAMED_AT_LEAST = 0.8
#: ... and both effects named in at least this share of the clear two-effect cases.
BOTH_NAMED_AT_LEAST = 0.5
#: Level of the two-sided Clopper-Pearson intervals of the rates.
CI_LEVEL = 0.90


def _draw_size(spec, share, rng) -> float:
    lo, hi = spec.typical
    if lo < 0 < hi:
        return float(rng.choice((-1.0, 1.0)) * share * min(-lo, hi))
    return float(lo + share * (hi - lo))


def _draw_share(rng) -> float:
    """A size as a share of the typical range, log-uniform in :data:`SIZE_RANGE`."""
    lo, hi = SIZE_RANGE
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def plan_case(seed: int, index: int) -> dict:
    """The truth of case ``index`` (seeded by ``seed``): robot, hidden effects with their sizes (SI,
    and each parameter's share of its typical range in ``size_shares``, keyed like ``hidden``),
    tube-parameter errors, noise."""
    import numpy as np

    from ctrplan.discrepancy.fits.parameters import parameter
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

    def draw(key, specs):
        shares[key] = {k: _draw_share(rng) for k in specs}
        hidden[key] = {k: _draw_size(s, shares[key][k], rng) for k, s in specs.items()}

    for e in chosen:
        specs = {p.name: p for p in REGISTRY[e].parameters(robot)}
        if e == "backlash":
            draw(e, {f"backlash_{i + 1}": specs[f"backlash_{i + 1}"] for i in rotating})
        elif e in ("time_offset", "offplane"):
            draw(e, specs)
        elif e == "friction":
            draw(e, {p.name: p for p in REGISTRY["friction"].parameters(robot)})
        elif e == "gradual_friction":
            draw("friction", {p.name: p for p in REGISTRY["friction"].parameters(robot)})
            draw(e, {"friction_angle": specs["friction_angle"]})
    from ctrplan.discrepancy.setup import default_baseline_parameters

    names = default_baseline_parameters(robot, register=False)
    errors = {nm: float(rng.choice((-1.0, 1.0)) * rng.uniform(*MISSPECIFICATION)) for nm in names}
    for nm in names:
        parameter(robot, nm)               # validates
    return {"seed": int(seed), "index": int(index), "robot": robot_key, "kind": kind, "truth": sorted(chosen), "hidden": hidden,
            "size_shares": shares, "tube_errors": errors, "ar1": float(rng.choice(AR1)), "noise_m": NOISE_M}


def _curved(sections) -> list:
    """Indices of the curved sections (a section is straight when both precurvatures are 0)."""
    return [j for j, sec in enumerate(sections) if sec.precurvature[0] != 0.0 or sec.precurvature[1] != 0.0]


def _truth_robot(plan: dict):
    """The base file's robot with its friction coefficients at 0, and the truth: that robot with
    the plan's tube-parameter errors, the hidden off-plane precurvatures and friction coefficients.

    Made from the robot description alone, changing the tube fields directly (no
    ``ctrplan.discrepancy`` and no ``ctrplan.effects``, whose parameters the workflow fits):

    - ``precurvature_y_i`` (error e): the in-plane precurvature ``u_y`` of the first curved
      section of tube i becomes ``u_y (1 + e)``; every other curved section of the tube is scaled
      by the same factor (the new value over the old one, in that order of operations);
    - ``k_xy_relative_i`` (error e): tube i's bending stiffness relative to tube 1,
      ``k_xy_i / k_xy_1``, becomes ``(k_xy_i / k_xy_1) (1 + e)``; tube 1 keeps its ``k_xy``;
    - hidden ``offplane`` ``precurvature_x_i``: the off-plane precurvature ``u_x`` of every curved
      section of tube i;
    - hidden ``friction`` ``mu_k``: the friction coefficient of pair k.

    Parameters
    ----------
    plan : dict
        :func:`plan_case`'s plan (``robot``, ``tube_errors``, ``hidden``).

    Returns
    -------
    base, truth : ctrplan.robot.Robot
        The base (precurvatures [1/m], stiffnesses [N m^2]) and the truth.

    Raises
    ------
    ValueError
        A tube-parameter name other than ``precurvature_y_i`` and ``k_xy_relative_i``.
    """
    import dataclasses

    from ctrplan.io.robot_file import load_robot
    from ctrplan.robot import Section

    robot = load_robot(ROBOTS[plan["robot"]])
    robot = robot.replace(friction_coefficients=(0.0,) * (robot.n_tubes - 1))
    tubes = list(robot.tubes)
    k_ref = robot.tubes[0].k_xy
    for name, error in plan["tube_errors"].items():
        kind, _, number = name.rpartition("_")
        i = int(number) - 1
        if kind == "precurvature_y":
            old = robot.tubes[i].sections[_curved(robot.tubes[i].sections)[0]].precurvature[1]
            new = old * (1.0 + error)
            secs = list(tubes[i].sections)
            for j in _curved(secs):
                x, y = secs[j].precurvature
                secs[j] = Section(secs[j].length, (x, y * new / old if old != 0.0 else new))
            tubes[i] = dataclasses.replace(tubes[i], sections=tuple(secs))
        elif kind == "k_xy_relative":
            tubes[i] = dataclasses.replace(tubes[i], k_xy=robot.tubes[i].k_xy / k_ref * (1.0 + error) * k_ref)
        else:
            raise ValueError(f"tube parameter {name!r}: expected precurvature_y_i or k_xy_relative_i")
    for name, value in plan["hidden"].get("offplane", {}).items():
        i = int(name.rpartition("_")[2]) - 1
        secs = list(tubes[i].sections)
        for j in _curved(secs):
            secs[j] = Section(secs[j].length, (float(value), secs[j].precurvature[1]))
        tubes[i] = dataclasses.replace(tubes[i], sections=tuple(secs))
    truth = robot.replace(tubes=tuple(tubes))
    if "friction" in plan["hidden"]:
        mu = plan["hidden"]["friction"]
        truth = truth.replace(friction_coefficients=tuple(mu[f"mu_{k + 1}"] for k in range(robot.n_tubes - 1)))
    return robot, truth


def true_values(plan: dict, effect: str) -> dict:
    """``{parameter: value}`` [SI] of a hidden effect: its own, and those of the effect it follows
    (``Effect.after``: gradual friction reports the friction coefficients, whose truth is the
    hidden friction's)."""
    from ctrplan.effects import REGISTRY

    values = dict(plan["hidden"].get(effect, {}))
    after = getattr(REGISTRY.get(effect), "after", None)
    if after:
        values.update(plan["hidden"].get(after, {}))
    return values


def final_parameter_table(res: dict) -> list:
    """The rows (``name``, ``value``, ``stderr`` [SI]) of the development-fit parameter table of
    the model a run ends with: the named effect's candidate, or the named pair
    (``res["combination"]["tried"][second]``); empty when nothing is named."""
    named = res["named_effects"]
    if len(named) == 1:
        return res["candidates"][named[0]]["parameter_table"]
    if len(named) == 2:
        comb = res["combination"]
        return comb["tried"][comb["named"]]["parameter_table"]
    return []


def written_stderr(res: dict, written: dict | None) -> dict:
    """``{effect: {parameter: standard error or None}}`` of the written values: the final model's
    development fit's (:func:`final_parameter_table`), None where the table has none."""
    rows = {r["name"]: r.get("stderr") for r in final_parameter_table(res)}
    return {e: {p: rows.get(p) for p in values} for e, values in (written or {}).items()}


def value_check(plan: dict, named: list, written: dict | None, stderr: dict | None) -> dict:
    """Each true parameter of the named effects that are hidden, against its written value:
    ``{parameter: {"true", "written", "stderr", "within_3_se", "within_20_pct"}}``.

    A value within ``VALUE_STDERRS`` standard errors or within ``VALUE_SHARE`` of the true value
    passes; a missing or non-finite standard error leaves only the share rule, and a value the
    robot file does not hold (or a missing file) fails both.
    """
    out = {}
    for e in named:
        if e not in plan["truth"]:
            continue
        for p, true in true_values(plan, e).items():
            w = ((written or {}).get(e) or {}).get(p)
            se = ((stderr or {}).get(e) or {}).get(p)
            finite = se is not None and math.isfinite(se)
            out[p] = {"true": true, "written": w, "stderr": se,
                      "within_3_se": w is not None and finite and abs(w - true) <= VALUE_STDERRS * se,
                      "within_20_pct": w is not None and abs(w - true) <= VALUE_SHARE * abs(true)}
    return out


def outcome(truth: list, verdict: str, named_effects: list, named_effect: str | None, check: dict) -> str:
    """One of :data:`OUTCOMES` (module docstring) for a run's verdict.

    Parameters
    ----------
    truth : list of str
        The hidden effects (empty for a control).
    verdict : {"named", "ambiguous", "none"}
    named_effects : list of str
        The effects of the final model.
    named_effect : str or None
        The verdict's named effect (the first of an ambiguous verdict; not what is written).
    check : dict
        :func:`value_check` of the named effects.
    """
    if verdict == "none":
        return "nothing"
    if not truth:
        return "wrong"
    if verdict == "ambiguous":
        return "ambiguous" if set(named_effects) <= set(truth) else "wrong"
    named = set(named_effects)
    if not named or not named <= set(truth):
        return "wrong"
    if named == set(truth):
        ok = all(c["within_3_se"] or c["within_20_pct"] for c in check.values())
        return "right" if ok else "right name, value off"
    return "partly right" if len(truth) == 2 and len(named) == 1 else "wrong"


def score_run(plan: dict, res: dict, written: dict | None) -> dict:
    """``{"outcome", "written_stderr", "value_check"}`` of a run's results ``res``
    (:func:`ctrplan.discrepancy.outputs.results.results_dict`) on the case ``plan`` whose written robot
    file holds ``written`` (:func:`written_values`)."""
    stderr = written_stderr(res, written)
    check = value_check(plan, res["named_effects"], written, stderr)
    return {"outcome": outcome(plan["truth"], res["verdict"], res["named_effects"], res["named_effect"], check),
            "written_stderr": stderr, "value_check": check}


def rescore(case: dict) -> dict:
    """A recorded case (a line of ``cases.jsonl``) scored by the present rules: ``outcome`` and
    ``value_check`` replaced; a case recorded without ``written_stderr`` has only the share rule."""
    check = value_check(case, case["named_effects"], case["written"], case.get("written_stderr"))
    return {**case, "value_check": check, "clear": _clear(case),
            "outcome": outcome(case["truth"], case["verdict"], case["named_effects"], case["named"], check)}


def _synthesize(plan: dict, noise: bool = True) -> tuple:
    """The reference synthesizer's record of the plan's truth: ``(base robot, frame, truth)``
    (:func:`synth_reference.synthesize_reference`; without noise when ``noise`` is false)."""
    from ctrplan_reference.synth_reference import synthesize_reference

    base, truth = _truth_robot(plan)
    hidden = plan["hidden"]
    kw = {}
    if "backlash" in hidden:
        kw["backlash"] = tuple(hidden["backlash"].get(f"backlash_{i + 1}", 0.0) for i in range(base.n_tubes))
    if "time_offset" in hidden:
        kw["time_offset"] = hidden["time_offset"]["time_offset"]
    if "friction" in hidden:
        kw["mu"] = truth.friction_coefficients
    if "gradual_friction" in hidden:
        kw["friction_angle"] = hidden["gradual_friction"]["friction_angle"]
    if not noise:
        kw.update(noise_position_rms=0.0, noise_angle_rms=0.0)
    else:
        kw["noise_position_rms"] = plan["noise_m"]
    frame, record = synthesize_reference(truth, samples=SAMPLES, seed=plan["seed"], noise_ar1=plan["ar1"], **kw)
    return base, frame, record


def without(plan: dict, effect: str) -> dict:
    """The plan with the hidden ``effect`` removed; the motion, the tube errors and the other
    effects stay. Friction and gradual friction are removed by setting every friction
    coefficient to zero: the truth stays the contact model (the clearance model throughout), so
    that what is removed is the friction's own displacement and not the clearance model's."""
    hidden = {k: v for k, v in plan["hidden"].items() if k != effect}
    if effect in ("friction", "gradual_friction"):
        hidden.pop("gradual_friction", None)
        hidden["friction"] = {k: 0.0 for k in plan["hidden"]["friction"]}
    return {**plan, "hidden": hidden, "truth": [e for e in plan["truth"] if e != effect]}


def effect_displacements(plan: dict, tip) -> dict:
    """``{effect: {"rms_m", "snr", "samples"}}`` of every hidden effect: the rms over the samples
    of the 3-D distance [m] between the noise-free tip ``tip`` (K, 3) of the case's record (robot
    frame, NaN where its solve failed) and the noise-free tip of the record made again without that
    effect (:func:`without`, the same motion), over the samples solved in both; ``snr`` is that rms
    over the noise's rms length (``plan["noise_m"]``)."""
    import numpy as np

    out = {}
    for e in plan["truth"]:
        _, _, record = _synthesize(without(plan, e), noise=False)
        d = np.linalg.norm(np.asarray(tip, float) - record["tip"], axis=1)
        d = d[np.isfinite(d)]
        rms = float(np.sqrt(np.mean(d ** 2))) if d.size else float("nan")
        out[e] = {"rms_m": rms, "snr": rms / plan["noise_m"], "samples": int(d.size)}
    return out


def synthesize_case(seed: int, index: int, out: str) -> tuple:
    """The base file, the data and the effects' signal-to-noise ratios of case ``index`` (seeded
    by ``seed``; reference synthesizer) in its folder under ``out``, made unless an earlier run
    made them for the same plan (``plan.json`` there; a folder of another plan is made again):
    ``(plan with "snr" and "clear", base file, data file, seconds spent making them)``."""
    from ctrplan.io.robot_file import robot_to_toml

    plan = plan_case(seed, index)
    folder = Path(out) / f"case-{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    stored = folder / "plan.json"
    data, snr_file = folder / "data.csv", folder / "snr.json"
    if not stored.exists() or json.loads(stored.read_text()) != plan:
        for f in (data, snr_file, stored, folder / "workflow.log"):
            f.unlink(missing_ok=True)
        shutil.rmtree(folder / "report", ignore_errors=True)     # stages of another plan's run
        stored.write_text(json.dumps(plan, indent=1) + "\n")
    base, _ = _truth_robot(plan)
    model = folder / "base.toml"
    model.write_text(robot_to_toml(base, header="sweep base file: nominal tube parameters, candidate effects off"))
    t0 = time.perf_counter()
    if not (data.exists() and snr_file.exists()):
        _, frame, record = _synthesize(plan)
        snr = effect_displacements(plan, record["tip"])
        tmp = data.with_suffix(".tmp")
        frame.to_csv(tmp, index=False)
        tmp.replace(data)
        snr_file.write_text(json.dumps(snr, indent=1) + "\n")
    snr = json.loads(snr_file.read_text())
    plan = {**plan, "snr": {e: v["snr"] for e, v in snr.items()}}
    plan["clear"] = _clear(plan)
    return plan, model, data, time.perf_counter() - t0


def run_case(seed: int, index: int, out: str, jobs: int) -> dict:
    """Case ``index`` (seeded by ``seed``): its data (:func:`synthesize_case`), then the workflow
    on it; the case's line of ``cases.jsonl`` (``seconds`` counts the data's making where this
    call made it, ``synth_seconds``; ``outcome``, ``written_stderr`` and ``value_check`` as
    :func:`score_run` gives them)."""
    from ctrplan.discrepancy.outputs import words
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
    written = written_values(res["updated_model_file"], final, fitted)
    scored = score_run(plan, res, written)
    return {**plan, "verdict": res["verdict"], "named": res["named_effect"], "ambiguous_with": res["ambiguous_with"],
            "decision": decision_record(res["decision"], plan["truth"], final),
            "named_effects": final, "outcome": scored["outcome"], "fitted": fitted, "written": written,
            "written_stderr": scored["written_stderr"], "value_check": scored["value_check"],
            "cautions": [words.caution(c) for c in res["decision"]["cautions"]], "noise_consistent": res["noise"]["consistent"],
            "noise_mm": res["noise"]["noise_rms_mm"],
            "test_mean_mm": {k: res["test_split"]["figures"][k]["mean_mm"]["value"] for k in ("file", "before", "after")},
            "prior_strength": res["baseline"]["prior_strength"], "synth_seconds": synth_s,
            "seconds": time.perf_counter() - t0, "load_average": os.getloadavg()[0],
            "stage_seconds": res.get("stage_seconds", {}),
            "source_sha256": res["provenance"]["source_sha256"]}


def decision_record(decision: dict, truth: list, named: list) -> dict:
    """What a case's verdict rests on, to say why a target is missed: the candidates that passed
    the Holm gate, the eligible ones, the best, the level of the rule, the reasons (``why_not``)
    for every hidden or named effect that has them, the separability of the named effect
    against the others (``{"a vs b": {"correlation", ...}}`` as the decision holds it), and
    whether two effects were named together that neither could be alone."""
    return {"holm_passed": sorted(e for e, ok in decision.get("holm", {}).items() if ok),
            "eligible": list(decision.get("eligible", [])), "best": decision.get("best"),
            "level": (decision.get("rule") or {}).get("level"),
            "why_not": {e: r for e, r in decision.get("why_not", {}).items() if r and (e in truth or e in named)},
            "inseparable": decision.get("inseparable"), "separability": decision.get("separability", {}),
            "named_jointly": any(n.get("kind") == "named jointly" for n in decision.get("notes") or []
                                 if isinstance(n, dict))}


def written_values(model_file, named, fitted) -> dict:
    """``{effect: {parameter: value}}`` of the named effects as the written robot file holds them
    (fitted jointly where two are named); the registration, which a robot file does not hold, as
    ``fitted`` gives it (each named effect fitted alone)."""
    from ctrplan.discrepancy.fits.parameters import read_parameters
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


def _rate(k: int, n: int) -> dict:
    """``{"count", "cases", "rate", "ci90"}`` of k successes in n (rate and interval None for n = 0)."""
    return {"count": k, "cases": n, "rate": k / n if n else None, "ci90": clopper_pearson(k, n, CI_LEVEL)}


def _clear(case: dict) -> bool:
    """Every hidden effect of the case reaches :data:`CLEAR_SNR` (a case recorded without
    signal-to-noise ratios is not clear)."""
    snr = case.get("snr") or {}
    return bool(case["truth"]) and all(snr.get(e, 0.0) >= CLEAR_SNR for e in case["truth"])


def summarize(cases: list) -> dict:
    """Counts of every outcome (all cases, by robot, by kind, by truth), the rate of every outcome
    with its 90 % Clopper-Pearson interval, and the targets (module docstring) with ``met``: true,
    false, or None when there are no cases to judge it by."""
    def counts(sub):
        return {o: sum(c["outcome"] == o for c in sub) for o in OUTCOMES}

    def label(c):
        return "+".join(c["truth"]) or "none"

    n = len(cases)
    truths = list(("none",) + EFFECTS) + sorted({label(c) for c in cases} - {"none", *EFFECTS})
    wrong = _rate(sum(c["outcome"] == "wrong" for c in cases), n)
    one = [c for c in cases if c["kind"] == "one" and _clear(c)]
    two = [c for c in cases if c["kind"] == "two" and _clear(c)]
    one_named = _rate(sum(c["outcome"] in NAMED_ALONE for c in one), len(one))
    both_named = _rate(sum(c["outcome"] in NAMED_ALONE for c in two), len(two))
    return {"cases": n, "by_outcome": counts(cases),
            "by_robot": {r: counts([c for c in cases if c["robot"] == r]) for r in ROBOTS},
            "by_kind": {k: counts([c for c in cases if c["kind"] == k]) for k in KINDS},
            "by_truth": {t: counts([c for c in cases if label(c) == t]) for t in truths},
            "rates": {o: _rate(sum(c["outcome"] == o for c in cases), n) for o in OUTCOMES},
            "clear_snr": CLEAR_SNR, "clear_cases": {k: sum(c["kind"] == k and _clear(c) for c in cases)
                                                   for k in ("one", "two")},
            "value_rule": {"stderrs": VALUE_STDERRS, "share": VALUE_SHARE},
            "targets": {
                "wrong": {**wrong, "rate_below": WRONG_RATE_BELOW, "upper_below": WRONG_UPPER_BELOW,
                          "met": None if not n else wrong["rate"] < WRONG_RATE_BELOW
                          and wrong["ci90"][1] < WRONG_UPPER_BELOW},
                "clear_one_named": {**one_named, "at_least": ONE_NAMED_AT_LEAST,
                                    "met": None if not one else one_named["rate"] >= ONE_NAMED_AT_LEAST},
                "clear_two_both_named": {**both_named, "at_least": BOTH_NAMED_AT_LEAST,
                                         "met": None if not two else both_named["rate"] >= BOTH_NAMED_AT_LEAST}}}


def sweep_code_digest() -> str:
    """SHA-256 (hex) of the code of this benchmark and of every ``tests/ctrplan_reference/*.py``: their
    paths (relative to the repository) and :func:`ctrplan.discrepancy.provenance.code_digest`,
    sorted by path (docstrings, comments and layout do not count)."""
    from ctrplan.discrepancy.provenance import code_digest

    paths = [Path(__file__).resolve(), *(ROOT / "tests" / "ctrplan_reference").glob("*.py")]
    h = hashlib.sha256()
    for rel, path in sorted((p.relative_to(ROOT).as_posix(), p) for p in paths):
        h.update(rel.encode() + b"\0" + code_digest(path.read_text(), rel).encode() + b"\0")
    return h.hexdigest()


def case_seconds(cases: list) -> dict:
    """Seconds of the workflow per case (the data's making, where a case's run made it, left out):
    total, mean, median, p90 and max, and the median of the cases' 1-minute load averages at their
    end (None when no case recorded one)."""
    import numpy as np

    t = np.array([c["seconds"] - c.get("synth_seconds", 0.0) for c in cases], float)
    load = [c["load_average"] for c in cases if c.get("load_average") is not None]
    return {"total": float(t.sum()), "mean": float(t.mean()), "median": float(np.median(t)),
            "p90": float(np.percentile(t, 90)), "max": float(t.max()),
            "load_average_median": float(np.median(load)) if load else None}


def data_ready(out, seed: int) -> bool:
    """The data and the signal-to-noise ratios of case ``seed`` exist under ``out`` (made by an
    earlier run or by ``--synthesize-only`` beside this one)."""
    folder = Path(out) / f"case-{seed}"
    return (folder / "data.csv").exists() and (folder / "snr.json").exists()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=100)
    ap.add_argument("--first-seed", type=int, default=2000)
    ap.add_argument("--jobs", type=int, default=2, help="worker processes within a case")
    ap.add_argument("--scheduler", default=None, help="address of a Dask scheduler to run the cases on")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench-discrepancy-sweep"))
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "discrepancy-sweep.json"))
    ap.add_argument("--run-first", type=int, nargs="+", default=(), metavar="SEED",
                    help="run the cases of these seeds (of the planned ones) before the others")
    ap.add_argument("--synthesize-only", action="store_true",
                    help="make the data of the planned cases not made yet, run no workflow, write no results")
    ap.add_argument("--ready-only", action="store_true",
                    help="run only the planned cases whose data is made; the others stay planned")
    ap.add_argument("--results-only", action="store_true",
                    help="rewrite the results file from the finished cases, rescored by the present rules, "
                         "without running any")
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
                plan = plan_case(c["seed"], c["index"])
                if {k: c.get(k) for k in plan} != plan:      # recorded under another plan: run it again
                    continue
                if "written" not in c:   # a case recorded before the written values were: read its file
                    files = sorted((out / f"case-{c['seed']}" / "report").glob("*.toml"))
                    c["written"] = written_values(files[-1], c["named_effects"], c["fitted"]) if files else None
                done[c["seed"]] = rescore(c)
    seeds = [args.first_seed + k for k in range(args.cases)]
    unknown = sorted(set(args.run_first) - set(seeds))
    if unknown:
        ap.error(f"--run-first: seeds {unknown} are not among the planned {seeds[0]}..{seeds[-1]}")
    first = [s for s in args.run_first if s not in done]
    todo = first + [s for s in seeds if s not in done and s not in first]
    waiting = 0
    if args.ready_only:
        ready = [s for s in todo if data_ready(out, s)]
        waiting, todo = len(todo) - len(ready), ready
    print(f"{len(seeds) - len(todo) - waiting} of {len(seeds)} cases finished earlier, {len(todo)} to run"
          + (f", {waiting} left for when their data is made" if args.ready_only else "")
          + f"; load average {os.getloadavg()[0]:.2f}", flush=True)
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
            "case_seconds": case_seconds(cases),
            "provenance": {**provenance(), "sweep_code_sha256": sweep_code_digest(),
                           "cases_source_sha256": sorted({c["source_sha256"] for c in cases})},
            "cases": cases}, indent=1) + "\n")
        return cases

    def record(case):
        done[case["seed"]] = case
        with log.open("a") as fh:
            fh.write(json.dumps(case) + "\n")
        write_results()
        print(f"  {case['seed']} {case['robot']:11s} truth {','.join(case['truth']) or 'none':28s} -> "
              f"{case['outcome']:21s} ({case['verdict']}: {','.join(case['named_effects']) or '-'}"
              + (f" or {case['ambiguous_with']}" if case["ambiguous_with"] else "") + f"); {case['seconds']:.0f} s",
              flush=True)

    if args.synthesize_only:
        from ctrplan.parallel import Executor

        # each case's data on its own process (--jobs of them, the reference synthesizer is serial)
        with Executor(n_jobs=args.jobs, scheduler=args.scheduler) as ex:
            for s, made in ex.run(synthesize_case, [(s, (s, s - args.first_seed, str(out))) for s in todo]):
                print(f"  {s} data made in {made[3]:.0f} s", flush=True)
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
        todo = list(todo)
        while todo:        # a case whose data is made runs before one whose data is still to make
            s = next((x for x in todo if data_ready(out, x)), todo[0])
            todo.remove(s)
            record(run_case(s, s - args.first_seed, str(out), args.jobs))
    cases = write_results()
    summary = summarize(cases)
    wall = time.perf_counter() - t0
    print(json.dumps({k: summary[k] for k in ("by_outcome", "rates", "targets")}, indent=1))
    print(f"{wall:.0f} s this run, {sum(c['seconds'] for c in cases):.0f} s of cases in all; load average "
          f"{os.getloadavg()[0]:.2f}")
    print(f"wrote {results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
