"""Stages 3, 6 and 8 of the discrepancy workflow: the baseline, the candidates and a second effect,
each fitted on the development data and cross-validated over its folds.

Every model is fitted once on all development samples (its reported parameters, with standard
errors and correlations) and once per fold without that fold's samples, started from the first
fit; the fold fits give the out-of-fold errors that the decision reads
(:func:`~ctrplan.discrepancy.evaluation.out_of_fold`).

How each candidate is fitted is its registry entry's ``fit`` (:data:`ctrplan.effects.FIT_STRATEGIES`),
dispatched through :data:`FITTERS`:

- ``"nested"``: its parameters refitted together with the baseline's, started from the effect
  switched off (the fit can only lower the calibration cost) or, with a start scan
  (``Effect.scan``), from the best scanned value refined alone with the baseline held;
- ``"grid"``: a grid search of its parameters with the tube parameters refitted with the
  clearance model (the paper's friction calibration, Section V-C and Table VII of Ha et al. 2019);
- ``"none"``: nothing to fit: evaluated with the clearance-model tube parameters;
- ``"scan"``: a 1-D scan of its parameters on top of the fit of the effect it follows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ..effects import MODEL_ORDER, REGISTRY
from .calibrate import (FAILED_RESIDUAL, CalibrationResult, _Eq49Model, _Objective, calibrate, covariance,
                        eq49_residuals, grid_search, information_criterion)
from .data import MeasuredData
from .evaluation import Errors, error_summary, out_of_fold
from .options import CONFIDENCE, DiscrepancyOptions
from .parameters import REGISTRATION, parameter, read_parameters
from .setup import DiscrepancySetup, effect_parameters, reported_parameters
from .split import DataSplit
from .statistics import paired_improvement

__all__ = ["CrossValidated", "Baseline", "Candidate", "Combination", "FITTERS", "cross_validate",
           "calibrate_baseline", "refit_contact_baseline", "fit_candidates", "fit_second_effect", "scan_fit",
           "atypical_values", "parameter_table", "display_value", "combined_model", "needs_contact_baseline",
           "candidate_report", "candidate_reports", "contained"]


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
    """

    name: str
    model: str
    fit: CalibrationResult
    folds: tuple
    params: dict
    oof: Errors | None
    r: np.ndarray | None

    def fold_params(self, k: int) -> dict:
        """The parameters fitted without fold ``k`` [SI]."""
        return dict(zip(*self.folds[k].all_parameters()))

    @property
    def converged(self) -> bool:
        """Every fit converged (no budget stop, no value at a bound or edge)."""
        return bool(self.fit.converged and all(f.converged for f in self.folds))


@dataclass(frozen=True, eq=False)
class Baseline:
    """Stage 3: the calibrated baseline (standard model).

    Attributes
    ----------
    cv : CrossValidated
    bic : float
        BIC of its development fit (:func:`~ctrplan.discrepancy.calibrate.information_criterion`).
    parameters : list of dict
        :func:`parameter_table` of its fitted values: uncertainty, change from the robot file's
        value, plausibility.
    """

    cv: CrossValidated
    bic: float
    parameters: list

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
        Shown values outside their typical range (:func:`atypical_values`).
    at_bound : tuple of str
        Fitted values at an optimizer bound or a grid's or scan's edge (the development fit's or a
        fold's).
    n_parameters : int
        Parameters counted in its BIC (the baseline's included).
    bic, delta_bic : float
        BIC of the development fit, and its difference to the baseline's (to the named effect's
        for a pair).
    improvement : dict
        :func:`~ctrplan.discrepancy.statistics.paired_improvement` of the out-of-fold Eq. (49)
        residuals over the baseline's (over the named effect's for a pair) [mm + deg], over units.
    improvement_position : dict
        The same for the tip position errors [m].
    fit_note : str
        What its fits say about themselves ("" if nothing).
    signature_significant, improvement_significant, eligible : bool or None
        The naming rule's verdicts (:func:`~ctrplan.discrepancy.decision.name_effect`).
    significant : bool or None
        A pair's verdict (:func:`fit_second_effect`).
    """

    effects: tuple
    label: str
    cv: CrossValidated
    shown: dict
    units: dict
    parameters: list
    atypical: list
    at_bound: tuple
    n_parameters: int
    bic: float
    delta_bic: float
    improvement: dict
    improvement_position: dict
    fit_note: str = ""
    signature_significant: bool | None = None
    improvement_significant: bool | None = None
    eligible: bool | None = None
    significant: bool | None = None

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


@dataclass(frozen=True, eq=False)
class Combination:
    """Stage 8: a second effect fitted on top of the named one.

    Attributes
    ----------
    first, first_label : str
        The named effect.
    named : str or None
        The second effect named with it.
    tried : mapping of str to Candidate
        Second effect -> the pair fitted and cross-validated.
    not_tried : mapping of str to str
        Every other candidate -> why it was not tried on top of the named one.
    rule : str
        The rule a pair is named by.
    """

    first: str
    first_label: str
    named: str | None
    tried: Mapping[str, Candidate]
    not_tried: Mapping[str, str]
    rule: str


# --------------------------------------------------------------------------- helpers
def display_value(name: str, value: float, unit: str) -> str:
    """A parameter for a printed report: rad as deg, m as mm, others in their SI unit."""
    if unit == "rad":
        return f"{name} = {np.rad2deg(value):.4g} deg"
    if unit == "m":
        return f"{name} = {value * 1e3:.4g} mm"
    return f"{name} = {value:.4g}" + ("" if unit == "-" else f" {unit}")


def atypical_values(robot, params: Mapping) -> list:
    """Fitted values outside their typical range: ``[{name, value, typical, unit, why}]``."""
    out = []
    for name, value in params.items():
        p = parameter(robot, name)
        if not p.is_typical(value):
            out.append({"name": name, "value": float(value), "typical": list(p.typical), "unit": p.unit,
                        "why": p.typical_source})
    return out


def parameter_table(robot, fit: CalibrationResult, names, *, reference: Mapping | None = None) -> list:
    """The fitted parameters ``names`` of ``fit`` as a report reads them.

    Returns
    -------
    list of dict
        Per parameter: ``name``, ``unit``, ``value``, ``stderr`` and the ``ci`` at
        :data:`~ctrplan.discrepancy.options.CONFIDENCE` (normal approximation; None without a
        standard error), ``typical`` range and whether the value lies in it, ``at_bound``
        (flag of the fit), ``resolution`` of a scan or grid that set it, and, with ``reference``
        (e.g. the robot file's values), ``reference`` and ``relative_change``.
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
               "typical_source": p.typical_source, "at_bound": n in flagged, "resolution": p.resolution,
               "fitted": n in values}
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


def _grid_progress(echo):
    state = {"last": -1}

    def report(done, total):
        pct = int(100 * done / total)
        if pct // 10 != state["last"]:
            state["last"] = pct // 10
            echo(f"    grid search: {done}/{total} points")
    return report


def scan_fit(robot, data: MeasuredData, model: str, fixed: dict, names, values, settings, n_jobs, *,
             uncertainty: bool = True) -> CalibrationResult:
    """Best of a 1-D scan: every parameter in ``names`` set to each of ``values`` in turn, the
    others ``fixed``; the cost (Eq. (49)) of each trial and the scan's resolution in the message.
    Not converged, with ``at_bound``, when the best value is the scan's last, or its first where
    the effect does not vanish there."""
    t0 = time.perf_counter()
    names = (names,) if isinstance(names, str) else tuple(names)
    values = tuple(float(v) for v in values)
    obj = _Objective(robot, data, model, names, fixed, settings, n_jobs)
    costs = []
    for v in values:
        r = obj.residuals(np.full(len(names), v))
        costs.append(float(r @ r))
    b = int(np.argmin(costs))
    x = np.full(len(names), values[b])
    r = obj.residuals(x)
    specs = [parameter(robot, n) for n in names]
    edge = ()
    if len(values) > 1 and (b == len(values) - 1 or (b == 0 and not all(p.vanishes_at_lower for p in specs))):
        edge = tuple(f"{n} (end of its scan at {values[b]:.4g} {p.unit})" for n, p in zip(names, specs))
    resolution = float(np.min(np.diff(sorted(values)))) if len(values) > 1 else float("nan")
    trail = ", ".join(f"{v:.4g}: {c:.4g}" for v, c in zip(values, costs))
    se, corr = None, None
    if uncertainty:
        lower, upper = np.array([p.lower for p in specs]), np.array([p.upper for p in specs])
        se, corr = covariance(_Eq49Model(obj, lower, upper).jac(x), float(r @ r), data.n_samples)
    return CalibrationResult(model, names, x, np.zeros(len(names)), dict(fixed), float(r @ r), data.n_samples,
                             int((r == FAILED_RESIDUAL).sum()), obj.evaluations, time.perf_counter() - t0,
                             f"scan of {', '.join(names)} (value: cost) {trail}; best {values[b]:.4g}; resolution "
                             f"{resolution:.4g}" + (f"; at the end of the scan, not converged" if edge else ""),
                             not edge, se, corr, edge)


# --------------------------------------------------------------------------- cross-validation
def cross_validate(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions, name: str, model: str,
                   fit_one, *, evaluate: bool = True, echo=print, progress: bool = False) -> CrossValidated:
    """Fit a model on all development samples and without each fold, and its out-of-fold errors.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    options : DiscrepancyOptions
    name : str
        Stage name (fits stored as ``fit-<name>`` and ``fit-<name>-fold<k>``).
    model : str
    fit_one : callable
        ``fit_one(k, start) -> CalibrationResult``: the fit without fold ``k`` (``k`` None: on
        all development samples), ``start`` the development fit for the fold fits (None for it).
    evaluate : bool
        Compute the out-of-fold errors.
    echo : callable
    progress : bool

    Returns
    -------
    CrossValidated
    """
    fits = {}
    for k in [None] + list(range(split.n_folds)):
        stage = f"fit-{name}" + ("" if k is None else f"-fold{k}")
        done = setup.stages.load(stage)
        if done is not None:
            fits[k] = CalibrationResult.from_dict(done)
            echo(f"  {stage}: reused from an earlier run")
            continue
        fits[k] = fit_one(k, fits.get(None))
        setup.stages.save(stage, fits[k].as_dict())
    folds = tuple(fits[k] for k in range(split.n_folds))
    oof = r = None
    if evaluate:
        oof = out_of_fold(setup, split, name, model, [dict(zip(*f.all_parameters())) for f in folds],
                          n_jobs=options.n_jobs, progress=progress, echo=echo)
        r = eq49_residuals(oof.position, oof.angle)
    return CrossValidated(name=name, model=model, fit=fits[None], folds=folds, params=dict(zip(*fits[None].all_parameters())),
                          oof=oof, r=r)


def _dev_units(split: DataSplit) -> np.ndarray:
    return split.units[split.dev_rows]


# --------------------------------------------------------------------------- stage 3
def calibrate_baseline(setup: DiscrepancySetup, split: DataSplit, options: DiscrepancyOptions, echo=print,
                       progress: bool = False) -> Baseline:
    """Stage 3: the baseline (standard model), by least squares on Eq. (49) of Ha, Fagogenis &
    Dupont 2019 (:func:`~ctrplan.discrepancy.calibrate.calibrate`) on the development samples
    and without each fold; its out-of-fold errors. Fits finished by an earlier run are reused.

    Returns
    -------
    Baseline
        With its parameters' standard errors, correlations, changes from the robot file's values
        and plausibility (:func:`parameter_table`).
    """
    data = setup.data

    def fit_one(k, start):
        where = "all development samples" if k is None else f"all but fold {k + 1}"
        echo(f"calibrating the baseline (standard model) on {where} ...")
        return calibrate(setup.robot, data.take(split.fit_rows(data, k)), "standard", setup.base_names,
                         initial=None if start is None else start.values, settings=setup.settings, n_jobs=options.n_jobs,
                         register=setup.register, max_evaluations=options.max_evaluations, uncertainty=k is None,
                         warm=start is not None)

    cv = cross_validate(setup, split, options, "baseline", "standard", fit_one, echo=echo, progress=progress)
    base = cv.fit
    echo(f"  baseline: cost {base.cost:.4g} on {base.n_samples} samples, {base.evaluations} model evaluations, "
         f"{base.seconds:.1f} s ({base.message})")
    tube_names = [n for n in setup.base_names if not n.startswith("registration")]
    reference = dict(zip(tube_names, read_parameters(setup.robot, tube_names)))
    table = parameter_table(setup.robot, base, setup.base_names, reference=reference)
    if setup.data.frame == "tracker":
        # the registration of a tracker-frame file maps between two unrelated frames: any value
        # is typical (its range is the one a robot-frame file must keep)
        for row in table:
            if row["name"] in REGISTRATION:
                row.update(typical=None, in_typical_range=True,
                           typical_source="tracker frame: any rigid registration")
    for row in table:
        if not row["in_typical_range"] or row["at_bound"]:
            echo(f"  baseline {display_value(row['name'], row['value'], row['unit'])}: "
                 + ("at a bound; " if row["at_bound"] else "") + f"outside its typical range ({row['typical_source']})")
    return Baseline(cv=cv, bic=information_criterion(base.cost, base.n_samples, len(base.names)), parameters=table)


# --------------------------------------------------------------------------- stage 6
def refit_contact_baseline(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, options: DiscrepancyOptions,
                           echo=print) -> CrossValidated | None:
    """Stage 6a: the baseline's tube parameters refitted with the clearance model, on the
    development samples and without each fold (started from the baseline's fit of the same
    samples), shared by the candidates fitted on it (friction, clearance; Section V-C and
    Table VII of Ha et al. 2019), within ``options.max_contact_evaluations``.

    Returns
    -------
    CrossValidated or None
        Without out-of-fold errors; None when no candidate needs it.
    """
    if not any(needs_contact_baseline(e) for e in setup.effects):
        return None
    data = setup.data

    def fit_one(k, start):
        base = baseline.fit if k is None else baseline.cv.folds[k]
        echo("recalibrating the tube parameters with the clearance model"
             + ("" if k is None else f" without fold {k + 1}") + " ...")
        return calibrate(setup.robot, data.take(split.fit_rows(data, k)), "clearance", base.names, fixed=base.fixed,
                         initial=(base.values if start is None else start.values), settings=setup.settings,
                         n_jobs=options.n_jobs, max_evaluations=options.max_contact_evaluations, uncertainty=False,
                         warm=start is not None)

    cv = cross_validate(setup, split, options, "contact-baseline", "clearance", fit_one, evaluate=False, echo=echo)
    echo(f"  clearance-model tube parameters: cost {cv.fit.cost:.4g}, {cv.fit.evaluations} evaluations"
         + ("" if cv.fit.converged else "; NOT converged (stopped at its budget)"))
    return cv


def _fit_nested(ctx) -> CalibrationResult:
    """Its parameters with the baseline's, from the effect switched off (or a start scan)."""
    setup, entry, base, options, extra = ctx["setup"], ctx["entry"], ctx["base"], ctx["options"], ctx["extra"]
    robot, fit_data, settings, start = setup.robot, ctx["fit_data"], setup.settings, ctx["start"]
    base_all = dict(zip(*base.all_parameters()))
    names = tuple(base.names) + extra
    if start is not None:
        init = np.asarray(start.values, float)
    else:
        init = np.concatenate([base.values, read_parameters(robot, extra)])
        if entry.scan is not None and extra:
            # best of a 1-D scan, then the effect's own parameters alone with the baseline held
            # (a few parameters: cheap steps), then everything together
            best = scan_fit(robot, fit_data, entry.model, base_all, extra, entry.scan, settings, options.n_jobs,
                            uncertainty=False)
            alone = calibrate(robot, fit_data, entry.model, extra, fixed=base_all, initial=best.values,
                              settings=settings, n_jobs=options.n_jobs, max_evaluations=options.max_evaluations,
                              uncertainty=False)
            init[len(base.names):] = alone.values
    return calibrate(robot, fit_data, entry.model, names, initial=init, settings=settings, n_jobs=options.n_jobs,
                     max_evaluations=options.max_evaluations, uncertainty=ctx["k"] is None, warm=start is not None)


def _fit_grid(ctx) -> CalibrationResult:
    """A grid search of its parameters on the clearance-model tube parameters."""
    setup, options, echo, start = ctx["setup"], ctx["options"], ctx["echo"], ctx["start"]
    return grid_search(setup.robot, ctx["fit_data"], ctx["contact"], ctx["extra"], ctx["entry"].model,
                       settings=setup.settings, n_jobs=options.n_jobs, coarse=options.friction_grid,
                       search_samples=options.friction_search_samples, seed=options.seed,
                       progress=_grid_progress(echo), start=None if start is None else start.values,
                       uncertainty=ctx["k"] is None)


def _fit_none(ctx) -> CalibrationResult:
    """Nothing to fit: evaluated with the clearance-model tube parameters."""
    setup, options = ctx["setup"], ctx["options"]
    return calibrate(setup.robot, ctx["fit_data"], ctx["entry"].model, (), fixed=ctx["contact"],
                     settings=setup.settings, n_jobs=options.n_jobs)


def _fit_scan(ctx) -> CalibrationResult:
    """A 1-D scan on top of the fit of the effect it follows."""
    setup, entry, options = ctx["setup"], ctx["entry"], ctx["options"]
    return scan_fit(setup.robot, ctx["fit_data"], entry.model, ctx["after"], ctx["extra"], entry.scan,
                    setup.settings, options.n_jobs, uncertainty=ctx["k"] is None)


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
        notes.append(f"at a bound or the edge of its grid or scan, not converged: {'; '.join(bounds)}")
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


def _candidate(setup, split, baseline, effects, label, cv, shown_names, reference_r, reference_pos, reference_bic,
               options, note) -> Candidate:
    robot = setup.robot
    params = cv.params
    shown = {n: float(params[n]) for n in shown_names}
    k_total = len(set(setup.base_names) | set(shown_names))
    bic = information_criterion(cv.fit.cost, cv.fit.n_samples, k_total)
    units = _dev_units(split)
    at_bound = tuple(sorted(set(cv.fit.at_bound) | {b for f in cv.folds for b in f.at_bound}))
    return Candidate(
        effects=tuple(effects), label=label, cv=cv, shown=shown, units={n: parameter(robot, n).unit for n in shown},
        parameters=parameter_table(robot, cv.fit, shown_names), atypical=atypical_values(robot, shown),
        at_bound=at_bound, n_parameters=k_total, bic=bic, delta_bic=bic - reference_bic,
        improvement=paired_improvement(reference_r, cv.r, units, seed=options.seed, confidence=CONFIDENCE),
        improvement_position=paired_improvement(reference_pos, cv.oof.position, units, seed=options.seed,
                                                confidence=CONFIDENCE),
        fit_note=note)


def fit_candidates(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, contact: CrossValidated | None,
                   options: DiscrepancyOptions, echo=print, progress: bool = False) -> dict:
    """Stage 6b: switch each candidate effect on, fit it by its entry's strategy (:data:`FITTERS`)
    on the development samples and without each fold, and compare its out-of-fold errors with the
    baseline's over units (:func:`~ctrplan.discrepancy.statistics.paired_improvement`). Fits
    finished by an earlier run are reused.

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

        def fit_one(k, start, entry=entry, extra=extra):
            where = "" if k is None else f" without fold {k + 1}"
            echo(f"candidate {entry.label}: fitting {', '.join(extra) or 'no parameters'} ({entry.model} model){where} ...")
            ctx = {"setup": setup, "entry": entry, "k": k, "start": start, "extra": extra, "options": options, "echo": echo,
                   "fit_data": data.take(split.fit_rows(data, k)),
                   "base": baseline.fit if k is None else baseline.cv.folds[k],
                   "contact": None if contact is None else (contact.params if k is None else contact.fold_params(k)),
                   "after": None if entry.after is None else (candidates[entry.after].params if k is None
                                                              else candidates[entry.after].cv.fold_params(k))}
            return FITTERS[entry.fit](ctx)

        cv = cross_validate(setup, split, options, e, entry.model, fit_one, echo=echo, progress=progress)
        c = candidates[e] = _candidate(setup, split, baseline, (e,), entry.label, cv, reported_parameters(robot, e, data),
                                       baseline.r, baseline.oof.position, baseline.bic, options,
                                       _fit_note(e, cv, baseline, contact, options))
        imp = c.improvement
        held = error_summary(c.oof.position, c.oof.angle, c.oof.seconds, c.oof.rows.size)
        echo(f"  {entry.label}: " + (", ".join(display_value(n, v, c.units[n]) for n, v in c.shown.items()) or "nominal")
             + f"; out-of-fold mean {held['position_mean_mm']:.3f} mm, max {held['position_max_mm']:.3f} mm; "
               f"improvement {imp['mean_difference']:.3f} (+- {imp['se']:.3f}) mm + deg, p = {imp['p_value']:.4f}"
             + (f"; {c.fit_note}" if c.fit_note else ""))
    return candidates


# --------------------------------------------------------------------------- stage 8
def fit_second_effect(setup: DiscrepancySetup, split: DataSplit, baseline: Baseline, contact: CrossValidated | None,
                      naming, options: DiscrepancyOptions, echo=print, progress: bool = False) -> Combination | None:
    """Stage 8: whether a second effect, fitted on top of the named one, still improves the
    out-of-fold error.

    Tried: every other candidate that does not contain the named one or lie inside it
    (``Effect.contains``) and whose cross-validated improvement alone was significant at
    ``options.significance`` (one that alone explains nothing beyond the baseline is said so);
    the report gives the reason for each one not tried. Each pair is fitted like a single
    candidate, on the development samples and without each fold, started from the named
    effect's fit of the same samples and the second effect's values: with the standard model
    the second effect's parameters alone (the named fit held), then everything together; with a
    contact model (dearer by ~30x) the second effect's parameters only, within
    ``options.max_contact_evaluations``, or, for an effect fitted by a grid or a scan (friction,
    gradual friction), the grid's refinements from its own values or its scan; with the tube
    parameters the clearance model was recalibrated to (``contact``: a standard-model fit's tube
    parameters do not fit with the clearance model). The pair is named by the rule for a single effect with
    the named effect in place of the baseline: its out-of-fold improvement over the named effect
    significant (Holm over the pairs tried), every fitted value typical and none at a bound;
    among such pairs the largest improvement.

    Returns
    -------
    Combination or None
        None when no effect is named.
    """
    from .statistics import holm

    named = naming.named
    if not named:
        return None
    robot, data, settings = setup.robot, setup.data, setup.settings
    candidates = naming.candidates
    first = candidates[named]
    first_names = reported_parameters(robot, named, data)
    rule = (f"out-of-fold Eq. (49) improvement over {first.label} alone significant at {options.significance} "
            f"(sign-flip test over units, Holm over the pairs tried), fitted values typical and none at a bound")
    not_tried, pool = {}, []
    for e, c in candidates.items():
        if e == named:
            continue
        if contained(e, named):
            not_tried[e] = f"{'it contains' if named in REGISTRY[e].contains else 'it is contained in'} {first.label}"
        elif not (c.improvement["p_value"] < options.significance and c.improvement["mean_difference"] > 0):
            not_tried[e] = (f"alone it does not lower the cross-validated error significantly "
                            f"(p = {c.improvement['p_value']:.3g})")
        elif not tuple(n for n in reported_parameters(robot, e, data) if n not in first.params):
            not_tried[e] = f"it adds no parameter to {first.label}"
        else:
            pool.append(e)
    tried = {}
    for e in pool:
        model = combined_model(named, e)
        second_names = tuple(n for n in reported_parameters(robot, e, data) if n not in first.params)
        tag = f"{named}+{e}"

        def fit_one(k, start, e=e, model=model, second_names=second_names):
            p_first = first.params if k is None else first.cv.fold_params(k)
            if model != "standard" and contact is not None:
                p_first = {**p_first, **(contact.params if k is None else contact.fold_params(k))}
            own = candidates[e].params if k is None else candidates[e].cv.fold_params(k)
            fit_data = data.take(split.fit_rows(data, k))
            echo(f"second effect: {candidates[e].label} on top of {first.label} ({model} model)"
                 + ("" if k is None else f" without fold {k + 1}") + " ...")
            if start is not None:
                fitted = dict(zip(*start.all_parameters()))
                init2 = np.array([fitted.get(n, own[n]) for n in second_names], float)
            else:
                init2 = np.array([own[n] for n in second_names], float)
            entry = REGISTRY[e]
            if model != "standard" and entry.fit in ("grid", "scan"):
                # a contact-model effect by its own strategy on top of the named fit: the grid's
                # refinements from its own values, or its scan (a least-squares fit of the
                # contact model would cost up to max_contact_evaluations)
                extra = effect_parameters(robot, e, data)
                values = dict(zip(second_names, init2))
                fixed = {**p_first, **{n: v for n, v in values.items() if n not in extra}}
                if entry.fit == "grid":
                    return grid_search(robot, fit_data, fixed, extra, model, settings=settings, n_jobs=options.n_jobs,
                                       start=[values.get(n, own.get(n, 0.0)) for n in extra],
                                       uncertainty=k is None)
                return scan_fit(robot, fit_data, model, fixed, extra, entry.scan, settings, options.n_jobs,
                                uncertainty=k is None)
            if model == "standard" and start is not None:
                # everything together from the pair's fit of all development samples
                return calibrate(robot, fit_data, "standard", tuple(start.names), initial=start.values,
                                 settings=settings, n_jobs=options.n_jobs, max_evaluations=options.max_evaluations,
                                 uncertainty=False, warm=True)
            budget = options.max_evaluations if model == "standard" else options.max_contact_evaluations
            fit = calibrate(robot, fit_data, model, second_names, fixed=p_first, initial=init2, settings=settings,
                            n_jobs=options.n_jobs, max_evaluations=budget, uncertainty=k is None and model != "standard",
                            warm=start is not None)
            if model == "standard":
                names = tuple(p_first) + second_names
                init = np.concatenate([np.array(list(p_first.values()), float), fit.values])
                joint = calibrate(robot, fit_data, "standard", names, initial=init, settings=settings,
                                  n_jobs=options.n_jobs, max_evaluations=options.max_evaluations, uncertainty=k is None)
                if joint.cost <= fit.cost or not fit.converged:
                    fit = joint
            return fit

        cv = cross_validate(setup, split, options, tag, model, fit_one, echo=echo, progress=progress)
        shown_names = first_names + tuple(n for n in reported_parameters(robot, e, data) if n not in first_names)
        note = "; ".join(x for x in (
            "" if cv.converged else "a fit did not converge or sits at a bound",) if x)
        tried[e] = _candidate(setup, split, baseline, (named, e), f"{first.label} + {candidates[e].label}", cv,
                              shown_names, first.r, first.oof.position, first.bic, options, note)
    verdict = holm({e: c.improvement["p_value"] for e, c in tried.items()}, options.significance) if tried else {}
    out = {}
    for e, c in tried.items():
        ok = bool(verdict[e] and c.improvement["mean_difference"] > 0)
        out[e] = replace(c, improvement_significant=ok, significant=ok and c.typical and not c.at_bound)
        imp = out[e].improvement
        echo(f"  {out[e].label}: " + ", ".join(display_value(n, v, out[e].units[n]) for n, v in out[e].shown.items())
             + f"; improvement over {first.label} {imp['mean_difference']:.3f} (+- {imp['se']:.3f}), "
               f"p = {imp['p_value']:.4f}" + ("" if out[e].cv.converged else "; a fit NOT converged"))
    passing = [e for e, c in out.items() if c.significant]
    second = max(passing, key=lambda e: out[e].improvement["mean_difference"]) if passing else None
    if second:
        echo(f"named combination: {out[second].label}")
    return Combination(first=named, first_label=first.label, named=second, tried=MappingProxyType(out),
                       not_tried=MappingProxyType(not_tried), rule=rule)


# --------------------------------------------------------------------------- report form
def candidate_report(c: Candidate) -> dict:
    """A candidate as ``results.json`` stores it (mm in ``out_of_fold``; SI in ``parameters``)."""
    oof = c.oof
    out = {"effects": list(c.effects), "label": c.label, "model": c.model, "fit": c.fit.as_dict(),
           "folds": [f.as_dict() for f in c.cv.folds], "parameters": c.shown, "units": c.units,
           "parameter_table": c.parameters, "atypical": c.atypical, "typical": c.typical,
           "at_bound": list(c.at_bound), "converged": c.cv.converged, "n_parameters": c.n_parameters, "bic": c.bic,
           "delta_bic": c.delta_bic,
           "out_of_fold": error_summary(oof.position, oof.angle, oof.seconds, oof.rows.size),
           "improvement_eq49": c.improvement, "improvement_position": c.improvement_position, "fit_note": c.fit_note}
    for key in ("signature_significant", "improvement_significant", "eligible", "significant"):
        if getattr(c, key) is not None:
            out[key] = getattr(c, key)
    return out


def candidate_reports(candidates: Mapping[str, Candidate]) -> dict:
    """:func:`candidate_report` of every candidate."""
    return {e: candidate_report(c) for e, c in candidates.items()}
