"""Is an out-of-sample tip residual consistent with the sensor's noise, correlated in time?

:func:`noise_test` is an F test of the residual's mean square against the noise variance that
:func:`ctrplan.discrepancy.measured.noise.estimate_noise` reads from the rests of the data. Under the null
(the model is right) the residual is the noise plus the error of the values fitted on other
samples, per component of variance ``sigma^2 (1 + p / n_eff)``. Its degrees of freedom combine
two parts (Satterthwaite 1946, Eq. (2)): the noise's, the effective number of independent squares
of K samples of the fitted correlation (Bayley & Hammersley 1946; ``3 K`` for white noise), and
the fitted values' error with the ``p`` parameters. The noise estimate's own degrees of freedom
(:attr:`~ctrplan.discrepancy.measured.noise.NoiseEstimate.dof`) are the denominator's; a stated noise has
none (a chi-square test). The result is a :class:`NoiseTest`.

References
----------
- F. E. Satterthwaite, "An approximate distribution of estimates of variance components",
  Biometrics Bull. 2:110, 1946, doi:10.2307/3002019.
- G. V. Bayley and J. M. Hammersley, "The 'effective' number of independent observations in an
  autocorrelated time series", J. R. Stat. Soc. Suppl. 8:184, 1946, doi:10.2307/2983560.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from ..measured.noise import NoiseEstimate

__all__ = ["NoiseTest", "noise_test"]


@dataclass(frozen=True)
class NoiseTest:
    """Outcome of :func:`noise_test`: is a residual consistent with the sensor's noise?

    Attributes
    ----------
    statistic : float
        ``F = mean(residual^2) / (sigma_hat^2 (1 + p / n_eff))`` [-].
    threshold : float
        Its ``1 - alpha`` quantile under the null [-].
    p_value : float
        Probability under the null of a statistic at least as large [-].
    inflation : float
        ``1 + p / n_eff``: the residual's variance over the noise's under the null [-].
    n_fitted_effective : float
        ``n_eff``: independent scalar observations the parameters were fitted on, worth of the
        ``n_fitted`` correlated ones.
    dof_residual : float
        ``nu_r``: degrees of freedom of the numerator (Satterthwaite).
    dof_noise : float or None
        Degrees of freedom of the noise estimate (the denominator); None when the noise is stated.
    n_samples : int
        Residual samples used (finite, not among the rests left out).
    n_rest_samples_left_out : int
        Residual samples left out because the noise was estimated on them.
    consistent : bool
        ``statistic <= threshold``: the residual is consistent with noise.
    false_alarm_rate : float
        ``alpha``: the test's level [-].
    noise_lower_bound : bool
        The noise is a lower bound (a rejection against it is not evidence of a missing effect).
    noise_upper_bound : bool
        The noise is an upper bound.
    residual_lag1 : float or None
        For a stated noise (whose correlation is unknown): the residual's lag-1 autocorrelation
        that sets the conservative degrees of freedom [-]; None for an estimated noise.
    """

    statistic: float
    threshold: float
    p_value: float
    inflation: float
    n_fitted_effective: float
    dof_residual: float
    dof_noise: float | None
    n_samples: int
    n_rest_samples_left_out: int
    consistent: bool
    false_alarm_rate: float
    noise_lower_bound: bool
    noise_upper_bound: bool
    residual_lag1: float | None = None

    def as_dict(self) -> dict:
        """The attributes by name, as plain Python values (JSON-ready)."""
        return asdict(self)


def _sum_squared_correlation(index: np.ndarray, sequence: np.ndarray, estimate: NoiseEstimate) -> float:
    """``sum_{i, j} rho(|t_i - t_j|)^2`` over the samples of each sequence (record rows
    ``index``): the denominator of the effective number of independent squares (Bayley &
    Hammersley 1946), for the estimate's fitted correlation."""
    if not estimate.correlated or not estimate.correlation_length:
        return float(index.size)
    return _sum_squared_ar1(index, sequence, 1.0 - estimate.nugget_share, np.exp(-2.0 / estimate.correlation_length))


def _residual_lag1(r: np.ndarray, index: np.ndarray, sequence: np.ndarray) -> float:
    """Lag-1 autocorrelation of a residual (K, 3), pooled over its components, from the pairs of
    samples at consecutive record rows of one sequence (each component centred); NaN without
    such a pair."""
    order = np.lexsort((index, sequence))
    x, t, seq = r[order], index[order], sequence[order]
    pair = (np.diff(t) == 1) & (seq[1:] == seq[:-1])
    if not np.any(pair):
        return float("nan")
    x = x - x.mean(axis=0)
    den = float(np.sum(x * x))
    return float(np.sum(x[:-1][pair] * x[1:][pair]) / den) if den > 0 else float("nan")


def _sum_squared_ar1(index: np.ndarray, sequence: np.ndarray, s: float, q2: float) -> float:
    """``sum_{i, j} rho(|t_i - t_j|)^2`` for ``rho(h) = s phi^h`` (``q2 = phi^2``) over the samples
    of each sequence. The cross terms of a sequence sorted by ``t`` are ``2 s^2 sum_j S_j`` with
    ``S_j = phi^(2 (t_j - t_{j-1})) (S_{j-1} + 1)``, exact in O(K)."""
    k = index.size
    total = float(k)
    order = np.lexsort((index, sequence))
    t, seq = index[order].astype(float), sequence[order]
    cross, run = 0.0, 0.0
    for j in range(1, k):
        if seq[j] != seq[j - 1]:
            run = 0.0
            continue
        run = q2 ** (t[j] - t[j - 1]) * (run + 1.0)
        cross += run
    return total + 2.0 * s * s * cross


def noise_test(residual, index, sequence, estimate: NoiseEstimate, *, n_parameters: int, n_fitted: int,
               alpha: float, smooth_regressors: bool = True, leave_out_rests: bool = True) -> NoiseTest:
    """Is an out-of-sample residual consistent with the estimated sensor noise?

    Under the null (the model is right), the residual is the noise plus the error of
    ``n_parameters`` values fitted on ``n_fitted`` other scalar observations: per component its
    variance is ``sigma^2 (1 + p / n_eff)`` (the prediction error of a fitted linear model).
    With noise correlated in time and regressors that vary slowly along the motion (the
    Jacobian of a model along a continuous trajectory; ``smooth_regressors``), the fitted
    values' error is that of ``n_eff = n_fitted / sum_h rho(h)`` independent observations
    (:meth:`~ctrplan.discrepancy.measured.noise.NoiseEstimate.long_run_factor`).

    The statistic ``F = mean(residual^2) / (sigma_hat^2 (1 + p / n_eff))`` has, approximately:

    - numerator: chi-square over its degrees of freedom ``nu_r``, from the two variance parts
      (Satterthwaite 1946, Eq. (2)): the noise with ``nu_noise = 3 K^2 / sum_{i,j} rho(t_i -
      t_j)^2`` (Bayley & Hammersley 1946: the effective number of independent squares of K
      samples at record rows ``t`` of the fitted correlation; ``3 K`` for white noise) and the
      fitted values' error with ``p``;
    - denominator: ``sigma_hat^2 / sigma^2``, chi-square over ``estimate.dof``;

    so ``F ~ F(nu_r, dof)``. A stated noise has no estimate (chi-square(nu_r) / nu_r) and no known
    correlation: white noise (``nu_noise = 3 K``, ``n_eff = n_fitted``) would overstate the
    degrees of freedom of correlated noise and raise false alarms, so its correlation is taken
    as an AR(1) at the residual's own lag-1 autocorrelation ``phi`` (pooled over components,
    from samples at consecutive record rows; clipped to [0, 0.999]) in both ``nu_noise`` and
    ``n_eff = n_fitted (1 - phi) / (1 + phi)``: under the null that is the noise's correlation, and
    a missing effect can only raise it, which lowers the degrees of freedom (conservative). The
    residual is *not* consistent with noise when F exceeds its ``1 - alpha`` quantile (false-alarm
    rate ``alpha``).

    The F distribution needs numerator and denominator independent: the residual's samples that
    are among the rests the noise came from are left out (``leave_out_rests``; their squares
    and the rests' differences share the same noise, which would make the test conservative:
    no false alarm at 5 % in 200 white-noise cases instead of about 5 %). Samples next to the
    rests still share correlated noise with them: the test stays somewhat conservative (about
    3 % false alarms at 5 %, none at 1 %, in tests/test_discrepancy_noise.py), and the
    estimate's upward bias of a few percent on correlated noise adds to that.

    Parameters
    ----------
    residual : array-like, shape (K, 3)
        Out-of-sample tip position residual [m] (rows with a non-finite value are dropped).
    index : array-like of int, shape (K,)
        Row of each residual sample in the whole record (``MeasuredData.rows``).
    sequence : array-like of int, shape (K,)
        Motion of each (samples of different motions are independent).
    estimate : NoiseEstimate
        :func:`~ctrplan.discrepancy.measured.noise.estimate_noise`; must be known.
    n_parameters : int
        Parameters fitted (``p``).
    n_fitted : int
        Scalar observations they were fitted on (3 per sample).
    alpha : float
        False-alarm rate, in (0, 1).
    smooth_regressors : bool
        The regressors vary slowly over the noise's correlation length (True, conservative);
        False: they are independent from sample to sample (``n_eff = n_fitted``).
    leave_out_rests : bool
        Leave out the residual's samples at the record rows of ``estimate.rest_rows`` (all are
        kept when that would leave none).

    Returns
    -------
    NoiseTest

    Raises
    ------
    ValueError
        Unknown noise, shapes that do not match, no finite residual, ``alpha`` outside (0, 1),
        ``n_parameters`` < 0 or ``n_fitted`` < 1.
    """
    if estimate.position_rms_m is None or not estimate.position_rms_m > 0:
        raise ValueError(f"the noise must be known to test a residual against it (estimate from "
                         f"{estimate.source or 'no source'}: {estimate.position_rms_m!r} m rms)")
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if n_parameters < 0 or n_fitted < 1:
        raise ValueError(f"need n_parameters >= 0 and n_fitted >= 1, got {n_parameters} and {n_fitted}")
    r = np.asarray(residual, float)
    index = np.asarray(index)
    sequence = np.asarray(sequence)
    if r.ndim != 2 or r.shape[1] != 3 or index.shape != (r.shape[0],) or sequence.shape != (r.shape[0],):
        raise ValueError(f"residual must have shape (K, 3) and index, sequence shape (K,); got {r.shape}, "
                         f"{index.shape}, {sequence.shape}")
    ok = np.all(np.isfinite(r), axis=1)
    if not np.any(ok):
        raise ValueError("the residual has no finite row")
    rest = np.isin(index, estimate.rest_rows) if leave_out_rests else np.zeros(index.shape, bool)
    if np.all(rest[ok]):
        rest[:] = False
    keep = ok & ~rest
    r, index, sequence = r[keep], index[keep].astype(np.int64), sequence[keep]
    k = r.shape[0]
    stated = estimate.dof is None
    lag1 = None
    if stated:
        # the stated noise's correlation is unknown: its squares are counted as correlated as the
        # residual's own (an AR(1) at the residual's lag-1 autocorrelation), which under the null
        # is the noise's and under a missing effect only lowers the degrees of freedom
        lag1 = _residual_lag1(r, index, sequence)
        phi = float(np.clip(np.nan_to_num(lag1, nan=0.0), 0.0, 0.999))
        factor = 1.0 if not smooth_regressors else (1.0 + phi) / (1.0 - phi)
        sum_sq = _sum_squared_ar1(index, sequence, 1.0, phi * phi) if phi > 0 else float(k)
    else:
        factor = 1.0 if not smooth_regressors else estimate.long_run_factor()
        sum_sq = _sum_squared_correlation(index, sequence, estimate)
    n_eff = n_fitted / factor
    extra = n_parameters / n_eff
    inflation = 1.0 + extra
    nu_noise = 3.0 * k * k / sum_sq
    # Satterthwaite: noise part (mean sigma^2, nu_noise) plus fitted-value part (sigma^2 p / n_eff, p)
    nu_r = inflation ** 2 / (1.0 / nu_noise + (extra ** 2 / n_parameters if n_parameters else 0.0))
    f = float(np.mean(r * r) / (estimate.variance_m2 * inflation))
    if stated:
        dist = stats.chi2(nu_r)
        threshold = float(dist.ppf(1.0 - alpha) / nu_r)
        p = float(dist.sf(f * nu_r))
    else:
        dist = stats.f(nu_r, estimate.dof)
        threshold = float(dist.ppf(1.0 - alpha))
        p = float(dist.sf(f))
    return NoiseTest(statistic=f, threshold=threshold, p_value=p, inflation=float(inflation),
                     n_fitted_effective=float(n_eff), dof_residual=float(nu_r),
                     dof_noise=None if stated else float(estimate.dof), n_samples=int(k),
                     n_rest_samples_left_out=int(np.count_nonzero(ok & rest)), consistent=bool(f <= threshold),
                     false_alarm_rate=float(alpha), noise_lower_bound=bool(estimate.lower_bound),
                     noise_upper_bound=bool(estimate.upper_bound), residual_lag1=lag1)
