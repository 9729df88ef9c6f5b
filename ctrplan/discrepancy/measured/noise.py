"""The sensor's tip position noise, correlated in time, and whether a residual is more than it.

A tracker's noise is correlated from one sample to the next (filtering inside the tracker, slow
drift of the field). Consecutive samples at rest then differ by less than the noise: the
variance of a lag-1 difference is ``2 sigma^2 (1 - rho(1))``, so a white-noise estimate from
lag-1 differences sees only ``1 - rho(1)`` of the variance (0.2 of it at ``rho(1) = 0.8``).
And a residual of K samples of correlated noise has fewer than 3 K independent components.

This module reads the noise from the **semivariogram** of the rests (Cressie 1993, Sec. 2.2,
2.4 and 2.6), separately for each lag ``h`` in samples::

    gamma(h) = E[(e_{t+h} - e_t)^2] / 2 = sigma^2 (1 - rho(h))       (per component)

and fits the model of a white nugget plus a first-order autoregressive (exponential) part::

    rho(h) = s phi^h  (h >= 1),    phi = exp(-1 / tau),
    gamma(h) = sigma^2 (1 - s phi^h),

whose sill ``sigma^2`` (the stationary variance, ``gamma(h)`` for large ``h``) is the noise
variance; ``1 - s`` is the nugget's share, ``tau`` the correlation length [samples].

**Estimator.** Per lag, the median of the squared 3-D differences over the expected sample
median of chi-square(3) (robust like the former lag-1 median, without the median's
small-sample bias); the white model (one level for all lags) is kept unless the correlated
model fits better than white noise on the same rests would allow (a 1 % test calibrated by
simulation: else the three-parameter model bends to the scatter of the long lags and
extrapolates); the correlated model is fitted by weighted least squares with Cressie's weights,
in closed form at each correlation length. When the rests are too short to see the
semivariogram level off, the value is a **lower bound** and says so. The uncertainty of the
estimate is read by simulating the fitted noise on the same rests and repeating the estimate
(a parametric bootstrap, Efron & Tibshirani 1993, Ch. 6).

**Efficiency, for the record.** On AR(1) noise of phi 0.8 and 60 rests of 3-15 samples the
estimate has about 45 degrees of freedom, against 77 for the Cramer-Rao bound of the Gaussian
likelihood of the same rests with the three parameters unknown (1383 with the correlation
known: it is the correlation, not the median, that costs most); on white noise about 750 of
the 1383.

- :class:`NoiseEstimate`: the estimate, the semivariogram and the fitted correlation model;
- :func:`estimate_noise`: from the rests of the samples a caller may use, else as stated, else
  from repeated configurations (an upper bound), else unknown.

Whether an out-of-sample residual is consistent with that noise is
:func:`ctrplan.discrepancy.verdict.consistency.noise_test`.

References
----------
- N. Cressie, *Statistics for Spatial Data*, revised ed., Wiley, 1993, doi:10.1002/9781119115151
  (semivariogram, Sec. 2.2; robust estimation, Sec. 2.4.3; weighted least-squares fit, Sec.
  2.6.2, Eq. (2.6.12)).
- N. Cressie, "Fitting variogram models by weighted least squares", Math. Geol. 17:563, 1985,
  doi:10.1007/BF01032109.
- F. E. Satterthwaite, "An approximate distribution of estimates of variance components",
  Biometrics Bull. 2:110, 1946, doi:10.2307/3002019.
- B. Efron and R. J. Tibshirani, *An Introduction to the Bootstrap*, Chapman & Hall, 1993,
  doi:10.1201/9780429246593.
- H. A. David and H. N. Nagaraja, *Order Statistics*, 3rd ed., Wiley, 2003,
  doi:10.1002/0471722162 (expected order statistics, Eq. (2.1.5)).
- G. H. Golub and V. Pereyra, "Separable nonlinear least squares: the variable projection method
  and its applications", Inverse Problems 19:R1, 2003, doi:10.1088/0266-5611/19/2/201.
- T. R. Chandrupatla, "An efficient quadratic fit-sectioning algorithm for minimization without
  derivatives", Comput. Methods Appl. Mech. Eng. 152:211, 1998,
  doi:10.1016/S0045-7825(97)00190-4 (``scipy.optimize.elementwise.find_minimum``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
from scipy import integrate, stats

try:                                    # scipy >= 1.15
    from scipy.optimize.elementwise import find_minimum
except ImportError:                     # older scipy: the grid's best correlation length
    find_minimum = None

#: How the correlation length is placed with the installed scipy: ``"find_minimum"`` (scipy >=
#: 1.15, ``scipy.optimize.elementwise.find_minimum`` between grid points) or ``"grid"`` (the
#: grid's best point). It enters the stage key (:func:`ctrplan.discrepancy.stages.stage_key`).
CORRELATION_LENGTH_METHOD = "grid" if find_minimum is None else "find_minimum"

from .data import MeasuredData
from ..options import MIN_REST_PAIRS

__all__ = ["NoiseEstimate", "estimate_noise", "NOISE_SOURCES", "CORRELATION_LENGTH_METHOD"]

#: Where a noise value comes from (None: unknown).
NOISE_SOURCES = ("rests", "stated", "repeated configurations")
#: Joints closer than this are identical (a rest) [rad], [m].
SAME_JOINTS = 1e-12
#: Pairs a lag needs to enter the semivariogram fit (a median of fewer is mostly noise).
MIN_LAG_PAIRS = 3
#: Lags needed to fit the three-parameter correlation model; with fewer the correlation is not seen.
MIN_FIT_LAGS = 4
#: Level of the test that leaves out the first samples of the rests while the tip still moves there
#: (:func:`_settled`).
SETTLING_LEVEL = 0.01
#: Correlation left at the longest fitted lag above which the sill is an extrapolation beyond the
#: rests (the semivariogram has not levelled off there).
SEEN_CORRELATION = 0.2
#: Longest correlation length the fit may take, in units of the longest fitted lag (beyond, the
#: semivariogram is a straight line over the rests and the sill is not seen).
MAX_CORRELATION_LENGTH = 4.0
#: Shortest correlation length the fit may take [samples] (shorter is white at these lags).
MIN_CORRELATION_LENGTH = 0.05
#: Correlation lengths of the grid that brackets the fit, log-spaced from
#: MIN_CORRELATION_LENGTH to MAX_CORRELATION_LENGTH times the longest lag (20 % apart for 14).
GRID_POINTS = 40
#: Tolerance of the fitted ln(correlation length) (0.2 % of the length).
LOG_TAU_TOLERANCE = 2e-3
#: Reweighting steps of the fit at a fixed correlation length.
IRLS_STEPS = 4
#: Simulations of the fitted noise that give the estimate's degrees of freedom.
N_SIMULATIONS = 200
#: Level at which white noise on the rests is taken for correlated (the correlated model is fitted
#: only when it beats the white one by more than white noise would in this share of cases).
SELECTION_LEVEL = 0.01
#: Simulations of white noise on the rests that give that threshold, and their fixed seed (the
#: threshold is a property of the rests' lengths, cached).
THRESHOLD_SIMULATIONS = 400
THRESHOLD_SEED = 20240917
#: Degrees of freedom given to an estimate whose simulations do not vary (never reached with
#: Gaussian noise; a guard against a zero variance).
MAX_DOF = 1e7
#: Relative diagonal jitter of the simulated runs' covariance (Cholesky of a nearly singular
#: matrix when the noise has no nugget and a long correlation).
COVARIANCE_JITTER = 1e-10


@dataclass(frozen=True, eq=False)
class NoiseEstimate:
    """The sensor's tip position noise, with where it comes from and how sure it is.

    Per component the noise is modelled as ``e_t = w_t + x_t``: white ``w`` (the nugget) plus a
    first-order autoregressive ``x`` (lag-1 coefficient ``phi``), the same and independent in x,
    y and z (see the module docstring).

    Attributes
    ----------
    position_rms_m : float or None
        rms length of the 3-D position noise vector [m], ``sqrt(3 sigma^2)`` with ``sigma^2``
        the per-component variance (the sill); None when unknown.
    source : {"rests", "stated", "repeated configurations"} or None
    n_runs : int
        Rests used: maximal runs of >= 2 samples adjacent in the record, of one motion, at
        identical joints.
    n_pairs : int
        Pairs of consecutive samples at rest (the lag-1 pairs; ``pair_counts[0]``), or rows at
        repeated configurations for that source.
    lags : ndarray of int, shape (L,)
        Lags of the empirical semivariogram [samples].
    semivariance : ndarray, shape (L,)
        Its value per component at each lag [m^2] (median-based, Eq. :func:`_semivariogram`).
    pair_counts : ndarray of int, shape (L,)
        Pairs at each lag.
    fitted_lags : int
        Leading lags the fit used (those with at least :data:`MIN_LAG_PAIRS` pairs).
    nugget_share : float or None
        ``1 - s``: share of the variance that is white.
    lag1_correlation : float or None
        ``rho(1) = s phi``.
    correlation_length : float or None
        ``tau = -1 / ln(phi)`` [samples]; 0 for white noise.
    correlation_seen : bool
        The rests are long enough that the semivariogram levels off within them (the fitted
        correlation at the longest fitted lag is at most :data:`SEEN_CORRELATION`).
    dof : float or None
        Effective degrees of freedom of the variance estimate, ``2 E[s2]^2 / Var[s2]`` over
        simulations of the fitted noise on the same rests; None when stated.
    upper_bound : bool
        The value is an upper bound (spread at repeated configurations).
    lower_bound : bool
        The value is a lower bound: the rests are too short to see the noise's correlation, and
        the value is the semivariance they reach.
    stated_m : float or None
        The noise rms the data's source states [m].
    rest_rows : ndarray of int, shape (R,)
        Rows in the whole record (``MeasuredData.rows``) of the samples at rest the estimate
        used, sorted (empty for another source).
    simulated_ratio : float or None
        Mean over the simulations of the estimate over the simulated truth (variance; 1 for an
        unbiased estimator).
    seed : int
        Seed of the simulations.
    settled_samples : int
        Samples left out at the start of every rest, where the tip still moved (:func:`_settled`).
    no_variation : bool
        The rests held at least :data:`~ctrplan.discrepancy.options.MIN_REST_PAIRS` pairs of
        consecutive samples but showed no variation (tracker resolution), so the estimate is the
        stated value or a fallback.
    """

    position_rms_m: float | None
    source: str | None
    n_runs: int = 0
    n_pairs: int = 0
    lags: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    semivariance: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pair_counts: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    fitted_lags: int = 0
    nugget_share: float | None = None
    lag1_correlation: float | None = None
    correlation_length: float | None = None
    correlation_seen: bool = False
    dof: float | None = None
    upper_bound: bool = False
    lower_bound: bool = False
    stated_m: float | None = None
    rest_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    simulated_ratio: float | None = None
    seed: int = 0
    settled_samples: int = 0
    no_variation: bool = False

    @property
    def variance_m2(self) -> float | None:
        """Noise variance per component ``sigma^2`` [m^2] (None when unknown)."""
        return None if self.position_rms_m is None else self.position_rms_m ** 2 / 3.0

    @property
    def correlated(self) -> bool:
        """A correlation model was fitted (``source == "rests"`` with enough lags; it may have
        found the noise white: ``correlation_length == 0``)."""
        return self.lag1_correlation is not None

    def correlation(self, h) -> np.ndarray:
        """Correlation of the noise at lags ``h`` [samples] (shape of ``h``): 1 at 0, ``s phi^h``
        beyond; 0 beyond lag 0 when no correlation was fitted (white)."""
        h = np.abs(np.asarray(h, float))
        if not self.correlated or not self.correlation_length:
            return np.where(h == 0, 1.0, 0.0)
        s = 1.0 - self.nugget_share
        return np.where(h == 0, 1.0, s * np.exp(-h / self.correlation_length))

    def long_run_factor(self) -> float:
        """``sum_h rho(h)`` over all lags, ``1 + 2 s phi / (1 - phi)``: the factor by which the
        variance of a mean of many consecutive samples exceeds the white-noise one (1 for white)."""
        if not self.correlated or not self.correlation_length:
            return 1.0
        phi = np.exp(-1.0 / self.correlation_length)
        return float(1.0 + 2.0 * (1.0 - self.nugget_share) * phi / (1.0 - phi))

    def as_dict(self) -> dict:
        """JSON-ready form (SI units; arrays as lists)."""
        return {"position_rms_m": self.position_rms_m, "source": self.source, "n_runs": self.n_runs,
                "n_pairs": self.n_pairs, "lags": [int(v) for v in self.lags],
                "semivariance_m2": [float(v) for v in self.semivariance],
                "pair_counts": [int(v) for v in self.pair_counts], "fitted_lags": self.fitted_lags,
                "nugget_share": self.nugget_share, "lag1_correlation": self.lag1_correlation,
                "correlation_length_samples": self.correlation_length, "correlation_seen": self.correlation_seen,
                "dof": self.dof, "upper_bound": self.upper_bound, "lower_bound": self.lower_bound,
                "stated_m": self.stated_m, "n_rest_samples": int(self.rest_rows.size),
                "simulated_ratio": self.simulated_ratio, "seed": self.seed,
                "settled_samples": self.settled_samples, "no_variation": self.no_variation}


# --------------------------------------------------------------------------- rests
def _rest_runs(data: MeasuredData, rows) -> list[np.ndarray]:
    """Maximal runs (positions in ``data``, each of length >= 2) of samples adjacent in the
    record (``data.rows`` differ by 1), of one ``sequence``, at identical joints, with finite
    tips, all in the mask ``rows``."""
    k = data.n_samples
    use = np.ones(k, bool) if rows is None else np.asarray(rows)
    if use.shape != (k,) or use.dtype != bool:
        raise ValueError(f"rows must be a boolean mask of shape ({k},), got {use.dtype} of shape {use.shape}")
    use = use & np.all(np.isfinite(data.tip), axis=1)
    joints = np.concatenate([data.alpha, data.beta], axis=1)
    link = (np.all(np.abs(np.diff(joints, axis=0)) <= SAME_JOINTS, axis=1) & (np.diff(data.sequence) == 0)
            & (np.diff(np.asarray(data.rows)) == 1) & use[:-1] & use[1:])
    # runs of True in link: a run of j links is a rest of j + 1 samples
    edges = np.diff(np.concatenate([[0], link.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [np.arange(a, b + 1) for a, b in zip(starts, ends)]


def _settled(data: MeasuredData, runs: list) -> tuple[list, int]:
    """The rests without their first samples while the tip still moves there.

    At the start of a rest (identical recorded joints) the tip may still move: the tubes settle,
    or the tracker lags the joint readings. The squared tip differences of consecutive samples at
    the first position of the rests are compared with those in the second half of the rests
    (one-sided Mann-Whitney U test at :data:`SETTLING_LEVEL`, ``scipy.stats.mannwhitneyu``); while
    they are larger, the first sample of every rest is left out.

    Returns
    -------
    runs : list of ndarray of int
        The rests from their first settled sample (those left with at least 2 samples).
    settle : int
        Samples left out at the start of every rest.
    """
    settle = 0
    while True:
        firsts, later = [], []
        for r in runs:
            if r.size - settle >= 3:
                d = np.sum(np.diff(data.tip[r], axis=0) ** 2, axis=1)
                firsts.append(d[settle])
                later.extend(d[max(settle + 1, d.size // 2):])
        if len(firsts) < MIN_REST_PAIRS or len(later) < MIN_REST_PAIRS:
            break
        if stats.mannwhitneyu(firsts, later, alternative="greater").pvalue >= SETTLING_LEVEL:
            break
        settle += 1
    return [r[settle:] for r in runs if r.size - settle >= 2], settle


def _lag_pairs(lengths) -> list[tuple[np.ndarray, np.ndarray]]:
    """For lags 1, 2, ... up to the longest run minus one: the pairs (i, i + h) of positions in
    the concatenated runs of ``lengths`` (each run's samples in order)."""
    lengths = np.asarray(lengths, int)
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    out = []
    for h in range(1, int(lengths.max(initial=1))):
        i = np.concatenate([o + np.arange(m - h) for o, m in zip(offsets, lengths) if m > h])
        out.append((i, i + h))
    return out


@lru_cache(maxsize=4096)
def _median_constant(n: int) -> float:
    """Expected sample median of ``n`` independent chi-square(3) values (David & Nagaraja 2003,
    Eq. (2.1.5): ``E X_(r) = int_0^1 F^-1(u) Beta(r, n - r + 1)(u) du``; the mean of the two middle
    order statistics for even ``n``). 3.0 (the mean) for n = 1 and 2, tends to the population
    median 2.366 as n grows."""
    ppf = stats.chi2(3).ppf

    def expected(r):
        beta = stats.beta(r, n - r + 1)
        return integrate.quad(lambda u: ppf(u) * beta.pdf(u), 0.0, 1.0, limit=200)[0]

    if n % 2:
        return expected((n + 1) // 2)
    return 0.5 * (expected(n // 2) + expected(n // 2 + 1))


def _semivariogram(y: np.ndarray, pairs) -> np.ndarray:
    """Median-based semivariance per component at each lag.

    For Gaussian noise the squared 3-D difference at lag ``h`` is ``2 gamma(h)`` times a
    chi-square(3) variable, so ``gamma(h) = median |d|^2 / (2 c(N))`` with ``c(N)`` the expected
    median of ``N`` chi-square(3) values (:func:`_median_constant`). The median keeps the
    robustness of a rank estimate to tracker outliers (breakdown 50 %, Cressie 1993, Sec.
    2.4.3); dividing by ``c(N)`` instead of the population median 2.366 removes its small-sample
    bias for skewed (chi-like) distances, up to 27 % high for 1 or 2 pairs, where the median is
    the mean (3.0).

    Parameters
    ----------
    y : ndarray, shape (B, M, 3)
        B realisations of the tips of the concatenated runs [m].
    pairs : list of (ndarray, ndarray)
        :func:`_lag_pairs`.

    Returns
    -------
    ndarray, shape (B, L)
        Semivariance per component [m^2].
    """
    i = np.concatenate([p[0] for p in pairs])
    j = np.concatenate([p[1] for p in pairs])
    yt = np.ascontiguousarray(np.swapaxes(y, 1, 2))                # (B, 3, M)
    d = yt[:, :, j] - yt[:, :, i]
    d2 = np.einsum("bcp,bcp->bp", d, d)                            # squared 3-D differences
    counts = [p[0].size for p in pairs]
    out = np.empty((y.shape[0], len(pairs)))
    for k, part in enumerate(np.split(d2, np.cumsum(counts)[:-1], axis=1)):
        out[:, k] = np.median(part, axis=1) / (2.0 * _median_constant(counts[k]))
    return out


# --------------------------------------------------------------------------- variogram fit
def _profile(log_tau, g: np.ndarray, n: np.ndarray, h: np.ndarray, weights=None):
    """The fit at fixed correlation lengths: for each row of ``g`` and its ``log_tau`` the
    weighted least-squares ``gamma(h) = a - c f(h)``, ``f(h) = exp(-h / tau)``, ``0 <= c <= a``.
    Each step is the closed-form solution of a convex two-parameter quadratic problem: the
    unconstrained one when feasible, else the better of its two edges ``c = 0`` (white) and
    ``c = a`` (no nugget).

    Parameters
    ----------
    log_tau : ndarray, shape (B, G)
        ``ln tau`` [ln samples].
    g : ndarray, shape (B, L)
        Semivariances (normalised to O(1)).
    n, h : ndarray, shape (L,)
        Pairs and lags.
    weights : ndarray, shape (B, L), optional
        Fixed weights (one step). None: Cressie's weights ``N_h / gamma(h)^2`` of the fit itself,
        by :data:`IRLS_STEPS` reweighting steps from the pair-weighted mean.

    Returns
    -------
    crit, a, c : ndarray, shape (B, G)
        The criterion at the solution (Cressie's ``sum_h N_h (g_h / gamma_h - 1)^2``, or
        ``sum_h w_h (g_h - gamma_h)^2`` with fixed weights), and the solution.
    """
    f = np.exp(-h / np.exp(log_tau)[..., None])                    # (B, G, L)
    y = g[:, None, :]
    gam = np.broadcast_to(np.sum(n * g, axis=1)[:, None, None] / n.sum(), f.shape)
    q = 1.0 - f
    for _ in range(IRLS_STEPS if weights is None else 1):
        w = n / np.maximum(gam, 1e-12) ** 2 if weights is None else weights[:, None, :]
        sw, swy = w.sum(-1), (w * y).sum(-1)
        swf, swff, swfy = (w * f).sum(-1), (w * f * f).sum(-1), (w * f * y).sum(-1)
        det = sw * swff - swf ** 2
        safe = np.where(det > 1e-12 * sw * swff, det, np.inf)
        a_u = (swy * swff - swf * swfy) / safe
        c_u = (swy * swf - sw * swfy) / safe
        a_w = swy / sw                                             # edge c = 0 (white)
        a_p = (w * q * y).sum(-1) / np.maximum((w * q * q).sum(-1), 1e-300)   # edge c = a (no nugget)
        ss_w = (w * (y - a_w[..., None]) ** 2).sum(-1)
        ss_p = (w * (y - a_p[..., None] * q) ** 2).sum(-1)
        inside = np.isfinite(safe) & (c_u >= 0.0) & (c_u <= a_u)
        a = np.where(inside, a_u, np.where(ss_w <= ss_p, a_w, a_p))
        c = np.where(inside, c_u, np.where(ss_w <= ss_p, 0.0, a_p))
        a = np.maximum(a, 1e-9)
        c = np.clip(c, 0.0, a)
        gam = a[..., None] - c[..., None] * f
    if weights is not None:
        return np.sum(w * (y - gam) ** 2, axis=-1), a, c
    crit = np.sum(n * (y / np.maximum(gam, 1e-12) - 1.0) ** 2, axis=-1)
    return crit, a, c


def _fit(g: np.ndarray, n: np.ndarray, h: np.ndarray):
    """Fit ``gamma(h) = a (1 - s exp(-h / tau))`` to each row of ``g`` by weighted least squares.

    The model is linear in ``(a, c = a s)`` at fixed ``tau`` (a separable problem, Golub &
    Pereyra 2003), so :func:`_profile` solves it there in closed form and ``ln tau`` minimises
    the profile over :data:`GRID_POINTS` log-spaced lengths, refined inside the grid's bracket
    by ``scipy.optimize.elementwise.find_minimum`` (:func:`_minimise`; all rows at once: the
    parametric bootstrap of :func:`estimate_noise` repeats this fit hundreds of times). Two
    stages:

    1. Cressie's criterion ``sum_h N_h (gamma_hat(h) / gamma(h) - 1)^2`` (Cressie 1985;
       Cressie 1993, Eq. (2.6.12)): weights ``N_h / gamma(h)^2`` of the model itself, which
       approximate the inverse variances of the semivariances but favour a model that runs
       above them (a relative error below counts more than one above): the sill comes out
       high by several percent on correlated noise.
    2. Weighted least squares with those weights frozen at the first stage's fit (generalised
       least squares with estimated weights: no pull upwards; the simulated median of the
       sill's estimate falls from 1.055 to 1.036 times the truth for an AR(1) of phi 0.8 on rests
       of 3-15 samples, and from 1.10 to 1.05 on the rests of Ha's trajectory).

    Parameters
    ----------
    g : ndarray, shape (B, L)
        Semivariances [m^2].
    n : ndarray, shape (L,)
        Pairs per lag.
    h : ndarray, shape (L,)
        Lags [samples].

    Returns
    -------
    params : ndarray, shape (B, 3)
        ``(a [m^2], s, tau [samples])`` per row.
    crit : ndarray, shape (B,)
        Cressie's criterion at the fit (for the choice against the white model).
    """
    scale = np.sum(n * g, axis=1) / n.sum()
    scale = np.where(scale > 0, scale, 1.0)
    gn = g / scale[:, None]
    grid = np.linspace(np.log(MIN_CORRELATION_LENGTH), np.log(MAX_CORRELATION_LENGTH * float(h.max())),
                       GRID_POINTS)
    log_tau = _minimise(grid, gn, n, h, None, refine=False)
    _, a, c = _profile(log_tau[:, None], gn, n, h)
    gam = a - c * np.exp(-h / np.exp(log_tau)[:, None])
    w = n / np.maximum(gam, 1e-12) ** 2
    log_tau = _minimise(grid, gn, n, h, w)
    _, a, c = _profile(log_tau[:, None], gn, n, h, w)
    gam = a - c * np.exp(-h / np.exp(log_tau)[:, None])
    crit = np.sum(n * (gn / np.maximum(gam, 1e-12) - 1.0) ** 2, axis=-1)
    a, c = a[:, 0], c[:, 0]
    return np.stack([a * scale, np.where(a > 0, c / a, 0.0), np.exp(log_tau)], axis=1), crit


def _minimise(grid: np.ndarray, g: np.ndarray, n: np.ndarray, h: np.ndarray, w, refine: bool = True) -> np.ndarray:
    """``ln tau`` (B,) minimising :func:`_profile`'s criterion for each row of ``g`` (B, L): the
    best point of ``grid`` (G,), refined (``refine``) to :data:`LOG_TAU_TOLERANCE` by
    ``scipy.optimize.elementwise.find_minimum`` inside its neighbours when it is not at an end
    (the grid's point with scipy < 1.15). ``w`` (B, L): fixed weights, or None for Cressie's."""
    b = g.shape[0]
    crit, _, _ = _profile(np.broadcast_to(grid, (b, grid.size)), g, n, h, w)
    k = np.argmin(crit, axis=1)
    log_tau = grid[k].copy()
    inner = np.flatnonzero((k > 0) & (k < grid.size - 1))
    if find_minimum is None or not inner.size or not refine:
        return log_tau

    def objective(x, row):
        row = row.astype(int)
        return _profile(x[:, None], g[row], n, h, None if w is None else w[row])[0][:, 0]

    res = find_minimum(objective, (grid[k[inner] - 1], grid[k[inner]], grid[k[inner] + 1]),
                       args=(inner.astype(float),), tolerances={"xatol": LOG_TAU_TOLERANCE, "xrtol": 0.0})
    better = np.isfinite(res.f_x) & (res.f_x <= crit[inner, k[inner]])
    log_tau[inner[better]] = res.x[better]
    return log_tau


@dataclass(frozen=True, eq=False)
class _Rests:
    """The lag structure of rests of ``lengths`` samples: ``pairs`` (:func:`_lag_pairs`),
    ``counts`` (L,) pairs per lag, ``lags`` (L,) [samples], ``fitted`` (leading lags with at
    least :data:`MIN_LAG_PAIRS` pairs)."""

    lengths: tuple

    @cached_property
    def pairs(self):
        return _lag_pairs(self.lengths)

    @cached_property
    def counts(self) -> np.ndarray:
        return np.array([i.size for i, _ in self.pairs], int)

    @property
    def lags(self) -> np.ndarray:
        return np.arange(1, len(self.pairs) + 1)

    @cached_property
    def fitted(self) -> int:
        few = self.counts < MIN_LAG_PAIRS
        return int(np.argmax(few)) if np.any(few) else int(few.size)


@lru_cache(maxsize=256)
def _white_threshold(lengths: tuple) -> float:
    """The ``1 - SELECTION_LEVEL`` quantile of the fall of Cressie's criterion from the white
    model to the correlated one when the noise on rests of ``lengths`` is white
    (:data:`THRESHOLD_SIMULATIONS` simulations, seed :data:`THRESHOLD_SEED`; the criterion is
    scale free, so this depends on the rests only)."""
    rests = _Rests(lengths)
    sims = _simulate(lengths, 1.0, 0.0, None, THRESHOLD_SIMULATIONS, np.random.default_rng(THRESHOLD_SEED))
    g = _semivariogram(sims, rests.pairs)[:, :rests.fitted]
    n, h = rests.counts[:rests.fitted].astype(float), rests.lags[:rests.fitted].astype(float)
    _, crit = _fit(g, n, h)
    return float(np.quantile(_white_criterion(g, n) - crit, 1.0 - SELECTION_LEVEL))


def _white_criterion(g: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Cressie's criterion (B,) of the white model, whose fit is the pair-weighted mean of ``g``
    (B, L) over the lags (weights ``n`` (L,))."""
    a = (g @ n / n.sum())[:, None]
    return np.sum(n * (g / a - 1.0) ** 2, axis=1)


def _assess(g: np.ndarray, rests: _Rests):
    """The estimator applied to semivariances ``g`` (B, L) of ``rests``.

    With fewer than :data:`MIN_FIT_LAGS` fitted lags the correlation cannot be seen: the value
    is the semivariance at the longest fitted lag, a lower bound. Else the white model (the
    pair-weighted mean of the semivariances) is kept unless the correlated model (:func:`_fit`)
    lowers Cressie's criterion by more than white noise would in ``1 - SELECTION_LEVEL`` of
    cases on these rests (:func:`_white_threshold`; without this choice, the three-parameter
    model bends to the scatter of the long lags of white noise and extrapolates a sill up to
    1.7 times the truth in 5 % of cases. At 1 % the estimate on white noise has about 750
    degrees of freedom on 60 rests of 3-15 samples, 570 at 5 %, while a correlation of lag-1
    0.3 is still taken for one in 99.5 % of cases). A correlated fit whose correlation at the longest
    fitted lag exceeds :data:`SEEN_CORRELATION` has not seen its sill within the rests: the
    value is the fitted semivariance there, a lower bound.

    Returns
    -------
    variance : ndarray, shape (B,)
        Noise variance per component [m^2].
    params : ndarray, shape (B, 3) or None
        ``(a [m^2], s, tau [samples])``; ``s = tau = 0`` where the white model is kept; None
        without a fit.
    seen : ndarray of bool, shape (B,)
        The value is the sill (False: a lower bound).
    """
    k = rests.fitted
    g = g[:, :k]
    if k < MIN_FIT_LAGS:
        return g[:, -1].copy(), None, np.zeros(g.shape[0], bool)
    n, h = rests.counts[:k].astype(float), rests.lags[:k].astype(float)
    p, crit = _fit(g, n, h)
    white = _white_criterion(g, n) - crit <= _white_threshold(tuple(sorted(rests.lengths)))
    p[white] = np.stack([g[white] @ n / n.sum(), np.zeros(white.sum()), np.zeros(white.sum())], axis=1)
    a, s, tau = p.T
    left = np.where(white, 0.0, s * np.exp(-h[-1] / np.where(white, 1.0, tau)))
    seen = left <= SEEN_CORRELATION
    return np.where(seen, a, a * (1.0 - left)), p, seen


def _simulate(lengths, a: float, s: float, tau: float | None, n_sim: int, rng) -> np.ndarray:
    """``n_sim`` realisations (n_sim, M, 3) of the noise model (per-component variance ``a``
    [m^2], correlated share ``s``, correlation length ``tau`` [samples]; white when None) on runs
    of ``lengths`` concatenated, runs independent, by the Cholesky factor of each run's
    covariance."""
    lengths = np.asarray(lengths, int)
    out = np.empty((n_sim, int(lengths.sum()), 3))
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    for m in np.unique(lengths):
        lag = np.abs(np.subtract.outer(np.arange(m), np.arange(m)))
        corr = np.eye(m) if tau is None or tau <= 0 else np.where(lag == 0, 1.0, s * np.exp(-lag / tau))
        chol = np.linalg.cholesky(a * (corr + COVARIANCE_JITTER * np.eye(m)))
        starts = offsets[lengths == m]
        z = rng.standard_normal((n_sim, starts.size, 3, m)) @ chol.T   # (n_sim, runs, 3, m)
        idx = starts[:, None] + np.arange(m)[None, :]
        out[:, idx, :] = np.swapaxes(z, 2, 3)
    return out


# --------------------------------------------------------------------------- the estimate
def estimate_noise(data: MeasuredData, rows=None, stated: float | None = None, *,
                   n_simulations: int = N_SIMULATIONS, seed: int = 0) -> NoiseEstimate:
    """The sensor's rms tip position noise from the rests of the samples in ``rows``, else as
    stated, else from repeated configurations (an upper bound), else unknown.

    **Rests.** Maximal runs of samples adjacent in the record (``data.rows`` differ by 1), of one
    motion (``data.sequence``), at identical joints, all in ``rows``, without their first samples
    while the tip still moves there (:func:`_settled`: a tube settling, a tracker lagging the
    joints): their tip differences are noise alone. The empirical semivariogram (Cressie 1993, Eq. (2.2.8)) is read at every lag
    within the runs, robustly (:func:`_semivariogram`: median of the squared 3-D differences
    over the expected median of chi-square(3), exact for small pair counts), on the lags with at
    least :data:`MIN_LAG_PAIRS` pairs. The white model (their pair-weighted mean) is kept unless
    the model of a white nugget plus an exponential (AR(1)) correlation, fitted by weighted
    least squares (:func:`_fit`), beats it by more than white noise would on these rests in
    ``1 - SELECTION_LEVEL`` of cases (:func:`_assess`). The sill is the noise variance per
    component.

    **Lower bound.** When the rests cannot see the semivariogram level off, the value is the
    semivariance they reach and the estimate a lower bound (``lower_bound``; the report's
    sentence begins "at least" and says why): with fewer than :data:`MIN_FIT_LAGS` lags (e.g. only pairs
    of consecutive samples), or when the fitted correlation at the longest lag still exceeds
    :data:`SEEN_CORRELATION` (the correlation outlasts the rests; the fitted sill would be an
    extrapolation). A lag-1 value is never reported as the noise of a sensor that may be
    correlated in time.

    **Degrees of freedom.** The fitted noise is simulated ``n_simulations`` times on the same
    runs and the whole estimate repeated (a parametric bootstrap, Efron & Tibshirani 1993,
    Ch. 6): ``dof = 2 E[s2]^2 / Var[s2]`` (the chi-square with the same first two moments,
    Satterthwaite 1946). On white noise it is about half of ``3 sum (m - 1)`` over runs of
    ``m`` samples (the bound with the correlation known; the median's efficiency is 0.6);
    correlated noise and short rests give far fewer (module docstring).

    **Fallbacks.** With fewer than :data:`~ctrplan.discrepancy.options.MIN_REST_PAIRS` pairs of
    consecutive samples at rest: the stated value; else the spread about the mean of
    configurations measured more than once (``data.config_id``, rows in ``rows``; an upper
    bound, since it holds whatever else differs between the visits); else unknown.

    Parameters
    ----------
    data : MeasuredData
        ``tip`` (K, 3) [m], ``alpha``, ``beta`` (K, n), ``sequence`` (K,), ``rows`` (K,),
        ``config_id`` (K,).
    rows : array-like of bool, shape (K,), optional
        Samples the estimate may use (the development samples; never a test split). Default all.
    stated : float, optional
        The noise rms as the data's source states it [m] (rms length of the 3-D vector).
    n_simulations : int
        Simulations of the fitted noise for ``dof`` (at least 20).
    seed : int
        Seed of those simulations (the estimate is reproducible).

    Returns
    -------
    NoiseEstimate

    Raises
    ------
    ValueError
        ``rows`` not a mask of shape (K,), a stated value that is not positive and finite, or
        fewer than 20 simulations.
    """
    if stated is not None and not (np.isfinite(stated) and stated > 0):
        raise ValueError(f"stated noise must be a positive rms [m], got {stated!r}")
    if n_simulations < 20:
        raise ValueError(f"n_simulations must be at least 20, got {n_simulations}")
    stated = None if stated is None else float(stated)
    runs, settle = _settled(data, _rest_runs(data, rows))
    lengths = np.array([r.size for r in runs], int)
    n_lag1 = int(np.sum(lengths - 1))
    no_variation = False
    if n_lag1 >= MIN_REST_PAIRS:
        est = _from_rests(data, runs, lengths, n_simulations, seed, stated, settle)
        if est is not None:
            return est
        no_variation = True
    if stated is not None:
        return NoiseEstimate(position_rms_m=stated, source="stated", n_runs=len(runs), n_pairs=n_lag1,
                             stated_m=stated, seed=seed, no_variation=no_variation)
    return _from_repeats(data, rows, n_lag1, no_variation)


def _from_rests(data, runs, lengths, n_simulations, seed, stated, settle=0) -> NoiseEstimate | None:
    """:func:`estimate_noise` from the rests (None when they show no variation at all)."""
    rests = _Rests(tuple(int(m) for m in lengths))
    counts, lags, fitted = rests.counts, rests.lags, rests.fitted
    y = np.concatenate([data.tip[r] for r in runs])[None]
    g = _semivariogram(y, rests.pairs)
    if fitted == 0 or not np.all(g[0, :fitted] > 0):
        return None
    variance, params, seen = _assess(g, rests)
    var, seen = float(variance[0]), bool(seen[0])
    rng = np.random.default_rng(seed)
    if params is None:
        nugget = lag1 = tau = None
        truth = var
        sims = _simulate(lengths, var, 0.0, None, n_simulations, rng)
    else:
        truth, s, tau = (float(v) for v in params[0])
        nugget, lag1 = 1.0 - s, (s * np.exp(-1.0 / tau) if tau > 0 else 0.0)
        sims = _simulate(lengths, truth, s, tau, n_simulations, rng)
    sim_var, _, _ = _assess(_semivariogram(sims, rests.pairs), rests)
    mean, spread = float(np.mean(sim_var)), float(np.var(sim_var, ddof=1))
    dof = float(min(2.0 * mean ** 2 / spread, MAX_DOF)) if spread > 0 else MAX_DOF
    rms = float(np.sqrt(3.0 * var))
    return NoiseEstimate(position_rms_m=rms, source="rests", n_runs=len(runs), n_pairs=int(counts[0]), lags=lags,
                         semivariance=g[0].copy(), pair_counts=counts, fitted_lags=fitted, nugget_share=nugget,
                         lag1_correlation=None if lag1 is None else float(lag1),
                         correlation_length=None if tau is None else float(tau), correlation_seen=seen, dof=dof,
                         upper_bound=False, lower_bound=not seen, stated_m=stated,
                         rest_rows=np.sort(np.asarray(data.rows)[np.concatenate(runs)]), simulated_ratio=mean / truth,
                         seed=seed, settled_samples=settle)


def _from_repeats(data: MeasuredData, rows, n_lag1: int, no_variation: bool) -> NoiseEstimate:
    """:func:`estimate_noise`'s last fallbacks: the spread at repeated configurations (an upper
    bound; white-noise degrees of freedom), else unknown."""
    use = np.ones(data.n_samples, bool) if rows is None else np.asarray(rows, bool)
    use = use & np.all(np.isfinite(data.tip), axis=1)
    ids, g, counts = np.unique(np.asarray(data.config_id)[use], return_inverse=True, return_counts=True)
    g = g.ravel()
    rep = counts[g] > 1 if ids.size else np.zeros(0, bool)
    if rep.sum() >= 2 * MIN_REST_PAIRS:
        tip = data.tip[use]
        mean = np.stack([np.bincount(g, tip[:, j], ids.size) for j in range(3)], axis=1) / counts[:, None]
        dev = (tip - mean[g])[rep]
        dof = int(rep.sum() - np.count_nonzero(counts > 1))
        rms = float(np.sqrt(np.sum(dev * dev) / max(dof, 1)))
        return NoiseEstimate(position_rms_m=rms, source="repeated configurations", n_pairs=int(rep.sum()),
                             dof=3.0 * dof, upper_bound=True, no_variation=no_variation)
    return NoiseEstimate(position_rms_m=None, source=None, n_pairs=n_lag1, no_variation=no_variation)
