"""Two effects named together when neither can be named alone (the joint search of stage 8).

The records are made by least squares on simulated regressors, independent of the workflow's
fits: a baseline (an intercept), one candidate per effect (the intercept and its own slowly
varying regressor), and a pair (both regressors), each fitted without every fold; the naming rule
(:func:`~ctrplan.discrepancy.verdict.decision.name_effect`) and the pair rule
(:func:`~ctrplan.discrepancy.fits.pairs.pair_decision`, :func:`joint_start`,
:func:`joint_naming`) then judge the out-of-fold errors as the workflow does.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ctrplan.choices import DecisionNoteKind, NoEffectCase, Verdict
from ctrplan.discrepancy.fits.fitting import compare
from ctrplan.discrepancy.fits.pairs import Combination, joint_naming, joint_start, pair_decision
from ctrplan.effects import REGISTRY

from test_discrepancy_history_effects import _candidate, _naming, _split
from test_discrepancy_statistics import _ar1, _out_of_fold_errors, _slow_regressor, _too_many

EFFECTS = ("backlash", "time_offset", "offplane", "poisson", "registration", "friction", "clearance",
           "gradual_friction")
BLOCKS, PER_BLOCK, FOLDS = 20, 20, 10         # the split of 500 samples' development part, 10 folds of 2 blocks


def _records(seed: int, reps: int, strengths: tuple) -> tuple:
    """``reps`` records of ``BLOCKS * PER_BLOCK`` samples: AR(1) noise (phi 0.8, unit variance)
    plus ``strengths[i]`` times the regressor of ``EFFECTS[i]`` (a square wave for the first, a
    random walk for the others; missing strengths are 0). Returns ``(split, regressors (E, R, K),
    y (R, K))``."""
    rng = np.random.default_rng(seed)
    k = BLOCKS * PER_BLOCK
    units = np.repeat(np.arange(BLOCKS), PER_BLOCK)
    split = _split(units, n_folds=FOLDS)
    x = np.stack([_slow_regressor(rng, "switch" if i == 0 else "walk", reps, k) for i in range(len(EFFECTS))])
    y = _ar1(rng, reps, k, 0.8)
    for i, c in enumerate(strengths):
        y = y + c * x[i]
    return split, x, y


def _errors(split, columns, y) -> np.ndarray:
    """Out-of-fold absolute errors of the least-squares fit of ``y`` on an intercept and
    ``columns`` (each (R, K)), shape (R, K)."""
    ones = np.ones_like(y)
    x = np.stack([ones, *columns], axis=-1)
    return _out_of_fold_errors(x, y, split.fold)


def _judge(split, x, y, r: int):
    """Record ``r`` judged as the workflow does: stage 7's naming, then, when it names nothing,
    the joint search from :func:`joint_start` with every other candidate that improves alone.
    Returns ``(naming, combination or None)``."""
    base = _errors(split, [], y[r:r + 1])[0]
    alone = {e: _errors(split, [x[i, r:r + 1]], y[r:r + 1])[0] for i, e in enumerate(EFFECTS)}
    cands = {e: _candidate(e, split, base, alone[e]) for e in EFFECTS}
    naming = _naming(cands, split)
    first = joint_start(naming)
    if first is None:
        return naming, None
    i = EFFECTS.index(first)
    family = [e for e in EFFECTS if e != first]
    tried, against = {}, {}
    for j, e in enumerate(EFFECTS):
        if e == first or not cands[e].improvement.mean_difference > 0:
            continue
        pair = _errors(split, [x[i, r:r + 1], x[j, r:r + 1]], y[r:r + 1])[0]
        tried[e] = replace(_candidate(e, split, alone[first], pair), effects=(first, e),
                           reverse=compare(split, alone[e], pair))
        against[e] = compare(split, base, pair)
    level = naming.decision.rule.level
    out, second, dropped, replaced, notes = pair_decision(
        first, tried, family, naming.decision.worse_than, level, eligible={e: False for e in EFFECTS},
        vanishes={e: None for e in tried}, joint_level=level / len(naming.decision.family), against_baseline=against)
    assert dropped is None and replaced is None
    comb = Combination(first=first, first_label=REGISTRY[first].label, named=second, tried=out, not_tried={},
                       family=tuple(family), significance=level, joint=True,
                       joint_level=level / len(naming.decision.family), against_baseline=against)
    return joint_naming(naming, comb), comb


def _named(naming, comb) -> set:
    if naming.verdict != Verdict.NAMED:
        return set()
    return {naming.named} | ({comb.named} if comb is not None and comb.named else set())


def test_two_effects_neither_named_alone_are_named_together():
    """A square wave and a random walk each twice as strong as the noise: each alone leaves the
    other in its out-of-fold errors, so the naming rule names neither in almost every record (60);
    the joint search names exactly the two in at least 10 of them (18 here), and never another
    effect. Catches a pair stage that starts only from a named effect (nothing named together)
    and a joint rule that names any other pair."""
    split, x, y = _records(11, 60, (2.0, 2.0))
    alone_named = together = wrong = 0
    for r in range(y.shape[0]):
        naming, comb = _judge(split, x, y, r)
        named = _named(naming, comb)
        if comb is None:
            alone_named += naming.verdict == Verdict.NAMED
            continue
        together += named == {"backlash", "time_offset"}
        wrong += bool(named - {"backlash", "time_offset"})
        if named:
            notes = [n for n in naming.decision.notes if n.kind == DecisionNoteKind.NAMED_JOINTLY]
            assert len(notes) == 1 and {notes[0].effect, notes[0].other} == named
            assert notes[0].comparison.p_value <= comb.joint_level
            assert naming.decision.no_effect_case is None
    assert alone_named <= 5, alone_named             # the case the joint search is for
    assert together >= 10 and wrong == 0, (together, wrong, alone_named)


@pytest.mark.parametrize("strengths", [(), (0.25,)], ids=["nothing", "one-weak-effect"])
def test_the_joint_search_names_no_absent_effect_beyond_its_level(strengths):
    """No effect (every regressor irrelevant) or one weak square wave that the naming rule seldom
    names alone: a pair with an absent effect is written at most at the naming rule's level
    (0.01), checked by an exact binomial test. Catches a joint rule without the comparison in
    both directions (an irrelevant partner rides on the real effect) or judged at a looser level
    than the family the start was chosen from."""
    split, x, y = _records(23 + len(strengths), 400, strengths)
    truth = {EFFECTS[i] for i, c in enumerate(strengths) if c}
    false, searched = 0, 0
    for r in range(y.shape[0]):
        naming, comb = _judge(split, x, y, r)
        searched += comb is not None
        false += bool(_named(naming, comb) - truth) if comb is not None else 0
    assert searched >= 100, searched                  # the search ran in a good share of the records
    assert not _too_many(false, y.shape[0], 0.01), (false, searched)


def test_the_joint_search_needs_a_best_explanation_that_could_be_named():
    """:func:`joint_start` starts only from a best explanation that lowers the error on average,
    has no value at its limit and is not outperformed, and never when the residual is consistent
    with the noise or when an effect was named; :func:`joint_naming` leaves a naming without a
    joint pair as it is. Catches a search started from an effect that cannot be named."""
    split, x, y = _records(5, 1, (1.0, 1.0))
    naming, comb = _judge(split, x, y, 0)
    base = _errors(split, [], y)[0]
    alone = {e: _errors(split, [x[i]], y)[0] for i, e in enumerate(EFFECTS)}
    cands = {e: _candidate(e, split, base, alone[e]) for e in EFFECTS}
    plain = _naming(cands, split)
    assert plain.verdict == Verdict.NONE             # the record this test is about (seeded)
    start = joint_start(plain)
    assert start == plain.decision.best
    at_limit = dict(cands, **{start: _candidate(start, split, base, alone[start], at_bound=("x (its limit)",))})
    assert joint_start(_naming(at_limit, split)) != start
    noise = replace(plain, decision=replace(plain.decision, no_effect_case=NoEffectCase.NOISE))
    assert joint_start(noise) is None
    strong = _errors(split, [x[0], x[1]], y)[0]
    named = _naming(dict(cands, backlash=_candidate("backlash", split, base, strong * 0.2)), split)
    assert named.verdict != Verdict.NONE and joint_start(named) is None
    assert joint_naming(named, None) is named
    assert comb is not None and not comb.named       # a joint search that named no pair (seeded)
    assert joint_naming(naming, comb) is naming


def test_the_workflow_runs_the_joint_search_when_nothing_is_named_and_reports_it(tmp_path):
    """The whole workflow on a tube-pair record with drive backlash and a tracker lag hidden
    (reference synthesizer), at a level no comparison can reach (1e-12): nothing is named alone,
    so stage 8 searches pairs from the best explanation, compares each with the baseline too,
    names none, and the results and the report say so. Catches a joint search that is never
    reached from the workflow, that loses its comparisons with the baseline, or that breaks the
    report."""
    from test_discrepancy_fast import _case

    res, _, _, result = _case(tmp_path, 31, ("backlash", "time_offset"), options=dict(significance=1e-12),
                              backlash=(0.0, np.deg2rad(4.0)), time_offset=0.15)
    assert res["verdict"] == "none" and res["named_effects"] == []
    comb = res["combination"]
    assert comb is not None and comb["joint"] and comb["named"] is None
    assert comb["first"] == res["decision"]["best"]
    other = ({"backlash", "time_offset"} - {comb["first"]}).pop()
    assert set(comb["tried"]) == {other} and set(comb["against_baseline"]) == {other}
    assert comb["rule"]["joint_level"] == pytest.approx(1e-12 / 2)
    assert comb["against_baseline"][other]["mean_difference"] > 0      # the pair does lower the error
    from ctrplan.discrepancy.outputs.report import write_report

    report = Path(write_report(result, tmp_path / "out")["markdown"]).read_text()
    assert "Two effects fitted together (neither named alone)" in report and "than the baseline by" in report
    assert result.naming.verdict.value == "none"
