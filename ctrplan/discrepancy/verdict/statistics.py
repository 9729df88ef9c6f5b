"""Statistics of the discrepancy workflow's decisions: comparisons of cross-validated models and
intervals over units.

Samples of a continuous motion are serially correlated, and the out-of-fold errors of one fold
all come from the same fitted model, so neither a sample nor a unit (a time block, or a
configuration group of a grid protocol) is an independent observation of how two models compare:

- :func:`cv_comparison`: two models' out-of-fold errors compared over the cross-validation
  folds, with the fold as the cluster: the log ratio of each fold's mean errors is one
  observation (all the samples a fold validates come from one fitted model), and the t test
  over them has ``folds - 1`` degrees of freedom (the cluster-robust small-sample rule of
  Cameron & Miller, J. Human Resources 50:317, 2015, Sec. VI), its variance corrected for the
  training data the folds' fits share (the corrected resampled t test of Nadeau & Bengio,
  Machine Learning 52:239, 2003);
- :func:`holm`: Holm's step-down correction of a family of p-values (family-wise level);
- :func:`ratio_interval`: a ratio of sums over units (a mean error, a relative shrink, a share
  covered) with a t-interval from the per-unit linearization of the ratio (the ratio estimator of
  survey sampling with units as clusters; Cochran, *Sampling Techniques*, 3rd ed., Wiley 1977,
  Sec. 6.4), ``units - 1`` degrees of freedom: the test split's figures.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

__all__ = ["Comparison", "Interval", "CORRECTED_METHOD", "UNCORRECTED_METHOD", "cv_comparison", "holm", "unit_sums",
           "ratio_interval", "mean_interval", "shrink_interval"]

_NAN2 = (float("nan"), float("nan"))

#: :attr:`Comparison.method` of :func:`cv_comparison` with the variance corrected for the training
#: data the folds share (``corrected=True``).
CORRECTED_METHOD = ("corrected resampled t test (Nadeau-Bengio) of the log ratio of the folds' mean errors, "
                    "clustered by fold: variance of the mean s^2 (1/F + n_validation/n_training), F - 1 "
                    "degrees of freedom")
#: :attr:`Comparison.method` of :func:`cv_comparison` without that correction (``corrected=False``).
UNCORRECTED_METHOD = ("t test of the log ratio of the folds' mean errors, clustered by fold: variance of the mean "
                      "s^2 / F, F - 1 degrees of freedom, not corrected for the training data the folds share")


@dataclass(frozen=True)
class Comparison:
    """Two models' out-of-fold errors compared over the cross-validation folds (:func:`cv_comparison`;
    positive: model b is better).

    Attributes
    ----------
    mean_difference : float
        Mean over folds of ``A_f - B_f``, in the errors' unit (Eq. (49) residuals [mm + deg], or
        tip distances [m]).
    ci : tuple of float
        Its t-interval over folds (low, high), same unit; NaN with fewer than two folds.
    ratio : float
        ``exp(mean d_f)``: the geometric mean of ``A_f / B_f`` [-].
    ratio_ci : tuple of float
        Its interval [-].
    reduction : float
        ``1 - 1 / ratio``: the share by which b lowers a's error [-].
    reduction_ci : tuple of float
        Its interval [-].
    se : float
        Standard error of the mean log ratio [-]: ``s sqrt(1/F + validation_to_training)``, ``s``
        the log ratios' standard deviation over the F folds.
    t : float
        t statistic of the mean log ratio.
    dof : int
        Degrees of freedom (folds - 1).
    p_value : float
        One-sided: b better than a.
    p_worse : float
        One-sided: b worse than a.
    n_folds : int
    n_samples : int
        Samples where both errors are finite.
    positive_folds : int
        Folds where b's mean error is lower.
    fold_differences : tuple of float, length n_folds
        ``A_f - B_f`` per fold, in the errors' unit.
    fold_log_ratios : tuple of float, length n_folds
        ``ln(A_f / B_f)`` per fold.
    method : str
        The test, in words (:data:`CORRECTED_METHOD` or :data:`UNCORRECTED_METHOD`).
    validation_to_training : float
        The Nadeau-Bengio term added to ``1/F`` in the variance of the means (of the log ratio and
        of the difference): the mean over folds of ``n_validation / n_training`` [-]; 0 when not
        corrected.
    """

    mean_difference: float
    ci: tuple
    ratio: float
    ratio_ci: tuple
    reduction: float
    reduction_ci: tuple
    se: float
    t: float
    dof: int
    p_value: float
    p_worse: float
    n_folds: int
    n_samples: int
    positive_folds: int
    fold_differences: tuple
    fold_log_ratios: tuple
    method: str
    validation_to_training: float = 0.0

    def as_dict(self) -> dict:
        """Plain JSON form (intervals as ``[low, high]`` lists; the errors' unit)."""
        return {"n_folds": self.n_folds, "n_samples": self.n_samples, "fold_differences": list(self.fold_differences),
                "fold_log_ratios": list(self.fold_log_ratios), "positive_folds": self.positive_folds,
                "method": self.method, "mean_difference": self.mean_difference, "ci": list(self.ci),
                "ratio": self.ratio, "ratio_ci": list(self.ratio_ci), "reduction": self.reduction,
                "reduction_ci": list(self.reduction_ci), "se": self.se, "t": self.t, "dof": self.dof,
                "p_value": self.p_value, "p_worse": self.p_worse,
                "validation_to_training": self.validation_to_training}


@dataclass(frozen=True)
class Interval:
    """An estimate with its t-interval over units (:func:`ratio_interval`).

    Attributes
    ----------
    value : float
        The estimate, in the unit of what it estimates (e.g. a mean tip error [m], or a share [-]);
        NaN without data.
    se : float
        Its standard error, same unit; NaN with fewer than two units.
    low, high : float
        The interval's ends, same unit; NaN with fewer than two units.
    dof : int
        Degrees of freedom (units - 1; 0 with fewer than two units).
    n_units : int
    """

    value: float
    se: float
    low: float
    high: float
    dof: int
    n_units: int

    @property
    def ci(self) -> tuple:
        """``(low, high)``."""
        return (self.low, self.high)

    def scaled(self, factor: float) -> "Interval":
        """The same interval in another unit: value, standard error and ends times ``factor`` (> 0)."""
        return replace(self, value=self.value * factor, se=self.se * factor, low=self.low * factor,
                       high=self.high * factor)

    def as_dict(self) -> dict:
        """``{"value", "se", "ci": [low, high], "dof", "n_units"}``."""
        return {"value": self.value, "se": self.se, "ci": [self.low, self.high], "dof": self.dof,
                "n_units": self.n_units}


def cv_comparison(err_a, err_b, fold, *, confidence: float = 0.95, corrected: bool = True) -> Comparison:
    """Is model b's out-of-fold error lower than model a's? A corrected resampled t test clustered
    by fold.

    Per fold f the mean errors ``A_f`` and ``B_f`` of the two models over its ``n_f`` validation
    samples (both finite) and their log ratio ``d_f = ln(A_f / B_f)``: one observation per fold,
    because every sample a fold validates was predicted by the same fitted models (a test over
    samples or units would treat them as independent). With ``d`` the mean and ``s`` the
    standard deviation of the F log ratios,

    .. math:: t = \\bar d / \\left(s \\sqrt{1/F + \\rho}\\right), \\qquad
              \\rho = \\frac{1}{F} \\sum_f \\frac{n_f}{N - n_f},

    against t with ``F - 1`` degrees of freedom, ``N = sum(n_f)``: the corrected resampled t test
    of Nadeau & Bengio (Machine Learning 52:239, 2003; their ``n_2 / n_1``), applied to k-fold
    cross-validation as by Bouckaert & Frank (PAKDD 2004, LNCS 3056:3). The term ``rho`` stands
    for the covariance between the folds' statistics that the shared training data cause (each
    fold's models are fitted on the other ``F - 1`` folds, so two folds' fits share
    ``(F - 2) / (F - 1)`` of it); 1 / (F - 1) for equal folds. It is taken from the samples'
    counts; rows that a buffer keeps out of a fit are not known here, so with a buffer ``rho``
    is a little low. ``corrected=False`` drops ``rho`` (variance
    ``s^2 / F``). The intervals use the same variance, of ``d`` for the ratio and of the fold
    differences for ``mean_difference``.

    The correction is used because the uncorrected test exceeds its level where the folds share
    their training data. Measured by simulation independent of the mechanics (AR(1) noise of
    unit variance at phi, 40 time blocks of 25 samples dealt to 10 folds as ``GroupKFold`` does,
    least squares fitted without each fold; 20000 records each; one-sided rejection rates at
    0.05 / 0.01 / 0.0014, the last the workflow's smallest Holm level 0.01 / 7; for two sides the
    larger):

    - two non-nested models equally good (each misses one of two equally strong, slowly varying
      regressors of the truth): uncorrected 0.065 / 0.017 / 0.0037 with random-walk regressors
      at phi = 0.9, 0.091 / 0.027 / 0.0052 with square-wave (dead-band-like) ones at phi = 0.9,
      0.069 / 0.017 / 0.0030 with those at phi = 0.5, each above its level (exact one-sided
      binomial test, p < 1e-6); corrected 0.021 / 0.0036 / 0.0003, 0.032 / 0.0051 / 0.0008 and
      0.022 / 0.0029 / 0.0003;
    - a candidate with one extra, slowly varying regressor (random walk, smoothed noise or
      square wave) whose true coefficient is 0, against its baseline, phi = 0.5 ... 0.9, 40 and
      60 blocks: uncorrected at most 0.018 / 0.0022 / 0.0004, corrected at most
      0.0031 / 0.0004 / 0.0001 (the extra parameter only adds variance out of fold); with an
      unmodelled slow discrepancy added to the noise (AR(1), phi = 0.995, unit variance) and a
      random-walk regressor, uncorrected 0.12 / 0.043 / 0.011, corrected 0.049 / 0.011 / 0.0021.

    Neither holds its level where the residual stays correlated across blocks: two equally
    good models with that slow discrepancy, corrected 0.11 / 0.040 / 0.010; blocks of 10 samples
    at phi = 0.9, corrected 0.062 / 0.016 / 0.0032 (uncorrected 0.13 / 0.054 / 0.017); keeping
    the folds apart is the job of the blocks and buffers of :mod:`~ctrplan.discrepancy.measured.split`.
    The correction costs power: a real extra effect (coefficient 1, noise phi = 0.8) is found at
    0.0014 in 25 % of records instead of 66 % (random-walk regressor), in 66 % instead of 95 %
    (square wave). tests/test_discrepancy_statistics.py checks the size at these levels with a
    tolerance that fails the uncorrected test. The ratio, not the difference, is compared: a
    missing effect's error grows with what the motion does in a fold (a lag with the speed, a
    dead band with the reversals), so the folds agree on the ratio far better than on the
    difference.

    Parameters
    ----------
    err_a, err_b : array-like, shape (K,)
        Per-sample out-of-fold errors of the two models, >= 0 (e.g. Eq. (49) residuals
        [mm + deg], or tip distances [m]); non-finite samples are left out of both, and of the
        counts ``n_f``.
    fold : array-like of int, shape (K,)
        Cross-validation fold of each sample.
    confidence : float
        Level of the two-sided intervals.
    corrected : bool
        Inflate the variance of the means by the Nadeau-Bengio term (``1/F + rho`` instead of
        ``1/F``).

    Returns
    -------
    Comparison
        Positive ``mean_difference`` and ``reduction`` when b is better; ``method`` is
        :data:`CORRECTED_METHOD` or :data:`UNCORRECTED_METHOD`, ``validation_to_training`` is
        ``rho`` (0 when not corrected).

    Raises
    ------
    ValueError
        Arrays of different lengths, or not 1-D.
    """
    a = np.asarray(err_a, float)
    b = np.asarray(err_b, float)
    f = np.asarray(fold)
    if not (a.shape == b.shape == f.shape) or a.ndim != 1:
        raise ValueError(f"err_a, err_b and fold must be 1-D of one length, got {a.shape}, {b.shape}, {f.shape}")
    ok = np.isfinite(a) & np.isfinite(b)
    ids, inv = np.unique(f[ok], return_inverse=True)
    counts = np.bincount(inv, minlength=ids.size)
    mean_a = np.bincount(inv, a[ok], ids.size) / np.maximum(counts, 1)
    mean_b = np.bincount(inv, b[ok], ids.size) / np.maximum(counts, 1)
    tiny = 1e-300
    logs = np.log(np.maximum(mean_a, tiny) / np.maximum(mean_b, tiny))
    diffs = mean_a - mean_b
    n_folds = int(ids.size)
    rho = float(np.mean(counts / (counts.sum() - counts))) if corrected and n_folds >= 2 else 0.0
    common = dict(n_folds=n_folds, n_samples=int(ok.sum()), fold_differences=tuple(diffs.tolist()),
                  fold_log_ratios=tuple(logs.tolist()), positive_folds=int(np.sum(logs > 0)),
                  method=CORRECTED_METHOD if corrected else UNCORRECTED_METHOD, validation_to_training=rho)
    if n_folds < 2:
        return Comparison(mean_difference=float(diffs.mean()) if n_folds else float("nan"), ci=_NAN2,
                          ratio=float(np.exp(logs.mean())) if n_folds else float("nan"), ratio_ci=_NAN2,
                          reduction=float("nan"), reduction_ci=_NAN2, se=float("nan"), t=float("nan"), dof=0,
                          p_value=1.0, p_worse=1.0, **common)
    dof = n_folds - 1
    q = float(stats.t.ppf(0.5 + confidence / 2, dof))
    scale = np.sqrt(1.0 / n_folds + rho)      # standard error of a mean over folds per standard deviation
    mean = float(logs.mean())
    se = float(logs.std(ddof=1) * scale)
    if se > 0:
        t = mean / se
        p, p_worse = float(stats.t.sf(t, dof)), float(stats.t.cdf(t, dof))
    else:                                    # every fold the same ratio
        t = float(np.sign(mean)) * np.inf if mean else 0.0
        p, p_worse = (0.0, 1.0) if mean > 0 else (1.0, 0.0) if mean < 0 else (1.0, 1.0)
    ratio_ci = (float(np.exp(mean - q * se)), float(np.exp(mean + q * se)))
    dmean = float(diffs.mean())
    dhalf = float(q * diffs.std(ddof=1) * scale)
    return Comparison(mean_difference=dmean, ci=(dmean - dhalf, dmean + dhalf), ratio=float(np.exp(mean)),
                      ratio_ci=ratio_ci, reduction=float(1.0 - np.exp(-mean)),
                      reduction_ci=(1.0 - 1.0 / ratio_ci[0], 1.0 - 1.0 / ratio_ci[1]), se=se, t=float(t), dof=dof,
                      p_value=p, p_worse=p_worse, **common)


def holm(p_values: dict, alpha: float) -> dict:
    """Holm's step-down test: which of the hypotheses ``{name: p}`` are rejected at family-wise
    level ``alpha`` (Holm, Scand. J. Stat. 6:65, 1979). The family is every key given: a
    hypothesis that was not tested belongs in it with p = 1."""
    order = sorted(p_values, key=p_values.get)
    m = len(order)
    out, still = {}, True
    for i, name in enumerate(order):
        still = still and p_values[name] <= alpha / (m - i)
        out[name] = bool(still)
    return out


def unit_sums(values, units) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per unit, the sum of the finite ``values`` (K,) and their count: (sums (U,), counts (U,),
    unit ids (U,)); units without a finite value are left out."""
    values = np.asarray(values, float)
    units = np.asarray(units)
    ok = np.isfinite(values)
    ids, u = np.unique(units[ok], return_inverse=True)
    u = u.ravel()
    return np.bincount(u, values[ok], ids.size), np.bincount(u, minlength=ids.size).astype(float), ids


def ratio_interval(numerator, denominator, *, confidence: float = 0.95) -> Interval:
    """``R = sum(numerator) / sum(denominator)`` over units, with a t-interval.

    The variance comes from the linearization ``z_u = N_u - R D_u`` of the ratio over the U units:
    ``se = sqrt(U s_z^2) / sum(D)`` with ``s_z^2`` the sample variance of ``z``, ``U - 1`` degrees
    of freedom (the ratio estimator with units as clusters; Cochran 1977, Sec. 6.4).

    Parameters
    ----------
    numerator, denominator : array-like, shape (U,)
        Per-unit sums (e.g. of errors [m], and sample counts).
    confidence : float

    Returns
    -------
    Interval
        In the unit of ``numerator / denominator``; NaN interval with fewer than two units.
    """
    num = np.asarray(numerator, float)
    den = np.asarray(denominator, float)
    n = num.size
    nan = float("nan")
    if n == 0 or not np.sum(den) > 0:
        return Interval(value=nan, se=nan, low=nan, high=nan, dof=0, n_units=n)
    r = float(num.sum() / den.sum())
    if n < 2:
        return Interval(value=r, se=nan, low=nan, high=nan, dof=0, n_units=n)
    z = num - r * den
    se = float(np.sqrt(n * z.var(ddof=1)) / den.sum())
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1) * se)
    return Interval(value=r, se=se, low=r - half, high=r + half, dof=n - 1, n_units=n)


def mean_interval(values, units, *, confidence: float = 0.95) -> Interval:
    """The mean of the finite ``values`` (K,) with a t-interval over ``units`` (K,)
    (:func:`ratio_interval` of per-unit sums and counts), an :class:`Interval` in the values' unit."""
    s, c, _ = unit_sums(values, units)
    return ratio_interval(s, c, confidence=confidence)


def shrink_interval(before, after, units, *, confidence: float = 0.95) -> Interval:
    """The relative fall of the mean error, ``1 - mean(after) / mean(before)`` over the samples where
    both are finite, with a t-interval from the per-unit paired sums (:func:`ratio_interval`).

    Parameters
    ----------
    before, after : array-like, shape (K,)
        Per-sample errors of the two models on the same samples [m].
    units : array-like, shape (K,)
    confidence : float

    Returns
    -------
    Interval
        The relative fall [-].
    """
    b = np.asarray(before, float)
    a = np.asarray(after, float)
    ok = np.isfinite(a) & np.isfinite(b)
    sa, _, ida = unit_sums(a[ok], np.asarray(units)[ok])
    sb, _, _ = unit_sums(b[ok], np.asarray(units)[ok])
    r = ratio_interval(sa, sb, confidence=confidence)
    return replace(r, value=1.0 - r.value, low=1.0 - r.high, high=1.0 - r.low)
