"""Separability of two candidate effects on the recorded motion, and what the verdict does with
two it cannot tell apart (ctrplan.discrepancy.verdict.separability, verdict.decision.name_effect,
outputs.output.final_candidate, fits.pairs.fit_second_effect).

The toy runs build each candidate's out-of-fold residuals by hand: a hidden field F moves the
tip; the baseline's residual is F plus noise; a candidate that reproduces a field G leaves
F - G plus noise. Two candidates whose fields are multiples of one shape cannot be told apart on
that motion, whichever has the lower error."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctrplan.discrepancy.options import DiscrepancyOptions
from test_discrepancy_history_effects import _split  # a split of development samples only, as GroupKFold deals it
from ctrplan.discrepancy.verdict.separability import (INSEPARABLE_CORRELATION, INSEPARABLE_VIF, displacement_field,
                                                       separability)

K_UNITS, PER_UNIT = 40, 10


def test_correlation_is_the_cosine_of_the_two_fields_and_the_threshold_a_vif_of_ten():
    """rho against the angle between the stacked fields computed independently (the law of
    cosines on their lengths and the length of their difference), sqrt(1 - rho^2) as the share
    one leaves unreproduced, and the threshold at VIF 10 (rho^2 = 0.9). Catches a centred
    correlation (a constant offset is part of a displacement field), a field taken with the
    wrong sign, and a threshold that is not the stated one."""
    rng = np.random.default_rng(11)
    base = rng.normal(0, 1e-3, (300, 3))
    fa, fb = rng.normal(0, 1e-3, (300, 3)), rng.normal(0, 1e-3, (300, 3))
    s = separability("a", "b", base, base - fa, base - fb)
    la, lb, ld = np.linalg.norm(fa), np.linalg.norm(fb), np.linalg.norm(fa - fb)
    cos = (la ** 2 + lb ** 2 - ld ** 2) / (2 * la * lb)
    assert s.correlation == pytest.approx(cos, abs=1e-12)
    assert s.unreproduced == pytest.approx(np.sqrt(1 - cos ** 2), abs=1e-12)
    assert s.rms_first_m == pytest.approx(la / np.sqrt(300), rel=1e-12)
    assert INSEPARABLE_VIF == 10.0 and INSEPARABLE_CORRELATION ** 2 == pytest.approx(0.9, abs=1e-15)
    # a constant offset with a small ripple: centred, the two would look unrelated; uncentred they are one field
    offset = np.tile([1e-3, 0.0, 0.0], (300, 1))
    s = separability("a", "b", base, base - offset - rng.normal(0, 2e-5, (300, 3)), base - 0.7 * offset)
    assert s.correlation > 0.99 and not s.separable
    # opposite signs are as collinear as equal ones
    s = separability("a", "b", base, base - fa, base + 2 * fa)
    assert s.correlation == pytest.approx(-1.0, abs=1e-12) and not s.separable
    assert separability("a", "b", base, base, base - fb).separable          # a zero field is no signature
    assert np.isnan(separability("a", "b", base, base, base - fb).correlation)


def test_separability_skips_failed_samples_and_refuses_mismatched_shapes():
    """Rows with a non-finite residual are left out and counted; shapes that differ raise.
    Catches NaN propagating into rho and silently misaligned candidates."""
    rng = np.random.default_rng(2)
    base = rng.normal(0, 1e-3, (50, 3))
    f = rng.normal(0, 1e-3, (50, 3))
    first = base - f
    first[3] = np.nan
    s = separability("a", "b", base, first, base - 2 * f)
    assert s.n_samples == 49 and s.correlation == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(ValueError, match="shapes"):
        displacement_field(base, base[:10])
    with pytest.raises(ValueError, match="threshold"):
        separability("a", "b", base, base, base, threshold=1.5)
    assert json.loads(json.dumps(s.as_dict()))["separable"] is False


def _errors(residual):
    from ctrplan.discrepancy.fits.evaluation import Errors

    k = residual.shape[0]
    return Errors(rows=np.arange(k), position=np.linalg.norm(residual, axis=1), angle=np.zeros(k),
                  residual_base=residual, tip_base=np.zeros((k, 3)), seconds=0.0)


def _candidate(effect, split, base_residual, residual):
    """A candidate whose out-of-fold residual vectors are ``residual`` [m] (Eq. (49) residual:
    their length in mm), compared with the baseline's."""
    from ctrplan.discrepancy.fits.fitting import Candidate, CrossValidated, compare
    from ctrplan.effects import REGISTRY

    r_base, r = 1e3 * np.linalg.norm(base_residual, axis=1), 1e3 * np.linalg.norm(residual, axis=1)
    cv = CrossValidated(name=effect, model="standard", fit=None, folds=(), params={}, oof=_errors(residual), r=r,
                        fold=split.fold)
    imp = compare(split, r_base, r)
    return Candidate(effects=(effect,), label=REGISTRY[effect].label, cv=cv, shown={}, units={}, parameters=(),
                     atypical=(), at_bound=(), widened=(), n_parameters=1, bic=0.0, delta_bic=0.0, improvement=imp,
                     improvement_position=imp)


def _run(second_shape):
    """Off-plane precurvature reproduces the hidden field F; a registration reproduces 0.8 of it
    (``"same"``) or its x component alone (``"x part"``), so that its error is significantly
    higher than off-plane's and lower than the baseline's. Returns the split, the baseline's
    errors and the candidates."""
    rng = np.random.default_rng(2029)
    units = np.repeat(np.arange(K_UNITS), PER_UNIT)
    k = units.size
    t = np.linspace(0, 6 * np.pi, k)
    F = 3e-3 * np.column_stack([np.cos(t), np.sin(t), 0.3 * np.ones(k)])
    G = F if second_shape == "same" else F * [1.0, 0.0, 0.0] / 0.8     # the x part of F alone: rho about 0.68
    noise = lambda: rng.normal(0, 0.2e-3, (k, 3))  # noqa: E731
    base = F + noise()
    split = _split(units)
    cands = {"offplane": _candidate("offplane", split, base, F - F + noise()),
             "registration": _candidate("registration", split, base, base - 0.8 * G + noise())}
    return split, _errors(base), cands


def _baseline(oof, fits=()):
    """The baseline as the naming rule reads it: its out-of-fold errors and its fits (development
    fit first, then the folds; all converged when none are given)."""
    from types import SimpleNamespace

    from ctrplan.discrepancy.fits.calibrate import CalibrationResult

    done = CalibrationResult("standard", ("k",), np.ones(1), np.ones(1))
    fits = list(fits) or [done] * 11
    return SimpleNamespace(oof=oof, cv=SimpleNamespace(fit=fits[0], folds=tuple(fits[1:])))


def _naming(split, baseline_oof, cands, fits=()):
    from ctrplan.discrepancy.measured.noise import estimate_noise
    from ctrplan.discrepancy.verdict.decision import NoiseCheck, name_effect

    noise = NoiseCheck(noise=estimate_noise(split.data, stated=0.35e-3), rms_m=3e-3, ratio=8.0, test=None)
    return name_effect(split, cands, {}, noise, DiscrepancyOptions(), baseline=_baseline(baseline_oof, fits))


def test_two_effects_with_collinear_fields_are_ambiguous_not_separable_and_neither_is_written():
    """Off-plane precurvature fits best and the registration significantly worse, but both
    improve on the baseline and the registration's fitted field is a multiple of the off-plane
    one: the verdict is ambiguous ("not separable on this motion"), the report says so with the
    correlation and the ``ctrplan design`` command, the run ends with the recalibrated baseline
    (no effect written) and no second effect is fitted on top. Catches the confident single name
    of the sweep's seeds 2015 and 2029 (a rotation of the tracker written for an off-plane
    precurvature because it fitted a little better on a motion that cannot separate them), an
    ambiguous verdict that still writes its first effect, and a pair stage run after it; a rival
    at its parameter's limit (which cannot reach the field) is not counted."""
    from ctrplan.choices import DecisionNoteKind
    from ctrplan.discrepancy.fits.pairs import fit_second_effect
    from ctrplan.discrepancy.outputs import words
    from ctrplan.discrepancy.outputs.output import final_candidate

    split, base, cands = _run("same")
    naming = _naming(split, base, cands)
    d = naming.decision
    assert d.worse_than["registration"] == ("offplane",)        # the errors alone would name off-plane
    assert d.holm["registration"] and d.holm["offplane"]
    assert d.verdict == "ambiguous" and d.inseparable, d
    assert (d.named, d.ambiguous_with) == ("offplane", "registration")
    sep = d.separability["offplane vs registration"]
    assert sep.correlation > INSEPARABLE_CORRELATION and not sep.separable
    assert [n.kind for n in d.notes if n.other == "registration"] == [DecisionNoteKind.NOT_SEPARABLE]
    stored = json.loads(json.dumps(d.as_dict()))
    assert stored == d.as_dict() and stored["inseparable"] is True
    said = [words.note(n, stored, words.labels_of(naming.candidates)) for n in stored["notes"]]
    assert any("not separable on this motion" in s and f"{sep.correlation:.3f}" in s for s in said), said
    assert final_candidate(naming, None) is None
    assert fit_second_effect(None, split, None, None, naming, DiscrepancyOptions(), False) is None
    # a collinear rival stopped at its parameter's limit cannot reach what the data ask: named alone
    from dataclasses import replace

    limit = ("registration_rz (upper bound 3.14 rad, its limit)",)
    cands["registration"] = replace(cands["registration"], at_bound=limit)
    d = _naming(split, base, cands).decision
    assert d.verdict == "named" and d.named == "offplane" and not d.separability, d


def test_two_effects_with_distinct_fields_keep_the_named_effect():
    """The registration reproduces the x component of the field alone, not collinear with the
    off-plane field (rho about 0.68): the motion separates them and off-plane precurvature is
    named alone, its separability from the registration recorded. Catches a rule that calls
    every pair of significant candidates inseparable."""
    from ctrplan.discrepancy.outputs.output import final_candidate

    split, base, cands = _run("x part")
    naming = _naming(split, base, cands)
    d = naming.decision
    assert d.verdict == "named" and d.named == "offplane" and not d.inseparable, d
    sep = d.separability["offplane vs registration"]
    assert 0.5 < sep.correlation < 0.8 and sep.separable
    assert final_candidate(naming, None) is naming.candidates["offplane"]


def test_separability_needs_the_candidates_at_the_baselines_samples():
    """A candidate's out-of-fold errors at other rows than the baseline's raise rather than
    compare misaligned fields."""
    from dataclasses import replace

    split, base, cands = _run("same")
    shifted = replace(base, rows=base.rows + 1)
    with pytest.raises(ValueError, match="other samples"):
        _naming(split, shifted, cands)


def test_nothing_is_named_over_a_baseline_whose_fit_stopped_at_its_budget():
    """The run of the test above, but the baseline's fit of fold 3 stopped at its evaluation
    budget (a fit stopped at a bound is finished): no candidate is eligible, each with the reason
    naming that fit, and the words say so. Catches an improvement over an unfinished baseline
    (the candidate, started from it, finishes the baseline's own fit) taken for an effect."""
    from ctrplan.choices import NotNamedReason
    from ctrplan.discrepancy.fits.calibrate import CalibrationResult
    from ctrplan.discrepancy.outputs import words
    from ctrplan.discrepancy.verdict.decision import unfinished_fits

    split, base, cands = _run("x part")
    done = CalibrationResult("standard", ("k",), np.ones(1), np.ones(1))
    stopped = CalibrationResult("standard", ("k",), np.ones(1), np.ones(1), converged=False)
    at_bound = CalibrationResult("standard", ("k",), np.ones(1), np.ones(1), converged=False,
                                 at_bound=("k (upper bound 5 -, its limit)",))
    fits = [done, done, at_bound, done, stopped] + [done] * 6
    assert unfinished_fits(_baseline(base, fits).cv) == ("fold 3",)
    naming = _naming(split, base, cands, fits)
    d = naming.decision
    assert d.verdict == "none" and not d.eligible, d
    for e in cands:
        assert d.why_not[e][0].reason == NotNamedReason.BASELINE_UNFINISHED and d.why_not[e][0].limits == ("fold 3",)
    stored = json.loads(json.dumps(d.as_dict()))
    text = words.why_not(stored["why_not"]["offplane"], stored["rule"], words.labels_of(naming.candidates))
    assert "stopped at their evaluation budget before converging (fold 3)" in text, text
    assert _naming(split, base, cands, [done, done, at_bound] + [done] * 8).decision.named == "offplane"


def _noise_beside_a_drift(seed):
    """A split of K_UNITS units of PER_UNIT samples and, per sample, white noise (0.4 mm per
    component) and a slow AR(1) drift (phi 0.995, 0.4 mm), with the generator that drew them."""
    from scipy import signal

    rng = np.random.default_rng(seed)
    split = _split(np.repeat(np.arange(K_UNITS), PER_UNIT))
    k = K_UNITS * PER_UNIT
    white = rng.normal(0, 0.4e-3, (k, 3))
    drift = 0.4e-3 * signal.lfilter([np.sqrt(1 - 0.995 ** 2)], [1.0, -0.995], rng.normal(0, 1.0, (k, 3)), axis=0)
    return split, white, drift, rng


def test_a_split_that_cannot_keep_its_folds_apart_names_only_at_a_level_seven_times_smaller():
    """One candidate whose improvement over the baseline has p between 0.01 / 7 and 0.01. Named
    when the buffer reached the autocorrelation threshold, and when it was capped at half a block
    (autocorrelation still 0.5 there) but the candidate's own out-of-fold residual is white (the
    effect was the slow part). Not named when the candidate leaves a slow drift (AR(1), phi 0.995)
    in its residual: the rule then runs at 0.01 / 7 and says why. Catches a verdict unchanged
    where the comparison's rate was measured at up to 7 times its level (residual correlated from
    one block to the next), and a penalty that hits every real effect (whose signature is what
    makes the pilot's residual slow)."""
    from dataclasses import replace

    from ctrplan.choices import BufferReason
    from ctrplan.discrepancy.fits.fitting import compare
    from ctrplan.discrepancy.measured.split import BufferChoice
    from ctrplan.discrepancy.outputs import words
    from ctrplan.discrepancy.verdict.decision import CORRELATED_FOLDS_SIZE_FACTOR, folds_kept_apart

    split, white, drift, rng = _noise_beside_a_drift(77)
    k = white.shape[0]
    offset = np.tile([1e-3, 0.0, 0.0], (k, 1))
    fold_scatter = rng.normal(0, 1.0, 10)[split.fold]

    def case(residual_left):
        """The baseline's residual and the candidate's, the candidate's improvement p between the
        two levels (the smallest gain that puts it there)."""
        for gain in np.linspace(0.0, 0.6, 241):
            cand = (1.0 - gain * (1.0 + 0.5 * fold_scatter))[:, None] * offset + residual_left
            base = offset + residual_left
            p = compare(split, np.linalg.norm(base, axis=1), np.linalg.norm(cand, axis=1)).p_value
            if 0.01 / CORRELATED_FOLDS_SIZE_FACTOR < p < 0.01:
                return base, {"time_offset": _candidate("time_offset", split, base, cand)}
        raise AssertionError("no gain puts p between the levels")

    apart = replace(split, buffer_choice=BufferChoice(5, BufferReason.AUTOCORRELATION_FALLS, lag_one=0.6))
    capped = replace(split, buffer_choice=BufferChoice(5, BufferReason.HALF_A_BLOCK, lag_one=0.9, still=0.5))
    assert folds_kept_apart(apart) and not folds_kept_apart(capped)
    base, cands = case(white)
    assert folds_kept_apart(capped, white)
    assert _naming(apart, _errors(base), cands).decision.named == "time_offset"
    d = _naming(capped, _errors(base), cands).decision
    assert d.named == "time_offset" and d.rule.folds_apart and d.rule.alpha == 0.01, d
    base, cands = case(white + drift)
    assert not folds_kept_apart(capped, white + drift)
    assert _naming(apart, _errors(base), cands).decision.named == "time_offset"
    d = _naming(capped, _errors(base), cands).decision
    assert d.verdict == "none" and d.rule.alpha == pytest.approx(0.01 / 7) and not d.rule.folds_apart, d
    text = words.rule(json.loads(json.dumps(d.as_dict()))["rule"])
    assert "divided by 7" in text and "folds are not kept apart" in text, text


def test_a_registration_far_outside_its_range_on_a_collinear_motion_is_neither_named_nor_written():
    """The sweep's seed 2029 in miniature: a registration rotation of 17 deg about the base axis
    (its whole interval beyond the typical +-10 deg) fits best, the off-plane precurvature that
    made the data fits significantly worse, and their fields are collinear. Today's verdict is
    ambiguous, not separable, the registration first with its caution; the run ends with the
    recalibrated baseline, so the sweep scores it "ambiguous", not "wrong". Catches the harm of a
    value wholly outside its range earning only a caution: the confident name of an effect that
    the motion cannot tell from the truth."""
    from dataclasses import replace

    from ctrplan.discrepancy.fits.estimates import AtypicalValue
    from ctrplan.discrepancy.outputs.output import final_candidate

    split, base, cands = _run("same")
    rot = AtypicalValue(name="registration_rz", value=float(np.deg2rad(17.1)), unit="rad",
                        typical=(float(np.deg2rad(-10)), float(np.deg2rad(10))), typical_text="-10..10 deg",
                        why="a robot-frame data file whose frame is off by more than 10 deg is a tracker-frame file",
                        check="the frame of the data file")
    cands = {"registration": replace(cands["offplane"], effects=("registration",), label="registration",
                                     atypical=(rot,)),
             "offplane": replace(cands["registration"], effects=("offplane",), label="off-plane precurvature")}
    naming = _naming(split, base, cands)
    d = naming.decision
    assert d.worse_than["offplane"] == ("registration",)
    assert d.verdict == "ambiguous" and d.inseparable and (d.named, d.ambiguous_with) == ("registration", "offplane")
    assert [c.value for c in d.cautions] == [rot]
    assert final_candidate(naming, None) is None


def test_a_joint_search_judges_its_folds_from_the_pair_that_explains_most():
    """Stage 7's best single effect leaves a slow residual, so its rule runs at 0.01 / 7; the
    pair fitted in the joint search takes the slow part away (its out-of-fold residual white at
    the capped buffer): the pairs' comparisons hold their level and run at 0.01. When the best
    pair (lowest error) still leaves the drift, they run at 0.01 / 7, whatever a worse pair
    leaves. Catches a joint search judged by a residual of a model it is not comparing."""
    from dataclasses import replace

    from ctrplan.choices import BufferReason
    from ctrplan.discrepancy.fits.pairs import joint_search_level
    from ctrplan.discrepancy.measured.split import BufferChoice
    from ctrplan.discrepancy.verdict.decision import CORRELATED_FOLDS_SIZE_FACTOR

    split, white, drift, rng = _noise_beside_a_drift(5)
    k = white.shape[0]
    base = white + drift + np.tile([1e-3, 0.0, 0.0], (k, 1))
    capped = replace(split, buffer_choice=BufferChoice(5, BufferReason.HALF_A_BLOCK, lag_one=0.9, still=0.5))
    apart = replace(split, buffer_choice=BufferChoice(5, BufferReason.AUTOCORRELATION_FALLS, lag_one=0.6))
    explains_both = _candidate("time_offset", split, base, white)
    leaves_drift = _candidate("backlash", split, base, 1.3 * (white + drift))
    assert explains_both.mean_error < leaves_drift.mean_error
    low = 0.01 / CORRELATED_FOLDS_SIZE_FACTOR
    assert joint_search_level(capped, {"time_offset": explains_both, "backlash": leaves_drift}, 0.01) == 0.01
    assert joint_search_level(capped, {"backlash": leaves_drift}, 0.01) == pytest.approx(low)
    worse_white = _candidate("time_offset", split, base, 3.0 * white)
    assert worse_white.mean_error > leaves_drift.mean_error
    assert joint_search_level(capped, {"time_offset": worse_white, "backlash": leaves_drift}, 0.01) == pytest.approx(low)
    assert joint_search_level(apart, {"backlash": leaves_drift}, 0.01) == 0.01
    assert joint_search_level(capped, {}, 0.01) == pytest.approx(low)
