"""Stage 8 of the discrepancy workflow: a second effect fitted together with the named one, and
whether either adds to the other (nested comparisons in both directions, cross-validated over the
same folds as every candidate; :mod:`~ctrplan.discrepancy.fits.fitting`).

When stage 7 names nothing, two missing effects may each leave the other's residual in its own
out-of-fold errors, so that neither alone improves on the baseline consistently over the folds.
The same stage then starts from the best explanation (:func:`joint_start`) and names a pair only
when the pair improves on the baseline at the strictest step of stage 7's Holm family and each
of its effects adds to the other (:func:`pair_decision` with ``joint_level``); both effects are
then named together (:func:`joint_naming`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ..._log import progress_level
from ...choices import CautionKind, DecisionNoteKind, FitNoteKind, NoEffectCase, NotNamedReason, NotPairedReason, Verdict
from ...effects import REGISTRY
from ...models import MODEL_INFO
from .calibrate import CalibrationResult, calibrate
from .fitoptions import FitRun, FitStart
from .estimates import display_value
from .fitting import (Candidate, combined_model, compare, contained, cross_validate, fit_rows, grid_spec, make_candidate,
                      scan_fit)
from .gridsearch import grid_search
from ..options import DiscrepancyOptions
from ..setup import DiscrepancySetup, effect_parameters, reported_parameters
from ..measured.split import DataSplit
from ..verdict.decision import comparison_level
from ..verdict.reasons import Caution, DecisionNote, FitNote, NotPaired
from ..verdict.statistics import holm

__all__ = ["Combination", "fit_second_effect", "first_vanishes", "pair_decision", "joint_start", "joint_naming",
           "joint_search_level"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Combination:
    """Stage 8: a second effect fitted together with the named one.

    Attributes
    ----------
    first, first_label : str
        The named effect.
    named : str or None
        The second effect named with it (the pair is the final model).
    dropped : str or None
        The named effect, when a pair shows it adds nothing once the second effect is in (the
        second effect alone is then the final model: ``replaced_by``).
    replaced_by : str or None
    tried : mapping of str to Candidate
        Second effect -> the pair fitted and cross-validated.
    not_tried : mapping of str to NotPaired
        Every other candidate -> why it was not tried with the named one.
    family : tuple of str
        Every candidate that could be paired with the named one: the Holm family of the pairs
        (a pair not tried counts with p = 1).
    significance : float
        The level of the rule a pair is named by (:func:`fit_second_effect`) [-].
    joint : bool
        Stage 7 named nothing and ``first`` is its best explanation (:func:`joint_start`): a
        pair named here names both of its effects.
    joint_level : float or None
        With ``joint``: the level at which a pair must improve on the baseline [-] (stage 7's
        level over the number of candidates it tried alone).
    against_baseline : mapping of str to Comparison
        With ``joint``: second effect -> the pair's out-of-fold Eq. (49) residuals against the
        baseline's (positive: the pair better) [mm + deg]; empty otherwise.
    """

    first: str
    first_label: str
    named: str | None
    tried: Mapping[str, Candidate]
    not_tried: Mapping
    family: tuple
    significance: float
    dropped: str | None = None
    replaced_by: str | None = None
    joint: bool = False
    joint_level: float | None = None
    against_baseline: Mapping = field(default_factory=lambda: MappingProxyType({}))


def _fit_pair(ctx) -> CalibrationResult:
    """A second effect fitted together with the named one, on fold ``k``'s samples.

    Started from the named effect's fit of the same samples. With the standard model: the second
    effect's own procedure (its start scan, then its parameters alone) with the named fit held,
    then every parameter together. With a contact model: the tube parameters refitted with the
    clearance model with the named effect's own parameters in place, the second effect by its own
    strategy (its grid, or its parameters alone from its single fit of the same samples), then
    every effect parameter and the baseline's parameters refitted together with the contact model,
    as a contact candidate alone is (:meth:`ctrplan.discrepancy.fits.fitting.FitContext.refine_contact`); every
    value is fitted with the other effect present.
    """
    setup, options, k, n_jobs = ctx["setup"], ctx["options"], ctx["k"], ctx["n_jobs"]
    robot, settings, fit_data, units = setup.robot, setup.settings, ctx["fit_data"], ctx["units"]
    first, second, model = ctx["first"], ctx["second"], ctx["model"]
    quiet = FitRun(settings=settings, n_jobs=n_jobs, uncertainty=False)
    final = FitRun(settings=settings, n_jobs=n_jobs, uncertainty=k is None, clusters=units)
    f1 = first.cv.fold_fit(k)
    p1 = dict(zip(*f1.all_parameters()))
    entry = REGISTRY[second.effects[0]]
    extra = ctx["extra"]
    if not MODEL_INFO[model].contact:
        own = second.cv.fold_params(k)
        start = np.array([own[n] for n in extra], float)
        if entry.scan is not None:
            start = scan_fit(robot, fit_data, model, p1, extra, entry.scan, run=quiet).values
        alone = calibrate(robot, fit_data, model, extra, fixed=p1, start=FitStart(start),
                          max_evaluations=options.max_evaluations, run=quiet)
        names = tuple(f1.names) + extra
        init = np.concatenate([f1.values, alone.values])
        return calibrate(robot, fit_data, model, names, fixed=f1.fixed, prior=ctx["prior"],
                         start=FitStart(init, warm=True), max_evaluations=options.max_evaluations, run=final)
    budget = options.max_contact_evaluations
    # the baseline parameters the named fit fitted (the robot file's, held by a prior of strength 0, stay held)
    base_names = tuple(n for n in setup.base_names if n in f1.names)
    first_extra = tuple(n for n in f1.names if n not in base_names)
    held = {n: v for n, v in p1.items() if n not in base_names}
    tube = calibrate(robot, fit_data, "clearance", base_names, fixed=held, prior=ctx["prior"],
                     start=FitStart([p1[n] for n in base_names], warm=True), max_evaluations=budget, run=quiet)
    params = {**held, **dict(zip(base_names, tube.values))}
    if entry.fit.pair_grid:
        g = grid_search(robot, fit_data, params, extra, model, grid=grid_spec(options), run=quiet)
        params.update(zip(extra, g.values))
    else:
        own = second.cv.fold_params(k)
        if extra:
            alone = calibrate(robot, fit_data, model, extra, fixed=params,
                              start=FitStart([own[n] for n in extra], warm=True), max_evaluations=budget, run=quiet)
            params.update(zip(extra, alone.values))
    free = base_names + tuple(dict.fromkeys(n for n in (*first_extra, *extra) if n not in base_names))
    if not free:
        return calibrate(robot, fit_data, model, (), fixed=params, run=FitRun(settings=settings, n_jobs=n_jobs))
    fixed = {n: v for n, v in params.items() if n not in free}
    return calibrate(robot, fit_data, model, free, fixed=fixed, prior=ctx["prior"],
                     start=FitStart([params[n] for n in free], warm=True), max_evaluations=budget, run=final)


def fit_second_effect(setup: DiscrepancySetup, split: DataSplit, baseline, contact, naming, options: DiscrepancyOptions,
                      progress: bool = False) -> Combination | None:
    """Stage 8: a second effect fitted together with the named one, and whether either adds to
    the other (nested comparisons in both directions).

    The family: every other candidate that does not contain the named one or lie inside it
    (``Effect.contains``), adds a parameter, and can be fitted without a third effect (Holm over
    this family, fixed before any pair is fitted; a pair not tried counts with p = 1). Tried:
    those whose fit alone lowered the baseline's out-of-fold error on average (one that alone
    makes it worse is not fitted). Each pair is fitted jointly (:func:`_fit_pair`) on the
    development samples and without each fold, cross-validated, and compared with the named
    effect alone (does the second effect add?) and with the second effect alone (does the named
    effect still add?). A pair is named when it improves on the named effect significantly
    (Holm), no fitted value is at its limit, and the named effect still adds to it significantly
    (``options.significance``); among such pairs the one with the lowest out-of-fold error. When
    the best significant pair is not significantly better than its second effect alone, the
    named effect is dropped only when it goes to zero beside the second (each of its jointly
    fitted intervals covers the value at which it is off: :func:`first_vanishes`) and the
    second effect alone is eligible in stage 7; the second effect alone is then the final model.
    Otherwise the named effect alone stays the final model, with a note of why.

    When stage 7 named nothing, the same search starts from its best explanation A when
    :func:`joint_start` allows it (a *joint* search). The rule is then stage 7's: every
    comparison at its level, lowered where the folds are not kept apart as judged from the best
    pair's residual (:func:`joint_search_level`), and a pair is named only when, besides both nested comparisons, its out-of-fold error
    is significantly lower than the baseline's at that level divided by the number of candidates
    stage 7 tried alone (the strictest step of its Holm family: A was chosen after those tests,
    so the pair may not be judged more leniently than any of them). Nothing is dropped: B alone
    is not eligible (stage 7 named nothing).

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    baseline : Baseline
        Stage 3 (its prior is kept in the pair fits; its out-of-fold errors are a joint pair's
        reference).
    contact : CrossValidated or None
        Stage 6a (unused: a pair refits its tube parameters from the named effect's fit).
    naming : Naming
        Stage 7.
    options : DiscrepancyOptions
    progress : bool
        Progress bars of the model evaluations.

    Returns
    -------
    Combination or None
        None when the verdict is ambiguous (which effect is there is still open; a second effect
        on top of either would answer another question), or when no effect is named and
        :func:`joint_start` gives none.
    """
    if naming.verdict == Verdict.AMBIGUOUS:
        return None
    named, joint = naming.named, False
    if not named:
        named = joint_start(naming)
        joint = named is not None
    if not named:
        return None
    robot, data = setup.robot, setup.data
    candidates = naming.candidates
    first = candidates[named]
    first_names = reported_parameters(robot, named, data)
    not_tried, family, pool = {}, [], []
    for e, c in candidates.items():
        if e == named:
            continue
        if contained(e, named):
            not_tried[e] = NotPaired(NotPairedReason.CONTAINS if named in REGISTRY[e].contains
                                     else NotPairedReason.CONTAINED)
            continue
        entry = REGISTRY[e]
        if entry.after is not None and entry.after != named:
            not_tried[e] = NotPaired(NotPairedReason.ON_A_THIRD_EFFECT, after_label=REGISTRY[entry.after].label)
            continue
        if not tuple(n for n in reported_parameters(robot, e, data) if n not in first.params) and entry.fit.adds_parameters:
            not_tried[e] = NotPaired(NotPairedReason.ADDS_NO_PARAMETER)
            continue
        family.append(e)
        if not c.improvement.mean_difference > 0:
            not_tried[e] = NotPaired(NotPairedReason.NO_IMPROVEMENT_ALONE,
                                     mean_difference=float(c.improvement.mean_difference))
            continue
        pool.append(e)
    tried = {}
    for e in pool:
        model = combined_model(named, e)
        extra = tuple(n for n in effect_parameters(robot, e, data) if n not in first.params)
        tag = f"{named}+{e}"
        logger.log(progress_level(), f"second effect: {candidates[e].label} with {first.label} ({model} model) ...")

        def fit_one(k, n_jobs, e=e, model=model, extra=extra):
            fit_data, units = fit_rows(setup, split, k, options.max_contact_samples if MODEL_INFO[model].contact else None)
            return _fit_pair({"setup": setup, "options": options, "k": k, "n_jobs": n_jobs, "fit_data": fit_data,
                              "units": units, "first": first, "second": candidates[e], "model": model, "extra": extra,
                              "prior": baseline.prior})

        cv = cross_validate(setup, split, options, tag, model, fit_one, progress=progress)
        shown_names = first_names + tuple(n for n in reported_parameters(robot, e, data) if n not in first_names)
        notes = () if cv.converged else (FitNote(FitNoteKind.PAIR_NOT_CONVERGED),)
        c = make_candidate(setup, split, baseline, (named, e), f"{first.label} + {candidates[e].label}", cv, shown_names,
                       first, notes)
        tried[e] = replace(c, reverse=compare(split, candidates[e].r, cv.r))
    eligible = {e: bool(c.eligible) for e, c in candidates.items()}
    vanishes = {e: first_vanishes(robot, named, c.parameters) for e, c in tried.items()}
    alpha, joint_level, against = options.significance, None, {}
    if joint:
        alpha = joint_search_level(split, tried, options.significance)
        joint_level = alpha / max(len(naming.decision.family), 1)
        against = {e: compare(split, baseline.r, c.cv.r) for e, c in tried.items()}
    out, second, dropped, replaced, notes = pair_decision(named, tried, family, naming.decision.worse_than, alpha,
                                                          eligible=eligible, vanishes=vanishes,
                                                          joint_level=joint_level, against_baseline=against)
    level = progress_level()
    for e, c in out.items():
        imp, rev = c.improvement, c.reverse
        base = (f"; than the baseline by {100 * against[e].reduction:.0f} %, p = {against[e].p_value:.3g}"
                if e in against else "")
        logger.log(level, f"  {c.label}: " + ", ".join(display_value(n, v, c.units[n]) for n, v in c.shown.items())
                   + f"; error lower than {first.label} alone by {100 * imp.reduction:.0f} %, p = {imp.p_value:.3g}; "
                     f"than {candidates[e].label} alone by {100 * rev.reduction:.0f} %, p = {rev.p_value:.3g}"
                   + base + ("" if c.cv.converged else "; a fit NOT converged"))
    for line in notes:
        logger.log(level, line)
    return Combination(first=named, first_label=first.label, named=second, tried=MappingProxyType(out),
                       not_tried=MappingProxyType(not_tried), family=tuple(family),
                       significance=alpha, dropped=dropped, replaced_by=replaced, joint=joint,
                       joint_level=joint_level, against_baseline=MappingProxyType(against))


def joint_search_level(split: DataSplit, tried: Mapping, significance: float) -> float:
    """The level of a joint search's comparisons: ``significance``, or that divided by
    :data:`~ctrplan.discrepancy.verdict.decision.CORRELATED_FOLDS_SIZE_FACTOR` where the folds
    are not kept apart (:func:`~ctrplan.discrepancy.verdict.decision.folds_kept_apart`) as judged
    from the out-of-fold residual of the pair with the lowest error.

    Stage 7 judges the folds from its best single explanation; when two effects are missing,
    that explanation leaves the other effect's slow residual between the folds, while the pair
    that explains both may leave a residual that falls to the threshold within the buffer. The
    pairs are then the models compared, and the rule is stage 7's, applied to them.

    Parameters
    ----------
    split : DataSplit
    tried : mapping of str to Candidate
        The pairs fitted (their ``cv.oof.residual_base`` [m] at the development samples).
    significance : float
        The level asked for (``DiscrepancyOptions.significance``).

    Returns
    -------
    float
    """
    return comparison_level(split, tried, significance)


def joint_start(naming) -> str | None:
    """The effect a joint search of stage 8 starts from when stage 7 named nothing: its best
    explanation (lowest out-of-fold error), when that lowers the baseline's error on average, no
    value of it sits at its limit, no other candidate explains the data significantly better, the
    baseline's fits converged, and the baseline's residual is not consistent with the sensor
    noise (``NoEffectCase.NOISE``: nothing is left to explain).

    Parameters
    ----------
    naming : Naming
        Stage 7.

    Returns
    -------
    str or None
        The effect, or None (an effect was named, the verdict is ambiguous, or a condition fails).
    """
    d = naming.decision
    if d.verdict != Verdict.NONE or d.best is None or d.no_effect_case == NoEffectCase.NOISE:
        return None
    best = naming.candidates[d.best]
    reasons = {w.reason for w in d.why_not.get(d.best, ())}
    if (not best.improvement.mean_difference > 0 or best.at_bound or d.worse_than.get(d.best)
            or reasons & {NotNamedReason.AT_LIMIT, NotNamedReason.OUTPERFORMED, NotNamedReason.BASELINE_UNFINISHED}):
        return None
    return d.best


def joint_naming(naming, combination: Combination | None):
    """Stage 7's verdict once a joint search of stage 8 named a pair: both effects named (the
    verdict ``NAMED`` with the search's start as the named effect and a ``NAMED_JOINTLY`` note;
    the pair is the final model through ``combination.named``). Any other case: ``naming`` as it
    is.

    Parameters
    ----------
    naming : Naming
        Stage 7.
    combination : Combination or None
        Stage 8.

    Returns
    -------
    Naming
    """
    if combination is None or not combination.joint or not combination.named:
        return naming
    first, second = combination.first, combination.named
    pair = combination.tried[second]
    note = DecisionNote(DecisionNoteKind.NAMED_JOINTLY, first, other=second,
                        comparison=combination.against_baseline.get(second))
    decision = replace(naming.decision, verdict=Verdict.NAMED, named=first, no_effect_case=None,
                       notes=(*naming.decision.notes, note),
                       cautions=tuple(Caution(CautionKind.ATYPICAL_VALUE, label=pair.label, value=b)
                                      for b in pair.atypical))
    return replace(naming, decision=decision)


def first_vanishes(robot, named: str, parameters) -> bool | None:
    """Whether the named effect goes to zero in a pair: every one of its parameters' jointly
    fitted interval covers the value at which the effect is off (``Effect.off_values``: e.g. a
    time offset of 0, the robot file's own stiffness ratio; for a parameter whose effect vanishes
    at its lower bound, an interval reaching down to that bound).

    Parameters
    ----------
    robot : Robot
        The robot file the workflow started from (its off values).
    named : str
        The named effect A.
    parameters : sequence of ParameterEstimate
        The pair's development-fit parameter table (A's and the second effect's) [SI].

    Returns
    -------
    bool or None
        True when every fitted parameter of A has an interval covering its off value, False when
        one interval excludes it, None when an interval is undefined (no finite standard error)
        or A has no fitted parameter in the table.
    """
    effect = REGISTRY[named]
    off = effect.off_values(robot)
    specs = {p.name: p for p in effect.parameters(robot)}
    if effect.after is not None:
        after = REGISTRY[effect.after]
        off = {**after.off_values(robot), **off}
        specs = {**{p.name: p for p in after.parameters(robot)}, **specs}
    rows = [p for p in parameters if p.name in off and p.fitted]
    if not rows:
        return None
    covers = []
    for p in rows:
        if p.ci is None or not all(np.isfinite(p.ci)):
            return None
        low, high = p.ci
        zero = float(off[p.name])
        spec = specs.get(p.name)
        if spec is not None and spec.vanishes_at_lower:
            zero = max(zero, spec.lower)
            covers.append(low <= zero + 1e-12 * max(1.0, abs(spec.upper - spec.lower)))
        else:
            covers.append(low <= zero <= high)
    return bool(all(covers))


def pair_decision(named: str, tried: Mapping, family, worse_than: Mapping, alpha: float, *,
                  eligible: Mapping, vanishes: Mapping, joint_level: float | None = None,
                  against_baseline: Mapping | None = None) -> tuple:
    """Which pair, if any, replaces the named effect (the rule of :func:`fit_second_effect`).

    Parameters
    ----------
    named : str
        The named effect A.
    tried : mapping of str to Candidate
        Second effect B -> the pair fitted jointly, with ``improvement`` (against A alone) and
        ``reverse`` (against B alone) comparisons.
    family : sequence of str
        Every B that could be paired with A (a B not in ``tried`` counts with p = 1).
    worse_than : mapping of str to sequence of str
        Stage 7's ``{candidate: [candidates significantly better]}``.
    alpha : float
    eligible : mapping of str to bool
        Stage 7's eligibility of each candidate alone (significant, not significantly worse than
        another, no value at its limit): B alone replaces A only when B alone may be named.
    vanishes : mapping of str to bool or None
        Second effect B -> :func:`first_vanishes` of A in the pair (None: not known).
    joint_level : float or None
        A joint search (A was not named alone): a pair is significant only when its comparison
        with the baseline (``against_baseline``) has p at most this level and a positive mean
        difference; A is then never dropped. None: A was named.
    against_baseline : mapping of str to Comparison, optional
        With ``joint_level``: B -> the pair's out-of-fold errors against the baseline's (a B
        missing counts as not significant).

    Returns
    -------
    pairs : dict of str to Candidate
        ``tried`` with ``improvement_significant`` (Holm over ``family``; with ``joint_level``
        also significant against the baseline) and ``significant`` (also no value at its limit).
    second : str or None
        B of the named pair: it improves on A significantly and A still improves on B alone.
    dropped, replaced_by : str or None
        A and B when the best significant pair is no better than B alone, A's jointly fitted
        intervals cover the values at which A is off (A goes to zero with B), B alone is eligible
        and not significantly worse than A: B alone is the final model.
    notes : list of str
    """
    verdict = holm({e: (tried[e].improvement.p_value if e in tried else 1.0) for e in family}, alpha) if family else {}
    out = {}
    for e, c in tried.items():
        ok = bool(verdict.get(e) and c.improvement.mean_difference > 0)
        if joint_level is not None:
            base = (against_baseline or {}).get(e)
            ok = ok and base is not None and base.p_value <= joint_level and base.mean_difference > 0
        out[e] = replace(c, improvement_significant=ok, significant=ok and not c.at_bound)
    passing = [e for e, c in out.items() if c.significant]
    best = min(passing, key=lambda e: out[e].mean_error) if passing else None
    second = dropped = replaced = None
    notes = []
    if best is not None:
        rev = out[best].reverse
        if rev.p_value < alpha and rev.mean_difference > 0:
            second = best
            notes.append(f"named combination: {out[best].label}")
        else:
            head = (f"the pair {out[best].label} improves on {named} alone but not significantly on {best} alone "
                    f"(p = {rev.p_value:.3g})")
            zero = vanishes.get(best)
            if joint_level is not None:
                notes.append(f"{head}: neither is named (nothing was named alone)")
            elif named in worse_than.get(best, ()):
                notes.append(f"{head}, which is itself significantly worse than {named}: {named} alone stays the "
                             f"final model")
            elif not eligible.get(best, False):
                notes.append(f"{head}, which alone cannot be named: {named} alone stays the final model")
            elif zero is None:
                notes.append(f"{head}; whether {named} goes to zero beside {best} is not known (an interval of its "
                             f"joint fit is undefined): {named} alone stays the final model")
            elif not zero:
                notes.append(f"{head}; {named}'s jointly fitted value does not go to zero (its interval excludes the "
                             f"value at which it is off): {named} alone stays the final model")
            else:
                dropped, replaced = named, best
                notes.append(f"{head}, and {named}'s jointly fitted interval covers the value at which it is off: "
                             f"{named} goes to zero once {best} is fitted with it, {named} is dropped, {best} alone "
                             f"is the final model")
    return out, second, dropped, replaced, notes
