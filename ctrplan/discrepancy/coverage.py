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
and here the "regressor" is the mechanics, so the plain finite-sample quantile is used. The
guarantee assumes exchangeable samples: the samples of a motion are serially correlated, so the
coverage is checked on the untouched test split with a t-interval over its units
(:func:`~ctrplan.discrepancy.statistics.ratio_interval` of the per-unit counts): a calibrated
bound whose test coverage falls short of its target by more than :data:`COVERAGE_TOLERANCE` (and
whose interval excludes the target) is reported as **failing**; one that exceeds it by as much is
**conservative** (wider than it needs to be, e.g. calibrated on out-of-fold errors of models fitted
on less data than the final one).
"""

from __future__ import annotations

import datetime
import logging
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from .._log import progress_level
from ..parallel import Executor
from .logtext import figure, interval
from .options import CONFIDENCE, ENVELOPE_NOISE_FACTOR
from .statistics import mean_interval

__all__ = ["NOISE_MULTIPLE", "DEFAULT_TARGET", "COVERAGE_TOLERANCE", "BoundValues", "bound_values", "Coverage",
           "coverage_figures", "conformal_factor", "BoundCalibration", "calibrate_bound", "BOUND_DEFINITION"]

logger = logging.getLogger(__name__)

#: Noise margin of the bound in units of the sensor's rms position noise (95 % of 3-D Gaussian
#: noise vectors are shorter than 1.62 times their rms length).
NOISE_MULTIPLE = ENVELOPE_NOISE_FACTOR
#: Default share of measured tips the calibrated bound is to cover.
DEFAULT_TARGET = 0.9
#: A calibrated bound fails when its test coverage misses the target by more than this (and the
#: target is outside the coverage's interval).
COVERAGE_TOLERANCE = 0.05
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
    from ..mechanics import evaluate_bound

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
        Its t-interval over units at :data:`~ctrplan.discrepancy.options.CONFIDENCE`, clipped to
        [0, 1] [-]; an end is None where it is not finite (fewer than two units, no samples).
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


def coverage_figures(error, bound, margin: float, units, *, seed: int = 0) -> Coverage:
    """Share of samples with ``error <= bound + margin``, with a t-interval over units, and the
    distribution of ``error / (bound + margin)``.

    Parameters
    ----------
    error, bound : array-like, shape (K,)
        [m]; non-finite samples are left out.
    margin : float
        Noise margin [m].
    units : array-like of int, shape (K,)
        Units of the interval (time blocks, configuration groups).
    seed : int
        Unused (kept for callers).

    Returns
    -------
    Coverage
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
    share = mean_interval(inside, u, confidence=CONFIDENCE)
    ci = tuple(None if not np.isfinite(x) else float(np.clip(x, 0.0, 1.0)) for x in share.ci)
    return Coverage(n=int(e.size), covered=float(inside.mean()), ci=ci, n_units=int(share.n_units),
                    ratio=_quantiles(e / (b + margin)), bound_median_m=float(np.median(b)),
                    error_median_m=float(np.median(e)))


def conformal_factor(error, bound, margin: float, target: float = DEFAULT_TARGET) -> float:
    """The split-conformal factor ``c``: the ``ceil((n + 1) target)``-th smallest of the n scores
    ``error / (bound + margin)`` (inf when that exceeds n).

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


@dataclass(frozen=True, eq=False)
class BoundCalibration:
    """A calibrated bound ``factor (b + margin)`` and how it did on the test split.

    Attributes
    ----------
    method : str
    target : float
        Share of measured tips it is to cover.
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
        The test coverage falls short of the target by more than :data:`COVERAGE_TOLERANCE` and its
        interval excludes it (an interval without finite ends, e.g. of a single unit, excludes
        nothing: the tolerance decides alone).
    status : {"met", "failing", "conservative"}
        ``"conservative"``: the coverage exceeds the target by as much.
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
    status: str = "met"

    def file_table(self, data_file: str, data_sha256: str) -> dict:
        """The robot file's ``[bound_calibration]`` table (SI; unknown figures left out)."""
        table = {"method": self.method, "target_coverage": self.target, "factor": self.factor,
                "noise_margin_m": self.margin_m, "noise_multiple": self.noise_multiple,
                "calibration_samples": self.n_calibration, "test_samples": self.test.n,
                "test_coverage": self.test.covered, "test_coverage_low": self.test.ci[0],
                "test_coverage_high": self.test.ci[1], "raw_bound_test_coverage": self.raw_test.covered,
                "failing": self.failing, "status": self.status, "data_file": data_file, "data_sha256": data_sha256,
                "date": datetime.date.today().isoformat()}
        return {k: v for k, v in table.items() if not (isinstance(v, float) and not np.isfinite(v))}


def calibrate_bound(cal_error, cal_bound, test_error, test_bound, test_units, *, noise_rms: float,
                    target: float = DEFAULT_TARGET, test_translation_last=None, test_released=None,
                    seed: int = 0) -> BoundCalibration:
    """Calibrate the bound on calibration samples and check it on test samples.

    Parameters
    ----------
    cal_error, cal_bound : array-like, shape (n,)
        Errors and bounds of calibration samples [m] (out-of-fold errors: the model did not see
        them).
    test_error, test_bound : array-like, shape (K,)
        Of the test samples [m].
    test_units : array-like, shape (K,)
    noise_rms : float
        Sensor rms position noise [m] (0 if unknown).
    target : float
    test_translation_last : array-like, shape (K,), optional
        Translation-last bound at the test samples [m].
    test_released : array-like of bool, shape (K,), optional
        Test samples after a final translation of every pair.
    seed : int

    Returns
    -------
    BoundCalibration
    """
    margin = NOISE_MULTIPLE * float(noise_rms)
    factor = conformal_factor(cal_error, cal_bound, margin, target)
    n_cal = int(np.sum(np.isfinite(np.asarray(cal_error, float)) & np.isfinite(np.asarray(cal_bound, float))))
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
    cov, (low, high) = test.covered, test.ci
    # an interval without finite ends (a single unit) excludes nothing: the tolerance decides alone
    in_interval = low is not None and high is not None and low <= target <= high
    outside = cov is None or (abs(cov - target) > COVERAGE_TOLERANCE and not in_interval)
    failing = bool(outside and (cov is None or cov < target))
    status = "failing" if failing else "conservative" if outside else "met"
    method = (f"split-conformal: factor = the ceil((n + 1) x {target:g})-th smallest of e / (b + m) over {n_cal} "
              f"out-of-fold calibration samples; calibrated bound = factor x (b + m)")
    return BoundCalibration(method=method, target=target, factor=factor, margin_m=margin,
                            noise_multiple=NOISE_MULTIPLE, noise_rms_m=float(noise_rms), n_calibration=n_cal,
                            test=test, raw_test=raw, translation_last=tl, failing=failing, status=status)


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
    and the running mechanics (:func:`ctrplan.cache.content_key`): 12 hexadecimal digits."""
    from ..cache import content_key, mechanics_version
    from ..io.robot_file import robot_to_toml

    return content_key({"robot": robot_to_toml(robot), "effects": effects.to_dict(),
                        "mechanics_version": mechanics_version()})[:12]


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
    from ..effects import EffectSet
    from .parameters import REGISTRATION, apply_parameters

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
    cal = calibrate_bound(np.where(cal_b.ok, cal_e, np.nan), cal_b.position,
                          np.where(test_b.ok, test_e, np.nan), test_b.position, split.units[test_rows],
                          noise_rms=sigma, target=options.bound_target,
                          test_translation_last=test_b.translation_last, test_released=released, seed=options.seed)
    logger.log(progress_level(), _bound_line(robot.friction_coefficients, cal))
    return cal


def _bound_line(mu, cal: BoundCalibration) -> str:
    """The log line of :func:`check_bound` (mm, %): the raw bound's coverage of the test split's
    measured tips, the calibrated factor and its coverage with its interval; a share over no
    sample, a ratio without samples and an interval over one unit print as "undefined" (never
    as 0 %).

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
    return (f"friction bound (mu = {', '.join(f'{m:g}' for m in mu)}) on the test split: "
            f"{figure(raw.covered, '.0f', 100, ' %')} of {raw.n} measured tips within b + {cal.margin_m * 1e3:.2f} mm "
            f"(median e / (b + m) {figure(raw.ratio['median'], '.2f')}); calibrated bound = "
            f"{cal.factor:.3g} x (b + m) covers {figure(t.covered, '.0f', 100, ' %')} (interval "
            f"{interval(t.ci[0], t.ci[1], '.0f', 100, ' %')}, target {100 * cal.target:.0f} %: {cal.status})")
