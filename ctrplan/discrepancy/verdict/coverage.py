"""How often the friction bound covers measured tips, and a bound calibrated to cover a chosen share.

**The bound and the error.** At a sample with joints (alpha, beta), the *bound* ``b`` is the
per-configuration friction bound of the calibrated robot (:func:`ctrplan.mechanics.evaluate_bound`:
the largest tip distance of any of the 2^(n-1) bounding friction solutions from the standard
model's tip; Section III of Ha, Fagogenis & Dupont 2019); after a final translation of every
pair, the *translation-last bound* (the clearance-only deviation, Section V-B). The *error* ``e``
is the distance between the measured tip and the tip of the model the workflow writes (the final
model: the calibrated baseline with the named effects); the bound is that model's robot's, at the
configuration that model puts the tubes in (history effects applied). A measured tip
is *within the bound* when ``e <= b + m``, with the noise margin ``m`` = :data:`NOISE_MULTIPLE`
times the sensor's rms position noise (95 % of 3-D Gaussian noise vectors are shorter).

**The calibrated bound** is ``c (b + m)``, with the factor ``c`` the split-conformal quantile of
the scores ``s = e / (b + m)`` of calibration samples (the final model's out-of-fold errors on the
development samples; ``m`` from the development samples' noise): the ``ceil((n + 1) t)``-th smallest of n
scores for a target coverage ``t`` (Vovk et al. 2005; Lei et al., JASA 113:1094, 2018). This is
split-conformal prediction itself; a conformal library (``mapie``) wraps scikit-learn regressors,
and here the "regressor" is the mechanics, so the plain finite-sample quantile is used.

**What the guarantee assumes.** The conformal guarantee (coverage at least ``t`` on a new sample)
assumes that calibration and new scores are exchangeable. The scores here are the final model's
out-of-fold errors along a continuous motion: serially correlated, so a development set of
~1,000 samples holds far fewer independent observations, and the coverage a factor attains on
new data wanders more about ``t`` than the exchangeable theory says. Two figures show how much:

- on the development samples, a cluster bootstrap over their units (time blocks): the factor
  recomputed on each resample of units, its interval, and the interval of the share of all
  development scores each recomputed factor covers (how far the coverage of a factor calibrated
  on another draw of such blocks may fall from ``t``; :func:`factor_spread`);
- on the untouched test split, the share of measured tips the calibrated bound covers, with a
  cluster-bootstrap interval over the test units (:func:`coverage_figures`), and a status
  (:func:`coverage_status`, :data:`COVERAGE_STATUSES`): **shown** when the interval's lower end
  is at or above ``t - COVERAGE_TOLERANCE``, **failed** when its upper end is below it, **not
  shown** otherwise (also when the interval is undefined: fewer than :data:`MIN_UNITS` units, no
  test sample). A bound whose interval lies wholly above ``t + COVERAGE_TOLERANCE`` is also
  flagged **conservative** (wider than it needs to be, e.g. calibrated on out-of-fold errors of
  models fitted on less data than the final one). The rule compares with ``t - COVERAGE_TOLERANCE``
  rather than ``t``: a bound calibrated to exactly ``t`` has its point estimate near ``t`` and its
  interval reaching below it, so a lower end asked to reach ``t`` itself would leave every
  well-calibrated bound "not shown". The point estimate takes no part in the status.

**The interval.** Units, not samples, are the independent observations: the covered share is
the ratio ``sum_u N_u / sum_u D_u`` of per-unit covered counts and sample counts, and each of
:data:`~ctrplan.discrepancy.options.BOOTSTRAP_RESAMPLES` resamples draws U units with replacement
(the cluster bootstrap; Davison & Hinkley, *Bootstrap Methods and their Application*, CUP 1997,
Sec. 3.8). The interval is the BCa interval (Efron, JASA 82:171, 1987: bias correction from the
resamples, acceleration from the leave-one-unit-out jackknife), at the level
:data:`~ctrplan.discrepancy.options.CONFIDENCE` expanded for few units: its normal quantile
``z`` replaced by ``sqrt(U / (U - 1)) t_(U-1)`` (the expanded percentile interval of Hesterberg,
Am. Stat. 69:371, 2015). Measured on AR(1) errors (lag-one correlation 0.9) in 12
independent blocks of 40 samples at a true coverage of 90 %, the 95 % interval holds the truth in
94 % of 400 draws (90 % without the expansion; over 5 to 8 units, 82-92 %), its misses mostly
above the truth (5 %); the same interval over samples taken as independent holds it in 49 %.
Over units that all share one value (every tip of every unit covered) the resamples have no
spread and the interval shrinks to that value.
"""

from __future__ import annotations

import datetime
import logging
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np
from scipy import stats

from ..._log import progress_level
from ...parallel import Executor
from ..outputs.logtext import figure, interval
from ..options import BOOTSTRAP_RESAMPLES, CONFIDENCE, ENVELOPE_NOISE_FACTOR
from .statistics import unit_sums

__all__ = ["BoundSamples", "NOISE_MULTIPLE", "DEFAULT_TARGET", "COVERAGE_TOLERANCE", "MIN_UNITS", "COVERAGE_STATUSES",
           "INTERVAL_METHOD", "BoundValues", "bound_values", "Coverage", "coverage_figures", "coverage_status",
           "conformal_factor", "FactorSpread", "factor_spread", "BoundCalibration", "calibrate_bound",
           "BOUND_DEFINITION"]

logger = logging.getLogger(__name__)

#: Noise margin of the bound in units of the sensor's rms position noise (95 % of 3-D Gaussian
#: noise vectors are shorter than 1.62 times their rms length).
NOISE_MULTIPLE = ENVELOPE_NOISE_FACTOR
#: Default share of measured tips the calibrated bound is to cover.
DEFAULT_TARGET = 0.9
#: Shortfall of the coverage from its target that still counts as meeting it [-]: the status
#: compares the interval's ends with ``target - COVERAGE_TOLERANCE`` (a bound calibrated to
#: exactly its target has a point estimate near it and an interval reaching below it, so the
#: target itself could never be shown).
COVERAGE_TOLERANCE = 0.05
#: Fewest units over which a coverage has an interval: the bootstrap over one or two units has
#: no spread worth a name.
MIN_UNITS = 3
#: The statuses of a calibrated bound's test coverage (:func:`coverage_status`), one line each.
COVERAGE_STATUSES = MappingProxyType({
    "shown": "the coverage interval's lower end is at or above the target less the tolerance",
    "failed": "the coverage interval's upper end is below the target less the tolerance",
    "not shown": "the coverage interval reaches across the target less the tolerance, or is undefined",
})
#: How the coverage intervals are computed (printed with them).
INTERVAL_METHOD = (f"cluster bootstrap over units ({BOOTSTRAP_RESAMPLES} resamples), BCa with the level expanded "
                   f"for few units; undefined over fewer than {MIN_UNITS} units")
#: The definition printed next to every coverage figure.
BOUND_DEFINITION = ("bound b: largest tip distance of the 2^(n-1) bounding friction solutions from the standard "
                    "model's tip (Ha et al. 2019, Sec. III) of the calibrated robot; translation-last bound: the "
                    "clearance-only deviation after a final translation (Sec. V-B); error e: measured tip to the tip "
                    "of the model the robot file is written from (the final model, its named effects included); "
                    "within the bound: e <= b + m, m = "
                    f"{NOISE_MULTIPLE:.2f} x the sensor's rms position noise")


@dataclass(frozen=True, eq=False)
class BoundValues:
    """The friction bound at K samples.

    Attributes
    ----------
    position : ndarray, shape (K,)
        Bound on the tip position [m]; NaN where a solve failed.
    translation_last : ndarray, shape (K,)
        Translation-last (clearance-only) bound [m].
    ok : ndarray of bool, shape (K,)
    """

    position: np.ndarray
    translation_last: np.ndarray
    ok: np.ndarray


def _bound_chunk(robot, alpha, beta, settings):
    """The bound at the rows of ``alpha``, ``beta`` (m, n): a list of m ``(position, translation_last, ok)``."""
    from ...mechanics import evaluate_bound

    out = []
    for a, b in zip(alpha, beta):
        try:
            r = evaluate_bound(robot, a, b, settings)
            out.append((r.position, r.translation_last_position, bool(r.diagnostics.converged)))
        except Exception:                                    # noqa: BLE001 - a failed sample is flagged, not fatal
            out.append((np.nan, np.nan, False))
    return out


def _bound_task(single_thread, robot, alpha, beta, settings):
    """:func:`_bound_chunk` as a task of the executor; ``single_thread``: with one BLAS / OpenMP
    thread (``threadpoolctl``) for the length of the task (a worker process)."""
    if not single_thread:
        return _bound_chunk(robot, alpha, beta, settings)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return _bound_chunk(robot, alpha, beta, settings)


def bound_values(robot, alpha, beta, settings=None, *, n_jobs: int = 1) -> BoundValues:
    """The friction bound (:func:`ctrplan.mechanics.evaluate_bound`) at K configurations.

    Parameters
    ----------
    robot : Robot
        With its friction coefficients (mu = 0 pairs contribute only clearance).
    alpha, beta : ndarray, shape (K, n)
        Base rotations [rad], translations [m].
    settings : ModelSettings, optional
    n_jobs : int
        Worker processes (:class:`ctrplan.parallel.Executor`, one BLAS thread each), over chunks of
        configurations; 1 evaluates them in this process.

    Returns
    -------
    BoundValues
        A configuration whose solve raised or did not converge has ``ok`` False (NaN where it
        raised).
    """
    alpha = np.asarray(alpha, float)
    beta = np.asarray(beta, float)
    k = alpha.shape[0]
    chunks = np.array_split(np.arange(k), max(1, min(k, 4 * n_jobs))) if k else []
    workers = n_jobs if n_jobs > 1 and k > 1 else 1
    parts = [None] * len(chunks)
    with Executor(workers) as ex:
        for t, part in ex.run(_bound_task, [(t, (workers > 1, robot, alpha[c], beta[c], settings))
                                            for t, c in enumerate(chunks)]):
            parts[t] = part
    rows = [r for p in parts for r in p]
    arr = np.array([(r[0], r[1]) for r in rows], float).reshape(k, 2)
    return BoundValues(position=arr[:, 0], translation_last=arr[:, 1], ok=np.array([r[2] for r in rows], bool))


@dataclass(frozen=True)
class Coverage:
    """How often a bound covers measured tips (:func:`coverage_figures`).

    Attributes
    ----------
    n : int
        Samples with a finite error and bound.
    covered : float or None
        Share of them with ``e <= b + m`` [-]; None without samples.
    ci : tuple of (float or None, float or None)
        Its cluster-bootstrap interval over units (module docstring) at the level
        :func:`coverage_figures` was given, within [0, 1] [-]; (None, None) over fewer than
        :data:`MIN_UNITS` units or without samples.
    n_units : int
        Units of the interval.
    ratio : mapping of str to float or None
        Read-only ``{"median", "p90", "p95", "max"}`` of ``e / (b + m)`` [-]; None without samples.
    bound_median_m : float or None
        Median bound [m] (:func:`calibrate_bound`: of the calibrated bound ``c (b + m)``).
    error_median_m : float or None
        Median error [m].
    """

    n: int
    covered: float | None
    ci: tuple[float | None, float | None]
    n_units: int
    ratio: Mapping[str, float | None]
    bound_median_m: float | None
    error_median_m: float | None

    def __post_init__(self):
        object.__setattr__(self, "ci", tuple(self.ci))
        object.__setattr__(self, "ratio", MappingProxyType(dict(self.ratio)))

    def __reduce__(self):
        # a mappingproxy does not pickle: rebuild from a plain dict
        return (type(self), (self.n, self.covered, self.ci, self.n_units, dict(self.ratio), self.bound_median_m,
                             self.error_median_m))

    def as_dict(self) -> dict:
        """``{"n", "covered", "ci": [low, high], "n_units", "ratio": {...}, "bound_median_m",
        "error_median_m"}`` (SI; plain Python types)."""
        return {"n": self.n, "covered": self.covered, "ci": list(self.ci), "n_units": self.n_units,
                "ratio": dict(self.ratio), "bound_median_m": self.bound_median_m,
                "error_median_m": self.error_median_m}


def _quantiles(x) -> dict:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if not x.size:
        return {"median": None, "p90": None, "p95": None, "max": None}
    return {"median": float(np.median(x)), "p90": float(np.percentile(x, 90)), "p95": float(np.percentile(x, 95)),
            "max": float(np.max(x))}


def _expanded_alpha(n_units: int, confidence: float) -> float:
    """The two-sided ``alpha`` whose normal quantile is ``sqrt(U / (U - 1)) t_(U-1)`` at ``confidence``
    (Hesterberg 2015): below ``1 - confidence`` for few units, equal to it for many."""
    z = np.sqrt(n_units / (n_units - 1)) * stats.t.ppf(0.5 + confidence / 2, n_units - 1)
    return float(2.0 * stats.norm.sf(z))


def _unit_draws(n_units: int, rng: np.random.Generator, resamples: int) -> np.ndarray:
    """How often each of ``n_units`` units is drawn in each of ``resamples`` resamples of as many
    units with replacement: int array, shape (resamples, n_units), rows summing to ``n_units``."""
    idx = rng.integers(0, n_units, size=(resamples, n_units)) + n_units * np.arange(resamples)[:, None]
    return np.bincount(idx.ravel(), minlength=resamples * n_units).reshape(resamples, n_units)


def _ratio_bootstrap(num: np.ndarray, den: np.ndarray, rng: np.random.Generator, confidence: float,
                     resamples: int) -> tuple[float, float]:
    """Cluster-bootstrap BCa interval, level expanded for few units, of ``sum(num) / sum(den)``.

    Parameters
    ----------
    num, den : ndarray, shape (U,)
        Per-unit sums (covered samples, samples); ``den > 0``, U >= 2.
    rng : numpy.random.Generator
    confidence : float
    resamples : int

    Returns
    -------
    tuple of float
        (low, high), in the unit of ``num / den``.
    """
    n_units = num.size
    theta = float(num.sum() / den.sum())
    draws = _unit_draws(n_units, rng, resamples).astype(float)
    boot = (draws @ num) / (draws @ den)
    if boot.max() == boot.min():                     # every unit the same share: no spread
        return theta, theta
    alpha = _expanded_alpha(n_units, confidence)
    # bias correction from the mid-rank of theta among the resamples (counts are whole numbers,
    # so equal shares are equal floats)
    below = (np.count_nonzero(boot < theta) + 0.5 * np.count_nonzero(boot == theta)) / resamples
    z0 = stats.norm.ppf(np.clip(below, 0.5 / resamples, 1.0 - 0.5 / resamples))
    # acceleration from the leave-one-unit-out jackknife (Efron 1987)
    jack = (num.sum() - num) / (den.sum() - den)
    d = jack.mean() - jack
    ss = float(np.sum(d * d))
    accel = float(np.sum(d ** 3) / (6.0 * ss ** 1.5)) if ss > 0 else 0.0
    z = stats.norm.ppf([alpha / 2, 1.0 - alpha / 2]) + z0
    denom = 1.0 - accel * z
    probs = np.where(denom > 0, stats.norm.cdf(z0 + z / np.where(denom > 0, denom, 1.0)), [0.0, 1.0])
    low, high = np.quantile(boot, probs)
    return float(low), float(high)


def coverage_figures(error, bound, margin: float, units, *, seed: int = 0, confidence: float = CONFIDENCE,
                     resamples: int = BOOTSTRAP_RESAMPLES) -> Coverage:
    """Share of samples with ``error <= bound + margin``, with a cluster-bootstrap interval over
    units, and the distribution of ``error / (bound + margin)``.

    The interval resamples units, not samples (module docstring): samples of one time block are
    serially correlated, and an interval over samples taken as independent is far too narrow.

    Parameters
    ----------
    error, bound : array-like, shape (K,)
        [m]; non-finite samples are left out.
    margin : float
        Noise margin [m].
    units : array-like of int, shape (K,)
        Units of the interval (time blocks, configuration groups), the independent observations.
    seed : int
        Seed of the resampling.
    confidence : float
        Level of the interval, in (0, 1).
    resamples : int
        Bootstrap resamples.

    Returns
    -------
    Coverage
        ``ci`` (None, None) without samples or over fewer than :data:`MIN_UNITS` units.
    """
    e = np.asarray(error, float)
    b = np.asarray(bound, float)
    u = np.asarray(units)
    ok = np.isfinite(e) & np.isfinite(b)
    e, b, u = e[ok], b[ok], u[ok]
    if not e.size:
        return Coverage(n=0, covered=None, ci=(None, None), n_units=0, ratio=_quantiles([]), bound_median_m=None,
                        error_median_m=None)
    inside = (e <= b + margin).astype(float)
    num, den, _ = unit_sums(inside, u)
    ci = (None, None)
    if num.size >= MIN_UNITS:
        ci = _ratio_bootstrap(num, den, np.random.default_rng(seed), confidence, resamples)
    return Coverage(n=int(e.size), covered=float(inside.mean()), ci=ci, n_units=int(num.size),
                    ratio=_quantiles(e / (b + margin)), bound_median_m=float(np.median(b)),
                    error_median_m=float(np.median(e)))


def coverage_status(low: float | None, high: float | None, target: float,
                    tolerance: float = COVERAGE_TOLERANCE) -> str:
    """The status of a coverage with interval ``(low, high)`` against ``target``
    (:data:`COVERAGE_STATUSES`).

    The point estimate takes no part: a coverage at its target whose interval reaches far below
    it is not shown. The comparison is with ``target - tolerance``, the least coverage that
    counts as meeting the target (:data:`COVERAGE_TOLERANCE`).

    Parameters
    ----------
    low, high : float or None
        Ends of the coverage's interval [-]; None where it is undefined.
    target : float
        Target coverage [-].
    tolerance : float
        [-].

    Returns
    -------
    {"shown", "failed", "not shown"}
        ``"shown"``: ``low >= target - tolerance``; ``"failed"``: ``high < target - tolerance``;
        ``"not shown"`` otherwise, and where an end is None.
    """
    if low is None or high is None:
        return "not shown"
    floor = target - tolerance
    return "shown" if low >= floor else "failed" if high < floor else "not shown"


def conformal_factor(error, bound, margin: float, target: float = DEFAULT_TARGET) -> float:
    """The split-conformal factor ``c``: the ``ceil((n + 1) target)``-th smallest of the n scores
    ``error / (bound + margin)`` (inf when that exceeds n).

    The finite-sample guarantee (a new sample's score is at most ``c`` with probability at least
    ``target``) assumes exchangeable scores; :func:`factor_spread` shows what serial correlation
    does to it.

    Parameters
    ----------
    error, bound : array-like, shape (n,)
        Calibration samples [m] (non-finite ones left out).
    margin : float
        [m], > 0 or the bounds > 0.
    target : float
        In (0, 1).

    Returns
    -------
    float

    Raises
    ------
    ValueError
        ``target`` outside (0, 1).
    """
    if not 0.0 < target < 1.0:
        raise ValueError(f"target coverage must be in (0, 1), got {target!r}")
    e = np.asarray(error, float)
    b = np.asarray(bound, float)
    ok = np.isfinite(e) & np.isfinite(b) & (b + margin > 0)
    s = np.sort(e[ok] / (b[ok] + margin))
    n = s.size
    rank = int(np.ceil((n + 1) * target))
    return float("inf") if rank > n or n == 0 else float(s[rank - 1])


def _finite_or_none(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


@dataclass(frozen=True)
class FactorSpread:
    """How the conformal factor moves over resampled calibration units (:func:`factor_spread`).

    Attributes
    ----------
    factor_ci : tuple of (float or None, float or None)
        Interval of the factor recomputed on resamples of the units [-]; an end is None where it
        is infinite (a resample too small for the rank) or undefined (fewer than
        :data:`MIN_UNITS` units).
    coverage_ci : tuple of (float or None, float or None)
        Interval of the share of all calibration scores the recomputed factors cover [-]: where
        the coverage of a factor calibrated on another draw of such units may lie.
    n_units : int
        Calibration units.
    """

    factor_ci: tuple[float | None, float | None]
    coverage_ci: tuple[float | None, float | None]
    n_units: int

    def as_dict(self) -> dict:
        """``{"factor_ci": [low, high], "coverage_ci": [low, high], "n_units"}`` (plain Python types)."""
        return {"factor_ci": list(self.factor_ci), "coverage_ci": list(self.coverage_ci), "n_units": self.n_units}


def factor_spread(error, bound, margin: float, units, target: float = DEFAULT_TARGET, *, seed: int = 0,
                  confidence: float = CONFIDENCE, resamples: int = BOOTSTRAP_RESAMPLES) -> FactorSpread:
    """The conformal factor (:func:`conformal_factor`) recomputed on cluster-bootstrap resamples of
    the calibration units, and the share of all calibration scores each covers.

    The spread of that share is the bootstrap's picture of how far the coverage of a factor
    calibrated on serially correlated scores may fall from ``target``: the exchangeable theory
    puts it within about ``sqrt(t (1 - t) / n)`` of ``t``; scores correlated within units move it
    by about as much as ``n`` / (samples per unit) independent scores would. Percentile intervals
    at ``confidence``, expanded for few units as in :func:`coverage_figures`. Measured on AR(1)
    scores (lag-one correlation 0.9) in 10 blocks of 40 samples, the 95 % interval of the covered
    share holds the coverage the factor attains on new samples in 94.5 % of 200 draws; over
    samples taken as independent, in 50 %.

    Parameters
    ----------
    error, bound : array-like, shape (n,)
        Calibration samples [m] (non-finite ones left out).
    margin : float
        [m].
    units : array-like, shape (n,)
        Units of the calibration samples (time blocks).
    target : float
        In (0, 1).
    seed : int
    confidence : float
    resamples : int

    Returns
    -------
    FactorSpread
        Undefined ends over fewer than :data:`MIN_UNITS` units.
    """
    e = np.asarray(error, float)
    b = np.asarray(bound, float)
    u = np.asarray(units)
    ok = np.isfinite(e) & np.isfinite(b) & (b + margin > 0)
    s = e[ok] / (b[ok] + margin)
    order = np.argsort(s, kind="stable")
    s = s[order]
    ids, inv = np.unique(u[ok][order], return_inverse=True)
    n_units = int(ids.size)
    if n_units < MIN_UNITS:
        return FactorSpread(factor_ci=(None, None), coverage_ci=(None, None), n_units=n_units)
    draws = _unit_draws(n_units, np.random.default_rng(seed), resamples).astype(np.int32)
    cum = np.cumsum(draws[:, inv.ravel()], axis=1, dtype=np.int32)      # (resamples, n) in score order
    total = cum[:, -1]
    rank = np.ceil((total + 1) * target).astype(np.int64)
    finite = rank <= total
    at = np.argmax(cum >= rank[:, None], axis=1)
    factor = np.where(finite, s[at], np.inf)
    covered = np.where(finite, np.searchsorted(s, s[at], side="right") / s.size, 1.0)
    alpha = _expanded_alpha(n_units, confidence)
    probs = [alpha / 2, 1.0 - alpha / 2]
    f_lo, f_hi = np.quantile(factor, probs, method="inverted_cdf")
    c_lo, c_hi = np.quantile(covered, probs, method="inverted_cdf")
    return FactorSpread(factor_ci=(_finite_or_none(f_lo), _finite_or_none(f_hi)),
                        coverage_ci=(float(c_lo), float(c_hi)), n_units=n_units)


@dataclass(frozen=True, eq=False)
class BoundCalibration:
    """A calibrated bound ``factor (b + margin)`` and how it did on the test split.

    Attributes
    ----------
    method : str
    target : float
        Share of measured tips it is to cover [-].
    factor : float
        The conformal factor ``c`` [-].
    margin_m : float
        Noise margin [m].
    noise_multiple : float
    noise_rms_m : float
    n_calibration : int
    test : Coverage
        :func:`coverage_figures` of the calibrated bound on the test split (``bound_median_m``: of
        the calibrated bound ``factor (b + margin)``).
    raw_test : Coverage
        The same for the raw bound ``b + margin``.
    translation_last : Coverage or None
        The translation-last bound's coverage on the test samples after a final translation of
        every pair (None without such samples).
    failing : bool
        True exactly when ``status`` is ``"failed"``.
    status : {"shown", "not shown", "failed"}
        :func:`coverage_status` of ``test`` against ``target`` (:data:`COVERAGE_STATUSES`).
    conservative : bool
        The test coverage's interval lies wholly above ``target + tolerance``: the bound is wider
        than it needs to be.
    calibration : FactorSpread or None
        The factor's spread over resampled calibration units (None without their units).
    confidence : float
        Level of the intervals [-].
    tolerance : float
        :data:`COVERAGE_TOLERANCE` the status was judged with [-].
    """

    method: str
    target: float
    factor: float
    margin_m: float
    noise_multiple: float
    noise_rms_m: float
    n_calibration: int
    test: Coverage
    raw_test: Coverage
    translation_last: Coverage | None
    failing: bool
    status: str = "not shown"
    conservative: bool = False
    calibration: FactorSpread | None = None
    confidence: float = CONFIDENCE
    tolerance: float = COVERAGE_TOLERANCE

    def file_table(self, data_file: str, data_sha256: str) -> dict:
        """The robot file's ``[bound_calibration]`` table (SI; unknown figures left out), as
        :class:`ctrplan.calibration.CalibratedBound` reads it."""
        table = {"method": self.method, "target_coverage": self.target, "factor": self.factor,
                "noise_margin_m": self.margin_m, "noise_multiple": self.noise_multiple,
                "calibration_samples": self.n_calibration, "test_samples": self.test.n,
                "test_coverage": self.test.covered, "test_coverage_low": self.test.ci[0],
                "test_coverage_high": self.test.ci[1], "raw_bound_test_coverage": self.raw_test.covered,
                "failing": self.failing, "status": self.status, "coverage_tolerance": float(self.tolerance),
                "conservative": bool(self.conservative),
                "data_file": data_file, "data_sha256": data_sha256,
                "date": datetime.date.today().isoformat()}
        return {k: v for k, v in table.items() if not (isinstance(v, float) and not np.isfinite(v))}


@dataclass(frozen=True, eq=False)
class BoundSamples:
    """Measured tips' errors and the bound at them: one set of samples of :func:`calibrate_bound`.

    Attributes
    ----------
    error : array-like, shape (n,)
        Distance of each measured tip from the model's tip [m] (NaN where undefined, e.g. where
        the bound did not solve).
    bound : array-like, shape (n,)
        The friction bound at each sample [m].
    units : array-like, shape (n,), optional
        The unit (time block) of each sample: the clusters of the bootstrap intervals. Required
        for the test samples; for the calibration samples it adds the factor's spread.
    translation_last : array-like, shape (n,), optional
        The translation-last bound at each sample [m].
    released : array-like of bool, shape (n,), optional
        Samples after a final translation of every pair (where ``translation_last`` applies).
    """

    error: object
    bound: object
    units: object = None
    translation_last: object = None
    released: object = None


def calibrate_bound(calibration: BoundSamples, test: BoundSamples, *, noise_rms: float,
                    target: float = DEFAULT_TARGET, seed: int = 0) -> BoundCalibration:
    """Calibrate the bound on calibration samples and check it on test samples.

    The factor is :func:`conformal_factor`; its guarantee assumes exchangeable scores, which
    serially correlated out-of-fold errors are not, so the coverage is checked on the test split
    with a cluster-bootstrap interval over its units (:func:`coverage_figures`) and judged by
    :func:`coverage_status` (with the calibration samples' units, :func:`factor_spread` shows the
    factor's spread as well).

    Parameters
    ----------
    calibration : BoundSamples
        Shape (n,): out-of-fold errors (the model did not see them) and bounds [m]; ``units``
        optional, ``translation_last`` and ``released`` unused.
    test : BoundSamples
        Shape (K,): errors, bounds [m] and ``units`` of the test samples; with
        ``translation_last`` and ``released``, the translation-last bound's coverage on the
        released samples too.
    noise_rms : float
        Sensor rms position noise [m] (0 if unknown).
    target : float
        In (0, 1).
    seed : int
        Seed of the bootstrap resampling.

    Returns
    -------
    BoundCalibration

    Raises
    ------
    ValueError
        ``target`` outside (0, 1); ``test.units`` missing.
    """
    if test.units is None:
        raise ValueError("calibrate_bound: the test samples need their units (BoundSamples.units)")
    cal_error, cal_bound, cal_units = calibration.error, calibration.bound, calibration.units
    test_error, test_bound, test_units = test.error, test.bound, test.units
    test_translation_last, test_released = test.translation_last, test.released
    margin = NOISE_MULTIPLE * float(noise_rms)
    factor = conformal_factor(cal_error, cal_bound, margin, target)
    n_cal = int(np.sum(np.isfinite(np.asarray(cal_error, float)) & np.isfinite(np.asarray(cal_bound, float))))
    spread = None if cal_units is None else factor_spread(cal_error, cal_bound, margin, cal_units, target, seed=seed)
    tb = np.asarray(test_bound, float)
    te = np.asarray(test_error, float)
    calibrated = factor * (tb + margin) - margin if np.isfinite(factor) else np.full_like(tb, np.inf)
    test = coverage_figures(te, calibrated, margin, test_units, seed=seed)
    test = replace(test, bound_median_m=float(np.nanmedian(factor * (tb + margin))) if tb.size else None)
    raw = coverage_figures(te, tb, margin, test_units, seed=seed)
    tl = None
    if test_translation_last is not None and test_released is not None and np.any(test_released):
        rel = np.asarray(test_released, bool)
        tl = coverage_figures(te[rel], np.asarray(test_translation_last, float)[rel], margin,
                              np.asarray(test_units)[rel], seed=seed)
    low, high = test.ci
    status = coverage_status(low, high, target)
    conservative = low is not None and low > target + COVERAGE_TOLERANCE
    method = (f"split-conformal: factor = the ceil((n + 1) x {target:g})-th smallest of e / (b + m) over {n_cal} "
              f"out-of-fold calibration samples; calibrated bound = factor x (b + m); test coverage interval: "
              f"{INTERVAL_METHOD}")
    return BoundCalibration(method=method, target=target, factor=factor, margin_m=margin,
                            noise_multiple=NOISE_MULTIPLE, noise_rms_m=float(noise_rms), n_calibration=n_cal,
                            test=test, raw_test=raw, translation_last=tl, failing=status == "failed", status=status,
                            conservative=conservative, calibration=spread)


def _stored_bounds(setup, stage: str, robot, alpha, beta, n_jobs: int) -> BoundValues:
    """The bound values of stage ``stage``: stored by an earlier run, else evaluated and stored."""
    cached = setup.stages.load(stage)
    if cached is not None:
        logger.log(progress_level(), f"  {stage}: reused from an earlier run")
        return BoundValues(position=np.array(cached["position"], float),
                           translation_last=np.array(cached["translation_last"], float),
                           ok=np.array(cached["ok"], bool))
    logger.log(progress_level(), f"  evaluating the friction bound at {len(alpha)} samples ({stage}) ...")
    values = bound_values(robot, alpha, beta, setup.settings, n_jobs=n_jobs)
    setup.stages.save(stage, {"position": values.position, "translation_last": values.translation_last,
                              "ok": values.ok})
    return values


def _bound_tag(robot, effects) -> str:
    """Tag of the stored bounds of ``robot`` (the written robot: every tube and pair parameter, as
    its robot file states it) with the history ``effects`` (:class:`ctrplan.effects.EffectSet`)
    and the running mechanics (:func:`ctrplan.cache.content_key`): 64 hexadecimal digits."""
    from ...cache import content_key, mechanics_version
    from ...io.robot_file import robot_to_toml

    return content_key({"robot": robot_to_toml(robot), "effects": effects.to_dict(),
                        "mechanics_version": mechanics_version()})


def check_bound(setup, split, final, test_errors, final_params: dict, noise, options) -> BoundCalibration:
    """Stage 10b: the friction bound of the written robot against the measured tips, and the
    calibrated bound (module docstring).

    The robot is the one the workflow writes (``final_params`` applied to the input robot: its
    tube parameters and friction coefficients), its bound evaluated at the configuration the final
    model puts the tubes in (its history effects applied to the recorded motion); the errors are
    the final model's: out of fold at up to ``options.bound_samples`` development samples (evenly
    spaced), which calibrate the factor, and on the test split at up to as many samples, which
    check it. The noise margin comes from the development samples' noise. Bounds are stored as
    stages, tagged with the written robot, the history effects and the mechanics' version
    (:func:`_bound_tag`).

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    final : CrossValidated
        The final model (the calibrated baseline when nothing is named): its out-of-fold errors.
    test_errors : Errors
        The final model's errors on the test split.
    final_params : dict
        The written model's parameters [SI].
    noise : NoiseCheck
        Estimated on the development samples.
    options : DiscrepancyOptions
        ``bound_target``, ``bound_samples``, ``n_jobs``, ``seed``.

    Returns
    -------
    BoundCalibration
    """
    from ...effects import EffectSet
    from ..fits.parameters import REGISTRATION, apply_parameters

    names = tuple(n for n in final_params if n not in REGISTRATION)
    robot = apply_parameters(setup.robot, names, tuple(final_params[n] for n in names))
    effects, _ = EffectSet.from_parameters(setup.robot, names, tuple(final_params[n] for n in names))
    state = setup.data.state(robot, effects)
    dev = np.flatnonzero(split.dev_rows)
    tst = np.flatnonzero(split.test_rows)
    limit = options.bound_samples

    def pick(idx):
        return idx if idx.size <= limit else idx[np.linspace(0, idx.size - 1, limit).round().astype(int)]

    cal_rows, test_rows = pick(dev), pick(tst)
    tag = _bound_tag(robot, effects)
    cal_b = _stored_bounds(setup, f"bound-development-{limit}-{tag}", robot, state.alpha[cal_rows],
                           state.beta[cal_rows], options.n_jobs)
    test_b = _stored_bounds(setup, f"bound-test-{limit}-{tag}", robot, state.alpha[test_rows], state.beta[test_rows],
                            options.n_jobs)
    oof = final.oof
    cal_e = oof.position[np.searchsorted(oof.rows, cal_rows)]
    test_e = test_errors.position[np.searchsorted(test_errors.rows, test_rows)]
    released = np.all(setup.data.translation_last[test_rows], axis=1)
    sigma = noise.rms or 0.0
    cal = calibrate_bound(BoundSamples(np.where(cal_b.ok, cal_e, np.nan), cal_b.position, split.units[cal_rows]),
                          BoundSamples(np.where(test_b.ok, test_e, np.nan), test_b.position, split.units[test_rows],
                                       test_b.translation_last, released),
                          noise_rms=sigma, target=options.bound_target, seed=options.seed)
    logger.log(progress_level(), _bound_line(robot.friction_coefficients, cal))
    return cal


def _bound_line(mu, cal: BoundCalibration) -> str:
    """The log line of :func:`check_bound` (mm, %): the raw bound's coverage of the test split's
    measured tips, the calibrated factor and its coverage with its interval and status; a share
    over no sample, a ratio without samples and an interval over fewer than :data:`MIN_UNITS`
    units print as "undefined" (never as 0 %).

    Parameters
    ----------
    mu : sequence of float
        The written robot's friction coefficients [-].
    cal : BoundCalibration

    Returns
    -------
    str
    """
    raw, t = cal.raw_test, cal.test
    status = cal.status + (", conservative" if cal.conservative else "")
    return (f"friction bound (mu = {', '.join(f'{m:g}' for m in mu)}) on the test split: "
            f"{figure(raw.covered, '.0f', 100, ' %')} of {raw.n} measured tips within b + {cal.margin_m * 1e3:.2f} mm "
            f"(median e / (b + m) {figure(raw.ratio['median'], '.2f')}); calibrated bound = "
            f"{cal.factor:.3g} x (b + m) covers {figure(t.covered, '.0f', 100, ' %')} (interval "
            f"{interval(t.ci[0], t.ci[1], '.0f', 100, ' %')}, target {100 * cal.target:.0f} %: {status}; "
            f"{t.n_units} units)")
