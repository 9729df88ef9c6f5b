"""What the verdict rests on, as kinds and numbers: why a candidate is not named, the notes of the
naming rule, the cautions, the rule itself, why a candidate is not fitted with the named effect, and what a
candidate's fits say about themselves.

The verdict stage (:mod:`~ctrplan.discrepancy.verdict.decision`) and the cautions of a run
(:func:`~ctrplan.discrepancy.outputs.output.run_cautions`) fill these records in SI units; their
``as_dict`` is what ``results.json`` stores, and :mod:`~ctrplan.discrepancy.outputs.words` turns
that stored form into the sentences of the log and the report.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from ...choices import CautionKind, DecisionNoteKind, FitNoteKind, NotNamedReason, NotPairedReason
from ..fits.estimates import AtypicalValue, ParameterEstimate
from .statistics import Comparison

__all__ = ["WhyNot", "DecisionNote", "Caution", "NamingRule", "NotPaired", "FitNote"]


@dataclass(frozen=True)
class WhyNot:
    """One reason why a candidate may not be named.

    Attributes
    ----------
    reason : NotNamedReason
    p_value : float or None
        ``NOT_SIGNIFICANT``: the one-sided p of its improvement over the baseline (before Holm) [-].
    outperformed_by : mapping of str to float
        ``OUTPERFORMED``: each candidate whose out-of-fold error is significantly lower -> the
        one-sided p of that comparison [-].
    limits : tuple of str
        ``AT_LIMIT``: the fit's values at a bound, a grid's edge or a scan's end
        (``Candidate.at_bound``); ``BASELINE_UNFINISHED``: the baseline's fits that stopped at
        their evaluation budget (``"development fit"``, ``"fold <k>"``).
    """

    reason: NotNamedReason
    p_value: float | None = None
    outperformed_by: Mapping = None
    limits: tuple = ()

    def as_dict(self) -> dict:
        """Plain JSON form: ``reason`` and the field of its kind."""
        out = {"reason": self.reason}
        if self.reason == NotNamedReason.NOT_SIGNIFICANT:
            out["p_value"] = self.p_value
        elif self.reason == NotNamedReason.OUTPERFORMED:
            out["outperformed_by"] = dict(self.outperformed_by or {})
        else:
            out["limits"] = list(self.limits)
        return out


@dataclass(frozen=True)
class DecisionNote:
    """A note of the naming rule.

    Attributes
    ----------
    kind : DecisionNoteKind
    effect : str
        ``SIGNIFICANT_NOT_NAMED``, ``BEST_NOT_NAMED``: the candidate not named; ``SIMPLER_NAMED``:
        the containing candidate passed over; ``AMBIGUOUS``: the named one; ``NAMED_JOINTLY``:
        the first of the pair named together.
    other : str or None
        ``SIMPLER_NAMED``: the simpler candidate named; ``AMBIGUOUS``: the second of the pair;
        ``NAMED_JOINTLY``: the second effect named with ``effect``.
    comparison : Comparison or None
        ``SIMPLER_NAMED``: ``other``'s out-of-fold Eq. (49) residuals against ``effect``'s
        (positive: ``effect`` better) [mm + deg]; ``AMBIGUOUS``: the second's against the named
        one's; ``NAMED_JOINTLY``: the pair's against the baseline's.
    """

    kind: DecisionNoteKind
    effect: str
    other: str | None = None
    comparison: Comparison | None = None

    def as_dict(self) -> dict:
        """Plain JSON form (the comparison's, if any, in Eq. (49) units)."""
        out = {"kind": self.kind, "effect": self.effect}
        if self.other is not None:
            out["other"] = self.other
        if self.comparison is not None:
            out["comparison"] = self.comparison.as_dict()
        return out


@dataclass(frozen=True)
class Caution:
    """What a reader of a run must not overlook.

    Attributes
    ----------
    kind : CautionKind
    label : str or None
        ``ATYPICAL_VALUE``: the label of the candidate whose value it is.
    value : AtypicalValue or None
        ``ATYPICAL_VALUE``: the value, its typical range and source, and what to check [SI].
    before_m, after_m : float or None
        ``MAXIMUM_RISES``: the test split's maximum tip error with the calibrated baseline and with
        the final model [m].
    parameter : ParameterEstimate or None
        ``BASELINE_PARAMETER``: the baseline's estimate outside its typical range or at its bound.
    """

    kind: CautionKind
    label: str | None = None
    value: AtypicalValue | None = None
    before_m: float | None = None
    after_m: float | None = None
    parameter: ParameterEstimate | None = None

    def as_dict(self) -> dict:
        """Plain JSON form (SI): ``kind`` and the fields of its kind."""
        if self.kind == CautionKind.ATYPICAL_VALUE:
            return {"kind": self.kind, "label": self.label, "value": self.value.as_dict()}
        if self.kind == CautionKind.MAXIMUM_RISES:
            return {"kind": self.kind, "before_m": self.before_m, "after_m": self.after_m}
        return {"kind": self.kind, "parameter": self.parameter.as_dict()}


@dataclass(frozen=True)
class NamingRule:
    """The naming rule's levels (:mod:`~ctrplan.discrepancy.verdict.decision`).

    Attributes
    ----------
    significance : float
        Family-wise level of the improvement over the baseline, and one-sided level of the
        comparisons between candidates [-].
    n_folds : int
        Cross-validation folds the tests run over.
    n_candidates : int
        Candidates tried alone: the Holm family.
    level : float or None
        The level the comparisons ran at [-]: ``significance``, or ``significance`` divided by
        :data:`~ctrplan.discrepancy.verdict.decision.CORRELATED_FOLDS_SIZE_FACTOR` when the split
        could not keep its folds apart (None: ``significance``).
    folds_apart : bool
        The buffer reached the autocorrelation threshold (the comparisons hold their level).
    """

    significance: float
    n_folds: int
    n_candidates: int
    level: float | None = None
    folds_apart: bool = True

    @property
    def alpha(self) -> float:
        """The level the comparisons ran at [-]."""
        return self.significance if self.level is None else self.level

    def as_dict(self) -> dict:
        """``{"significance", "n_folds", "n_candidates", "level", "folds_apart"}``."""
        return {"significance": self.significance, "n_folds": self.n_folds, "n_candidates": self.n_candidates,
                "level": self.alpha, "folds_apart": self.folds_apart}


@dataclass(frozen=True)
class NotPaired:
    """Why a candidate is not fitted together with the named effect
    (:func:`~ctrplan.discrepancy.fits.pairs.fit_second_effect`).

    Attributes
    ----------
    reason : NotPairedReason
    after_label : str or None
        ``ON_A_THIRD_EFFECT``: the label of the effect it is fitted on top of.
    mean_difference : float or None
        ``NO_IMPROVEMENT_ALONE``: its mean out-of-fold improvement over the baseline alone
        (not positive) [mm + deg].
    """

    reason: NotPairedReason
    after_label: str | None = None
    mean_difference: float | None = None

    def as_dict(self) -> dict:
        """Plain JSON form: ``reason`` and the field of its kind."""
        out = {"reason": self.reason}
        if self.reason == NotPairedReason.ON_A_THIRD_EFFECT:
            out["after_label"] = self.after_label
        elif self.reason == NotPairedReason.NO_IMPROVEMENT_ALONE:
            out["mean_difference"] = self.mean_difference
        return out


@dataclass(frozen=True)
class FitNote:
    """What a candidate's fits say about themselves (``Candidate.fit_notes``).

    Attributes
    ----------
    kind : FitNoteKind
    max_evaluations : int or None
        ``CONTACT_REFIT_NOT_CONVERGED``: the refit's evaluation budget.
    development : bool
        ``NOT_CONVERGED``: the fit on every development sample stopped at its budget.
    folds : tuple of int
        ``NOT_CONVERGED``: the folds (from 1) whose fits stopped at their budget.
    limits : tuple of str
        ``AT_LIMIT``: the values at a bound, a grid's edge or a scan's end.
    cost, baseline_cost : float or None
        ``WORSE_THAN_*``, ``OVERFITS``: the development fit's least-squares cost and the
        baseline's (Eq. (49) units squared).
    model : str or None
        ``WORSE_THAN_STANDARD_BASELINE``: the candidate's mechanics model.
    mean_m, baseline_mean_m : float or None
        ``OVERFITS``: the candidate's and the baseline's mean out-of-fold tip position errors [m].
    """

    kind: FitNoteKind
    max_evaluations: int | None = None
    development: bool = False
    folds: tuple = ()
    limits: tuple = ()
    cost: float | None = None
    baseline_cost: float | None = None
    model: str | None = None
    mean_m: float | None = None
    baseline_mean_m: float | None = None

    def as_dict(self) -> dict:
        """Plain JSON form (SI): ``kind`` and the fields of its kind."""
        k = FitNoteKind
        fields = {k.CONTACT_REFIT_NOT_CONVERGED: ("max_evaluations",), k.NOT_CONVERGED: ("development", "folds"),
                  k.AT_LIMIT: ("limits",), k.WORSE_THAN_CONTAINED_BASELINE: ("cost", "baseline_cost"),
                  k.WORSE_THAN_STANDARD_BASELINE: ("cost", "baseline_cost", "model"),
                  k.OVERFITS: ("cost", "baseline_cost", "mean_m", "baseline_mean_m"),
                  k.PAIR_NOT_CONVERGED: ()}[self.kind]
        out = {"kind": self.kind}
        for name in fields:
            value = getattr(self, name)
            out[name] = list(value) if isinstance(value, tuple) else value
        return out
