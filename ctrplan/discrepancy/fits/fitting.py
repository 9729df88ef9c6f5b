"""Fitting and cross-validating the models of the discrepancy workflow, and stage 6: the candidate
effects.

Every model is fitted once on all development samples (its reported parameters, with standard
errors clustered over units) and once per fold without that fold's samples and their buffer
(:class:`~ctrplan.discrepancy.measured.split.DataSplit`), by the **same procedure from the same cold
start** (:func:`cross_validate`): every start scan, coarse grid and least-squares stage runs in
every fold fit, and what a fold fit starts from is that fold's own fit of the model it builds on
(the baseline, the contact baseline, the named effect). No fold fit sees its validation samples,
not even through a starting point. The fold fits give the out-of-fold errors that the decision
reads (:func:`~ctrplan.discrepancy.fits.evaluation.out_of_fold`). Chosen once on the development data
and reused by the folds: the buffer and the scale of the prior (from the pilot fit,
:func:`~ctrplan.discrepancy.fits.baseline.pilot_fit`), and the prior's strength (by the baseline's
out-of-fold error, :func:`~ctrplan.discrepancy.fits.baseline.calibrate_baseline`). The baseline is in
:mod:`~ctrplan.discrepancy.fits.baseline`, a second effect fitted with the named one in
:mod:`~ctrplan.discrepancy.fits.pairs`.

How each candidate is fitted is its registry entry's ``fit``, a :class:`ctrplan.effects.FitStrategy`
called with a :class:`FitContext` (the fit's samples, its starting fits and the solvers):

- ``NESTED``: its parameters refitted together with the baseline's, started from the effect
  switched off or, with a start scan (``Effect.scan``), from the best scanned value refined alone
  with the baseline held;
- ``GRID``: a grid search of its parameters with the tube parameters refitted with the
  clearance model (the paper's friction calibration, Section V-C and Table VII of Ha et al. 2019),
  then refitted together with the baseline's parameters;
- ``NO_FIT``: nothing to fit: evaluated with the clearance-model tube parameters;
- ``SCAN``: a 1-D scan of its parameters on top of the fit of the effect it follows.

A scan or grid whose best point is at its end is extended there, and a least-squares value at an
optimizer bound has the bound widened, up to the parameter's limit (``ParameterSpec.limit``);
only a value at that limit is "at bound".
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

import numpy as np

from ..._log import progress_level
from ...choices import FitNoteKind
from ...effects import REGISTRY
from ...models import MODEL_INFO, MODELS
from ...parallel import Executor
from .calibrate import CalibrationResult, _uncertainty, calibrate, information_criterion
from .objective import FitObjective
from .fitoptions import FitRun, FitStart, GridSpec
from ..measured.data import MeasuredData
from .estimates import atypical_values, display_value, parameter_table
from .evaluation import ErrorFigures, Errors, out_of_fold
from .gridsearch import grid_search
from ..options import CONFIDENCE, DiscrepancyOptions
from .parameters import parameter, read_parameters
from .predictions import FAILED_RESIDUAL, eq49_residuals
from ..setup import DiscrepancySetup, effect_parameters, reported_parameters
from ..measured.split import DataSplit, subsample
from ..verdict.reasons import FitNote
from ..verdict.statistics import Comparison, cv_comparison

__all__ = ["CrossValidated", "Candidate", "FitContext", "cross_validate", "refit_contact_baseline", "fit_candidates",
           "scan_fit", "combined_model", "needs_contact_baseline", "contained", "compare", "run_fits", "fit_rows", "stage_name",
           "make_candidate"]

logger = logging.getLogger(__name__)


# --------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class CrossValidated:
    """A model fitted on the development samples and cross-validated over their folds.

    Attributes
    ----------
    name : str
        Its stage name (``"baseline"``, an effect, ``"<a>+<b>"``).
    model : str
        Mechanics model (``"standard"``, ``"clearance"``, ``"friction"``).
    fit : CalibrationResult
        Fitted on every development sample (at most ``max_calibration_samples``); the reported
        parameters, with standard errors (cost in (mm + deg)^2, Eq. (49)).
    folds : tuple of CalibrationResult
        Fitted without each fold.
    params : dict of str to float
        ``fit``'s parameters, fitted and fixed [SI].
    oof : Errors or None
        Out-of-fold errors at the development samples [m, rad] (None where not evaluated).
    r : ndarray, shape (K_dev,), or None
        Their Eq. (49) residuals [mm + deg].
    fold : ndarray of int, shape (K_dev,), or None
        The fold that validated each development sample.
    """

    name: str
    model: str
    fit: CalibrationResult
    folds: tuple
    params: dict
    oof: Errors | None
    r: np.ndarray | None
    fold: np.ndarray | None = None

    def fold_params(self, k: int | None) -> dict:
        """The parameters fitted without fold ``k`` (the development fit's for None) [SI]."""
        return dict(self.params) if k is None else dict(zip(*self.folds[k].all_parameters()))

    def fold_fit(self, k: int | None) -> CalibrationResult:
        """The fit without fold ``k`` (the development fit for None)."""
        return self.fit if k is None else self.folds[k]

    @property
    def converged(self) -> bool:
        """Every fit converged (no budget stop, no value at a bound it could not widen)."""
        return bool(self.fit.converged and all(f.converged for f in self.folds))


@dataclass(frozen=True, eq=False)
class Candidate:
    """A candidate effect (or, in :class:`~ctrplan.discrepancy.fits.pairs.Combination`, a pair of effects),
    fitted and cross-validated.

    Attributes
    ----------
    effects : tuple of str
        The effect, or the named effect and the second one.
    label : str
    cv : CrossValidated
    shown : dict of str to float
        The parameters reported as its own [SI].
    units : dict of str to str
    parameters : tuple of ParameterEstimate
        :func:`~ctrplan.discrepancy.fits.estimates.parameter_table` of the shown parameters.
    atypical : tuple of AtypicalValue
        Shown values outside their typical range
        (:func:`~ctrplan.discrepancy.fits.estimates.atypical_values`), each with what to check.
    at_bound : tuple of str
        Fitted values at a bound or a grid's or scan's edge that could not be widened (the
        development fit's or a fold's).
    widened : tuple of str
        Bounds, grids and scans widened because a fit ended at them.
    n_parameters : int
        Parameters counted in its BIC (the baseline's included).
    bic, delta_bic : float
        BIC of the development fit, and its difference to the baseline's (to the named effect's
        for a pair).
    improvement : Comparison
        :func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison` of the out-of-fold Eq. (49)
        residuals against the baseline's (against the named effect's for a pair) [mm + deg].
    improvement_position : Comparison
        The same for the tip position errors [m].
    fit_notes : tuple of FitNote
        What its fits say about themselves (empty if nothing).
    improvement_significant : bool or None
        Its improvement is significant within its Holm family (stage 7 or 8).
    eligible : bool or None
        It may be named (stage 7): significant, not significantly worse than another candidate,
        not at a bound.
    significant : bool or None
        A pair's verdict (stage 8).
    reverse : Comparison or None
        A pair against its second effect alone (does the named effect still add anything?).
    """

    effects: tuple
    label: str
    cv: CrossValidated
    shown: dict
    units: dict
    parameters: tuple
    atypical: tuple
    at_bound: tuple
    widened: tuple
    n_parameters: int
    bic: float
    delta_bic: float
    improvement: Comparison
    improvement_position: Comparison
    fit_notes: tuple = ()
    improvement_significant: bool | None = None
    eligible: bool | None = None
    significant: bool | None = None
    reverse: Comparison | None = None

    @property
    def model(self) -> str:
        return self.cv.model

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

    @property
    def typical(self) -> bool:
        """Every shown value within its typical range."""
        return not self.atypical

    @property
    def mean_error(self) -> float:
        """Mean out-of-fold Eq. (49) residual [mm + deg]."""
        return float(np.nanmean(self.r))

    @property
    def out_of_fold_figures(self) -> ErrorFigures:
        """Its out-of-fold errors at the development samples summarized [m, rad]."""
        return ErrorFigures.of(self.oof)


# --------------------------------------------------------------------------- helpers
def combined_model(*effects: str) -> str:
    """Mechanics model of effects together: the most complete one any of them needs (the latest in
    :data:`ctrplan.models.MODELS`)."""
    return max((REGISTRY[e].model for e in effects), key=MODELS.index)


def needs_contact_baseline(effect: str) -> bool:
    """The effect's fit starts from the clearance-model refit of the tube parameters."""
    e = REGISTRY[effect]
    return e.fit.from_contact_baseline or (e.after is not None and needs_contact_baseline(e.after))


def contained(a: str, b: str) -> bool:
    """One of the two effects contains the other (never combined)."""
    return a in REGISTRY[b].contains or b in REGISTRY[a].contains


def compare(split: DataSplit, err_a, err_b) -> Comparison:
    """:func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison` of two models' out-of-fold errors at
    the development samples (positive: b is better), always the corrected resampled t test.

    Every comparison that can name an effect uses it: a candidate against the baseline, two
    candidates, a pair against either of its effects, a containing candidate against the one it
    contains. The uncorrected form holds its level for a model against one it contains only while
    the residual is the noise: with a slow unmodelled discrepancy beside it (any real robot's, and
    any misspecified file's) its rejection rate at 0.0014 is 0.011, eight times the level, where
    the corrected one gives 0.0021; and candidates fitted with a contact model (their own tube
    parameters, a grid search of the friction coefficients) do not contain the baseline at all.
    The size of this test at the workflow's levels is what tests/test_discrepancy_statistics.py
    checks (:func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison`'s notes give the
    figures and the power it costs).
    """
    return cv_comparison(err_a, err_b, split.fold[split.dev_rows], confidence=CONFIDENCE, corrected=True)


def grid_spec(options: DiscrepancyOptions) -> GridSpec:
    """The friction grid of ``options`` (``friction_grid``, ``friction_search_samples``, ``seed``)
    as :func:`~ctrplan.discrepancy.fits.gridsearch.grid_search` takes it."""
    return GridSpec(coarse=options.friction_grid, search_samples=options.friction_search_samples, seed=options.seed)


def _extend_scan(values: tuple, spec, end: str) -> tuple:
    """The scan ``values`` (increasing) continued past its ``end`` ("upper"/"lower") by its own
    pattern, within the parameter's limit; () when it cannot go further."""
    v = np.asarray(values, float)
    lo, hi = spec.hard
    if end == "upper":
        more = v[-1] + (v[1:] - v[0])
        more = more[more <= hi + 1e-12]
    else:
        more = (v[0] - (v[-1] - v[:-1]))[::-1]
        more = more[more >= lo - 1e-12]
    return tuple(more.tolist())


def scan_fit(robot, data: MeasuredData, model: str, fixed: dict, names, values, *,
             run: FitRun = FitRun()) -> CalibrationResult:
    """Best of a 1-D scan: every parameter in ``names`` set to each of ``values`` in turn, the
    others ``fixed``; the cost (Eq. (49)) of each trial and the scan's resolution in the message.
    A best value at the scan's last value (or its first, where the effect does not vanish there)
    extends the scan by its own pattern, up to the parameters' limit; only a best value at that
    limit is "at bound" (not converged). ``run``: solver settings, worker processes, standard
    errors and their clusters (:class:`~ctrplan.discrepancy.fits.fitoptions.FitRun`)."""
    t0 = time.perf_counter()
    settings, n_jobs, uncertainty, clusters = run.settings, run.n_jobs, run.uncertainty, run.clusters
    names = (names,) if isinstance(names, str) else tuple(names)
    values = tuple(sorted(float(v) for v in values))
    obj = FitObjective(robot, data, model, names, fixed, settings, n_jobs)
    specs = [parameter(robot, n) for n in names]
    tight = max(specs, key=lambda p: p.hard[0])  # the narrowest limit governs a common scan
    costs = {}
    widened = []
    while True:
        for v in values:
            if v not in costs:
                r = obj.residuals(np.full(len(names), v))
                costs[v] = float(r @ r)
        axis = sorted(costs)
        b = min(costs, key=costs.get)
        side = "upper" if b == axis[-1] else "lower" if (b == axis[0] and not all(p.vanishes_at_lower for p in specs)) \
            else None
        if side is None or len(axis) < 2:
            break
        more = _extend_scan(tuple(axis), min(specs, key=lambda p: p.hard[1]) if side == "upper" else tight, side)
        if not more:
            break
        widened.append(f"scan of {', '.join(names)} extended to {more[-1] if side == 'upper' else more[0]:.4g} "
                       f"{specs[0].unit}")
        values = more
    x = np.full(len(names), b)
    r = obj.residuals(x)
    edge = ()
    if side is not None and len(axis) > 1:
        edge = tuple(f"{n} (end of its scan at {b:.4g} {p.unit}, its limit)" for n, p in zip(names, specs))
    resolution = float(np.min(np.diff(axis))) if len(axis) > 1 else float("nan")
    trail = ", ".join(f"{v:.4g}: {costs[v]:.4g}" for v in axis)
    unc = _uncertainty(obj, specs, x, clusters) if uncertainty else None
    se, corr = (None, None) if unc is None else (unc.stderr, unc.correlation)
    return CalibrationResult(model, names, x, np.zeros(len(names)), dict(fixed), float(r @ r), data.n_samples,
                             int((r == FAILED_RESIDUAL).sum()), obj.evaluations, time.perf_counter() - t0,
                             f"scan of {', '.join(names)} (value: cost) {trail}; best {b:.4g}; resolution "
                             f"{resolution:.4g}" + ("; at the end of the scan, not converged" if edge else ""),
                             not edge, se, corr, edge, tuple(widened),
                             n_clusters=None if unc is None else unc.n_clusters)


# --------------------------------------------------------------------------- cross-validation
def _call(fn, args):
    return fn(*args)


def run_fits(jobs: list, n_jobs: int):
    """Run independent fits ``[(callable, args)]``: on ``n_jobs`` local worker processes when there
    are several (:class:`ctrplan.parallel.Executor`), else here in order.

    Yields
    ------
    tuple
        ``(index into jobs, result)`` as each fit finishes, so that each is stored at once: an
        interrupted run loses at most the fits under way.
    """
    workers = min(n_jobs, len(jobs)) if n_jobs > 1 and len(jobs) > 1 else 1
    with Executor(workers) as ex:
        yield from ex.run(_call, [(i, (f, a)) for i, (f, a) in enumerate(jobs)])


def fit_rows(setup, split: DataSplit, k: int | None, limit: int | None = None) -> tuple[MeasuredData, np.ndarray]:
    """The samples fold ``k``'s fit uses (all development samples for None; at most ``limit`` of
    them, evenly chosen) and their units."""
    rows = split.fit_rows(setup.data, k)
    if limit is not None:
        rows = subsample(setup.data, rows, limit, split.seed)
    return setup.data.take(rows), split.units[rows]


def cross_validate(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions, name: str, model: str,
                   fit_one, *, evaluate: bool = True, progress: bool = False) -> CrossValidated:
    """Fit a model on all development samples and without each fold, and its out-of-fold errors.

    The fits are independent (each fold's from the same cold start), so they run in parallel
    worker processes with ``options.n_jobs`` > 1 (:func:`run_fits`), each with one
    model-evaluation process. Fits stored by an earlier run with the same stage key are reused,
    and each new fit is stored as it finishes.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    options : DiscrepancyOptions
    name : str
        Stage name (fits stored as ``fit-<name>`` and ``fit-<name>-fold<k>``).
    model : str
    fit_one : callable
        ``fit_one(k, n_jobs) -> CalibrationResult``: the fit without fold ``k`` (``k`` None: on
        all development samples), evaluating the model with ``n_jobs`` processes.
    evaluate : bool
        Compute the out-of-fold errors.
    progress : bool
        Progress bars of the model evaluations.

    Returns
    -------
    CrossValidated
    """
    fits, todo = {}, []
    for k in [None] + list(range(split.n_folds)):
        done = setup.stages.load(stage_name(name, k))
        if done is not None:
            fits[k] = CalibrationResult.from_dict(done)
        else:
            todo.append(k)
    level = progress_level()
    if len(todo) < split.n_folds + 1:
        logger.log(level, f"  fit-{name}: {split.n_folds + 1 - len(todo)} of {split.n_folds + 1} fits reused from an "
                          f"earlier run")
    if todo:
        parallel = options.n_jobs > 1 and len(todo) > 1
        logger.log(level, f"  fitting {name} ({model} model) on the development samples and without each of "
                          f"{split.n_folds} folds"
                   + (f" ({len(todo)} fits, {min(options.n_jobs, len(todo))} at once)" if parallel
                      else f" ({len(todo)} fits)") + " ...")
        inner = 1 if parallel else options.n_jobs
        for i, res in run_fits([(fit_one, (k, inner)) for k in todo], options.n_jobs):
            fits[todo[i]] = res
            setup.stages.save(stage_name(name, todo[i]), res.as_dict())
    folds = tuple(fits[k] for k in range(split.n_folds))
    oof = r = None
    if evaluate:
        oof = out_of_fold(setup, split, name, model, [dict(zip(*f.all_parameters())) for f in folds],
                          n_jobs=options.n_jobs, progress=progress)
        r = eq49_residuals(oof.position, oof.angle)
    return CrossValidated(name=name, model=model, fit=fits[None], folds=folds, params=dict(zip(*fits[None].all_parameters())),
                          oof=oof, r=r, fold=split.fold[split.dev_rows])


def stage_name(name: str, k: int | None) -> str:
    """The stage a fit of model ``name`` is stored under: ``fit-<name>`` (development fit, ``k``
    None) or ``fit-<name>-fold<k>``."""
    return f"fit-{name}" + ("" if k is None else f"-fold{k}")


# --------------------------------------------------------------------------- stage 6
def refit_contact_baseline(setup: DiscrepancySetup, split: DataSplit, baseline, options: DiscrepancyOptions
                           ) -> CrossValidated | None:
    """Stage 6a: the baseline's tube parameters refitted with the clearance model (with the same
    prior), on the development samples and without each fold, each started from the baseline's
    fit of the same samples; shared by the candidates fitted on it (friction, clearance; Section
    V-C and Table VII of Ha et al. 2019), within ``options.max_contact_evaluations``, on at most
    ``options.max_contact_samples`` of the fit's samples (a contact solve costs some 30 standard
    ones).

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    baseline : Baseline
        Stage 3 (:func:`~ctrplan.discrepancy.fits.baseline.calibrate_baseline`).
    options : DiscrepancyOptions

    Returns
    -------
    CrossValidated or None
        Without out-of-fold errors; None when no candidate needs it.
    """
    if not any(needs_contact_baseline(e) for e in setup.effects):
        return None

    def fit_one(k, n_jobs):
        base = baseline.cv.fold_fit(k)
        fit_data, units = fit_rows(setup, split, k, options.max_contact_samples)
        return calibrate(setup.robot, fit_data, "clearance", base.names, fixed=base.fixed, prior=baseline.prior,
                         start=FitStart(base.values, warm=True), max_evaluations=options.max_contact_evaluations,
                         run=FitRun(settings=setup.settings, n_jobs=n_jobs, uncertainty=False, clusters=units))

    cv = cross_validate(setup, split, options, "contact-baseline", "clearance", fit_one, evaluate=False)
    logger.log(progress_level(), f"  clearance-model tube parameters: cost {cv.fit.cost:.4g}, {cv.fit.evaluations} "
                                 f"evaluations" + ("" if cv.fit.converged else "; NOT converged (stopped at its budget)"))
    return cv


@dataclass(frozen=True)
class FitContext:
    """What a fit strategy (:class:`ctrplan.effects.FitStrategy`) fits one candidate from: the
    fit's samples, its starting fits and the solvers, bound to them.

    Attributes
    ----------
    setup : DiscrepancySetup
    entry : Effect
        The candidate's registry entry.
    k : int or None
        The fold left out (None: the development fit).
    extra : tuple of str
        The effect's fitted parameters on these data.
    options : DiscrepancyOptions
    n_jobs : int
    fit_data : MeasuredData
        The fit's samples.
    units : ndarray of int or None
        Their clusters for the standard errors.
    base : CalibrationResult
        The baseline's fit of the same samples.
    prior : object
        The baseline's prior.
    contact : dict or None
        The clearance-model refit of the tube parameters on the same samples (stage 6a).
    after : dict or None
        The fitted parameters of the effect this one follows (``Effect.after``) on the same samples.
    """

    setup: DiscrepancySetup
    entry: object
    k: int | None
    extra: tuple
    options: DiscrepancyOptions
    n_jobs: int
    fit_data: MeasuredData
    units: object
    base: CalibrationResult
    prior: object
    contact: dict | None
    after: dict | None

    def run(self, uncertainty: bool, clusters=None) -> FitRun:
        """The fit's :class:`~ctrplan.discrepancy.fits.fitoptions.FitRun`: the setup's solver
        settings and ``n_jobs``, with ``uncertainty`` and ``clusters``."""
        return FitRun(settings=self.setup.settings, n_jobs=self.n_jobs, uncertainty=uncertainty, clusters=clusters)

    def calibrate(self, model: str, names, *, fixed=None, prior=None, initial=None, warm: bool = False,
                  max_evaluations: int = 40, uncertainty: bool = True, clusters=None) -> CalibrationResult:
        """:func:`~ctrplan.discrepancy.fits.calibrate.calibrate` of the robot on the fit's samples with
        the setup's solver settings and ``n_jobs``, started from ``initial`` (warm: stage 1 skipped);
        other arguments as there (a strategy calls it without importing the workflow's types)."""
        return calibrate(self.setup.robot, self.fit_data, model, names, fixed=fixed, prior=prior,
                         start=FitStart(initial, warm=warm), max_evaluations=max_evaluations,
                         run=self.run(uncertainty, clusters))

    def scan(self, model: str, fixed, names, values, uncertainty: bool, clusters=None) -> CalibrationResult:
        """:func:`scan_fit` of ``names`` over ``values`` on the fit's samples."""
        return scan_fit(self.setup.robot, self.fit_data, model, fixed, names, values,
                        run=self.run(uncertainty, clusters))

    def grid(self, fixed, names, model: str, uncertainty: bool, clusters=None) -> CalibrationResult:
        """:func:`~ctrplan.discrepancy.fits.gridsearch.grid_search` of ``names`` on the fit's samples
        with the options' grid, search samples and seed."""
        return grid_search(self.setup.robot, self.fit_data, fixed, names, model, grid=grid_spec(self.options),
                           run=self.run(uncertainty, clusters))

    def refine_contact(self, start: CalibrationResult, names: tuple) -> CalibrationResult:
        """A contact-model candidate's parameters ``names``, started from its grid or scan
        (``start``), refitted together with the baseline's parameters with its own model.

        The grid and the scan only place the coefficients: they run on tube parameters fitted
        with the clearance model, which absorb part of the friction. Refitting everything
        together, as the standard-model candidates are, sizes the coefficients continuously and
        leaves no misfit for a second effect to take up in place of the first. The baseline's
        prior is kept; a value at the limit of its grid or scan stays reported at bound.
        """
        base = self.base
        values = dict(zip(*start.all_parameters()))
        fitted = tuple(base.names) + tuple(n for n in names if n not in base.names)
        fixed = {n: v for n, v in values.items() if n not in fitted}
        init = [values[n] if n in values else read_parameters(self.setup.robot, (n,))[0] for n in fitted]
        fit = self.calibrate(start.model, fitted, fixed=fixed, prior=self.prior, initial=init, warm=True,
                             max_evaluations=self.options.max_contact_evaluations, uncertainty=self.k is None,
                             clusters=self.units)
        return replace(fit, message=f"{start.message}; then refitted with the baseline's parameters: {fit.message}",
                       seconds=start.seconds + fit.seconds, evaluations=start.evaluations + fit.evaluations,
                       at_bound=tuple(sorted(set(fit.at_bound) | set(start.at_bound))),
                       widened=tuple(start.widened) + tuple(fit.widened), converged=fit.converged and start.converged)

    def read_parameters(self, names) -> np.ndarray:
        """The robot file's values of ``names`` (SI)."""
        return read_parameters(self.setup.robot, names)

    def effect_parameters(self, effect: str) -> tuple:
        """The parameters the workflow fits for ``effect`` on the setup's data."""
        return effect_parameters(self.setup.robot, effect, self.setup.data)

    @staticmethod
    def needs_contact(model: str) -> bool:
        """The mechanics model ``model`` needs the contact solve."""
        return MODEL_INFO[model].contact

    @staticmethod
    def with_work(fit: CalibrationResult, before) -> CalibrationResult:
        """``fit`` with the time and evaluations of the fits ``before`` it added."""
        return replace(fit, seconds=fit.seconds + sum(f.seconds for f in before),
                       evaluations=fit.evaluations + sum(f.evaluations for f in before))


def _fit_notes(effect: str, c: CrossValidated, base, contact: CrossValidated | None, options) -> tuple:
    """What a candidate's fits say about themselves: not converged, at a bound, worse on the
    calibration data than the baseline, or better there but worse out of fold (overfitting).

    Returns
    -------
    tuple of FitNote
    """
    notes = []
    if needs_contact_baseline(effect) and contact is not None and not contact.converged:
        notes.append(FitNote(FitNoteKind.CONTACT_REFIT_NOT_CONVERGED, max_evaluations=options.max_contact_evaluations))
    folds = tuple(k + 1 for k, f in enumerate(c.folds) if not f.converged and not f.at_bound)
    development = not c.fit.converged and not c.fit.at_bound
    if folds or development:
        notes.append(FitNote(FitNoteKind.NOT_CONVERGED, development=development, folds=folds))
    bounds = sorted(set(c.fit.at_bound) | {b for f in c.folds for b in f.at_bound})
    if bounds:
        notes.append(FitNote(FitNoteKind.AT_LIMIT, limits=tuple(bounds)))
    fit, bfit = c.fit, base.fit
    base_mean, cand_mean = float(np.nanmean(base.oof.position)), float(np.nanmean(c.oof.position))
    costs = {"cost": float(fit.cost), "baseline_cost": float(bfit.cost)}
    if fit.cost > bfit.cost * (1 + 1e-9):
        if REGISTRY[effect].fit.contains_baseline:
            notes.append(FitNote(FitNoteKind.WORSE_THAN_CONTAINED_BASELINE, **costs))
        else:
            notes.append(FitNote(FitNoteKind.WORSE_THAN_STANDARD_BASELINE, model=fit.model, **costs))
    elif cand_mean > base_mean:
        notes.append(FitNote(FitNoteKind.OVERFITS, mean_m=cand_mean, baseline_mean_m=base_mean, **costs))
    return tuple(notes)


def make_candidate(setup, split, baseline, effects, label, cv, shown_names, reference, notes=()) -> Candidate:
    """A fitted and cross-validated model as a :class:`Candidate`: its shown parameters
    ``shown_names`` with their table and atypical values, its BIC (every baseline and shown
    parameter counted) and its comparisons with ``reference`` (the baseline, or the named
    effect for a pair: anything with ``bic``, ``r`` and ``oof``)."""
    robot = setup.robot
    params = cv.params
    shown = {n: float(params[n]) for n in shown_names}
    k_total = len(set(baseline.fit.names) | set(shown_names))
    bic = information_criterion(cv.fit.cost, cv.fit.n_samples, k_total)
    at_bound = tuple(sorted(set(cv.fit.at_bound) | {b for f in cv.folds for b in f.at_bound}))
    widened = tuple(sorted(set(cv.fit.widened) | {w for f in cv.folds for w in f.widened}))
    return Candidate(
        effects=tuple(effects), label=label, cv=cv, shown=shown, units={n: parameter(robot, n).unit for n in shown},
        parameters=parameter_table(robot, cv.fit, shown_names), atypical=atypical_values(robot, shown),
        at_bound=at_bound, widened=widened, n_parameters=k_total, bic=bic, delta_bic=bic - reference.bic,
        improvement=compare(split, reference.r, cv.r),
        improvement_position=compare(split, reference.oof.position, cv.oof.position),
        fit_notes=tuple(notes))


def _context(setup, split, baseline, contact, candidates, entry, extra, options, k, n_jobs) -> FitContext:
    fit_data, units = fit_rows(setup, split, k, options.max_contact_samples if MODEL_INFO[entry.model].contact else None)
    return FitContext(setup=setup, entry=entry, k=k, extra=extra, options=options, n_jobs=n_jobs,
                      fit_data=fit_data, units=units, base=baseline.cv.fold_fit(k), prior=baseline.prior,
                      contact=None if contact is None else contact.fold_params(k),
                      after=None if entry.after is None else candidates[entry.after].cv.fold_params(k))


def fit_candidates(setup: DiscrepancySetup, split: DataSplit, baseline, contact: CrossValidated | None,
                   options: DiscrepancyOptions, progress: bool = False) -> dict:
    """Stage 6b: switch each candidate effect on, fit it by its entry's strategy (``Effect.fit``)
    on the development samples and without each fold (each fold from its own baseline), and
    compare its out-of-fold errors with the baseline's
    (:func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison`). Fits finished by an earlier run are
    reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    baseline : Baseline
        Stage 3.
    contact : CrossValidated or None
        Stage 6a (:func:`refit_contact_baseline`).
    options : DiscrepancyOptions
    progress : bool
        Progress bars of the model evaluations.

    Returns
    -------
    dict of str to Candidate
        One per effect of ``setup.effects``, in order, without the naming verdicts.
    """
    robot, data = setup.robot, setup.data
    candidates = {}
    for e in setup.effects:
        entry = REGISTRY[e]
        extra = effect_parameters(robot, e, data)
        logger.log(progress_level(), f"candidate {entry.label}: fitting {', '.join(extra) or 'no parameters'} "
                                     f"({entry.model} model) ...")

        def fit_one(k, n_jobs, entry=entry, extra=extra):
            return entry.fit.fit(_context(setup, split, baseline, contact, candidates, entry, extra, options, k,
                                          n_jobs))

        cv = cross_validate(setup, split, options, e, entry.model, fit_one, progress=progress)
        c = make_candidate(setup, split, baseline, (e,), entry.label, cv, reported_parameters(robot, e, data), baseline,
                       _fit_notes(e, cv, baseline, contact, options))
        if entry.after is not None and candidates[entry.after].at_bound:
            # it carries the values of the fit it starts from: a value at its limit there is one here
            c = replace(c, at_bound=tuple(sorted(set(c.at_bound) | set(candidates[entry.after].at_bound))))
        candidates[e] = c
        imp, held = c.improvement, c.out_of_fold_figures
        logger.log(progress_level(),
                   f"  {entry.label}: " + (", ".join(display_value(n, v, c.units[n]) for n, v in c.shown.items())
                                           or "nominal")
                   + f"; out-of-fold mean {1e3 * held.position_mean:.3f} mm, max {1e3 * held.position_max:.3f} mm; "
                     f"error lower by {100 * imp.reduction:.0f} % ({100 * imp.reduction_ci[0]:.0f}.."
                     f"{100 * imp.reduction_ci[1]:.0f} %; {imp.mean_difference:.3f} mm + deg), p = {imp.p_value:.3g}"
                   + (f"; {', '.join(n.kind for n in c.fit_notes)}" if c.fit_notes else ""))
    return candidates

