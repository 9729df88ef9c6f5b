"""Stages 5 and 7 of the discrepancy workflow: the sensor noise, and which effect is named."""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from .data import MeasuredData
from .fitting import Candidate, candidate_reports, display_value, paired_improvement
from .options import BIC_MARGIN, MIN_REST_PAIRS, NOISE_RATIO, DiscrepancyOptions
from .split import SampleSplit

__all__ = ["NoiseCheck", "Naming", "estimate_noise", "noise_check", "check_noise", "name_effect", "decide",
           "cautions", "no_effect_sentence", "range_text"]


@dataclass(frozen=True, eq=False)
class NoiseCheck:
    """Stage 5: is the baseline's held-out residual more than the sensor noise?

    Attributes
    ----------
    noise : dict
        :func:`estimate_noise` (``position_rms_m`` [m] or None, ``source``, ``n``,
        ``upper_bound``, ``description``).
    rms_m : float
        rms of the baseline's held-out position errors [m] (NaN without a finite one).
    ratio : float or None
        ``rms_m`` over the noise rms; None when the noise is unknown.
    consistent : bool or None
        ``ratio <= NOISE_RATIO``; None when the noise is unknown.
    """

    noise: dict
    rms_m: float
    ratio: float | None
    consistent: bool | None

    def as_dict(self) -> dict:
        """The report's form (``results.json["noise"]``; mm)."""
        sigma = self.noise["position_rms_m"]
        return {"rms_mm": self.rms_m * 1e3, "noise_rms_mm": None if sigma is None else sigma * 1e3,
                "ratio": self.ratio, "consistent": self.consistent, "threshold_ratio": NOISE_RATIO,
                "noise": self.noise}


@dataclass(frozen=True, eq=False)
class Naming:
    """Stage 7: the named effect.

    Attributes
    ----------
    candidates : mapping of str to Candidate
        Every tried candidate with the naming rule's verdicts.
    decision : dict
        :func:`decide`'s ``named``, ``eligible``, ``equally_good``, ``passed_over_implausible``,
        ``notes``, and ``no_effect_case`` (``"noise"``, ``"unexplained"``, ``"unknown"``) when
        none is named.
    """

    candidates: Mapping[str, Candidate]
    decision: dict

    @property
    def named(self) -> str | None:
        """The named effect, or None."""
        return self.decision["named"]


def estimate_noise(data: MeasuredData, stated: float | None = None) -> dict:
    """The sensor's rms tip position noise: as stated, else from the data.

    From rests (consecutive samples of a sequence at identical joints: their tip difference is
    noise alone; robust, from the median of |d|, Maxwell-distributed for Gaussian noise), else
    from configurations measured more than once (spread about the configuration mean; an upper
    bound, since it includes whatever else differs between the visits, e.g. the approach
    direction).

    Parameters
    ----------
    data : MeasuredData
    stated : float, optional
        The noise rms as the data's source states it [m].

    Returns
    -------
    dict
        ``position_rms_m`` (None when unknown), ``source`` ("stated", "rests",
        "repeated configurations", None), ``n`` (pairs or rows used), ``upper_bound`` (bool),
        ``description``.
    """
    if stated is not None:
        return {"position_rms_m": float(stated), "source": "stated", "n": 0, "upper_bound": False,
                "description": f"{stated * 1e3:.3f} mm rms as stated for the data"}
    joints = np.concatenate([data.alpha, data.beta], axis=1)
    same = (np.all(np.abs(np.diff(joints, axis=0)) <= 1e-12, axis=1)
            & (np.diff(data.sequence) == 0))
    d = np.linalg.norm(np.diff(data.tip, axis=0)[same], axis=1)
    d = d[np.isfinite(d)]
    if d.size >= MIN_REST_PAIRS:
        # |d| of two samples with per-component sigma s: Maxwell with scale sqrt(2) s, median
        # 1.5382 sqrt(2) s; position rms = sqrt(3) s
        rms = float(np.median(d) / (1.5382 * np.sqrt(2.0)) * np.sqrt(3.0))
        return {"position_rms_m": rms, "source": "rests", "n": int(d.size), "upper_bound": False,
                "description": f"{rms * 1e3:.3f} mm rms from {d.size} pairs of consecutive samples at rest"}
    _, g, counts = np.unique(data.config_id, return_inverse=True, return_counts=True)
    g = g.ravel()
    rep = counts[g] > 1
    if rep.sum() >= 2 * MIN_REST_PAIRS:
        n_g = int(g.max()) + 1
        mean = np.stack([np.bincount(g, data.tip[:, j], n_g) for j in range(3)], axis=1) / counts[:, None]
        dev = (data.tip - mean[g])[rep]
        dof = int(rep.sum() - np.count_nonzero(counts > 1))
        rms = float(np.sqrt(np.sum(dev * dev) / max(dof, 1)))
        return {"position_rms_m": rms, "source": "repeated configurations", "n": int(rep.sum()),
                "upper_bound": True,
                "description": f"at most {rms * 1e3:.3f} mm rms: spread of {int(rep.sum())} rows at repeated "
                               f"configurations (includes any direction-dependent effect)"}
    return {"position_rms_m": None, "source": None, "n": 0, "upper_bound": False,
            "description": "unknown: not stated (--noise-position-mm) and the data has neither rests nor "
                           "repeated configurations"}


def noise_check(position, noise: dict) -> NoiseCheck:
    """Held-out rms position error against the noise rms (ratio <= :data:`NOISE_RATIO`:
    consistent).

    Parameters
    ----------
    position : ndarray, shape (K,)
        Held-out tip position errors [m]; NaN rows ignored.
    noise : dict
        :func:`estimate_noise` (``position_rms_m`` [m] or None).

    Returns
    -------
    NoiseCheck
    """
    pos = position[np.isfinite(position)]
    rms = float(np.sqrt(np.mean(pos * pos))) if pos.size else float("nan")
    sigma = noise["position_rms_m"]
    ratio = rms / sigma if sigma else None
    return NoiseCheck(noise=noise, rms_m=rms, ratio=ratio,
                      consistent=None if ratio is None else bool(ratio <= NOISE_RATIO))


def check_noise(setup, baseline, options: DiscrepancyOptions, echo=print) -> NoiseCheck:
    """Stage 5: the sensor noise (stated in ``options.noise_position`` [m], else estimated from
    all the data's rests or repeats, :func:`estimate_noise`) against the baseline's held-out
    residual (:func:`noise_check`).

    Returns
    -------
    NoiseCheck
    """
    noise = estimate_noise(setup.data, options.noise_position)
    check = noise_check(baseline.held_out.position, noise)
    echo(f"  sensor noise: {noise['description']}; held-out baseline rms {check.rms_m * 1e3:.3f} mm"
         + (f" = {check.ratio:.2f} x noise" if check.ratio is not None else ""))
    return check


def range_text(b: dict) -> str:
    """A plausible range ``{"plausible": [lo, hi], "unit": ...}`` for a report (rad as deg)."""
    lo, hi = b["plausible"]
    if b["unit"] == "rad":
        return f"{np.rad2deg(lo):.3g}..{np.rad2deg(hi):.3g} deg"
    return f"{lo:.3g}..{hi:.3g}" + ("" if b["unit"] == "-" else f" {b['unit']}")


def decide(candidates: dict, eligible: list, units, options) -> dict:
    """Name an effect among the eligible ones.

    Plausible candidates first (an effect whose fitted values are implausible is not named
    while a plausible one is eligible); among them the largest held-out improvement. Others
    whose held-out residual does not differ significantly from the named one's (paired
    sign-flip test, ``options.significance``) explain the data equally well and are listed.

    Parameters
    ----------
    candidates : dict
        Effect -> ``{"label", "plausible", "implausible", "improvement_eq49", "_r"}``.
    eligible : list of str
    units : ndarray of int, shape (K,)
        Held-out units of the paired tests.
    options : DiscrepancyOptions

    Returns
    -------
    dict
        ``named``, ``eligible``, ``equally_good``, ``passed_over_implausible``, ``notes``.
    """
    plausible = [e for e in eligible if candidates[e]["plausible"]]
    pool = plausible or eligible
    out = {"named": None, "eligible": list(eligible), "equally_good": [], "passed_over_implausible": [],
           "notes": []}
    if not pool:
        return out
    ranked = sorted(pool, key=lambda e: -candidates[e]["improvement_eq49"]["mean_difference"])
    named = ranked[0]
    out["named"] = named
    label = candidates[named]["label"]
    for e in eligible:
        if e not in pool:
            bad = ", ".join(f"{display_value(b['name'], b['value'], b['unit'])} (plausible {range_text(b)})"
                            for b in candidates[e]["implausible"])
            out["passed_over_implausible"].append(e)
            out["notes"].append(f"{candidates[e]['label']} also explains the held-out data but needs {bad}; it is "
                                f"not named while the plausible {label} explains the data")
    for e in ranked[1:]:
        t = paired_improvement(candidates[e]["_r"], candidates[named]["_r"], units, seed=options.seed)
        if not (t["p_value"] < options.significance):
            out["equally_good"].append({"effect": e, "label": candidates[e]["label"],
                                        "mean_difference": t["mean_difference"], "p_value": t["p_value"]})
    if out["equally_good"]:
        others = ", ".join(f"{d['label']} (held-out Eq. (49) difference {d['mean_difference']:.3f}, p = "
                           f"{d['p_value']:.3f})" for d in out["equally_good"])
        out["notes"].append(f"{label} and {others} explain the held-out data equally well within their "
                            f"uncertainty: the data cannot tell them apart; {label} is listed first for its "
                            f"larger mean improvement only")
    if candidates[named]["implausible"]:
        out["notes"].append(f"{label} is named although its fitted values are implausible: no plausible "
                            f"candidate explains the data")
    return out


def no_effect_sentence(decision: dict, check: dict, candidates: dict) -> str:
    """Why no effect was named, for the report (``check`` is :meth:`NoiseCheck.as_dict`)."""
    case = decision["no_effect_case"]
    noise = check["noise"]
    if case == "noise":
        return (f"no candidate is eligible, and the held-out residual of the calibrated baseline (rms "
                f"{check['rms_mm']:.3f} mm) is consistent with the sensor noise ({noise['description']}; "
                f"ratio {check['ratio']:.2f} <= {NOISE_RATIO})")
    if case == "unexplained":
        best = min(candidates, key=lambda e: candidates[e]["held_out"]["position_mean_mm"], default=None)
        tail = (f"; the best candidate, {candidates[best]['label']}, reaches a held-out mean of "
                f"{candidates[best]['held_out']['position_mean_mm']:.3f} mm" if best else "")
        return (f"the held-out residual of the calibrated baseline (rms {check['rms_mm']:.3f} mm) is "
                f"{check['ratio']:.1f} times the sensor noise ({noise['description']}): NOT consistent with "
                f"noise. The model misses something that no candidate explains{tail}")
    return (f"no candidate is eligible; whether the held-out residual (rms {check['rms_mm']:.3f} mm) is noise "
            f"cannot be said: the sensor noise is {noise['description']}")


def name_effect(split: SampleSplit, candidates: Mapping[str, Candidate], tests: Mapping, noise: NoiseCheck,
                options: DiscrepancyOptions, echo=print) -> Naming:
    """Stage 7: name the missing effect.

    A candidate is eligible when its signature test is significant, its held-out Eq. (49)
    improvement is significant (paired sign-flip test over held-out units, one-sided) and its
    BIC beats the baseline's by more than :data:`BIC_MARGIN`; among the eligible, :func:`decide`
    names the plausible one with the largest held-out improvement. When none is named, the
    decision says whether the baseline's held-out residual is consistent with the noise.

    Parameters
    ----------
    split : SampleSplit
        Its held-out ``units``.
    candidates : mapping of str to Candidate
        :func:`~ctrplan.discrepancy.fitting.fit_candidates`.
    tests : mapping of str to SignatureTest
        :func:`~ctrplan.discrepancy.signatures.diagnose_residuals`.
    noise : NoiseCheck
    options : DiscrepancyOptions
        ``significance``, ``seed``.
    echo : callable

    Returns
    -------
    Naming
    """
    judged = {}
    eligible = []
    for e, c in candidates.items():
        sig = tests.get(e)
        signature = bool(sig is not None and sig.testable and sig.p_value < options.significance)
        improvement = bool(c.improvement_eq49["p_value"] < options.significance
                           and c.improvement_eq49["mean_difference"] > 0)
        bic_better = bool(c.delta_bic < -BIC_MARGIN)
        judged[e] = replace(c, signature_significant=signature, improvement_significant=improvement,
                            bic_better=bic_better, eligible=signature and improvement and bic_better)
        if judged[e].eligible:
            eligible.append(e)
    records = {e: {"label": c.label, "plausible": c.plausible, "implausible": c.implausible,
                   "improvement_eq49": c.improvement_eq49, "_r": c.r} for e, c in judged.items()}
    decision = decide(records, eligible, split.units, options)
    named = decision["named"]
    if named:
        echo(f"named effect: {judged[named].label}")
        for line in decision["notes"]:
            echo(f"  {line}")
    else:
        decision["no_effect_case"] = ("noise" if noise.consistent else
                                      "unexplained" if noise.consistent is False else "unknown")
        echo("no effect named: " + no_effect_sentence(decision, noise.as_dict(),
                                                       candidate_reports(judged, split.val.n_samples)))
    return Naming(candidates=MappingProxyType(judged), decision=decision)


def cautions(named, candidate, before: dict, after: dict) -> list[str]:
    """What a reader of the named effect must not overlook: a fitted value outside what the
    physics allows, or an addition that lowers the mean error but raises the maximum.

    Parameters
    ----------
    named : str or None
    candidate : dict
        The named candidate's report (``implausible`` list).
    before, after : dict
        Held-out error summaries (``position_max_mm``).

    Returns
    -------
    list of str
    """
    out = []
    if named is None:
        return out
    for b in candidate.get("implausible") or []:
        out.append(f"{display_value(b['name'], b['value'], b['unit'])} is outside its plausible range "
                   f"{range_text(b)} ({b['why']})")
    if after["position_max_mm"] > before["position_max_mm"]:
        out.append(f"the held-out maximum tip error rises from {before['position_max_mm']:.2f} to "
                   f"{after['position_max_mm']:.2f} mm while the mean falls: the added effect makes some "
                   f"samples worse")
    return out
