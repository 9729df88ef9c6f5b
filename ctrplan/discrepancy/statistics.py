"""Statistics of the discrepancy workflow's decisions: tests and intervals over exchangeable units.

Samples of a continuous motion are serially correlated, so every test and interval here treats
a **unit** (a time block, or a configuration group of a grid protocol) as one observation:

- :func:`paired_improvement`: the mean per-unit difference of two models' errors, its standard
  error and t-interval over units, and a one-sided sign-flip (randomisation) p-value;
- :func:`holm`: Holm's step-down correction of several p-values (family-wise level);
- :func:`block_bootstrap`: percentile intervals of statistics of the pooled samples, resampling
  whole units (``scipy.stats.bootstrap``);
- :func:`noise_test`: whether a residual's mean square is consistent with the sensor noise,
  accounting for the fitted parameters and for the noise estimate's own uncertainty (an F test).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = ["unit_means", "paired_improvement", "holm", "block_bootstrap", "noise_test"]


def unit_means(values, units) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``values`` (K,) per unit, NaN samples dropped: (means (U,), unit ids (U,))."""
    values = np.asarray(values, float)
    units = np.asarray(units)
    ok = np.isfinite(values)
    ids, u = np.unique(units[ok], return_inverse=True)
    u = u.ravel()
    if not ids.size:
        return np.zeros(0), ids
    return np.bincount(u, values[ok], ids.size) / np.bincount(u, minlength=ids.size), ids


def paired_improvement(err_base, err_cand, units, *, n_permutations: int = 9999, seed: int = 0,
                       confidence: float = 0.95) -> dict:
    """How much a model lowers another's errors, over units.

    Per unit, the mean of ``err_base - err_cand`` (samples where both are finite); the
    improvement is their mean. Its standard error is their standard deviation over sqrt(U); the
    interval is the t-interval with U - 1 degrees of freedom; the p-value is one-sided, of the
    null "no systematic improvement": every unit's difference has a random sign (exact
    enumeration up to 2^15 units' signs, else ``n_permutations`` random flips).

    Parameters
    ----------
    err_base, err_cand : array-like, shape (K,)
        Per-sample errors (Eq. (49) residuals, or tip distances).
    units : array-like of int, shape (K,)
    n_permutations, seed : int
    confidence : float

    Returns
    -------
    dict
        ``mean_difference``, ``se``, ``ci`` ([low, high]), ``p_value``, ``n_units``, ``positive_units``
        (units where the candidate is better).
    """
    a = np.asarray(err_base, float)
    b = np.asarray(err_cand, float)
    ok = np.isfinite(a) & np.isfinite(b)
    d, _ = unit_means((a - b)[ok], np.asarray(units)[ok])
    n = d.size
    if n < 2:
        return {"mean_difference": float(d.mean()) if n else float("nan"), "se": float("nan"),
                "ci": [float("nan"), float("nan")], "p_value": 1.0, "n_units": int(n),
                "positive_units": int(np.sum(d > 0))}
    obs = float(d.mean())
    se = float(d.std(ddof=1) / np.sqrt(n))
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1) * se)
    if n <= 15:
        signs = 1.0 - 2.0 * ((np.arange(2 ** n)[:, None] >> np.arange(n)) & 1)
        null = (signs * d).mean(axis=1)
        p = float(np.mean(null >= obs - 1e-15 * max(1.0, abs(obs))))
    else:
        rng = np.random.default_rng(seed)
        null = (rng.choice((-1.0, 1.0), size=(n_permutations, n)) * d).mean(axis=1)
        p = float((1 + np.count_nonzero(null >= obs)) / (1 + n_permutations))
    return {"mean_difference": obs, "se": se, "ci": [obs - half, obs + half], "p_value": p, "n_units": int(n),
            "positive_units": int(np.sum(d > 0))}


def holm(p_values: dict, alpha: float) -> dict:
    """Holm's step-down test: which of the hypotheses ``{name: p}`` are rejected at family-wise
    level ``alpha`` (Holm, Scand. J. Stat. 6:65, 1979)."""
    order = sorted(p_values, key=p_values.get)
    m = len(order)
    out, still = {}, True
    for i, name in enumerate(order):
        still = still and p_values[name] <= alpha / (m - i)
        out[name] = bool(still)
    return out


def block_bootstrap(samples: dict, units, statistic, *, n_resamples: int = 2000, confidence: float = 0.95,
                    seed: int = 0) -> dict:
    """Percentile intervals of statistics of pooled samples, resampling whole units.

    Parameters
    ----------
    samples : dict of str to ndarray, shape (K,)
        Per-sample values of each model on the same K samples (resampled together: paired).
    units : array-like of int, shape (K,)
    statistic : callable
        ``statistic({name: values}) -> float``, e.g. the relative fall of the mean error.
    n_resamples : int
    confidence : float
    seed : int

    Returns
    -------
    dict
        ``value`` (on the data), ``ci`` ([low, high]) by ``scipy.stats.bootstrap`` (percentile
        method) over units, ``n_units``.
    """
    units = np.asarray(units)
    ids = np.unique(units)
    members = [np.flatnonzero(units == u) for u in ids]
    value = float(statistic(samples))

    def stat(picked):
        rows = np.concatenate([members[int(i)] for i in picked])
        return float(statistic({k: v[rows] for k, v in samples.items()}))

    if ids.size < 2:
        return {"value": value, "ci": [float("nan"), float("nan")], "n_units": int(ids.size)}
    res = stats.bootstrap((np.arange(ids.size),), stat, vectorized=False, n_resamples=n_resamples,
                          confidence_level=confidence, method="percentile", random_state=np.random.default_rng(seed))
    return {"value": value, "ci": [float(res.confidence_interval.low), float(res.confidence_interval.high)],
            "n_units": int(ids.size)}


def noise_test(mean_square: float, n_values: int, sigma2: float, sigma2_dof: float | None, *, n_parameters: int,
               n_fitted: int, alpha: float) -> dict:
    """Is a residual's mean square consistent with sensor noise of variance ``sigma2``?

    Under the null (the model is right, the residual is noise plus the error of ``n_parameters``
    values fitted on ``n_fitted`` other samples), an out-of-sample residual component has
    variance about ``sigma2 (1 + n_parameters / n_fitted)`` (the prediction error of a fitted
    linear model). The statistic ``F = mean_square / (sigma2 (1 + p / n))`` is then
    F(``n_values``, ``sigma2_dof``)-distributed, or chi-square / ``n_values`` when the noise is
    stated (``sigma2_dof`` None); the residual is *not* consistent with noise when F exceeds
    its ``1 - alpha`` quantile (false-alarm rate ``alpha``).

    Parameters
    ----------
    mean_square : float
        Mean of the squared residual components [m^2].
    n_values : int
        Residual components (3 per sample).
    sigma2 : float
        Noise variance per component [m^2].
    sigma2_dof : float or None
        Degrees of freedom of its estimate (None: stated, exact).
    n_parameters, n_fitted : int
    alpha : float

    Returns
    -------
    dict
        ``statistic``, ``threshold`` (the 1 - alpha quantile), ``p_value``, ``inflation``
        (1 + p / n), ``consistent`` (bool), ``false_alarm_rate``.
    """
    inflation = 1.0 + n_parameters / max(n_fitted, 1)
    f = mean_square / (sigma2 * inflation)
    if sigma2_dof is None:
        dist = stats.chi2(n_values)
        threshold = float(dist.ppf(1 - alpha) / n_values)
        p = float(dist.sf(f * n_values))
    else:
        dist = stats.f(n_values, sigma2_dof)
        threshold = float(dist.ppf(1 - alpha))
        p = float(dist.sf(f))
    return {"statistic": float(f), "threshold": threshold, "p_value": p, "inflation": float(inflation),
            "consistent": bool(f <= threshold), "false_alarm_rate": float(alpha)}
