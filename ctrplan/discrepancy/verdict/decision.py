"""Stages 5 and 7 of the discrepancy workflow: the sensor noise, and what is named.

**Naming rule: the best explanation wins.** Every candidate's out-of-fold errors are compared
with the baseline's and with every other candidate's by the corrected resampled t test of the
folds' log ratios (the test whose size the statistics tests check; uncorrected, a comparison with
the baseline exceeds its level eightfold beside a slow unmodelled residual) over the
cross-validation folds
(:func:`~ctrplan.discrepancy.fits.fitting.compare`,
:func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison`). A candidate is
*eligible* when

- its improvement over the baseline is significant at the family-wise level
  ``options.significance``, Holm over every candidate tried alone (the family is fixed before any
  fit);
- no other candidate's out-of-fold error is significantly lower (one-sided, at
  ``options.significance``): a candidate that another explains significantly better is never
  named, whatever the other's typical range;
- none of its values sits at a bound that could not be widened (a fit at an optimizer bound, a
  grid's edge or a scan's end is first extended, up to the parameter's limit);
- no fit of the baseline it is compared with stopped at its evaluation budget before converging
  (:func:`unfinished_fits`: a candidate fitted from an unfinished baseline improves on it by
  finishing the baseline's own fit).

Where the split could not keep its folds apart (:func:`folds_kept_apart`: the buffer capped
short of the pilot residual's autocorrelation threshold, and the best candidate's out-of-fold
residual still correlated beyond it), every comparison runs at ``significance`` /
:data:`CORRELATED_FOLDS_SIZE_FACTOR` (the rule records both levels).

The eligible candidate with the lowest out-of-fold error is named, with a caution when a value
lies outside its typical range (the value, the range with its source, and what to check). When
another eligible candidate that does not contain it (or lie in it) remains, the two explain the
data equally well within their uncertainty and the verdict is **ambiguous**: both are listed,
best first, with what data would separate them (``Effect.separated_by``). A candidate that is
the best explanation but sits at its limit is left unnamed, and the report says that it is the
best explanation.

**Separability.** Before an effect is named alone, its fitted tip displacement field on the
recorded motion is compared with that of every other candidate that improves on the baseline
significantly (Holm), neither contains it nor lies in it, and has no value at its limit
(:mod:`~ctrplan.discrepancy.verdict.separability`): when the two fields are collinear (correlation
at or above :data:`~ctrplan.discrepancy.verdict.separability.INSEPARABLE_CORRELATION`), the motion
cannot tell the two effects apart, whatever the comparison of their errors says, and the verdict
is **ambiguous: not separable on this motion**, the most collinear such candidate second. An
ambiguous verdict of either kind writes neither effect to the robot file (the recalibrated
baseline), and no second effect is fitted on top of it: which effect is there is the open
question, and a motion that separates them (``ctrplan design``) answers it.

**Noise.** The sensor noise comes from the development data's rests (consecutive samples at
identical joints, at several lags, so that noise correlated in time is seen) when it has
enough, else from what its source states (:mod:`~ctrplan.discrepancy.measured.noise`); the baseline's
out-of-fold residual is "consistent with noise" by an F test that allows for the fitted
parameters, the noise's correlation and the noise estimate's own uncertainty, with false-alarm
rate ``options.significance``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ...choices import BufferReason, CautionKind, DecisionNoteKind, NoEffectCase, NotNamedReason, Verdict
from ...effects import REGISTRY
from .consistency import NoiseTest, noise_test
from ..fits.evaluation import ErrorFigures
from ..fits.fitting import Candidate, compare
from ..measured.noise import NoiseEstimate, estimate_noise
from ..options import DiscrepancyOptions
from ..measured.split import DataSplit, residual_autocorrelation
from .reasons import Caution, DecisionNote, NamingRule, WhyNot
from .separability import Separability, separability
from .statistics import Comparison, holm

__all__ = ["NoiseCheck", "Naming", "Decision", "RunnerUp", "Separability", "check_noise", "name_effect", "cautions",
           "no_effect_case", "unfinished_fits", "folds_kept_apart", "comparison_level",
           "CORRELATED_FOLDS_SIZE_FACTOR", "VERDICTS"]


#: Where the split could not keep its folds apart (:func:`folds_kept_apart`: the buffer capped at
#: half a block and the best candidate's residual still correlated above
#: :data:`~ctrplan.discrepancy.measured.split.BUFFER_AUTOCORRELATION` there), the comparisons run at ``significance`` divided by this: the corrected comparison's
#: rejection rate was measured at up to 7 times its level where the residual stays correlated
#: from one block to the next (0.010 at 0.0014 for two equally good models beside a slow
#: discrepancy, 0.0032 at 0.0014 with blocks of 10 samples at phi 0.9;
#: :func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison`'s notes), so a level divided by 7
#: keeps the rate at most the one asked for in every regime measured.
CORRELATED_FOLDS_SIZE_FACTOR = 7.0

#: What a run concludes: one effect (or a pair) named, two candidates the data cannot tell apart,
#: or none.
VERDICTS = tuple(Verdict)


@dataclass(frozen=True, eq=False)
class NoiseCheck:
    """Stage 5: is the baseline's out-of-fold residual more than the sensor noise?

    Attributes
    ----------
    noise : NoiseEstimate
        The noise estimate (:func:`~ctrplan.discrepancy.measured.noise.estimate_noise`), from the
        development samples only; its ``position_rms_m`` [m] is None when unknown.
    rms_m : float
        rms of the baseline's out-of-fold position errors [m] (NaN without a finite one).
    ratio : float or None
        ``rms_m`` over the noise rms [-]; None when the noise is unknown.
    test : NoiseTest or None
        :func:`~ctrplan.discrepancy.verdict.consistency.noise_test`; None when the noise is unknown.
    """

    noise: NoiseEstimate
    rms_m: float
    ratio: float | None
    test: NoiseTest | None

    @property
    def consistent(self) -> bool | None:
        """The residual is consistent with the noise (None: the noise is unknown)."""
        return None if self.test is None else bool(self.test.consistent)

    @property
    def rms(self) -> float | None:
        """The noise rms [m] (None when unknown)."""
        return self.noise.position_rms_m


@dataclass(frozen=True)
class RunnerUp:
    """The second candidate of an ambiguous verdict.

    Attributes
    ----------
    effect, label : str
    difference : Comparison
        The named candidate's out-of-fold Eq. (49) residuals against this one's (positive: the
        named one is better) [mm + deg].
    """

    effect: str
    label: str
    difference: Comparison


@dataclass(frozen=True)
class Decision:
    """Stage 7's verdict and what it rests on.

    Attributes
    ----------
    verdict : Verdict
        Named, ambiguous or none.
    named : str or None
        The best eligible effect (the first of an ambiguous pair), or None.
    ambiguous_with : str or None
        The second of an ambiguous pair.
    eligible : tuple of str
        Eligible candidates, lowest out-of-fold error first.
    holm : mapping of str to bool
        Each candidate's improvement over the baseline significant within the Holm family.
    family : tuple of str
        Every candidate tried alone (the Holm family).
    best : str or None
        The candidate with the lowest out-of-fold error, eligible or not.
    worse_than : mapping of str to tuple of str
        Candidate -> the candidates whose out-of-fold error is significantly lower.
    why_not : mapping of str to tuple of WhyNot
        Candidate -> why it may not be named (only candidates with a reason).
    comparisons : mapping of str to Comparison
        ``"<b> vs <a>"`` -> :func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison` of a's and b's
        out-of-fold Eq. (49) residuals (positive: b better) [mm + deg], every ordered pair.
    separated_by : mapping of str to str, or None
        An ambiguous pair: each effect -> the data that would tell it apart
        (``Effect.separated_by``; effects without one left out).
    cautions : tuple of Caution
        The named effect's values outside their typical range, with what to check.
    notes : tuple of DecisionNote
    rule : NamingRule
        The naming rule's levels.
    runner_up : RunnerUp or None
        The second of an ambiguous pair.
    separability : mapping of str to Separability
        ``"<named> vs <other>"`` -> the two fitted displacement fields compared, for every other
        candidate significant over the baseline and not nested with the named one (empty when
        nothing is named or no baseline residuals were given).
    inseparable : bool
        The verdict is ambiguous because the motion cannot separate the pair (not because both
        are eligible).
    no_effect_case : NoEffectCase or None
        When none is named: the residual is consistent with noise, it is not (unexplained), it is
        not but the noise is only a lower bound (inconclusive), or the noise is unknown
        (:func:`no_effect_case`).
    """

    verdict: Verdict
    named: str | None
    ambiguous_with: str | None
    eligible: tuple
    holm: Mapping
    family: tuple
    best: str | None
    worse_than: Mapping
    why_not: Mapping
    comparisons: Mapping
    separated_by: Mapping | None
    cautions: tuple
    notes: tuple
    rule: NamingRule
    runner_up: RunnerUp | None = None
    separability: Mapping = field(default_factory=lambda: MappingProxyType({}))
    inseparable: bool = False
    no_effect_case: NoEffectCase | None = None

    def as_dict(self) -> dict:
        """Plain JSON form (``results.json["decision"]``; comparisons in Eq. (49) units)."""
        out = {"verdict": self.verdict, "named": self.named, "ambiguous_with": self.ambiguous_with,
               "eligible": list(self.eligible), "holm": dict(self.holm), "family": list(self.family),
               "best": self.best, "worse_than": {k: list(v) for k, v in self.worse_than.items()},
               "why_not": {k: [w.as_dict() for w in v] for k, v in self.why_not.items()},
               "comparisons": {k: c.as_dict() for k, c in self.comparisons.items()},
               "separated_by": None if self.separated_by is None else dict(self.separated_by),
               "cautions": [c.as_dict() for c in self.cautions], "notes": [n.as_dict() for n in self.notes],
               "rule": self.rule.as_dict()}
        if self.runner_up is not None:
            r = self.runner_up
            out["runner_up"] = {"effect": r.effect, "label": r.label, "difference": r.difference.as_dict()}
        if self.no_effect_case is not None:
            out["no_effect_case"] = self.no_effect_case
        out["separability"] = {k: v.as_dict() for k, v in self.separability.items()}
        out["inseparable"] = bool(self.inseparable)
        return out


@dataclass(frozen=True, eq=False)
class Naming:
    """Stage 7: the verdict.

    Attributes
    ----------
    candidates : mapping of str to Candidate
        Every tried candidate with the naming rule's verdicts (``improvement_significant``,
        ``eligible``).
    decision : Decision
    """

    candidates: Mapping[str, Candidate]
    decision: Decision

    @property
    def named(self) -> str | None:
        """The best eligible effect (first of an ambiguous pair), or None."""
        return self.decision.named

    @property
    def verdict(self) -> Verdict:
        """Named, ambiguous or none."""
        return self.decision.verdict


def check_noise(setup, split: DataSplit, baseline, options: DiscrepancyOptions) -> NoiseCheck:
    """Stage 5: the sensor noise (:func:`~ctrplan.discrepancy.measured.noise.estimate_noise` of the
    development samples, never the test split) against the baseline's out-of-fold residual on the
    development samples (:func:`~ctrplan.discrepancy.verdict.consistency.noise_test` with the baseline's
    fitted parameters and the position components, 3 per sample, each fold's fit used).

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    baseline : Baseline
    options : DiscrepancyOptions
        ``noise_position`` (a stated noise) and ``significance`` (the false-alarm rate).

    Returns
    -------
    NoiseCheck
    """
    data = setup.data
    estimate = estimate_noise(data, rows=split.dev_rows, stated=options.noise_position)
    oof = baseline.oof
    res = oof.residual_base
    fin = res[np.all(np.isfinite(res), axis=1)]
    rms = float(np.sqrt(np.mean(np.sum(fin * fin, axis=1)))) if fin.size else float("nan")
    sigma = estimate.position_rms_m
    test = None
    if sigma and fin.size:
        n_fit = min(f.n_samples for f in baseline.cv.folds)
        test = noise_test(res, data.rows[oof.rows], data.sequence[oof.rows], estimate,
                          n_parameters=len(baseline.fit.names), n_fitted=3 * n_fit, alpha=options.significance)
    return NoiseCheck(noise=estimate, rms_m=rms, ratio=rms / sigma if sigma else None, test=test)


def _separated_by(a: str, b: str) -> dict:
    """What data would tell effects ``a`` and ``b`` apart: each one's ``separated_by``."""
    return {e: REGISTRY[e].separated_by for e in (a, b) if REGISTRY[e].separated_by}


def no_effect_case(noise: NoiseCheck) -> NoEffectCase:
    """What the noise test says when no effect is named.

    A rejection against a noise that is only a lower bound (rests too short to see its
    correlation) is no evidence of a missing effect
    (:class:`~ctrplan.discrepancy.verdict.consistency.NoiseTest`): the test is then inconclusive. An
    acceptance against an upper bound (spread over repeated configurations) still says the
    residual is no larger than such noise.

    Parameters
    ----------
    noise : NoiseCheck

    Returns
    -------
    NoEffectCase
        ``NOISE`` (the residual is consistent with the noise), ``UNEXPLAINED`` (it is not),
        ``INCONCLUSIVE`` (not consistent with a noise that is only a lower bound) or ``UNKNOWN``
        (no noise known).
    """
    test = noise.test
    if test is None:
        return NoEffectCase.UNKNOWN
    if test.noise_lower_bound and not test.consistent:
        return NoEffectCase.INCONCLUSIVE
    return NoEffectCase.NOISE if test.consistent else NoEffectCase.UNEXPLAINED


def name_effect(split: DataSplit, candidates: Mapping[str, Candidate], tests: Mapping, noise: NoiseCheck,
                options: DiscrepancyOptions, *, baseline=None) -> Naming:
    """Stage 7: the verdict, by the rule of the module docstring.

    Parameters
    ----------
    split : DataSplit
        Its folds.
    candidates : mapping of str to Candidate
        :func:`~ctrplan.discrepancy.fits.fitting.fit_candidates`: every candidate tried alone (the
        Holm family).
    tests : mapping of str to SignatureTest
        :func:`~ctrplan.discrepancy.verdict.signatures.diagnose_residuals` (reported; not a condition).
    noise : NoiseCheck
    options : DiscrepancyOptions
        ``significance``.
    baseline : Baseline, optional, keyword-only
        Stage 3: its out-of-fold errors at the development samples (``oof``, whose
        ``residual_base`` [m] is compared with the candidates' at the same rows) and its fits
        (``cv``: a fit that stopped at its evaluation budget makes every candidate ineligible).
        Without it neither is checked (the workflow always gives it).

    Returns
    -------
    Naming
    """
    alpha = comparison_level(split, candidates, options.significance)
    apart = alpha == options.significance   # the level is divided where the folds are not apart
    significant = holm({e: (c.improvement.p_value if c.improvement.mean_difference > 0 else 1.0)
                        for e, c in candidates.items()}, alpha) if candidates else {}
    names = list(candidates)
    comparisons, worse_than = {}, {e: [] for e in names}
    for a in names:
        for b in names:
            if a == b:
                continue
            # positive: b better than a
            cmp = comparisons[f"{b} vs {a}"] = compare(split, candidates[a].r, candidates[b].r)
            if cmp.p_worse < alpha and cmp.mean_difference < 0:
                worse_than[b].append(a)
    why_not: dict = {}
    judged = {}
    unfinished = unfinished_fits(baseline.cv) if baseline is not None else ()
    for e, c in candidates.items():
        reasons = [WhyNot(NotNamedReason.BASELINE_UNFINISHED, limits=unfinished)] if unfinished else []
        if not significant.get(e, False):
            reasons.append(WhyNot(NotNamedReason.NOT_SIGNIFICANT, p_value=c.improvement.p_value))
        if worse_than[e]:
            reasons.append(WhyNot(NotNamedReason.OUTPERFORMED, outperformed_by=MappingProxyType(
                {d: comparisons[f"{e} vs {d}"].p_worse for d in worse_than[e]})))
        if c.at_bound:
            reasons.append(WhyNot(NotNamedReason.AT_LIMIT, limits=tuple(c.at_bound)))
        why_not[e] = reasons
        judged[e] = replace(c, improvement_significant=bool(significant.get(e, False)), eligible=not reasons)
    eligible = sorted((e for e, c in judged.items() if c.eligible), key=lambda e: judged[e].mean_error)
    best = min(judged, key=lambda e: judged[e].mean_error) if judged else None
    notes = [DecisionNote(DecisionNoteKind.SIGNIFICANT_NOT_NAMED, e)
             for e, c in judged.items() if c.improvement_significant and not c.eligible]
    decision = Decision(
        verdict=Verdict.NONE, named=None, ambiguous_with=None, eligible=tuple(eligible),
        holm=MappingProxyType({e: bool(v) for e, v in significant.items()}), family=tuple(names), best=best,
        worse_than=MappingProxyType({e: tuple(v) for e, v in worse_than.items()}),
        why_not=MappingProxyType({e: tuple(r) for e, r in why_not.items() if r}),
        comparisons=MappingProxyType(comparisons), separated_by=None, cautions=(), notes=(),
        rule=NamingRule(significance=options.significance, n_folds=split.n_folds, n_candidates=len(names),
                        level=alpha, folds_apart=apart))
    if eligible:
        named = eligible[0]
        # parsimony between nested candidates: one that contains another eligible one (gradual
        # friction contains friction) is named only when it improves on it significantly
        for simpler in eligible[1:]:
            if simpler not in REGISTRY[named].contains:
                continue
            gain = compare(split, judged[simpler].r, judged[named].r)
            comparisons[f"{named} vs {simpler} (nested)"] = gain
            if not (gain.p_value < alpha and gain.mean_difference > 0):
                notes.append(DecisionNote(DecisionNoteKind.SIMPLER_NAMED, named, other=simpler, comparison=gain))
                named = simpler
                break
        decision = replace(decision, verdict=Verdict.NAMED, named=named)
        rivals = [e for e in eligible if e != named and not contained(e, named)]
        seps = _separabilities(named, judged, significant, None if baseline is None else baseline.oof)
        decision = replace(decision, separability=MappingProxyType({f"{named} vs {e}": v for e, v in seps.items()}))
        confused = sorted((e for e, v in seps.items() if not v.separable), key=lambda e: -abs(seps[e].correlation))
        if rivals or confused:
            second = rivals[0] if rivals else confused[0]
            diff = comparisons[f"{named} vs {second}"]
            decision = replace(decision, verdict=Verdict.AMBIGUOUS, ambiguous_with=second,
                               separated_by=MappingProxyType(_separated_by(named, second)),
                               runner_up=RunnerUp(effect=second, label=judged[second].label, difference=diff),
                               inseparable=not rivals)
            notes.append(DecisionNote(DecisionNoteKind.AMBIGUOUS if rivals else DecisionNoteKind.NOT_SEPARABLE,
                                      named, other=second, comparison=diff))
        decision = replace(decision, cautions=tuple(Caution(CautionKind.ATYPICAL_VALUE, label=judged[named].label,
                                                            value=b) for b in judged[named].atypical))
        if best != named and why_not[best]:         # (an eligible best passed over is a SIMPLER_NAMED note)
            notes.append(DecisionNote(DecisionNoteKind.BEST_NOT_NAMED, best))
        decision = replace(decision, notes=tuple(notes))
    else:
        decision = replace(decision, notes=tuple(notes), no_effect_case=no_effect_case(noise))
    return Naming(candidates=MappingProxyType(judged), decision=decision)


def _separabilities(named: str, judged: Mapping, significant: Mapping, baseline_oof) -> dict:
    """:func:`~ctrplan.discrepancy.verdict.separability.separability` of the named candidate against
    every other candidate significant over the baseline, not nested with it and not at its limit
    (one whose value stops at the parameter's limit cannot reach what the data ask, which tells
    them apart) (empty without the baseline's out-of-fold errors).

    Raises
    ------
    ValueError
        A candidate's out-of-fold errors are at other samples than the baseline's.
    """
    first = judged[named].cv.oof
    if baseline_oof is None or first is None:
        return {}
    out = {}
    for e, c in judged.items():
        if e == named or not significant.get(e, False) or contained(e, named) or c.at_bound or c.cv.oof is None:
            continue
        for cand in (named, e):
            if not np.array_equal(judged[cand].cv.oof.rows, baseline_oof.rows):
                raise ValueError(f"separability: {cand}'s out-of-fold errors are at other samples than the baseline's")
        out[e] = separability(named, e, baseline_oof.residual_base, first.residual_base, c.cv.oof.residual_base)
    return out


def folds_kept_apart(split: DataSplit, residual=None) -> bool:
    """The folds' comparisons hold their level: the split's buffer reached the autocorrelation
    threshold (:data:`~ctrplan.discrepancy.measured.split.BUFFER_AUTOCORRELATION`) of the pilot
    fit's residuals, or, where it was capped at half a block short of it, the best candidate's
    out-of-fold residual ``residual`` falls to the threshold within the buffer.

    The pilot's residual holds whatever effect is missing, so a capped buffer alone says only
    that something slow is left; when the best explanation takes it away, what remains between
    the folds is near-independent and the comparisons hold their level. When even the best
    explanation leaves the residual correlated beyond the buffer (a slow discrepancy no candidate
    models, the regime where the comparisons were measured at up to 7 times their level), they
    do not.

    Parameters
    ----------
    split : DataSplit
    residual : ndarray, shape (K_dev, 3), optional
        The best candidate's out-of-fold residual vectors at the development samples [m]
        (without it, a capped buffer is not kept apart).

    Returns
    -------
    bool
    """
    choice = split.buffer_choice
    if not (choice is not None and choice.reason == BufferReason.HALF_A_BLOCK and choice.still is not None
            and choice.still > choice.threshold):
        return True
    if residual is None:
        return False
    lag = int(choice.samples) + 1
    left = residual_autocorrelation(residual, split.data.take(split.dev_rows), lag)[lag]
    return bool(np.isfinite(left) and left <= choice.threshold)


def comparison_level(split: DataSplit, fitted: Mapping, significance: float) -> float:
    """The level of comparisons among fitted models: ``significance``, or that divided by
    :data:`CORRELATED_FOLDS_SIZE_FACTOR` where the folds are not kept apart
    (:func:`folds_kept_apart`), judged from the out-of-fold residual of the model with the lowest
    error among ``fitted``.

    Parameters
    ----------
    split : DataSplit
    fitted : mapping of str to Candidate
        The models compared (their ``mean_error`` [m] and ``cv.oof.residual_base`` [m] at the
        development samples); empty: the folds of a capped buffer are not kept apart.
    significance : float
        The level asked for (``DiscrepancyOptions.significance``).

    Returns
    -------
    float
    """
    lowest = min(fitted, key=lambda e: fitted[e].mean_error) if fitted else None
    oof = None if lowest is None else fitted[lowest].cv.oof
    apart = folds_kept_apart(split, None if oof is None else oof.residual_base)
    return significance if apart else significance / CORRELATED_FOLDS_SIZE_FACTOR


def unfinished_fits(cv) -> tuple:
    """The fits of a cross-validated model that stopped at their evaluation budget: not
    converged, and not because a value sits at a bound (``"development fit"``, ``"fold <k>"``).

    A candidate is fitted from the baseline's fit of the same fold and compared with its
    out-of-fold errors; when that fit stopped before converging, the candidate's extra
    iterations of the baseline's own parameters look like an improvement of its effect.

    Parameters
    ----------
    cv : CrossValidated

    Returns
    -------
    tuple of str
    """
    out = ("development fit",) if _unfinished(cv.fit) else ()
    return out + tuple(f"fold {k}" for k, f in enumerate(cv.folds) if _unfinished(f))


def _unfinished(fit) -> bool:
    return fit is not None and not fit.converged and not fit.at_bound


def contained(a: str, b: str) -> bool:
    """``a`` contains ``b`` or the reverse (e.g. gradual friction and friction): not rivals."""
    return a in REGISTRY[b].contains or b in REGISTRY[a].contains


def cautions(verdict: Verdict, candidate: Candidate | None, before: ErrorFigures, after: ErrorFigures) -> list:
    """What a reader of the named effect must not overlook: a fitted value outside its typical
    range (with what to check), or an addition that lowers the mean error but raises the maximum.

    Parameters
    ----------
    verdict : Verdict
    candidate : Candidate or None
        The final model's candidate.
    before, after : ErrorFigures
        The calibrated baseline's and the final model's errors on the test split [m].

    Returns
    -------
    list of Caution
        ``ATYPICAL_VALUE`` per value of ``candidate.atypical``, then ``MAXIMUM_RISES`` when the
        maximum rises.
    """
    out = []
    if verdict == Verdict.NONE or candidate is None:
        return out
    for b in candidate.atypical:
        out.append(Caution(CautionKind.ATYPICAL_VALUE, label=candidate.label, value=b))
    if after.position_max is not None and after.position_max > before.position_max:
        out.append(Caution(CautionKind.MAXIMUM_RISES, before_m=float(before.position_max),
                           after_m=float(after.position_max)))
    return out
