"""Stage 3 of the discrepancy workflow: the baseline (the standard model of Section II-A of Ha,
Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906) calibrated by least squares on their Eq.
(49) with a prior toward the robot file's tube parameters, on the development samples and
without each cross-validation fold.

A pilot fit without a prior (:func:`pilot_fit`) chooses what the folds then share: the buffer
around validation and test blocks and the prior's scale. The prior's strength is then chosen by
the out-of-fold error among ``options.prior_strengths`` and 0 (the robot file's tube parameters,
only a registration fitted) (:func:`calibrate_baseline`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from ..._log import details, progress_level
from ...choices import PoseFrame
from .calibrate import CalibrationResult, calibrate, information_criterion
from .fitoptions import FitRun, FitStart
from .estimates import display_value, parameter_table
from .evaluation import Errors, evaluate_rows
from .fitting import CrossValidated, compare, cross_validate, fit_rows, run_fits, stage_name
from ..options import DiscrepancyOptions
from .parameters import REGISTRATION, parameter, read_parameters
from ..setup import DiscrepancySetup
from ..measured.split import DataSplit, choose_buffer
from ..verdict.statistics import Comparison

__all__ = ["Baseline", "PriorChoice", "pilot_fit", "calibrate_baseline", "baseline_prior"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PriorChoice:
    """One prior strength tried for the baseline.

    Attributes
    ----------
    strength : float
        The prior strength tau [-] (0: the robot file's tube parameters held; inf: no prior).
    mean_position : float
        The baseline's out-of-fold mean tip position error with it [m].
    mean_eq49 : float
        Its out-of-fold mean Eq. (49) residual [mm + deg].
    against_file : Comparison
        Its out-of-fold Eq. (49) residuals against the robot file's parameters' (tau 0)
        (:func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison`; positive: better than the file).
    """

    strength: float
    mean_position: float
    mean_eq49: float
    against_file: Comparison


@dataclass(frozen=True, eq=False)
class Baseline:
    """Stage 3: the calibrated baseline (standard model) and the choice of its prior.

    Attributes
    ----------
    cv : CrossValidated
        The baseline with the chosen prior strength.
    bic : float
        BIC of its development fit (:func:`~ctrplan.discrepancy.fits.calibrate.information_criterion`).
    parameters : tuple of ParameterEstimate
        :func:`~ctrplan.discrepancy.fits.estimates.parameter_table` of its fitted values:
        uncertainty, change from the robot file's value, typical range.
    strength : float
        The chosen prior strength tau (0: the robot file's tube parameters, only the registration
        fitted; inf: no prior).
    prior : dict
        ``{name: (robot file's value, scale)}`` of the chosen prior (:class:`~ctrplan.discrepancy.fits.calibrate.Prior`);
        empty for tau 0 and inf.
    choices : tuple of PriorChoice
        Every strength tried, strongest first.
    file_cv : CrossValidated
        The robot file's tube parameters with only a registration fitted (tau 0).
    residual_scale : float
        The pilot fit's rms Eq. (49) residual [mm + deg] that scales the prior.
    """

    cv: CrossValidated
    bic: float
    parameters: tuple
    strength: float
    prior: dict
    choices: tuple
    file_cv: CrossValidated
    residual_scale: float

    @property
    def fit(self) -> CalibrationResult:
        return self.cv.fit

    @property
    def params(self) -> dict:
        return self.cv.params

    @property
    def oof(self) -> Errors:
        return self.cv.oof

    @property
    def r(self) -> np.ndarray:
        return self.cv.r


def _tube_names(setup) -> tuple:
    return tuple(n for n in setup.base_names if n not in REGISTRATION)


def pilot_fit(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions) -> tuple:
    """Stage 3a: the baseline fitted once on the development samples without a prior (the pilot),
    to choose what the folds then share: the buffer (from its residuals' autocorrelation,
    :func:`~ctrplan.discrepancy.measured.split.choose_buffer`) and the prior's scale (its rms Eq. (49)
    residual). It never sees the test split.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
        Without a buffer yet.
    options : DiscrepancyOptions

    Returns
    -------
    split : DataSplit
        With the buffer.
    residual_scale : float
        rms Eq. (49) residual of the pilot fit [mm + deg].
    pilot : CalibrationResult
    """
    data = setup.data
    stage = setup.stages.load("pilot")
    if stage is not None:
        pilot = CalibrationResult.from_dict(stage)
        logger.log(progress_level(), "  pilot: reused from an earlier run")
    else:
        logger.log(progress_level(), "calibrating the baseline once on the development samples (pilot: buffer and "
                                     "prior scale) ...")
        pilot = calibrate(setup.robot, data.take(split.fit_rows(data)), "standard", setup.base_names,
                          start=FitStart(register=setup.register), max_evaluations=options.max_evaluations,
                          run=FitRun(settings=setup.settings, n_jobs=options.n_jobs, uncertainty=False))
        setup.stages.save("pilot", pilot.as_dict())
    dev = split.dev_rows
    e = evaluate_rows(setup, dev, "pilot-residual", "standard", dict(zip(*pilot.all_parameters())),
                      n_jobs=options.n_jobs)
    choice = choose_buffer(e.residual_base, data.take(dev), split.block_samples)
    scale = float(np.sqrt(pilot.cost / max(pilot.n_samples, 1)))
    return split.with_buffer(choice), scale, pilot


def baseline_prior(setup, strength: float, scale: float) -> dict:
    """The prior of strength ``strength`` (tau) toward the robot file's tube parameters:
    ``{name: (file value, tau |file value| / scale)}`` (a relative change tau costs as much as one
    sample's Eq. (49) residual of ``scale``); empty for tau 0 (the parameters are held) and inf."""
    if not (0.0 < strength < np.inf):
        return {}
    names = _tube_names(setup)
    values = read_parameters(setup.robot, names)
    out = {}
    for n, v in zip(names, values):
        ref = abs(v) if v != 0.0 else parameter(setup.robot, n).scale
        out[n] = (float(v), strength * ref / scale)
    return out


def _baseline_path(setup, split, options, strengths, scale, k, n_jobs) -> dict:
    """The baseline of every prior strength on fold ``k``'s calibration samples: tau inf from the
    cold start (robot file's values, closed-form registration), each stronger prior continued
    from the previous one's minimum, tau 0 the registration alone (tube parameters held at the
    robot file's values). Same procedure for every fold and the development fit."""
    fit_data, units = fit_rows(setup, split, k)
    tube = _tube_names(setup)
    fixed_file = dict(zip(tube, read_parameters(setup.robot, tube)))
    out, prev = {}, None
    for tau in sorted(strengths, reverse=True):
        kw = dict(max_evaluations=options.max_evaluations,
                  run=FitRun(settings=setup.settings, n_jobs=n_jobs, uncertainty=k is None, clusters=units))
        cold = FitStart(register=setup.register)
        if tau == 0.0:
            names = tuple(n for n in setup.base_names if n in REGISTRATION)
            fit = calibrate(setup.robot, fit_data, "standard", names, fixed=fixed_file, start=cold, **kw)
        elif prev is None:
            fit = calibrate(setup.robot, fit_data, "standard", setup.base_names,
                            prior=baseline_prior(setup, tau, scale), start=cold, **kw)
        else:
            fit = calibrate(setup.robot, fit_data, "standard", setup.base_names,
                            prior=baseline_prior(setup, tau, scale),
                            start=FitStart(prev.values, register=setup.register, warm=True), **kw)
        out[tau] = fit
        prev = fit if tau > 0 else prev
    return out


def _tau_name(tau: float) -> str:
    return "baseline" + ("-file" if tau == 0 else "" if np.isinf(tau) else f"-tau{tau:g}")


def calibrate_baseline(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions,
                       progress: bool = False, *, residual_scale: float = 1.0) -> Baseline:
    """Stage 3b: the baseline (standard model), by least squares on Eq. (49) of Ha, Fagogenis &
    Dupont 2019 (:func:`~ctrplan.discrepancy.fits.calibrate.calibrate`) with a prior toward the robot
    file's tube parameters, on the development samples and without each fold.

    The prior adds rows ``residual_scale (theta - theta_file) / (tau |theta_file|)`` for every tube
    parameter (:func:`baseline_prior`); its strength tau is the one of ``options.prior_strengths``
    whose baseline has the lowest mean out-of-fold Eq. (49) residual, among them 0 (the robot
    file's tube parameters with only a registration) and inf (no prior). Every strength is
    cross-validated with the same folds; fits finished by an earlier run are reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
        With its buffer (:func:`pilot_fit`).
    options : DiscrepancyOptions
    progress : bool
        Progress bars of the model evaluations.
    residual_scale : float, keyword-only
        The pilot fit's rms Eq. (49) residual [mm + deg] (:func:`pilot_fit`).

    Returns
    -------
    Baseline
        With the chosen strength, every strength's out-of-fold figures and its comparison with
        the robot file's parameters, and the parameters' clustered standard errors, changes from
        the robot file's values and typical ranges
        (:func:`~ctrplan.discrepancy.fits.estimates.parameter_table`).
    """
    strengths = tuple(sorted(set(float(t) for t in options.prior_strengths) | {0.0}, reverse=True))
    cache: dict = {}

    def path(k, n_jobs):
        if k not in cache:
            cache[k] = _baseline_path(setup, split, options, strengths, residual_scale, k, n_jobs)
        return cache[k]

    # the path of every fold is one job; each strength is then stored as its own cross-validated model
    missing = [k for k in [None] + list(range(split.n_folds))
               if any(setup.stages.load(stage_name(_tau_name(t), k)) is None for t in strengths)]
    level = progress_level()
    if missing:
        logger.log(level, f"calibrating the baseline (standard model) with prior strengths "
                          f"{', '.join(f'{t:g}' for t in strengths)} on the development samples and without each of "
                          f"{split.n_folds} folds ({len(missing)} paths) ...")
        parallel = options.n_jobs > 1 and len(missing) > 1
        jobs = [(_baseline_path, (setup, split, options, strengths, residual_scale, k, 1 if parallel else options.n_jobs))
                for k in missing]
        for i, res in run_fits(jobs, options.n_jobs):
            cache[missing[i]] = res
            for t, fit in res.items():
                setup.stages.save(stage_name(_tau_name(t), missing[i]), fit.as_dict())
    with details():     # every strength's own messages as details
        cvs = {t: cross_validate(setup, split, options, _tau_name(t), "standard", lambda k, n, t=t: path(k, n)[t],
                                 progress=progress) for t in strengths}
    file_cv = cvs[0.0]
    choices = tuple(PriorChoice(strength=t, mean_position=float(np.nanmean(cvs[t].oof.position)),
                                mean_eq49=float(np.nanmean(cvs[t].r)), against_file=compare(split, file_cv.r, cvs[t].r))
                    for t in strengths)
    best = min(strengths, key=lambda t: (np.nanmean(cvs[t].r), -t))
    cv = cvs[best]
    base = cv.fit
    logger.log(level, "  prior strength tau: out-of-fold mean tip error "
               + ", ".join(f"{_strength_label(c.strength)} {1e3 * c.mean_position:.3f} mm" for c in choices)
               + f"; chosen: {_strength_text(best)}")
    logger.log(level, f"  baseline: cost {base.cost:.4g} on {base.n_samples} samples, {base.evaluations} model "
                      f"evaluations, {base.seconds:.1f} s ({base.message})")
    tube_names = _tube_names(setup)
    reference = dict(zip(tube_names, read_parameters(setup.robot, tube_names)))
    table = parameter_table(setup.robot, base, setup.base_names, reference=reference)
    if setup.data.frame == PoseFrame.TRACKER:
        # the registration of a tracker-frame file maps between two unrelated frames: any value
        # is typical (its range is the one a robot-frame file must keep)
        table = tuple(replace(row, typical=None, in_typical_range=True,
                              typical_source="tracker frame: any rigid registration")
                      if row.name in REGISTRATION else row for row in table)
    for row in table:
        if not row.in_typical_range or row.at_bound:
            logger.warning(f"  baseline {display_value(row.name, row.value, row.unit)}: "
                           + ("at a bound; " if row.at_bound else "") + f"outside its typical range "
                                                                         f"({row.typical_source})")
    n_fitted = len(base.names)
    return Baseline(cv=cv, bic=information_criterion(base.cost, base.n_samples, n_fitted), parameters=table,
                    strength=best, prior=baseline_prior(setup, best, residual_scale), choices=choices,
                    file_cv=file_cv, residual_scale=residual_scale)


def _strength_label(t: float) -> str:
    return "file" if t == 0 else "none" if np.isinf(t) else f"{t:g}"


def _strength_text(t: float) -> str:
    if t == 0:
        return "the robot file's tube parameters (registration only)"
    if np.isinf(t):
        return "no prior"
    return f"tau = {t:g}"

