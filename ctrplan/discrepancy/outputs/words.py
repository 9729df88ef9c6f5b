"""The verdict's reasons, notes, cautions and rule in words, for the log and the report.

The verdict stage records kinds and numbers (:mod:`~ctrplan.discrepancy.verdict.reasons`); these
functions read their stored form (``results.json["decision"]``, ``results.json["cautions"]``,
``results.json["noise"]``) and write the sentences: millimetres and degrees, p values to two or
three digits. A label is a candidate's ``label`` in ``results.json["candidates"]``
(:func:`labels_of`); an effect without one is shown by its name. An entry that is already a
sentence (in a ``results.json`` from an earlier ctrplan, which stored words) is returned as it is.
"""

from __future__ import annotations

import logging
from typing import Mapping

import numpy as np

from ...choices import (BlocksKept, BufferReason, CautionKind, DecisionNoteKind, FitNoteKind, NoEffectCase,
                        NotNamedReason, NotPairedReason, SplitUnit)
from ..fits.estimates import display_value
from ..measured.noise import MIN_LAG_PAIRS
from ..options import MIN_REST_PAIRS
from .logtext import figure

__all__ = ["labels_of", "why_not", "rule", "note", "separated_by", "caution", "range_text", "no_effect",
           "verdict_lines", "split_text", "buffer_text", "noise_text", "envelope_text",
           "pair_rule", "not_paired", "fit_note"]

#: Why the best explanation is not named, when the stored decision gives no reason.
NOT_SIGNIFICANT_TEXT = "its improvement is not significant"


def labels_of(candidates: Mapping) -> dict:
    """Effect -> report label, from ``results.json["candidates"]`` (or any mapping of effect to a
    dict with ``"label"``, or to an object with ``.label``)."""
    out = {}
    for e, c in (candidates or {}).items():
        label = c.get("label") if isinstance(c, Mapping) else getattr(c, "label", None)
        out[e] = label or str(e)
    return out


def _label(labels: Mapping, effect) -> str:
    return labels.get(effect) or str(effect)


def why_not(reasons, rule_levels: Mapping, labels: Mapping) -> str:
    """Why a candidate may not be named, one clause per reason, joined by "; ".

    Parameters
    ----------
    reasons : sequence of dict
        ``results.json["decision"]["why_not"][effect]`` (:class:`~ctrplan.discrepancy.verdict.reasons.WhyNot`).
    rule_levels : dict
        ``results.json["decision"]["rule"]``: the Holm family's size and level.
    labels : mapping of str to str

    Returns
    -------
    str
    """
    out = []
    for r in reasons:
        if isinstance(r, str):
            out.append(r)
            continue
        kind = NotNamedReason(r["reason"])
        if kind == NotNamedReason.NOT_SIGNIFICANT:
            out.append(f"its improvement over the baseline is not significant (p = {figure(r.get('p_value'), '.3g')}, "
                       f"Holm over {rule_levels['n_candidates']} candidates at "
                       f"{figure(rule_levels.get('level', rule_levels['significance']), '.3g')})")
        elif kind == NotNamedReason.OUTPERFORMED:
            out.append("its out-of-fold error is significantly higher than "
                       + ", ".join(f"{_label(labels, d)}'s (p = {figure(p, '.2g')})"
                                   for d, p in r["outperformed_by"].items()))
        elif kind == NotNamedReason.BASELINE_UNFINISHED:
            out.append("the baseline's fits it is compared with stopped at their evaluation budget before "
                       "converging (" + ", ".join(r["limits"]) + "): an improvement over an unfinished fit is no "
                       "evidence of a missing effect")
        else:
            out.append("at its limit, not converged: " + "; ".join(r["limits"]))
    return "; ".join(out)


def rule(levels: Mapping) -> str:
    """The naming rule with its levels (``results.json["decision"]["rule"]``)."""
    if isinstance(levels, str):
        return levels
    alpha = levels.get("level", levels["significance"])
    apart = ("" if levels.get("folds_apart", True) else
             f"; every level is the significance {levels['significance']} divided by "
             f"{levels['significance'] / alpha:.0f} because the buffer could not reach the autocorrelation threshold "
             f"and the best candidate's residual stays correlated beyond it: the folds are not kept apart, where the "
             f"comparison's rate was measured at up to that many times its level")
    level = figure(alpha, ".3g")
    return (f"out-of-fold improvement over the baseline significant at {level} (corrected resampled t test of the "
            f"log ratios over {levels['n_folds']} folds, Holm over the {levels['n_candidates']} candidates tried), no "
            f"other candidate significantly better (one-sided at {level}), no value at its limit, the baseline's fits "
            f"finished; the lowest out-of-fold error wins, unless it contains another such candidate on which it does "
            f"not improve significantly (then the simpler one); ambiguous when another such candidate remains, or "
            f"when a candidate significant over the baseline moves the tip along a collinear field (not separable "
            f"on this motion){apart}")


def separated_by(decision: Mapping, labels: Mapping) -> str | None:
    """What data would tell an ambiguous pair apart (None when the verdict is not ambiguous)."""
    texts = decision.get("separated_by")
    if texts is None or isinstance(texts, str):
        return texts
    parts = [f"{_label(labels, e)}: {t}" for e, t in texts.items()]
    return "; ".join(parts) if parts else "more data of the kinds of motion where they differ"


def note(entry: Mapping, decision: Mapping, labels: Mapping) -> str:
    """A note of the naming rule (an entry of ``results.json["decision"]["notes"]``) in words.

    Parameters
    ----------
    entry : dict
        :class:`~ctrplan.discrepancy.verdict.reasons.DecisionNote` as stored.
    decision : dict
        ``results.json["decision"]`` (its ``why_not``, ``rule`` and ``separated_by``).
    labels : mapping of str to str

    Returns
    -------
    str
    """
    if isinstance(entry, str):
        return entry
    kind = DecisionNoteKind(entry["kind"])
    effect = entry["effect"]
    first, other = _label(labels, effect), _label(labels, entry.get("other"))
    cmp = entry.get("comparison") or {}
    reasons = why_not((decision.get("why_not") or {}).get(effect, ()), decision["rule"], labels)
    if kind == DecisionNoteKind.SIGNIFICANT_NOT_NAMED:
        return f"{first} improves on the baseline significantly but is not named: {reasons}"
    if kind == DecisionNoteKind.BEST_NOT_NAMED:
        return f"the lowest out-of-fold error is {first}'s, which cannot be named: {reasons}"
    if kind == DecisionNoteKind.NAMED_JOINTLY:
        return (f"{first} and {other} are named together: neither improves on the baseline significantly alone, "
                f"the pair does (out-of-fold Eq. (49) error lower by {figure(cmp.get('reduction'), '.0f', 100)} %, "
                f"p = {figure(cmp.get('p_value'), '.2g')} over {cmp.get('n_folds')} folds), and each adds to the "
                f"other significantly")
    if kind == DecisionNoteKind.SIMPLER_NAMED:
        return (f"{first} contains {other} and does not improve on it significantly (out-of-fold Eq. (49) error "
                f"lower by {figure(cmp.get('reduction'), '.0f', 100)} %, p = {figure(cmp.get('p_value'), '.2g')}): "
                f"the simpler {other} is named")
    lo, hi = cmp.get("reduction_ci") or (None, None)
    errors = (f"out-of-fold Eq. (49) error of the first lower by {figure(cmp.get('reduction'), '.0f', 100)} %, "
              f"{figure(lo, '.0f', 100)}..{figure(hi, '.0f', 100)} %, p = {figure(cmp.get('p_value'), '.2g')} over "
              f"{cmp.get('n_folds')} folds")
    if kind == DecisionNoteKind.NOT_SEPARABLE:
        sep = (decision.get("separability") or {}).get(f"{effect} vs {entry.get('other')}") or {}
        return (f"ambiguous: {first} and {other} are not separable on this motion: their fitted tip displacement "
                f"fields correlate at {figure(sep.get('correlation'), '.3f')} (not separable at "
                f"{figure(sep.get('threshold'), '.3f')} or more; {figure(sep.get('unreproduced'), '.0f', 100)} % of "
                f"either left unreproduced by the other), so whichever fits better ({errors}) is not evidence of "
                f"which is there; data that would separate them: {separated_by(decision, labels)}")
    return (f"ambiguous: {first} and {other} explain the data equally well within their uncertainty ({errors}); data "
            f"that would separate them: {separated_by(decision, labels)}")


def range_text(typical, unit: str) -> str:
    """A typical range (low, high) [unit] for a report (rad as deg)."""
    lo, hi = typical
    if unit == "rad":
        return f"{np.rad2deg(lo):.3g}..{np.rad2deg(hi):.3g} deg"
    return f"{lo:.3g}..{hi:.3g}" + ("" if unit == "-" else f" {unit}")


def caution(entry: Mapping) -> str:
    """A caution (an entry of ``results.json["decision"]["cautions"]`` or ``results.json["cautions"]``,
    :class:`~ctrplan.discrepancy.verdict.reasons.Caution` as stored) in words: the value, the
    range with its source and what to check; the maximum's rise in mm; a baseline parameter with its
    change from the robot file."""
    if isinstance(entry, str):
        return entry
    kind = CautionKind(entry["kind"])
    if kind == CautionKind.ATYPICAL_VALUE:
        b = entry["value"]
        lo, hi = b["typical"]
        side = "more" if b["value"] > hi else "less"
        check = f": check {b['check']}" if b.get("check") else ""
        return (f"{entry['label']}: {display_value(b['name'], b['value'], b['unit'])}, {side} than its typical "
                f"{range_text(b['typical'], b['unit'])} ({b['why']}){check}")
    if kind == CautionKind.MAXIMUM_RISES:
        return (f"the test split's maximum tip error rises from {figure(entry['before_m'], '.2f', 1e3)} to "
                f"{figure(entry['after_m'], '.2f', 1e3)} mm while the mean falls: the added effect makes some samples "
                f"worse")
    r = entry["parameter"]
    change = "" if r.get("relative_change") is None else f", {100 * r['relative_change']:+.0f} % from the robot file"
    return (f"baseline {display_value(r['name'], r['value'], r['unit'])}{change}"
            + (": at its bound" if r.get("at_bound") else "") + f"; typical: {r.get('typical_source')}")


def no_effect(decision: Mapping, noise: Mapping, candidates: Mapping) -> str:
    """Why no effect was named: the noise test's case with its figures, and the best explanation
    with why it is not named.

    Parameters
    ----------
    decision : dict
        ``results.json["decision"]`` (``no_effect_case``, ``best``, ``why_not``, ``rule``).
    noise : dict
        ``results.json["noise"]`` (mm; its ``test`` and the estimate, said by :func:`noise_text`).
    candidates : dict
        ``results.json["candidates"]`` (labels and out-of-fold means [mm]).

    Returns
    -------
    str
        One sentence (mm in the text).
    """
    labels = labels_of(candidates)
    case = NoEffectCase(decision.get("no_effect_case") or NoEffectCase.UNKNOWN)
    description = noise_text(noise.get("noise") or {})
    test = noise.get("test") or {}
    rms = figure(noise.get("rms_mm"), ".3f")
    best = decision.get("best")
    best_text = ""
    if best and best in (candidates or {}):
        mean = ((candidates[best].get("out_of_fold") or {}).get("position_mean_mm"))
        reasons = (decision.get("why_not") or {}).get(best)
        best_text = (f"; the best explanation is {_label(labels, best)} (out-of-fold mean {figure(mean, '.3f')} mm), "
                     f"not named: " + (why_not(reasons, decision["rule"], labels) if reasons else NOT_SIGNIFICANT_TEXT))
    stat, threshold, alpha = figure(test.get("statistic"), ".3g"), figure(test.get("threshold"), ".3g"), test.get(
        "false_alarm_rate")
    if case == NoEffectCase.NOISE:
        return (f"no candidate is eligible, and the out-of-fold residual of the calibrated baseline (rms {rms} mm) is "
                f"consistent with the sensor noise ({description}; F = {stat} <= {threshold}, false-alarm rate "
                f"{figure(alpha, 'g')})" + best_text)
    if case == NoEffectCase.INCONCLUSIVE:
        return (f"no candidate is eligible; the out-of-fold residual of the calibrated baseline (rms {rms} "
                f"mm) exceeds the sensor noise (F = {stat} > {threshold}), but that noise is only a lower bound "
                f"({description}): the noise test is inconclusive, no evidence that the model misses something"
                + best_text)
    if case == NoEffectCase.UNEXPLAINED:
        inflation = test.get("inflation")
        added = figure(None if inflation is None else inflation - 1, ".0f", 100)
        ratio = figure(noise.get("ratio"), ".1f")
        return (f"the out-of-fold residual of the calibrated baseline (rms {rms} mm, {ratio} times the sensor noise: "
                f"{description}) is NOT consistent with noise (F = {stat} > {threshold} at false-alarm rate "
                f"{figure(alpha, 'g')}, after allowing for the {added} % a fitted model adds): the model misses "
                f"something that no candidate explains" + best_text)
    return (f"no candidate is eligible; whether the out-of-fold residual (rms {rms} mm) is noise cannot be said: "
            f"the sensor noise is {description}" + best_text)


def pair_rule(combination: Mapping) -> str:
    """The rule a second effect is named by (``results.json["combination"]``: its ``rule`` and
    ``first_label``); for a joint search (``rule["joint_level"]`` given: nothing was named alone)
    also the level at which the pair must improve on the baseline."""
    levels, first = combination["rule"], combination["first_label"]
    if isinstance(levels, str):
        return levels
    alpha = levels["significance"]
    rule = (f"out-of-fold Eq. (49) improvement over {first} alone significant at {alpha:.3g} (corrected resampled t "
            f"test of the log ratios over the folds, Holm over the family of pairs), no value at its limit, and "
            f"{first} still improving on the second effect alone at {alpha:.3g}")
    if levels.get("joint_level") is None:
        return rule
    return (f"{first} is the best explanation, named nothing alone; a pair names both of its effects when its "
            f"improvement over the baseline is significant at {levels['joint_level']:.3g} (the naming rule's level "
            f"over the candidates tried alone), its {rule}")


def not_paired(entry, first_label: str) -> str:
    """Why a candidate was not fitted with the named effect (an entry of
    ``results.json["combination"]["not_tried"]``; ``first_label`` the named effect's label)."""
    if isinstance(entry, str):
        return entry
    kind = NotPairedReason(entry["reason"])
    if kind == NotPairedReason.CONTAINS:
        return f"it contains {first_label}"
    if kind == NotPairedReason.CONTAINED:
        return f"it is contained in {first_label}"
    if kind == NotPairedReason.ON_A_THIRD_EFFECT:
        return f"it is fitted on top of {entry['after_label']}, a third effect"
    if kind == NotPairedReason.ADDS_NO_PARAMETER:
        return f"it adds no parameter to {first_label}"
    return (f"alone it does not lower the baseline's out-of-fold error (mean difference "
            f"{figure(entry.get('mean_difference'), '.3g')} mm + deg): counted in the family, not fitted")


def fit_note(entry) -> str:
    """What a candidate's fits say about themselves (an entry of
    ``results.json["candidates"][effect]["fit_notes"]``, :class:`~ctrplan.discrepancy.verdict.reasons.FitNote`
    as stored), costs to four digits, means in mm."""
    if isinstance(entry, str):
        return entry
    kind = FitNoteKind(entry["kind"])
    if kind == FitNoteKind.CONTACT_REFIT_NOT_CONVERGED:
        return (f"the clearance-model refit of the tube parameters it shares did not converge (stopped at the budget "
                f"of {entry['max_evaluations']} evaluations): the candidate may be underrated")
    if kind == FitNoteKind.NOT_CONVERGED:
        fits = (["the development fit"] if entry.get("development") else []) + [f"fold {k}" for k in entry["folds"]]
        return f"its fit did not converge (stopped at the evaluation budget): {', '.join(fits)}"
    if kind == FitNoteKind.AT_LIMIT:
        return f"at its limit, not converged: {'; '.join(entry['limits'])}"
    if kind == FitNoteKind.PAIR_NOT_CONVERGED:
        return "a fit did not converge or sits at its limit"
    cost = f"cost {figure(entry['cost'], '.4g')} against {figure(entry['baseline_cost'], '.4g')}"
    if kind == FitNoteKind.WORSE_THAN_CONTAINED_BASELINE:
        return (f"it fits the calibration data worse than the baseline ({cost}) although it contains the baseline: "
                f"the fit failed")
    if kind == FitNoteKind.WORSE_THAN_STANDARD_BASELINE:
        return (f"it fits the calibration data worse than the standard baseline ({cost}): the {entry['model']} model "
                f"with the shared refitted tube parameters does not reach the standard model's fit")
    return (f"it fits the calibration data better ({cost}) but the held-out folds worse (mean "
            f"{figure(entry['mean_m'], '.3f', 1e3)} against {figure(entry['baseline_mean_m'], '.3f', 1e3)} mm): its "
            f"parameters absorb a pattern of the calibration samples that does not hold elsewhere (overfitting)")


def verdict_lines(results: Mapping) -> list:
    """The verdict for the log, from a run's ``results.json`` form: the named effect (or pair) or
    why none is, the cautions and the notes.

    Returns
    -------
    list of (int, str)
        Each line with its logging level: ``logging.WARNING`` for a caution, ``logging.INFO``
        for the rest.
    """
    d = results["decision"]
    labels = labels_of(results.get("candidates"))
    if d["verdict"] == "none":
        text = no_effect(d, results.get("noise") or {}, results.get("candidates"))
        lines = [(logging.INFO, "no effect named: " + text)]
    else:
        lines = [(logging.INFO, f"{'ambiguous' if d['verdict'] == 'ambiguous' else 'named effect'}: "
                          f"{_label(labels, d['named'])}"
                  + (f" or {_label(labels, d['ambiguous_with'])}" if d.get("ambiguous_with") else ""))]
        lines += [(logging.WARNING, f"  caution: {caution(c)}") for c in d.get("cautions") or ()]
    lines += [(logging.INFO, f"  {note(n, d, labels)}") for n in d.get("notes") or ()]
    return lines


def _samples(n: int) -> str:
    return f"{n} calibration sample{'s' if n != 1 else ''}"


def split_text(split: Mapping) -> str:
    """The units, the test split and the folds, and why so many, from a split's stored form
    (:meth:`~ctrplan.discrepancy.measured.split.DataSplit.as_dict`; a results file from an
    earlier ctrplan, which stored the sentence as ``how``, gives it back as stored)."""
    if "rule" not in split:
        return str(split.get("how", ""))
    r = split["rule"]
    kind, block = r["unit_kind"], r["block_samples"]
    why_blocks = ("" if kind != SplitUnit.TIME_BLOCK else
                  " (as asked)" if r["blocks_asked"] else
                  f" ({r['max_blocks']} at most, of at least {r['min_block_samples']} samples)")
    why_test = (f"at least {r['min_test_units']} units, more than {r['test_fraction']:.0%}" if r["test_at_minimum"]
                else f"{r['test_fraction']:.0%} of the units")
    why_folds = ("as asked" if r["folds_asked"] else
                 f"{r['max_folds']} at most, with at least {r['min_units_per_fold']} development units each")
    recut = ("" if r["recut_block"] is None else
             f"; the stretches between test blocks re-cut into blocks of at least {r['recut_block']} samples, a "
             f"shorter stretch whole")
    return (f"{r['n_units']} {kind}s" + (f" of {block} samples" if block else "") + why_blocks
            + f"; test split: {r['n_test_units']} units ({r['n_test_samples']} samples; {why_test}) held back before "
              f"any fit; development: {r['n_development_units']} units ({r['n_development_samples']} samples{recut}) "
              f"in {r['n_folds']} cross-validation folds (GroupKFold; {why_folds})"
            + (" (the file's 'subset' column is not used for the split)" if r["subset_ignored"] else ""))


def buffer_text(split: Mapping) -> str:
    """How long the buffer is and why, from a split's stored form (``buffer``:
    :meth:`~ctrplan.discrepancy.measured.split.BufferChoice.as_dict`; a results file from an
    earlier ctrplan gives back its ``buffer_note``)."""
    b = split.get("buffer")
    if not isinstance(b, Mapping):
        return str(split.get("buffer_note", "not yet chosen"))
    n, reason = b["samples"], b["reason"]
    if reason == BufferReason.CONFIGURATION_GROUPS:
        return "no buffer: the units are configuration groups, not blocks of a continuous motion"
    lag_one = f"(lag 1: {figure(b['lag_one'], '.2f')})"
    if reason == BufferReason.AUTOCORRELATION_FALLS:
        text = f"{n} samples: the residuals' autocorrelation falls to {b['threshold']:g} at lag {n + 1} {lag_one}"
    else:
        text = (f"{n} samples (half a block, the most allowed): the residuals' autocorrelation is still "
                f"{figure(b['still'], '.2f')} at lag {n + 1} {lag_one}")
    if b.get("lengthened_to") is not None:
        text += (f"; development blocks lengthened from {b['lengthened_from']} to at least {b['lengthened_to']} "
                 f"samples")
        text += (" so that it is at most half a block" if reason == BufferReason.AUTOCORRELATION_FALLS else
                 f", the longest within the stretches between test blocks that leave {b['min_units']} development "
                 f"units and {_samples(b['min_fit_samples'])} in every fit")
    elif b.get("kept") == BlocksKept.ASKED:
        text += " (blocks as asked, not lengthened)"
    elif b.get("kept") == BlocksKept.MINIMUMS:
        text += (f" (longer blocks would cut across test blocks, or leave fewer than {b['min_units']} development "
                 f"units or {_samples(b['min_fit_samples'])} in a fit)")
    return text


def noise_text(noise: Mapping) -> str:
    """The sensor noise estimate in one line (mm), from its stored form
    (:meth:`~ctrplan.discrepancy.measured.noise.NoiseEstimate.as_dict`; a results file from an
    earlier ctrplan, which stored the line as ``description``, gives it back as stored)."""
    if noise.get("description") is not None:
        return str(noise["description"])
    source, rms, n_pairs = noise.get("source"), noise.get("position_rms_m"), noise.get("n_pairs")
    if source == "stated":
        why = (f"{n_pairs} pairs of consecutive samples at rest that show no variation (tracker resolution)"
               if noise.get("no_variation") else
               f"{n_pairs} pairs of consecutive samples at rest, fewer than {MIN_REST_PAIRS}")
        return f"{figure(rms, '.3f', 1e3)} mm rms as stated for the data (it has {why})"
    if source == "repeated configurations":
        return (f"at most {figure(rms, '.3f', 1e3)} mm rms: spread of {n_pairs} rows at repeated configurations "
                f"(includes any direction-dependent effect)")
    if source != "rests":
        return ("unknown: not stated (--noise-position-mm) and the data has neither rests nor repeated "
                "configurations")
    fitted = noise.get("fitted_lags") or 0
    h_fit = int(noise["lags"][fitted - 1]) if fitted else 0
    span = "lag 1" if h_fit == 1 else f"lags 1-{h_fit}"
    where = f"{noise.get('n_runs')} rests ({n_pairs} pairs of consecutive samples, {span})"
    lag1, tau = noise.get("lag1_correlation"), noise.get("correlation_length_samples")
    if noise.get("correlation_seen"):
        corr = ("white (no correlation in time seen)" if not tau else
                f"lag-1 correlation {figure(lag1, '.2f')}, correlation length {figure(tau, '.1f')} samples, nugget "
                f"{figure(noise.get('nugget_share'), '.0f', 100)} %")
        text = (f"{figure(rms, '.3f', 1e3)} mm rms from {where}; {corr}; {figure(noise.get('dof'), '.0f')} degrees "
                f"of freedom")
    else:
        why = (f"only {span} {'has' if h_fit == 1 else 'have'} {MIN_LAG_PAIRS} or more pairs, too few to see a "
               f"correlation in time" if lag1 is None else
               f"the correlation (lag-1 {figure(lag1, '.2f')}, length {figure(tau, '.0f')} samples) outlasts the rests")
        text = (f"at least {figure(rms, '.3f', 1e3)} mm rms from {where}: {why}; the noise of a sensor correlated in "
                f"time is larger than what such rests show")
    settle = noise.get("settled_samples") or 0
    if settle:
        text += (f"; the first {settle} sample{'s' if settle > 1 else ''} of every rest left out (the tip still "
                 f"moved there)")
    if noise.get("stated_m") is not None:
        text += f"; the data's source states {figure(noise['stated_m'], '.3f', 1e3)} mm"
    return text


def envelope_text(envelope: Mapping, noise: Mapping) -> str:
    """How the friction envelope's coverage was measured, from its stored form (``results.json
    ["prediction"]["envelopes"]``) and the noise estimate's (:func:`noise_text`); an earlier
    results file's ``description`` is given back as stored."""
    if envelope.get("description") is not None:
        return str(envelope["description"])
    return (f"{envelope['n_samples']} evenly spaced held-out samples; convex hull of the {envelope['n_solutions']} "
            f"bounding friction solutions (all eta, no release); margin {envelope['noise_factor']} x the noise rms "
            f"({noise_text(noise)})")
