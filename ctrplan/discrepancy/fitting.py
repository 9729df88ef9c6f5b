"""Stages 3, 6 and 8 of the discrepancy workflow: the baseline, the candidates and a second effect,
each fitted on the development data and cross-validated over its folds.

Every model is fitted once on all development samples (its reported parameters, with standard
errors clustered over units) and once per fold without that fold's samples and their buffer
(:class:`~ctrplan.discrepancy.split.DataSplit`), by the **same procedure from the same cold
start**: every start scan, coarse grid and least-squares stage runs in every fold fit, and what a
fold fit starts from is that fold's own fit of the model it builds on (the baseline, the contact
baseline, the named effect). No fold fit sees its validation samples, not even through a
starting point. The fold fits give the out-of-fold errors that the decision reads
(:func:`~ctrplan.discrepancy.evaluation.out_of_fold`). Chosen once on the development data and
reused by the folds: the buffer and the scale of the prior (from the pilot fit,
:func:`pilot_fit`), and the prior's strength (by the baseline's out-of-fold error,
:func:`calibrate_baseline`).

How each candidate is fitted is its registry entry's ``fit`` (:data:`ctrplan.effects.FIT_STRATEGIES`),
dispatched through :data:`FITTERS`:

- ``"nested"``: its parameters refitted together with the baseline's, started from the effect
  switched off or, with a start scan (``Effect.scan``), from the best scanned value refined alone
  with the baseline held;
- ``"grid"``: a grid search of its parameters with the tube parameters refitted with the
  clearance model (the paper's friction calibration, Section V-C and Table VII of Ha et al. 2019);
- ``"none"``: nothing to fit: evaluated with the clearance-model tube parameters;
- ``"scan"``: a 1-D scan of its parameters on top of the fit of the effect it follows.

A scan or grid whose best point is at its end is extended there, and a least-squares value at an
optimizer bound has the bound widened, up to the parameter's limit (``ParameterSpec.limit``);
only a value at that limit is "at bound".
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ..effects import MODEL_ORDER, REGISTRY
from .calibrate import (FAILED_RESIDUAL, CalibrationResult, _Objective, _uncertainty, calibrate, eq49_residuals,
                        grid_search, information_criterion)
from .data import MeasuredData
from .evaluation import Errors, error_summary, out_of_fold
from .options import CONFIDENCE, DiscrepancyOptions
from .parameters import REGISTRATION, parameter, read_parameters
from .setup import DiscrepancySetup, effect_parameters, reported_parameters
from .split import DataSplit, choose_buffer, subsample
from .statistics import cv_comparison, holm

__all__ = ["CrossValidated", "Baseline", "Candidate", "Combination", "FITTERS", "cross_validate", "pilot_fit",
           "calibrate_baseline", "refit_contact_baseline", "fit_candidates", "fit_second_effect", "scan_fit",
           "atypical_values", "parameter_table", "display_value", "combined_model", "needs_contact_baseline",
           "candidate_report", "candidate_reports", "contained", "compare", "pair_decision"]


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
class Baseline:
    """Stage 3: the calibrated baseline (standard model) and the choice of its prior.

    Attributes
    ----------
    cv : CrossValidated
        The baseline with the chosen prior strength.
    bic : float
        BIC of its development fit (:func:`~ctrplan.discrepancy.calibrate.information_criterion`).
    parameters : list of dict
        :func:`parameter_table` of its fitted values: uncertainty, change from the robot file's
        value, typical range.
    strength : float
        The chosen prior strength tau (0: the robot file's tube parameters, only the registration
        fitted; inf: no prior).
    prior : dict
        ``{name: (robot file's value, scale)}`` of the chosen prior (:class:`~ctrplan.discrepancy.calibrate.Prior`);
        empty for tau 0 and inf.
    choices : list of dict
        Every strength tried: ``strength``, its out-of-fold mean tip error [m] and Eq. (49)
        residual, and its comparison with the robot file's parameters
        (:func:`~ctrplan.discrepancy.statistics.cv_comparison`, positive: better than the file).
    file_cv : CrossValidated
        The robot file's tube parameters with only a registration fitted (tau 0).
    residual_scale : float
        The pilot fit's rms Eq. (49) residual [mm + deg] that scales the prior.
    """

    cv: CrossValidated
    bic: float
    parameters: list
    strength: float
    prior: dict
    choices: list
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


@dataclass(frozen=True, eq=False)
class Candidate:
    """A candidate effect (or, in :class:`Combination`, a pair of effects), fitted and cross-validated.

    Attributes
    ----------
    effects : tuple of str
        The effect, or the named effect and the second one.
    label : str
    cv : CrossValidated
    shown : dict of str to float
        The parameters reported as its own [SI].
    units : dict of str to str
    parameters : list of dict
        :func:`parameter_table` of the shown parameters.
    atypical : list of dict
        Shown values outside their typical range (:func:`atypical_values`), each with what to check.
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
    improvement : dict
        :func:`~ctrplan.discrepancy.statistics.cv_comparison` of the out-of-fold Eq. (49)
        residuals against the baseline's (against the named effect's for a pair) [mm + deg].
    improvement_position : dict
        The same for the tip position errors [m].
    fit_note : str
        What its fits say about themselves ("" if nothing).
    improvement_significant : bool or None
        Its improvement is significant within its Holm family (stage 7 or 8).
    eligible : bool or None
        It may be named (stage 7): significant, not significantly worse than another candidate,
        not at a bound.
    significant : bool or None
        A pair's verdict (stage 8).
    reverse : dict or None
        A pair against its second effect alone (does the named effect still add anything?).
    """

    effects: tuple
    label: str
    cv: CrossValidated
    shown: dict
    units: dict
    parameters: list
    atypical: list
    at_bound: tuple
    widened: tuple
    n_parameters: int
    bic: float
    delta_bic: float
    improvement: dict
    improvement_position: dict
    fit_note: str = ""
    improvement_significant: bool | None = None
    eligible: bool | None = None
    significant: bool | None = None
    reverse: dict | None = None

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


@dataclass(frozen=True, eq=False)
class Combination:
    """Stage 8: a second effect fitted together with the named one.

    Attributes
    ----------
    first, first_label : str
        The named effect.
    named : str or None
        The second effect named with it (the pair is the final model).
    dropped : str or None
        The named effect, when a pair shows it adds nothing once the second effect is in (the
        second effect alone is then the final model: ``replaced_by``).
    replaced_by : str or None
    tried : mapping of str to Candidate
        Second effect -> the pair fitted and cross-validated.
    not_tried : mapping of str to str
        Every other candidate -> why it was not tried with the named one.
    family : tuple of str
        Every candidate that could be paired with the named one: the Holm family of the pairs
        (a pair not tried counts with p = 1).
    rule : str
        The rule a pair is named by.
    """

    first: str
    first_label: str
    named: str | None
    tried: Mapping[str, Candidate]
    not_tried: Mapping[str, str]
    family: tuple
    rule: str
    dropped: str | None = None
    replaced_by: str | None = None


# --------------------------------------------------------------------------- helpers
def display_value(name: str, value: float, unit: str) -> str:
    """A parameter for a printed report: rad as deg, m as mm, others in their SI unit."""
    if unit == "rad":
        return f"{name} = {np.rad2deg(value):.4g} deg"
    if unit == "m":
        return f"{name} = {value * 1e3:.4g} mm"
    return f"{name} = {value:.4g}" + ("" if unit == "-" else f" {unit}")


def atypical_values(robot, params: Mapping) -> list:
    """Fitted values outside their typical range: ``[{name, value, typical, typical_text, unit, why,
    check}]`` (``why``: the range's source; ``check``: what to check on the robot)."""
    out = []
    for name, value in params.items():
        p = parameter(robot, name)
        if not p.is_typical(value):
            out.append({"name": name, "value": float(value), "typical": list(p.typical), "unit": p.unit,
                        "typical_text": p.typical_text(), "why": p.typical_source, "check": p.check})
    return out


def parameter_table(robot, fit: CalibrationResult, names, *, reference: Mapping | None = None) -> list:
    """The fitted parameters ``names`` of ``fit`` as a report reads them.

    Returns
    -------
    list of dict
        Per parameter: ``name``, ``unit``, ``value``, ``stderr`` (clustered over units when the
        fit computed it so) and the ``ci`` at :data:`~ctrplan.discrepancy.options.CONFIDENCE`
        (normal approximation; None without a standard error), ``typical`` range and whether
        the value lies in it, ``at_bound`` (flag of the fit), ``resolution`` of a scan or grid
        that set it, and, with ``reference`` (e.g. the robot file's values), ``reference`` and
        ``relative_change``.
    """
    from scipy import stats

    z = float(stats.norm.ppf(0.5 + CONFIDENCE / 2))
    values = dict(zip(fit.names, fit.values))
    errors = dict(zip(fit.names, fit.stderr)) if fit.stderr is not None else {}
    flagged = {b.split(" ")[0] for b in fit.at_bound}
    out = []
    for n in names:
        v = float(values.get(n, fit.fixed.get(n, np.nan)))
        p = parameter(robot, n)
        se = errors.get(n)
        row = {"name": n, "unit": p.unit, "value": v, "stderr": None if se is None else float(se),
               "ci": None if se is None or not np.isfinite(se) else [v - z * se, v + z * se],
               "typical": None if p.typical is None else list(p.typical), "in_typical_range": p.is_typical(v),
               "typical_source": p.typical_source, "check": p.check, "at_bound": n in flagged,
               "resolution": p.resolution, "fitted": n in values}
        if reference is not None and n in reference:
            ref = float(reference[n])
            row.update({"reference": ref, "relative_change": (v - ref) / ref if ref else None})
        out.append(row)
    return out


def combined_model(*effects: str) -> str:
    """Mechanics model of effects together: the most complete one any of them needs."""
    return max((REGISTRY[e].model for e in effects), key=MODEL_ORDER.index)


def needs_contact_baseline(effect: str) -> bool:
    """The effect's fit starts from the clearance-model refit of the tube parameters."""
    e = REGISTRY[effect]
    return e.fit in ("grid", "none") or (e.after is not None and needs_contact_baseline(e.after))


def contained(a: str, b: str) -> bool:
    """One of the two effects contains the other (never combined)."""
    return a in REGISTRY[b].contains or b in REGISTRY[a].contains


def compare(split: DataSplit, err_a, err_b) -> dict:
    """:func:`~ctrplan.discrepancy.statistics.cv_comparison` of two models' out-of-fold errors at
    the development samples (positive: b is better)."""
    return cv_comparison(err_a, err_b, split.fold[split.dev_rows], confidence=CONFIDENCE)


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


def scan_fit(robot, data: MeasuredData, model: str, fixed: dict, names, values, settings, n_jobs, *,
             uncertainty: bool = True, clusters=None) -> CalibrationResult:
    """Best of a 1-D scan: every parameter in ``names`` set to each of ``values`` in turn, the
    others ``fixed``; the cost (Eq. (49)) of each trial and the scan's resolution in the message.
    A best value at the scan's last value (or its first, where the effect does not vanish there)
    extends the scan by its own pattern, up to the parameters' limit; only a best value at that
    limit is "at bound" (not converged)."""
    t0 = time.perf_counter()
    names = (names,) if isinstance(names, str) else tuple(names)
    values = tuple(sorted(float(v) for v in values))
    obj = _Objective(robot, data, model, names, fixed, settings, n_jobs)
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
    se, corr = _uncertainty(obj, specs, x, clusters) if uncertainty else (None, None)
    return CalibrationResult(model, names, x, np.zeros(len(names)), dict(fixed), float(r @ r), data.n_samples,
                             int((r == FAILED_RESIDUAL).sum()), obj.evaluations, time.perf_counter() - t0,
                             f"scan of {', '.join(names)} (value: cost) {trail}; best {b:.4g}; resolution "
                             f"{resolution:.4g}" + (f"; at the end of the scan, not converged" if edge else ""),
                             not edge, se, corr, edge, tuple(widened))


# --------------------------------------------------------------------------- cross-validation
def _run_fits(jobs: list, n_jobs: int):
    """Run independent fits ``[(callable, args)]``: in joblib (loky) worker processes when there
    are several and ``n_jobs`` > 1, else here; yields the results in order as they finish (so
    that each is stored before the next ends: an interrupted run loses at most the fits under way)."""
    if n_jobs > 1 and len(jobs) > 1:
        from joblib import Parallel, delayed

        yield from Parallel(n_jobs=min(n_jobs, len(jobs)), return_as="generator")(delayed(f)(*a) for f, a in jobs)
    else:
        for f, a in jobs:
            yield f(*a)


def _fit_rows(setup, split: DataSplit, k: int | None, limit: int | None = None) -> tuple[MeasuredData, np.ndarray]:
    """The samples fold ``k``'s fit uses (all development samples for None; at most ``limit`` of
    them, evenly chosen) and their units."""
    rows = split.fit_rows(setup.data, k)
    if limit is not None:
        rows = subsample(setup.data, rows, limit, split.seed)
    return setup.data.take(rows), split.units[rows]


def cross_validate(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions, name: str, model: str,
                   fit_one, *, evaluate: bool = True, echo=print, progress: bool = False) -> CrossValidated:
    """Fit a model on all development samples and without each fold, and its out-of-fold errors.

    The fits are independent (each fold's from the same cold start), so they run in parallel
    worker processes with ``options.n_jobs`` > 1, each with one model-evaluation process.

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
    echo : callable
    progress : bool

    Returns
    -------
    CrossValidated
    """
    fits, todo = {}, []
    for k in [None] + list(range(split.n_folds)):
        done = setup.stages.load(_stage(name, k))
        if done is not None:
            fits[k] = CalibrationResult.from_dict(done)
        else:
            todo.append(k)
    if len(todo) < split.n_folds + 1:
        echo(f"  fit-{name}: {split.n_folds + 1 - len(todo)} of {split.n_folds + 1} fits reused from an earlier run")
    if todo:
        parallel = options.n_jobs > 1 and len(todo) > 1
        echo(f"  fitting {name} ({model} model) on the development samples and without each of {split.n_folds} folds"
             + (f" ({len(todo)} fits, {min(options.n_jobs, len(todo))} at once)" if parallel else f" ({len(todo)} fits)")
             + " ...")
        inner = 1 if parallel else options.n_jobs
        for k, res in zip(todo, _run_fits([(fit_one, (k, inner)) for k in todo], options.n_jobs)):
            fits[k] = res
            setup.stages.save(_stage(name, k), res.as_dict())
    folds = tuple(fits[k] for k in range(split.n_folds))
    oof = r = None
    if evaluate:
        oof = out_of_fold(setup, split, name, model, [dict(zip(*f.all_parameters())) for f in folds],
                          n_jobs=options.n_jobs, progress=progress, echo=echo)
        r = eq49_residuals(oof.position, oof.angle)
    return CrossValidated(name=name, model=model, fit=fits[None], folds=folds, params=dict(zip(*fits[None].all_parameters())),
                          oof=oof, r=r, fold=split.fold[split.dev_rows])


def _stage(name: str, k: int | None) -> str:
    return f"fit-{name}" + ("" if k is None else f"-fold{k}")


# --------------------------------------------------------------------------- stage 3
def _tube_names(setup) -> tuple:
    return tuple(n for n in setup.base_names if n not in REGISTRATION)


def pilot_fit(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions, echo=print) -> tuple:
    """Stage 3a: the baseline fitted once on the development samples without a prior (the pilot),
    to choose what the folds then share: the buffer (from its residuals' autocorrelation,
    :func:`~ctrplan.discrepancy.split.choose_buffer`) and the prior's scale (its rms Eq. (49)
    residual). It never sees the test split.

    Returns
    -------
    split : DataSplit
        With the buffer.
    residual_scale : float
        rms Eq. (49) residual of the pilot fit [mm + deg].
    pilot : CalibrationResult
    """
    from .evaluation import evaluate_rows

    data = setup.data
    stage = setup.stages.load("pilot")
    if stage is not None:
        pilot = CalibrationResult.from_dict(stage)
        echo("  pilot: reused from an earlier run")
    else:
        echo("calibrating the baseline once on the development samples (pilot: buffer and prior scale) ...")
        pilot = calibrate(setup.robot, data.take(split.fit_rows(data)), "standard", setup.base_names, settings=setup.settings,
                          n_jobs=options.n_jobs, register=setup.register, max_evaluations=options.max_evaluations,
                          uncertainty=False)
        setup.stages.save("pilot", pilot.as_dict())
    dev = split.dev_rows
    e = evaluate_rows(setup, dev, "pilot-residual", "standard", dict(zip(*pilot.all_parameters())),
                      n_jobs=options.n_jobs, echo=echo)
    buffer, why = choose_buffer(e.residual_base, data.take(dev), split.block_samples)
    scale = float(np.sqrt(pilot.cost / max(pilot.n_samples, 1)))
    echo(f"  buffer: {why}; prior scale: the pilot's rms Eq. (49) residual {scale:.3g} mm + deg")
    return split.with_buffer(buffer, why), scale, pilot


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
    fit_data, units = _fit_rows(setup, split, k)
    tube = _tube_names(setup)
    fixed_file = dict(zip(tube, read_parameters(setup.robot, tube)))
    out, prev = {}, None
    for tau in sorted(strengths, reverse=True):
        kw = dict(settings=setup.settings, n_jobs=n_jobs, register=setup.register,
                  max_evaluations=options.max_evaluations, uncertainty=k is None, clusters=units)
        if tau == 0.0:
            names = tuple(n for n in setup.base_names if n in REGISTRATION)
            fit = calibrate(setup.robot, fit_data, "standard", names, fixed=fixed_file, **kw)
        elif prev is None:
            fit = calibrate(setup.robot, fit_data, "standard", setup.base_names,
                            prior=baseline_prior(setup, tau, scale), **kw)
        else:
            fit = calibrate(setup.robot, fit_data, "standard", setup.base_names, initial=prev.values, warm=True,
                            prior=baseline_prior(setup, tau, scale), **kw)
        out[tau] = fit
        prev = fit if tau > 0 else prev
    return out


def _tau_name(tau: float) -> str:
    return "baseline" + ("-file" if tau == 0 else "" if np.isinf(tau) else f"-tau{tau:g}")


def calibrate_baseline(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions, echo=print,
                       progress: bool = False, *, residual_scale: float = 1.0) -> Baseline:
    """Stage 3b: the baseline (standard model), by least squares on Eq. (49) of Ha, Fagogenis &
    Dupont 2019 (:func:`~ctrplan.discrepancy.calibrate.calibrate`) with a prior toward the robot
    file's tube parameters, on the development samples and without each fold.

    The prior adds rows ``residual_scale (theta - theta_file) / (tau |theta_file|)`` for every tube
    parameter (:func:`baseline_prior`); its strength tau is the one of ``options.prior_strengths``
    whose baseline has the lowest mean out-of-fold Eq. (49) residual, among them 0 (the robot
    file's tube parameters with only a registration) and inf (no prior). Every strength is
    cross-validated with the same folds; fits finished by an earlier run are reused.

    Returns
    -------
    Baseline
        With the chosen strength, every strength's out-of-fold figures and its comparison with
        the robot file's parameters, and the parameters' clustered standard errors, changes from
        the robot file's values and typical ranges (:func:`parameter_table`).
    """
    strengths = tuple(sorted(set(float(t) for t in options.prior_strengths) | {0.0}, reverse=True))
    cache: dict = {}

    def path(k, n_jobs):
        if k not in cache:
            cache[k] = _baseline_path(setup, split, options, strengths, residual_scale, k, n_jobs)
        return cache[k]

    # the path of every fold is one job; each strength is then stored as its own cross-validated model
    missing = [k for k in [None] + list(range(split.n_folds))
               if any(setup.stages.load(_stage(_tau_name(t), k)) is None for t in strengths)]
    if missing:
        echo(f"calibrating the baseline (standard model) with prior strengths {', '.join(f'{t:g}' for t in strengths)} "
             f"on the development samples and without each of {split.n_folds} folds ({len(missing)} paths) ...")
        parallel = options.n_jobs > 1 and len(missing) > 1
        for k, res in zip(missing, _run_fits([(_baseline_path, (setup, split, options, strengths, residual_scale, k,
                                                                 1 if parallel else options.n_jobs))
                                              for k in missing], options.n_jobs)):
            cache[k] = res
            for t, fit in res.items():
                setup.stages.save(_stage(_tau_name(t), k), fit.as_dict())
    cvs = {t: cross_validate(setup, split, options, _tau_name(t), "standard", lambda k, n, t=t: path(k, n)[t],
                             echo=lambda s: None, progress=progress) for t in strengths}
    file_cv = cvs[0.0]
    choices = []
    for t in strengths:
        cv = cvs[t]
        cmp = compare(split, file_cv.r, cv.r)
        choices.append({"strength": t, "mean_position_m": float(np.nanmean(cv.oof.position)),
                        "mean_eq49": float(np.nanmean(cv.r)), "against_file": cmp})
    best = min(strengths, key=lambda t: (np.nanmean(cvs[t].r), -t))
    cv = cvs[best]
    base = cv.fit
    echo("  prior strength tau: out-of-fold mean tip error "
         + ", ".join(f"{_strength_label(c['strength'])} {1e3 * c['mean_position_m']:.3f} mm" for c in choices)
         + f"; chosen: {_strength_text(best)}")
    echo(f"  baseline: cost {base.cost:.4g} on {base.n_samples} samples, {base.evaluations} model evaluations, "
         f"{base.seconds:.1f} s ({base.message})")
    tube_names = _tube_names(setup)
    reference = dict(zip(tube_names, read_parameters(setup.robot, tube_names)))
    table = parameter_table(setup.robot, base, setup.base_names, reference=reference)
    if setup.data.frame == "tracker":
        # the registration of a tracker-frame file maps between two unrelated frames: any value
        # is typical (its range is the one a robot-frame file must keep)
        for row in table:
            if row["name"] in REGISTRATION:
                row.update(typical=None, in_typical_range=True, typical_source="tracker frame: any rigid registration")
    for row in table:
        if not row["in_typical_range"] or row["at_bound"]:
            echo(f"  baseline {display_value(row['name'], row['value'], row['unit'])}: "
                 + ("at a bound; " if row["at_bound"] else "") + f"outside its typical range ({row['typical_source']})")
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


# --------------------------------------------------------------------------- stage 6
def refit_contact_baseline(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, options: DiscrepancyOptions,
                           echo=print) -> CrossValidated | None:
    """Stage 6a: the baseline's tube parameters refitted with the clearance model (with the same
    prior), on the development samples and without each fold, each started from the baseline's
    fit of the same samples; shared by the candidates fitted on it (friction, clearance; Section
    V-C and Table VII of Ha et al. 2019), within ``options.max_contact_evaluations``, on at most
    ``options.max_contact_samples`` of the fit's samples (a contact solve costs some 30 standard
    ones).

    Returns
    -------
    CrossValidated or None
        Without out-of-fold errors; None when no candidate needs it.
    """
    if not any(needs_contact_baseline(e) for e in setup.effects):
        return None

    def fit_one(k, n_jobs):
        base = baseline.cv.fold_fit(k)
        fit_data, units = _fit_rows(setup, split, k, options.max_contact_samples)
        return calibrate(setup.robot, fit_data, "clearance", base.names, fixed=base.fixed, initial=base.values,
                         settings=setup.settings, n_jobs=n_jobs, max_evaluations=options.max_contact_evaluations,
                         uncertainty=False, warm=True, prior=baseline.prior, clusters=units)

    cv = cross_validate(setup, split, options, "contact-baseline", "clearance", fit_one, evaluate=False, echo=echo)
    echo(f"  clearance-model tube parameters: cost {cv.fit.cost:.4g}, {cv.fit.evaluations} evaluations"
         + ("" if cv.fit.converged else "; NOT converged (stopped at its budget)"))
    return cv


def _fit_nested(ctx) -> CalibrationResult:
    """Its parameters with the baseline's, from the effect switched off (or a start scan)."""
    setup, entry, base, options, extra = ctx["setup"], ctx["entry"], ctx["base"], ctx["options"], ctx["extra"]
    robot, fit_data, settings, n_jobs = setup.robot, ctx["fit_data"], setup.settings, ctx["n_jobs"]
    base_all = dict(zip(*base.all_parameters()))
    names = tuple(base.names) + extra
    init = np.concatenate([base.values, read_parameters(robot, extra)])
    if entry.scan is not None and extra:
        # best of a 1-D scan, then the effect's own parameters alone with the baseline held
        # (a few parameters: cheap steps), then everything together
        best = scan_fit(robot, fit_data, entry.model, base_all, extra, entry.scan, settings, n_jobs, uncertainty=False)
        alone = calibrate(robot, fit_data, entry.model, extra, fixed=base_all, initial=best.values,
                          settings=settings, n_jobs=n_jobs, max_evaluations=options.max_evaluations,
                          uncertainty=False)
        init[len(base.names):] = alone.values
    return calibrate(robot, fit_data, entry.model, names, fixed=base.fixed, initial=init, settings=settings,
                     n_jobs=n_jobs, max_evaluations=options.max_evaluations, uncertainty=ctx["k"] is None,
                     prior=ctx["prior"], clusters=ctx["units"])


def _refine_contact(ctx, start: CalibrationResult, names: tuple) -> CalibrationResult:
    """A contact-model candidate's parameters ``names``, started from its grid or scan
    (``start``), refitted together with the baseline's parameters with its own model.

    The grid and the scan only place the coefficients: they run on tube parameters fitted with the
    clearance model, which absorb part of the friction. Refitting everything together, as the
    standard-model candidates are (:func:`_fit_nested`), sizes the coefficients continuously and
    leaves no misfit for a second effect to take up in place of the first. The baseline's prior is
    kept; a value at the limit of its grid or scan stays reported at bound.
    """
    setup, options, k = ctx["setup"], ctx["options"], ctx["k"]
    base = ctx["base"]
    values = dict(zip(*start.all_parameters()))
    fitted = tuple(base.names) + tuple(n for n in names if n not in base.names)
    fixed = {n: v for n, v in values.items() if n not in fitted}
    init = [values[n] if n in values else read_parameters(setup.robot, (n,))[0] for n in fitted]
    fit = calibrate(setup.robot, ctx["fit_data"], start.model, fitted, fixed=fixed, initial=init,
                    settings=setup.settings, n_jobs=ctx["n_jobs"], max_evaluations=options.max_contact_evaluations,
                    uncertainty=k is None, warm=True, prior=ctx["prior"], clusters=ctx["units"])
    return replace(fit, message=f"{start.message}; then refitted with the baseline's parameters: {fit.message}",
                   at_bound=tuple(sorted(set(fit.at_bound) | set(start.at_bound))),
                   widened=tuple(start.widened) + tuple(fit.widened), converged=fit.converged and start.converged)


def _fit_grid(ctx) -> CalibrationResult:
    """A grid search of its parameters on the clearance-model tube parameters, then those
    parameters refitted together with the baseline's (:func:`_refine_contact`)."""
    setup, options = ctx["setup"], ctx["options"]
    g = grid_search(setup.robot, ctx["fit_data"], ctx["contact"], ctx["extra"], ctx["entry"].model,
                    settings=setup.settings, n_jobs=ctx["n_jobs"], coarse=options.friction_grid,
                    search_samples=options.friction_search_samples, seed=options.seed,
                    uncertainty=False, clusters=ctx["units"])
    return _refine_contact(ctx, g, tuple(ctx["extra"]))


def _fit_none(ctx) -> CalibrationResult:
    """Nothing to fit: evaluated with the clearance-model tube parameters."""
    setup = ctx["setup"]
    return calibrate(setup.robot, ctx["fit_data"], ctx["entry"].model, (), fixed=ctx["contact"],
                     settings=setup.settings, n_jobs=ctx["n_jobs"])


def _fit_scan(ctx) -> CalibrationResult:
    """A 1-D scan on top of the fit of the effect it follows; with a contact model, then its
    parameters and those of the effect it follows refitted together with the baseline's
    (:func:`_refine_contact`)."""
    setup, entry = ctx["setup"], ctx["entry"]
    contact = entry.model != "standard"
    s = scan_fit(setup.robot, ctx["fit_data"], entry.model, ctx["after"], ctx["extra"], entry.scan,
                 setup.settings, ctx["n_jobs"], uncertainty=ctx["k"] is None and not contact, clusters=ctx["units"])
    if not contact:
        return s
    followed = effect_parameters(setup.robot, entry.after, setup.data)
    return _refine_contact(ctx, s, tuple(followed) + tuple(ctx["extra"]))


#: Fitting strategy of an effect entry (``Effect.fit``) -> the function that fits it.
FITTERS = {"nested": _fit_nested, "grid": _fit_grid, "none": _fit_none, "scan": _fit_scan}


def _fit_note(effect: str, c: CrossValidated, base: Baseline, contact: CrossValidated | None, options) -> str:
    """What a candidate's fits say about themselves: not converged, at a bound, worse on the
    calibration data than the baseline, or better there but worse out of fold (overfitting)."""
    notes = []
    if needs_contact_baseline(effect) and contact is not None and not contact.converged:
        notes.append(f"the clearance-model refit of the tube parameters it shares did not converge (stopped at the "
                     f"budget of {options.max_contact_evaluations} evaluations): the candidate may be underrated")
    budget = [f"fold {k + 1}" for k, f in enumerate(c.folds) if not f.converged and not f.at_bound]
    if not c.fit.converged and not c.fit.at_bound:
        budget.insert(0, "the development fit")
    if budget:
        notes.append(f"its fit did not converge (stopped at the evaluation budget): {', '.join(budget)}")
    bounds = sorted(set(c.fit.at_bound) | {b for f in c.folds for b in f.at_bound})
    if bounds:
        notes.append(f"at its limit, not converged: {'; '.join(bounds)}")
    fit, bfit = c.fit, base.fit
    base_mean, cand_mean = float(np.nanmean(base.oof.position)), float(np.nanmean(c.oof.position))
    if fit.cost > bfit.cost * (1 + 1e-9):
        if REGISTRY[effect].fit == "nested":
            notes.append(f"it fits the calibration data worse than the baseline (cost {fit.cost:.4g} against "
                         f"{bfit.cost:.4g}) although it contains the baseline: the fit failed")
        else:
            notes.append(f"it fits the calibration data worse than the standard baseline (cost {fit.cost:.4g} against "
                         f"{bfit.cost:.4g}): the {fit.model} model with the shared refitted tube parameters does not "
                         f"reach the standard model's fit")
    elif cand_mean > base_mean:
        notes.append(f"it fits the calibration data better (cost {fit.cost:.4g} against {bfit.cost:.4g}) but the "
                     f"held-out folds worse (mean {cand_mean * 1e3:.3f} against {base_mean * 1e3:.3f} mm): its "
                     f"parameters absorb a pattern of the calibration samples that does not hold elsewhere "
                     f"(overfitting)")
    return "; ".join(notes)


def _candidate(setup, split, baseline, effects, label, cv, shown_names, reference: "Candidate | Baseline", note,
               widened=()) -> Candidate:
    robot = setup.robot
    params = cv.params
    shown = {n: float(params[n]) for n in shown_names}
    k_total = len(set(baseline.fit.names) | set(shown_names))
    bic = information_criterion(cv.fit.cost, cv.fit.n_samples, k_total)
    at_bound = tuple(sorted(set(cv.fit.at_bound) | {b for f in cv.folds for b in f.at_bound}))
    widened = tuple(sorted(set(widened) | set(cv.fit.widened) | {w for f in cv.folds for w in f.widened}))
    return Candidate(
        effects=tuple(effects), label=label, cv=cv, shown=shown, units={n: parameter(robot, n).unit for n in shown},
        parameters=parameter_table(robot, cv.fit, shown_names), atypical=atypical_values(robot, shown),
        at_bound=at_bound, widened=widened, n_parameters=k_total, bic=bic, delta_bic=bic - reference.bic,
        improvement=compare(split, reference.r, cv.r),
        improvement_position=compare(split, reference.oof.position, cv.oof.position),
        fit_note=note)


def _context(setup, split, baseline, contact, candidates, entry, extra, options, k, n_jobs) -> dict:
    fit_data, units = _fit_rows(setup, split, k, None if entry.model == "standard" else options.max_contact_samples)
    return {"setup": setup, "entry": entry, "k": k, "extra": extra, "options": options, "n_jobs": n_jobs,
            "fit_data": fit_data, "units": units, "base": baseline.cv.fold_fit(k), "prior": baseline.prior,
            "contact": None if contact is None else contact.fold_params(k),
            "after": None if entry.after is None else candidates[entry.after].cv.fold_params(k)}


def fit_candidates(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, contact: CrossValidated | None,
                   options: DiscrepancyOptions, echo=print, progress: bool = False) -> dict:
    """Stage 6b: switch each candidate effect on, fit it by its entry's strategy (:data:`FITTERS`)
    on the development samples and without each fold (each fold from its own baseline), and
    compare its out-of-fold errors with the baseline's
    (:func:`~ctrplan.discrepancy.statistics.cv_comparison`). Fits finished by an earlier run are
    reused.

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
        echo(f"candidate {entry.label}: fitting {', '.join(extra) or 'no parameters'} ({entry.model} model) ...")

        def fit_one(k, n_jobs, entry=entry, extra=extra):
            return FITTERS[entry.fit](_context(setup, split, baseline, contact, candidates, entry, extra, options, k,
                                               n_jobs))

        cv = cross_validate(setup, split, options, e, entry.model, fit_one, echo=echo, progress=progress)
        c = _candidate(setup, split, baseline, (e,), entry.label, cv, reported_parameters(robot, e, data), baseline,
                       _fit_note(e, cv, baseline, contact, options))
        if entry.after is not None and candidates[entry.after].at_bound:
            # it carries the values of the fit it starts from: a value at its limit there is one here
            c = replace(c, at_bound=tuple(sorted(set(c.at_bound) | set(candidates[entry.after].at_bound))))
        candidates[e] = c
        imp = c.improvement
        held = error_summary(c.oof.position, c.oof.angle, c.oof.seconds, c.oof.rows.size)
        echo(f"  {entry.label}: " + (", ".join(display_value(n, v, c.units[n]) for n, v in c.shown.items()) or "nominal")
             + f"; out-of-fold mean {held['position_mean_mm']:.3f} mm, max {held['position_max_mm']:.3f} mm; "
               f"error lower by {100 * imp['reduction']:.0f} % ({100 * imp['reduction_ci'][0]:.0f}.."
               f"{100 * imp['reduction_ci'][1]:.0f} %; {imp['mean_difference']:.3f} mm + deg), p = {imp['p_value']:.3g}"
             + (f"; {c.fit_note}" if c.fit_note else ""))
    return candidates


# --------------------------------------------------------------------------- stage 8
def _fit_pair(ctx) -> CalibrationResult:
    """A second effect fitted together with the named one, on fold ``k``'s samples.

    Started from the named effect's fit of the same samples. With the standard model: the second
    effect's own procedure (its start scan, then its parameters alone) with the named fit held,
    then every parameter together. With a contact model: the tube parameters refitted with the
    clearance model with the named effect's own parameters in place, the second effect by its own
    strategy (its grid, or its parameters alone from its single fit of the same samples), then
    every effect parameter and the baseline's parameters refitted together with the contact model,
    as a contact candidate alone is (:func:`_refine_contact`); every value is fitted with the other
    effect present.
    """
    setup, options, k, n_jobs = ctx["setup"], ctx["options"], ctx["k"], ctx["n_jobs"]
    robot, settings, fit_data, units = setup.robot, setup.settings, ctx["fit_data"], ctx["units"]
    first, second, model = ctx["first"], ctx["second"], ctx["model"]
    f1 = first.cv.fold_fit(k)
    p1 = dict(zip(*f1.all_parameters()))
    entry = REGISTRY[second.effects[0]]
    extra = ctx["extra"]
    if model == "standard":
        own = second.cv.fold_params(k)
        start = np.array([own[n] for n in extra], float)
        if entry.scan is not None:
            start = scan_fit(robot, fit_data, model, p1, extra, entry.scan, settings, n_jobs, uncertainty=False).values
        alone = calibrate(robot, fit_data, model, extra, fixed=p1, initial=start, settings=settings, n_jobs=n_jobs,
                          max_evaluations=options.max_evaluations, uncertainty=False)
        names = tuple(f1.names) + extra
        init = np.concatenate([f1.values, alone.values])
        return calibrate(robot, fit_data, model, names, fixed=f1.fixed, initial=init, settings=settings, n_jobs=n_jobs,
                         max_evaluations=options.max_evaluations, uncertainty=k is None, warm=True,
                         prior=ctx["prior"], clusters=units)
    budget = options.max_contact_evaluations
    # the baseline parameters the named fit fitted (the robot file's, held by a prior of strength 0, stay held)
    base_names = tuple(n for n in setup.base_names if n in f1.names)
    first_extra = tuple(n for n in f1.names if n not in base_names)
    held = {n: v for n, v in p1.items() if n not in base_names}
    tube = calibrate(robot, fit_data, "clearance", base_names, fixed=held, initial=[p1[n] for n in base_names],
                     settings=settings, n_jobs=n_jobs, max_evaluations=budget, uncertainty=False, warm=True,
                     prior=ctx["prior"])
    params = {**held, **dict(zip(base_names, tube.values))}
    if entry.fit == "grid":
        g = grid_search(robot, fit_data, params, extra, model, settings=settings, n_jobs=n_jobs,
                        coarse=options.friction_grid, search_samples=options.friction_search_samples, seed=options.seed,
                        uncertainty=False)
        params.update(zip(extra, g.values))
    else:
        own = second.cv.fold_params(k)
        if extra:
            alone = calibrate(robot, fit_data, model, extra, fixed=params, initial=[own[n] for n in extra],
                              settings=settings, n_jobs=n_jobs, max_evaluations=budget, uncertainty=False, warm=True)
            params.update(zip(extra, alone.values))
    free = base_names + tuple(dict.fromkeys(n for n in (*first_extra, *extra) if n not in base_names))
    if not free:
        return calibrate(robot, fit_data, model, (), fixed=params, settings=settings, n_jobs=n_jobs)
    fixed = {n: v for n, v in params.items() if n not in free}
    return calibrate(robot, fit_data, model, free, fixed=fixed, initial=[params[n] for n in free], settings=settings,
                     n_jobs=n_jobs, max_evaluations=budget, uncertainty=k is None, warm=True, prior=ctx["prior"],
                     clusters=units)


def fit_second_effect(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, contact: CrossValidated | None,
                      naming, options: DiscrepancyOptions, echo=print, progress: bool = False) -> Combination | None:
    """Stage 8: a second effect fitted together with the named one, and whether either adds to
    the other (nested comparisons in both directions).

    The family: every other candidate that does not contain the named one or lie inside it
    (``Effect.contains``), adds a parameter, and can be fitted without a third effect (Holm over
    this family, fixed before any pair is fitted; a pair not tried counts with p = 1). Tried:
    those whose fit alone lowered the baseline's out-of-fold error on average (one that alone
    makes it worse is not fitted). Each pair is fitted jointly (:func:`_fit_pair`) on the
    development samples and without each fold, cross-validated, and compared with the named
    effect alone (does the second effect add?) and with the second effect alone (does the named
    effect still add?). A pair is named when it improves on the named effect significantly
    (Holm), no fitted value is at its limit, and the named effect still adds to it significantly
    (``options.significance``); among such pairs the one with the lowest out-of-fold error. When
    the best significant pair is not better than its second effect alone, the named effect is
    dropped: it goes to zero when fitted with the second, and the second effect alone is the
    final model.

    Returns
    -------
    Combination or None
        None when no effect is named.
    """
    named = naming.named
    if not named:
        return None
    robot, data = setup.robot, setup.data
    candidates = naming.candidates
    first = candidates[named]
    first_names = reported_parameters(robot, named, data)
    rule = (f"out-of-fold Eq. (49) improvement over {first.label} alone significant at {options.significance} "
            f"(corrected resampled t test over the folds, Holm over the family of pairs), no value at its limit, and "
            f"{first.label} still improving on the second effect alone at {options.significance}")
    not_tried, family, pool = {}, [], []
    for e, c in candidates.items():
        if e == named:
            continue
        if contained(e, named):
            not_tried[e] = f"{'it contains' if named in REGISTRY[e].contains else 'it is contained in'} {first.label}"
            continue
        entry = REGISTRY[e]
        if entry.after is not None and entry.after != named:
            not_tried[e] = f"it is fitted on top of {REGISTRY[entry.after].label}, a third effect"
            continue
        if not tuple(n for n in reported_parameters(robot, e, data) if n not in first.params) and entry.fit != "none":
            not_tried[e] = f"it adds no parameter to {first.label}"
            continue
        family.append(e)
        if not c.improvement["mean_difference"] > 0:
            not_tried[e] = (f"alone it does not lower the baseline's out-of-fold error (mean difference "
                            f"{c.improvement['mean_difference']:.3g} mm + deg): counted in the family, not fitted")
            continue
        pool.append(e)
    tried = {}
    for e in pool:
        model = combined_model(named, e)
        extra = tuple(n for n in effect_parameters(robot, e, data) if n not in first.params)
        tag = f"{named}+{e}"
        echo(f"second effect: {candidates[e].label} with {first.label} ({model} model) ...")

        def fit_one(k, n_jobs, e=e, model=model, extra=extra):
            fit_data, units = _fit_rows(setup, split, k, None if model == "standard" else options.max_contact_samples)
            return _fit_pair({"setup": setup, "options": options, "k": k, "n_jobs": n_jobs, "fit_data": fit_data,
                              "units": units, "first": first, "second": candidates[e], "model": model, "extra": extra,
                              "prior": baseline.prior})

        cv = cross_validate(setup, split, options, tag, model, fit_one, echo=echo, progress=progress)
        shown_names = first_names + tuple(n for n in reported_parameters(robot, e, data) if n not in first_names)
        note = "" if cv.converged else "a fit did not converge or sits at its limit"
        c = _candidate(setup, split, baseline, (named, e), f"{first.label} + {candidates[e].label}", cv, shown_names,
                       first, note)
        tried[e] = replace(c, reverse=compare(split, candidates[e].r, cv.r))
    out, second, dropped, replaced, notes = pair_decision(named, tried, family, naming.decision.get("worse_than", {}),
                                                          options.significance)
    for e, c in out.items():
        imp, rev = c.improvement, c.reverse
        echo(f"  {c.label}: " + ", ".join(display_value(n, v, c.units[n]) for n, v in c.shown.items())
             + f"; error lower than {first.label} alone by {100 * imp['reduction']:.0f} %, p = {imp['p_value']:.3g}; "
               f"than {candidates[e].label} alone by {100 * rev['reduction']:.0f} %, p = {rev['p_value']:.3g}"
             + ("" if c.cv.converged else "; a fit NOT converged"))
    for line in notes:
        echo(line)
    return Combination(first=named, first_label=first.label, named=second, tried=MappingProxyType(out),
                       not_tried=MappingProxyType(not_tried), family=tuple(family), rule=rule, dropped=dropped,
                       replaced_by=replaced)


def pair_decision(named: str, tried: Mapping, family, worse_than: Mapping, alpha: float) -> tuple:
    """Which pair, if any, replaces the named effect (the rule of :func:`fit_second_effect`).

    Parameters
    ----------
    named : str
        The named effect A.
    tried : mapping of str to Candidate
        Second effect B -> the pair fitted jointly, with ``improvement`` (against A alone) and
        ``reverse`` (against B alone) comparisons.
    family : sequence of str
        Every B that could be paired with A (a B not in ``tried`` counts with p = 1).
    worse_than : mapping of str to list of str
        Stage 7's ``{candidate: [candidates significantly better]}``.
    alpha : float

    Returns
    -------
    pairs : dict of str to Candidate
        ``tried`` with ``improvement_significant`` (Holm over ``family``) and ``significant``
        (also no value at its limit).
    second : str or None
        B of the named pair: it improves on A significantly and A still improves on B alone.
    dropped, replaced_by : str or None
        A and B when the best significant pair is no better than B alone (A goes to zero with B)
        and B alone is not significantly worse than A: B alone is the final model.
    notes : list of str
    """
    verdict = holm({e: (tried[e].improvement["p_value"] if e in tried else 1.0) for e in family}, alpha) if family else {}
    out = {}
    for e, c in tried.items():
        ok = bool(verdict.get(e) and c.improvement["mean_difference"] > 0)
        out[e] = replace(c, improvement_significant=ok, significant=ok and not c.at_bound)
    passing = [e for e, c in out.items() if c.significant]
    best = min(passing, key=lambda e: out[e].mean_error) if passing else None
    second = dropped = replaced = None
    notes = []
    if best is not None:
        rev = out[best].reverse
        if rev["p_value"] < alpha and rev["mean_difference"] > 0:
            second = best
            notes.append(f"named combination: {out[best].label}")
        elif named not in worse_than.get(best, ()):
            dropped, replaced = named, best
            notes.append(f"{named} adds nothing once {best} is fitted with it (the pair against {best} alone: "
                         f"p = {rev['p_value']:.3g}): {named} is dropped, {best} alone is the final model")
        else:
            notes.append(f"the pair {out[best].label} improves on {named} alone but not on {best} alone, which is "
                         f"itself significantly worse than {named}: {named} alone stays the final model")
    return out, second, dropped, replaced, notes


# --------------------------------------------------------------------------- report form
def candidate_report(c: Candidate) -> dict:
    """A candidate as ``results.json`` stores it (mm in ``out_of_fold``; SI in ``parameters``)."""
    oof = c.oof
    out = {"effects": list(c.effects), "label": c.label, "model": c.model, "fit": c.fit.as_dict(),
           "folds": [f.as_dict() for f in c.cv.folds], "parameters": c.shown, "units": c.units,
           "parameter_table": c.parameters, "atypical": c.atypical, "typical": c.typical,
           "at_bound": list(c.at_bound), "widened": list(c.widened), "converged": c.cv.converged,
           "n_parameters": c.n_parameters, "bic": c.bic, "delta_bic": c.delta_bic,
           "out_of_fold": error_summary(oof.position, oof.angle, oof.seconds, oof.rows.size),
           "mean_eq49": c.mean_error, "improvement_eq49": c.improvement, "improvement_position": c.improvement_position,
           "fit_note": c.fit_note}
    for key in ("improvement_significant", "eligible", "significant", "reverse"):
        if getattr(c, key) is not None:
            out[key] = getattr(c, key)
    return out


def candidate_reports(candidates: Mapping[str, Candidate]) -> dict:
    """:func:`candidate_report` of every candidate."""
    return {e: candidate_report(c) for e, c in candidates.items()}
