"""Stages 5 and 7 of the discrepancy workflow: the sensor noise, and what is named.

**Naming rule.** A candidate is *eligible* when its cross-validated improvement over the
baseline (out-of-fold Eq. (49) residuals, compared unit by unit:
:func:`~ctrplan.discrepancy.statistics.paired_improvement`) is significant at the family-wise
level ``options.significance`` (Holm over the candidates), its fitted values are typical, and
none of its fits ends at an optimizer bound, a grid's edge or a scan's end. The eligible
candidate with the largest improvement is named, unless the next best candidate (typical, not
at a bound, improving on average) is within its uncertainty: the interval of the difference of
their out-of-fold errors over units covers 0. Then the verdict is **ambiguous**: both are
listed, best first, with what data would separate them (``Effect.separated_by``).

**Noise.** The sensor noise comes from the data's rests (consecutive samples at identical
joints) when it has enough, else from what its source states; the baseline's out-of-fold
residual is "consistent with noise" by an F test that allows for the fitted parameters and for
the noise estimate's own uncertainty (:func:`~ctrplan.discrepancy.statistics.noise_test`), with
false-alarm rate ``options.significance``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ..effects import REGISTRY
from .data import MeasuredData
from .fitting import Candidate, candidate_reports, display_value
from .options import CONFIDENCE, MIN_REST_PAIRS, DiscrepancyOptions
from .split import DataSplit
from .statistics import holm, noise_test, paired_improvement

__all__ = ["NoiseCheck", "Naming", "estimate_noise", "check_noise", "name_effect", "cautions", "no_effect_sentence",
           "range_text", "VERDICTS"]

#: What a run concludes: one effect (or a pair) named, two candidates the data cannot tell apart,
#: or none.
VERDICTS = ("named", "ambiguous", "none")
#: Efficiency of the median-based noise estimate relative to the mean square (chi-distributed
#: distances of 3-D Gaussian noise): its degrees of freedom are counted at this fraction.
MEDIAN_EFFICIENCY = 0.6


@dataclass(frozen=True, eq=False)
class NoiseCheck:
    """Stage 5: is the baseline's out-of-fold residual more than the sensor noise?

    Attributes
    ----------
    noise : dict
        :func:`estimate_noise` (``position_rms_m`` [m] or None, ``source``, ``n``, ``dof``,
        ``description``).
    rms_m : float
        rms of the baseline's out-of-fold position errors [m] (NaN without a finite one).
    ratio : float or None
        ``rms_m`` over the noise rms; None when the noise is unknown.
    test : dict or None
        :func:`~ctrplan.discrepancy.statistics.noise_test`; None when the noise is unknown.
    """

    noise: dict
    rms_m: float
    ratio: float | None
    test: dict | None

    @property
    def consistent(self) -> bool | None:
        """The residual is consistent with the noise (None: the noise is unknown)."""
        return None if self.test is None else bool(self.test["consistent"])

    def as_dict(self) -> dict:
        """The report's form (``results.json["noise"]``; mm)."""
        sigma = self.noise["position_rms_m"]
        return {"rms_mm": self.rms_m * 1e3, "noise_rms_mm": None if sigma is None else sigma * 1e3,
                "ratio": self.ratio, "consistent": self.consistent, "test": self.test, "noise": self.noise}


@dataclass(frozen=True, eq=False)
class Naming:
    """Stage 7: the verdict.

    Attributes
    ----------
    candidates : mapping of str to Candidate
        Every tried candidate with the naming rule's verdicts.
    decision : dict
        ``verdict`` (:data:`VERDICTS`), ``named`` (the best eligible effect or None),
        ``ambiguous_with`` (the second of an ambiguous pair or None), ``eligible``, ``holm``,
        ``separated_by`` (what data would tell an ambiguous pair apart), ``notes``, and
        ``no_effect_case`` (``"noise"``, ``"unexplained"``, ``"unknown"``) when none is named.
    """

    candidates: Mapping[str, Candidate]
    decision: dict

    @property
    def named(self) -> str | None:
        """The best eligible effect (first of an ambiguous pair), or None."""
        return self.decision["named"]

    @property
    def verdict(self) -> str:
        return self.decision["verdict"]


def _rests(data: MeasuredData) -> np.ndarray:
    """Tip differences (R, 3) of consecutive samples of one motion at identical joints [m]."""
    joints = np.concatenate([data.alpha, data.beta], axis=1)
    same = (np.all(np.abs(np.diff(joints, axis=0)) <= 1e-12, axis=1) & (np.diff(data.sequence) == 0))
    d = np.diff(data.tip, axis=0)[same]
    return d[np.all(np.isfinite(d), axis=1)]


def estimate_noise(data: MeasuredData, stated: float | None = None) -> dict:
    """The sensor's rms tip position noise: from the data's rests, else as stated, else from
    repeated configurations.

    From rests (consecutive samples of a motion at identical joints: their tip difference is
    noise alone; robust, from the median of |d|, Maxwell-distributed for Gaussian noise), when
    there are at least :data:`~ctrplan.discrepancy.options.MIN_REST_PAIRS`; else the stated
    value; else from configurations measured more than once (spread about the configuration
    mean; an upper bound, since it includes whatever else differs between the visits).

    Parameters
    ----------
    data : MeasuredData
    stated : float, optional
        The noise rms as the data's source states it [m].

    Returns
    -------
    dict
        ``position_rms_m`` (None when unknown), ``source`` ("rests", "stated", "repeated
        configurations", None), ``n`` (pairs or rows used), ``dof`` (degrees of freedom of the
        variance estimate; None when stated), ``upper_bound`` (bool), ``stated_m`` (the stated
        value, if any), ``description``.
    """
    d = np.linalg.norm(_rests(data), axis=1)
    stated_text = "" if stated is None else f" (the data's source states {stated * 1e3:.3f} mm)"
    if d.size >= MIN_REST_PAIRS:
        # |d| of two samples with per-component sigma s: Maxwell with scale sqrt(2) s, median
        # 1.5382 sqrt(2) s; position rms = sqrt(3) s
        rms = float(np.median(d) / (1.5382 * np.sqrt(2.0)) * np.sqrt(3.0))
        return {"position_rms_m": rms, "source": "rests", "n": int(d.size), "dof": MEDIAN_EFFICIENCY * 3 * d.size,
                "upper_bound": False, "stated_m": stated,
                "description": f"{rms * 1e3:.3f} mm rms from {d.size} pairs of consecutive samples at rest{stated_text}"}
    if stated is not None:
        return {"position_rms_m": float(stated), "source": "stated", "n": 0, "dof": None, "upper_bound": False,
                "stated_m": stated, "description": f"{stated * 1e3:.3f} mm rms as stated for the data (it has "
                                                   f"{d.size} rest pairs, fewer than {MIN_REST_PAIRS})"}
    _, g, counts = np.unique(data.config_id, return_inverse=True, return_counts=True)
    g = g.ravel()
    rep = counts[g] > 1
    if rep.sum() >= 2 * MIN_REST_PAIRS:
        n_g = int(g.max()) + 1
        mean = np.stack([np.bincount(g, data.tip[:, j], n_g) for j in range(3)], axis=1) / counts[:, None]
        dev = (data.tip - mean[g])[rep]
        dof = int(rep.sum() - np.count_nonzero(counts > 1))
        rms = float(np.sqrt(np.sum(dev * dev) / max(dof, 1)))
        return {"position_rms_m": rms, "source": "repeated configurations", "n": int(rep.sum()), "dof": 3.0 * dof,
                "upper_bound": True, "stated_m": None,
                "description": f"at most {rms * 1e3:.3f} mm rms: spread of {int(rep.sum())} rows at repeated "
                               f"configurations (includes any direction-dependent effect)"}
    return {"position_rms_m": None, "source": None, "n": 0, "dof": None, "upper_bound": False, "stated_m": None,
            "description": "unknown: not stated (--noise-position-mm) and the data has neither rests nor "
                           "repeated configurations"}


def check_noise(setup, split: DataSplit, baseline, options: DiscrepancyOptions, echo=print) -> NoiseCheck:
    """Stage 5: the sensor noise (:func:`estimate_noise` of all the data) against the baseline's
    out-of-fold residual on the development samples
    (:func:`~ctrplan.discrepancy.statistics.noise_test` with the baseline's fitted parameters and
    the samples each fold's fit used).

    Returns
    -------
    NoiseCheck
    """
    noise = estimate_noise(setup.data, options.noise_position)
    res = baseline.oof.residual_base
    res = res[np.all(np.isfinite(res), axis=1)]
    rms = float(np.sqrt(np.mean(np.sum(res * res, axis=1)))) if res.size else float("nan")
    sigma = noise["position_rms_m"]
    test = None
    if sigma and res.size:
        n_fit = min(f.n_samples for f in baseline.cv.folds)
        test = noise_test(float(np.mean(res * res)), res.size, sigma ** 2 / 3.0, noise["dof"],
                          n_parameters=len(baseline.fit.names), n_fitted=n_fit, alpha=options.significance)
    check = NoiseCheck(noise=noise, rms_m=rms, ratio=rms / sigma if sigma else None, test=test)
    echo(f"  sensor noise: {noise['description']}; out-of-fold baseline rms {rms * 1e3:.3f} mm"
         + (f" = {check.ratio:.2f} x noise; consistent with noise: {check.consistent} (F = {test['statistic']:.3g}, "
            f"threshold {test['threshold']:.3g} at false-alarm rate {test['false_alarm_rate']:g})" if test else ""))
    return check


def range_text(b: dict) -> str:
    """A typical range ``{"typical": [lo, hi], "unit": ...}`` for a report (rad as deg)."""
    lo, hi = b["typical"]
    if b["unit"] == "rad":
        return f"{np.rad2deg(lo):.3g}..{np.rad2deg(hi):.3g} deg"
    return f"{lo:.3g}..{hi:.3g}" + ("" if b["unit"] == "-" else f" {b['unit']}")


def _separated_by(a: str, b: str) -> str:
    """What data would tell effects ``a`` and ``b`` apart (their entries' ``separated_by``)."""
    parts = [f"{REGISTRY[e].label}: {REGISTRY[e].separated_by}" for e in (a, b) if REGISTRY[e].separated_by]
    return "; ".join(parts) if parts else "more data of the kinds of motion where they differ"


def no_effect_sentence(decision: dict, check: dict, candidates: dict) -> str:
    """Why no effect was named, for the report (``check`` is :meth:`NoiseCheck.as_dict`)."""
    case = decision["no_effect_case"]
    noise = check["noise"]
    test = check.get("test") or {}
    if case == "noise":
        return (f"no candidate is eligible, and the out-of-fold residual of the calibrated baseline (rms "
                f"{check['rms_mm']:.3f} mm) is consistent with the sensor noise ({noise['description']}; F = "
                f"{test['statistic']:.3g} <= {test['threshold']:.3g}, false-alarm rate {test['false_alarm_rate']:g})")
    if case == "unexplained":
        best = min(candidates, key=lambda e: candidates[e]["out_of_fold"]["position_mean_mm"], default=None)
        tail = (f"; the best candidate, {candidates[best]['label']}, reaches an out-of-fold mean of "
                f"{candidates[best]['out_of_fold']['position_mean_mm']:.3f} mm" if best else "")
        return (f"the out-of-fold residual of the calibrated baseline (rms {check['rms_mm']:.3f} mm, "
                f"{check['ratio']:.1f} times the sensor noise: {noise['description']}) is NOT consistent with noise "
                f"(F = {test['statistic']:.3g} > {test['threshold']:.3g} at false-alarm rate "
                f"{test['false_alarm_rate']:g}, after allowing for the {100 * (test['inflation'] - 1):.0f} % a fitted "
                f"model adds): the model misses something that no candidate explains{tail}")
    return (f"no candidate is eligible; whether the out-of-fold residual (rms {check['rms_mm']:.3f} mm) is noise "
            f"cannot be said: the sensor noise is {noise['description']}")


def name_effect(split: DataSplit, candidates: Mapping[str, Candidate], tests: Mapping, noise: NoiseCheck,
                options: DiscrepancyOptions, echo=print) -> Naming:
    """Stage 7: the verdict, by the rule of the module docstring.

    Parameters
    ----------
    split : DataSplit
        Its units.
    candidates : mapping of str to Candidate
        :func:`~ctrplan.discrepancy.fitting.fit_candidates`.
    tests : mapping of str to SignatureTest
        :func:`~ctrplan.discrepancy.signatures.diagnose_residuals` (reported; not a condition).
    noise : NoiseCheck
    options : DiscrepancyOptions
        ``significance``, ``seed``.
    echo : callable

    Returns
    -------
    Naming
    """
    units = split.units[split.dev_rows]
    improving = {e: c for e, c in candidates.items() if c.improvement["mean_difference"] > 0}
    significant = holm({e: c.improvement["p_value"] for e, c in improving.items()}, options.significance)
    judged = {}
    for e, c in candidates.items():
        sig = tests.get(e)
        judged[e] = replace(c, signature_significant=bool(sig is not None and sig.testable
                                                          and sig.p_value < options.significance),
                            improvement_significant=bool(significant.get(e, False)),
                            eligible=bool(significant.get(e, False) and c.typical and not c.at_bound))
    eligible = sorted((e for e, c in judged.items() if c.eligible),
                      key=lambda e: -judged[e].improvement["mean_difference"])
    decision = {"verdict": "none", "named": None, "ambiguous_with": None, "eligible": eligible,
                "holm": {e: bool(v) for e, v in significant.items()}, "separated_by": None, "notes": [],
                "rule": (f"cross-validated improvement significant at {options.significance} (Holm over the "
                         f"candidates, sign-flip test over {np.unique(units).size} units), fitted values typical and "
                         f"none at a bound; ambiguous when the next best candidate's out-of-fold error is within the "
                         f"{CONFIDENCE:.0%} interval")}
    for e, c in judged.items():
        if c.improvement_significant and not c.eligible:
            why = []
            if not c.typical:
                why.append("atypical " + ", ".join(f"{display_value(b['name'], b['value'], b['unit'])} (typical "
                                                      f"{range_text(b)})" for b in c.atypical))
            if c.at_bound:
                why.append("at bound, not converged: " + "; ".join(c.at_bound))
            decision["notes"].append(f"{c.label} improves the cross-validated error significantly but is not named: "
                                     + "; ".join(why))
    if eligible:
        best = eligible[0]
        decision.update(verdict="named", named=best)
        others = [e for e, c in judged.items() if e != best and c.typical and not c.at_bound
                  and c.improvement["mean_difference"] > 0 and not _nested_in(e, best)]
        if others:
            second = max(others, key=lambda e: judged[e].improvement["mean_difference"])
            diff = paired_improvement(judged[second].r, judged[best].r, units, seed=options.seed,
                                      confidence=CONFIDENCE)
            decision["runner_up"] = {"effect": second, "label": judged[second].label, "difference": diff}
            if diff["ci"][0] <= 0.0:
                decision.update(verdict="ambiguous", ambiguous_with=second,
                                separated_by=_separated_by(best, second))
                decision["notes"].append(
                    f"ambiguous: {judged[best].label} and {judged[second].label} explain the data equally well within "
                    f"their uncertainty (out-of-fold Eq. (49) difference {diff['mean_difference']:.3f}, {CONFIDENCE:.0%} "
                    f"interval {diff['ci'][0]:.3f}..{diff['ci'][1]:.3f} mm + deg over {diff['n_units']} units); data "
                    f"that would separate them: {decision['separated_by']}")
        echo(f"{'ambiguous' if decision['verdict'] == 'ambiguous' else 'named effect'}: {judged[best].label}"
             + (f" or {judged[decision['ambiguous_with']].label}" if decision["ambiguous_with"] else ""))
    else:
        decision["no_effect_case"] = ("noise" if noise.consistent else
                                      "unexplained" if noise.consistent is False else "unknown")
        echo("no effect named: " + no_effect_sentence(decision, noise.as_dict(), candidate_reports(judged)))
    for line in decision["notes"]:
        echo(f"  {line}")
    return Naming(candidates=MappingProxyType(judged), decision=decision)


def _nested_in(a: str, b: str) -> bool:
    """``a`` contains ``b`` or the reverse (e.g. gradual friction and friction): not rivals."""
    return a in REGISTRY[b].contains or b in REGISTRY[a].contains


def cautions(verdict: str, candidate, before: dict, after: dict) -> list[str]:
    """What a reader of the named effect must not overlook: a fitted value outside what the
    physics allows, or an addition that lowers the mean error but raises the maximum.

    Parameters
    ----------
    verdict : str
        :data:`VERDICTS`.
    candidate : dict or None
        The named candidate's report (``atypical`` list).
    before, after : dict
        Error summaries on the test split (``position_max_mm``).

    Returns
    -------
    list of str
    """
    out = []
    if verdict == "none" or candidate is None:
        return out
    for b in candidate.get("atypical") or []:
        out.append(f"{display_value(b['name'], b['value'], b['unit'])} is outside its typical range "
                   f"{range_text(b)} ({b['why']})")
    if after["position_max_mm"] is not None and after["position_max_mm"] > before["position_max_mm"]:
        out.append(f"the test split's maximum tip error rises from {before['position_max_mm']:.2f} to "
                   f"{after['position_max_mm']:.2f} mm while the mean falls: the added effect makes some "
                   f"samples worse")
    return out
