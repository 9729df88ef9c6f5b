"""Stages 3, 6 and 8 of the discrepancy workflow: the baseline, the candidates, and a second effect.

How each candidate is fitted is its registry entry's ``fit`` (:data:`ctrplan.effects.FIT_STRATEGIES`),
dispatched through :data:`FITTERS`:

- ``"nested"``: its parameters refitted together with the baseline's, started from the effect
  switched off (the fit can only lower the calibration cost) or, with a start scan
  (``Effect.scan``), from the best scanned value refined alone with the baseline held;
- ``"grid"``: a grid search of its parameters with the tube parameters refitted once with the
  clearance model (the paper's friction calibration, Section V-C and Table VII of Ha et al. 2019);
- ``"none"``: nothing to fit: evaluated with the clearance-model tube parameters;
- ``"scan"``: a 1-D scan of its parameters on top of the fit of the effect it follows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ..effects import MODEL_ORDER, REGISTRY
from .calibrate import (FAILED_RESIDUAL, CalibrationResult, _Objective, calibrate, eq49_residuals, grid_search,
                        information_criterion)
from .data import MeasuredData
from .evaluation import HeldOut, HeldOutFn, error_summary
from .options import BIC_MARGIN, DiscrepancyOptions
from .parameters import apply_parameters, parameter, read_parameters
from .setup import DiscrepancySetup, effect_parameters, reported_parameters
from .split import SampleSplit
from .stages import result_from_dict

__all__ = ["Baseline", "Candidate", "Combination", "FITTERS", "calibrate_baseline", "refit_contact_baseline",
           "fit_candidates", "fit_second_effect", "scan_fit", "implausible_values", "paired_improvement",
           "display_value", "combined_model", "needs_contact_baseline", "candidate_report", "candidate_reports"]


@dataclass(frozen=True, eq=False)
class Baseline:
    """Stage 3: the calibrated baseline (standard model).

    Attributes
    ----------
    fit : CalibrationResult
        Its least-squares fit on ``SampleSplit.fit_data`` (cost in (mm + deg)^2, Eq. (49)).
    params : dict of str to float
        Every parameter of the fit (fitted and fixed) [SI: 1/m, -, rad, m].
    bic : float
        Its Bayesian information criterion (:func:`~ctrplan.discrepancy.calibrate.information_criterion`).
    held_out : HeldOut
        Its held-out errors [m, rad].
    r : ndarray, shape (K,)
        Its held-out Eq. (49) residuals [mm + deg].
    """

    fit: CalibrationResult
    params: dict
    bic: float
    held_out: HeldOut
    r: np.ndarray


@dataclass(frozen=True, eq=False)
class Candidate:
    """A candidate effect (or, in :class:`Combination`, a pair of effects) fitted and evaluated.

    Attributes
    ----------
    effects : tuple of str
        The effect, or the named effect and the second one.
    label : str
    model : str
        Mechanics model it is evaluated with (``"standard"``, ``"clearance"``, ``"friction"``).
    fit : CalibrationResult
    params : dict of str to float
        Every parameter of the fit (fitted and fixed) [SI].
    shown : dict of str to float
        The parameters reported as its own [SI: -, 1/m, rad, m, s].
    units : dict of str to str
        Unit of each shown parameter.
    implausible : list of dict
        Shown values outside their plausible range (:func:`implausible_values`; SI).
    n_parameters : int
        Parameters counted in its BIC (the baseline's included).
    bic, delta_bic : float
        BIC, and its difference to the baseline's (to the named effect's, for a pair).
    held_out : HeldOut
        Held-out errors [m, rad].
    r : ndarray, shape (K,)
        Held-out Eq. (49) residuals [mm + deg].
    improvement_eq49, improvement_position : dict
        :func:`paired_improvement` of the Eq. (49) residuals [mm + deg] and of the position
        errors [m] over the baseline (over the named effect, for a pair).
    fit_note : str
        What its fit says about itself ("" if nothing).
    signature_significant, improvement_significant, bic_better, eligible : bool or None
        The naming rule's verdicts (set by :func:`~ctrplan.discrepancy.decision.name_effect`; for a
        pair, :func:`fit_second_effect` sets the middle two and ``eligible`` is None).
    significant : bool or None
        A pair's verdict (:func:`fit_second_effect`).
    """

    effects: tuple
    label: str
    model: str
    fit: CalibrationResult
    params: dict
    shown: dict
    units: dict
    implausible: list
    n_parameters: int
    bic: float
    delta_bic: float
    held_out: HeldOut
    r: np.ndarray
    improvement_eq49: dict
    improvement_position: dict
    fit_note: str = ""
    signature_significant: bool | None = None
    improvement_significant: bool | None = None
    bic_better: bool | None = None
    eligible: bool | None = None
    significant: bool | None = None

    @property
    def plausible(self) -> bool:
        """Every shown value within its plausible range."""
        return not self.implausible


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
        Second effect -> the pair fitted and evaluated.
    notes : tuple of str
    rule : str
        The rule a pair is named by.
    """

    first: str
    first_label: str
    named: str | None
    tried: Mapping[str, Candidate]
    notes: tuple
    rule: str


# --------------------------------------------------------------------------- helpers
def candidate_report(c: Candidate, n_val: int) -> dict:
    """A single candidate as ``results.json["candidates"][effect]`` stores it (mm in ``held_out``)."""
    out = {"label": c.label, "model": c.model, "fit": c.fit.as_dict(), "parameters": c.shown, "units": c.units,
           "implausible": c.implausible, "n_parameters": c.n_parameters, "bic": c.bic, "delta_bic": c.delta_bic,
           "held_out": error_summary(c.held_out.position, c.held_out.angle, c.held_out.seconds, n_val),
           "improvement_eq49": c.improvement_eq49, "improvement_position": c.improvement_position,
           "fit_note": c.fit_note}
    if c.eligible is not None:
        out.update({"signature_significant": c.signature_significant,
                    "improvement_significant": c.improvement_significant, "bic_better": c.bic_better,
                    "eligible": c.eligible, "plausible": c.plausible})
    return out


def candidate_reports(candidates: Mapping[str, Candidate], n_val: int) -> dict:
    """:func:`candidate_report` of every candidate."""
    return {e: candidate_report(c, n_val) for e, c in candidates.items()}


def paired_improvement(err_base, err_cand, units, *, n_permutations: int = 9999, seed: int = 0) -> dict:
    """Held-out improvement of a candidate over the baseline, tested over units.

    Per unit (a configuration group or time block), the mean of ``err_base - err_cand``; the
    statistic is their mean, the null flips the sign of every unit's difference (no systematic
    improvement), one-sided.

    Parameters
    ----------
    err_base, err_cand : ndarray, shape (K,)
        Per-sample errors (e.g. Eq. (49) residuals or tip distances); NaN rows dropped.
    units : ndarray of int, shape (K,)

    Returns
    -------
    dict
        ``mean_difference``, ``p_value``, ``n_units``.
    """
    ok = np.isfinite(err_base) & np.isfinite(err_cand)
    _, u = np.unique(np.asarray(units)[ok], return_inverse=True)
    u = u.ravel()
    n_u = int(u.max()) + 1 if u.size else 0
    if n_u < 2:
        return {"mean_difference": float("nan"), "p_value": 1.0, "n_units": n_u}
    d = np.bincount(u, (err_base - err_cand)[ok], n_u) / np.bincount(u, minlength=n_u)
    obs = float(d.mean())
    rng = np.random.default_rng(seed)
    signs = rng.choice((-1.0, 1.0), size=(n_permutations, n_u))
    null = (signs * d).mean(axis=1)
    p = float((1 + np.count_nonzero(null >= obs)) / (1 + n_permutations))
    return {"mean_difference": obs, "p_value": p, "n_units": n_u}


def display_value(name: str, value: float, unit: str) -> str:
    """A parameter for a printed report: rad as deg, m as mm, others in their SI unit."""
    if unit == "rad":
        return f"{name} = {np.rad2deg(value):.4g} deg"
    if unit == "m":
        return f"{name} = {value * 1e3:.4g} mm"
    return f"{name} = {value:.4g}" + ("" if unit == "-" else f" {unit}")


def implausible_values(robot, params: Mapping) -> list:
    """Fitted values outside their plausible range: ``[{name, value, plausible, unit, why}]``."""
    out = []
    for name, value in params.items():
        p = parameter(robot, name)
        if not p.is_plausible(value):
            out.append({"name": name, "value": float(value), "plausible": list(p.plausible), "unit": p.unit,
                        "why": p.plausible_note})
    return out


def combined_model(*effects: str) -> str:
    """Mechanics model of effects together: the most complete one any of them needs."""
    return max((REGISTRY[e].model for e in effects), key=MODEL_ORDER.index)


def needs_contact_baseline(effect: str) -> bool:
    """The effect's fit starts from the clearance-model refit of the tube parameters."""
    e = REGISTRY[effect]
    return e.fit in ("grid", "none") or (e.after is not None and needs_contact_baseline(e.after))


def _grid_progress(echo):
    state = {"last": -1}

    def report(done, total):
        pct = int(100 * done / total)
        if pct // 10 != state["last"]:
            state["last"] = pct // 10
            echo(f"    grid search: {done}/{total} points")
    return report


def scan_fit(robot, data: MeasuredData, model: str, fixed: dict, names, values, settings,
             n_jobs) -> CalibrationResult:
    """Best of a 1-D scan: every parameter in ``names`` set to each of ``values`` in turn, the
    others ``fixed``; the cost (Eq. (49)) of each trial in the message."""
    t0 = time.perf_counter()
    names = (names,) if isinstance(names, str) else tuple(names)
    obj = _Objective(robot, data, model, names, fixed, settings, n_jobs)
    costs = []
    for v in values:
        r = obj.residuals(np.full(len(names), v))
        costs.append(float(r @ r))
    b = int(np.argmin(costs))
    x = np.full(len(names), values[b])
    r = obj.residuals(x)
    trail = ", ".join(f"{v:.4g}: {c:.4g}" for v, c in zip(values, costs))
    return CalibrationResult(model, names, x, np.zeros(len(names)), dict(fixed), float(r @ r), data.n_samples,
                             int((r == FAILED_RESIDUAL).sum()), obj.evaluations, time.perf_counter() - t0,
                             f"scan of {', '.join(names)} (value: cost) {trail}; best {values[b]:.4g}", True)


def _fit_note(effect, fit, base, base_val: HeldOut, val_e: HeldOut) -> str:
    """What a candidate's fit says about itself: not converged, worse on the calibration data
    than the baseline, or better there but worse held-out (overfitting)."""
    notes = []
    if not fit.converged:
        notes.append("its fit did not converge (stopped at the evaluation budget)")
    base_mean = float(np.nanmean(base_val.position))
    cand_mean = float(np.nanmean(val_e.position))
    if fit.cost > base.cost * (1 + 1e-9):
        if REGISTRY[effect].fit == "nested":
            notes.append(f"it fits the calibration data worse than the baseline (cost {fit.cost:.4g} against "
                         f"{base.cost:.4g}) although it contains the baseline: the fit failed")
        else:
            notes.append(f"it fits the calibration data worse than the standard baseline (cost {fit.cost:.4g} "
                         f"against {base.cost:.4g}): the {fit.model} model with the shared refitted tube "
                         f"parameters does not reach the standard model's fit, which costs it in the BIC; "
                         f"either the refit (see its convergence) or the model is at fault")
    elif cand_mean > base_mean:
        notes.append(f"it fits the calibration data better (cost {fit.cost:.4g} against {base.cost:.4g}) but the "
                     f"held-out data worse (mean {cand_mean * 1e3:.3f} against {base_mean * 1e3:.3f} mm): its "
                     f"extra parameters absorb a pattern of the calibration samples that does not hold on the "
                     f"held-out ones (overfitting)")
    return "; ".join(notes)


# --------------------------------------------------------------------------- stage 3
def calibrate_baseline(setup: DiscrepancySetup, split: SampleSplit, options: DiscrepancyOptions,
                       held_out: HeldOutFn, echo=print) -> Baseline:
    """Stage 3: calibrate the baseline (standard model) on the fitted calibration samples, by
    least squares on Eq. (49) of Ha, Fagogenis & Dupont 2019 (:func:`calibrate`), and evaluate
    it on the held-out samples. A baseline fit finished by an earlier run is reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    options : DiscrepancyOptions
        ``max_evaluations``, ``n_jobs``.
    held_out : callable
        ``held_out(name, model, params) -> HeldOut`` (:func:`evaluate_held_out` bound to the run).
    echo : callable

    Returns
    -------
    Baseline
    """
    stages = setup.stages
    done = stages.load("baseline")
    if done is None:
        echo(f"calibrating the baseline (standard model) on {', '.join(setup.base_names)} ...")
        base = calibrate(setup.robot, split.fit_data, "standard", setup.base_names, settings=setup.settings,
                         n_jobs=options.n_jobs, register=setup.register, max_evaluations=options.max_evaluations)
        stages.save("baseline", base.as_dict())
    else:
        base = result_from_dict(done)
        echo("baseline calibration: reused from an earlier run")
    echo(f"  baseline: cost {base.cost:.4g} on {base.n_samples} samples, {base.evaluations} model "
         f"evaluations, {base.seconds:.1f} s ({base.message})")
    base_all = dict(zip(*base.all_parameters()))
    base_val = held_out("baseline", "standard", base_all)
    return Baseline(fit=base, params=base_all, bic=information_criterion(base.cost, base.n_samples, len(base.names)),
                    held_out=base_val, r=eq49_residuals(base_val.position, base_val.angle))


# --------------------------------------------------------------------------- stage 6
def refit_contact_baseline(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline,
                           options: DiscrepancyOptions, echo=print) -> CalibrationResult | None:
    """Stage 6a: the baseline parameters refitted once with the clearance model, shared by the
    candidates fitted on it (friction, clearance; Section V-C and Table VII of Ha et al. 2019),
    within ``options.max_contact_evaluations``. Reused when an earlier run finished it.

    Returns
    -------
    CalibrationResult or None
        None when no candidate needs it.
    """
    if not any(needs_contact_baseline(e) for e in setup.effects):
        return None
    base = baseline.fit
    done = setup.stages.load("contact-baseline")
    if done is None:
        echo("recalibrating the baseline parameters with the clearance model (shared by the contact-model "
             "candidates) ...")
        contact = calibrate(setup.robot, split.fit_data, "clearance", base.names, fixed=base.fixed,
                            initial=base.values, settings=setup.settings, n_jobs=options.n_jobs,
                            max_evaluations=options.max_contact_evaluations)
        setup.stages.save("contact-baseline", contact.as_dict())
    else:
        contact = result_from_dict(done)
    echo(f"  clearance-model parameters: cost {contact.cost:.4g}, {contact.evaluations} evaluations, "
         f"{contact.seconds:.1f} s" + ("" if contact.converged else "; NOT converged (stopped at its budget)"))
    return contact


def _fit_nested(ctx) -> CalibrationResult:
    """Its parameters with the baseline's, from the effect switched off (or a start scan)."""
    setup, entry, base, base_all, options = ctx["setup"], ctx["entry"], ctx["base"], ctx["base_all"], ctx["options"]
    robot, fit_data, settings, extra = setup.robot, ctx["fit_data"], setup.settings, ctx["extra"]
    names = tuple(base.names) + extra
    start = apply_parameters(robot, tuple(base_all), tuple(base_all.values()))
    init = np.concatenate([base.values, read_parameters(start, extra)])
    if entry.scan is not None and extra:
        # best of a 1-D scan, then the effect's own parameters alone with the baseline held (a
        # few parameters: cheap steps), then everything together
        best = scan_fit(robot, fit_data, entry.model, base_all, extra, entry.scan, settings, options.n_jobs)
        alone = calibrate(robot, fit_data, entry.model, extra, fixed=base_all, initial=best.values,
                          settings=settings, n_jobs=options.n_jobs, max_evaluations=options.max_evaluations)
        init[len(base.names):] = alone.values
    return calibrate(start, fit_data, entry.model, names, initial=init, settings=settings, n_jobs=options.n_jobs,
                     max_evaluations=options.max_evaluations)


def _fit_grid(ctx) -> CalibrationResult:
    """A grid search of its parameters on the clearance-model tube parameters."""
    setup, options, echo = ctx["setup"], ctx["options"], ctx["echo"]
    return grid_search(setup.robot, ctx["fit_data"], ctx["contact_all"], ctx["extra"], ctx["entry"].model,
                       settings=setup.settings, n_jobs=options.n_jobs, coarse=options.friction_grid,
                       search_samples=options.friction_search_samples, seed=options.seed,
                       progress=_grid_progress(echo))


def _fit_none(ctx) -> CalibrationResult:
    """Nothing to fit: evaluated with the clearance-model tube parameters."""
    setup, options = ctx["setup"], ctx["options"]
    return calibrate(setup.robot, ctx["fit_data"], ctx["entry"].model, (), fixed=ctx["contact_all"],
                     settings=setup.settings, n_jobs=options.n_jobs)


def _fit_scan(ctx) -> CalibrationResult:
    """A 1-D scan on top of the fit of the effect it follows."""
    setup, entry, options = ctx["setup"], ctx["entry"], ctx["options"]
    after = ctx["candidates"][entry.after]
    return scan_fit(setup.robot, ctx["fit_data"], entry.model, dict(after.params), ctx["extra"], entry.scan,
                    setup.settings, options.n_jobs)


#: Fitting strategy of an effect entry (``Effect.fit``) -> the function that fits it.
FITTERS = {"nested": _fit_nested, "grid": _fit_grid, "none": _fit_none, "scan": _fit_scan}


def fit_candidates(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline,
                   contact: CalibrationResult | None, options: DiscrepancyOptions, held_out: HeldOutFn,
                   echo=print) -> dict:
    """Stage 6b: switch each candidate effect on, fit it by its entry's strategy
    (:data:`FITTERS`), and measure its error on the held-out samples. Fits finished by an earlier
    run are reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    baseline : Baseline
    contact : CalibrationResult or None
        :func:`refit_contact_baseline`.
    options : DiscrepancyOptions
    held_out : callable
        ``held_out(name, model, params) -> HeldOut``.
    echo : callable

    Returns
    -------
    dict of str to Candidate
        One per effect of ``setup.effects``, in order, without the naming verdicts.
    """
    robot, units = setup.robot, split.units
    base, base_val = baseline.fit, baseline.held_out
    contact_all = dict(zip(*contact.all_parameters())) if contact is not None else None
    candidates = {}
    for e in setup.effects:
        entry = REGISTRY[e]
        extra = effect_parameters(robot, e, setup.data)
        done = setup.stages.load(f"fit-{e}")
        if done is not None:
            echo(f"candidate {entry.label}: fit reused from an earlier run")
            fit = result_from_dict(done)
        else:
            echo(f"candidate {entry.label}: fitting {', '.join(extra) or 'no parameters'} ({entry.model} model) ...")
            fit = FITTERS[entry.fit]({"setup": setup, "entry": entry, "base": base, "base_all": baseline.params,
                                      "contact_all": contact_all, "candidates": candidates, "extra": extra,
                                      "fit_data": split.fit_data, "options": options, "echo": echo})
            setup.stages.save(f"fit-{e}", fit.as_dict())
        params = dict(zip(*fit.all_parameters()))
        val_e = held_out(e, entry.model, params)
        r = eq49_residuals(val_e.position, val_e.angle)
        shown_names = reported_parameters(robot, e, setup.data)
        k_total = len(set(setup.base_names) | set(shown_names))
        bic = information_criterion(fit.cost, fit.n_samples, k_total)
        test = paired_improvement(baseline.r, r, units, seed=options.seed)
        pos_test = paired_improvement(base_val.position, val_e.position, units, seed=options.seed)
        shown = {n: float(params[n]) for n in shown_names}
        fit_note = "; ".join(n for n in (
            ("the clearance-model refit of the tube parameters it shares did not converge (stopped at "
             f"the budget of {options.max_contact_evaluations} evaluations): the candidate may be underrated"
             if needs_contact_baseline(e) and contact is not None and not contact.converged else ""),
            _fit_note(e, fit, base, base_val, val_e)) if n)
        c = candidates[e] = Candidate(
            effects=(e,), label=entry.label, model=entry.model, fit=fit, params=params, shown=shown,
            units={n: parameter(robot, n).unit for n in shown}, implausible=implausible_values(robot, shown),
            n_parameters=k_total, bic=bic, delta_bic=bic - baseline.bic, held_out=val_e, r=r,
            improvement_eq49=test, improvement_position=pos_test, fit_note=fit_note)
        held = error_summary(val_e.position, val_e.angle, val_e.seconds, split.val.n_samples)
        echo(f"  {entry.label}: {', '.join(f'{n} = {params[n]:.4g}' for n in shown_names) or 'nominal'}; "
             f"held-out mean {held['position_mean_mm']:.3f} mm, max {held['position_max_mm']:.3f} mm; "
             f"dBIC {c.delta_bic:.1f}; improvement p = {test['p_value']:.4f}"
             + (f"; {c.fit_note}" if c.fit_note else ""))
    return candidates


# --------------------------------------------------------------------------- stage 8
def _contained(a: str, b: str) -> bool:
    """One of the two effects contains the other (never combined)."""
    return a in REGISTRY[b].contains or b in REGISTRY[a].contains


def fit_second_effect(setup: DiscrepancySetup, split: SampleSplit, baseline: Baseline, naming,
                      options: DiscrepancyOptions, held_out: HeldOutFn, echo=print) -> Combination | None:
    """Stage 8: whether a second effect, fitted on top of the named one, still improves the
    held-out error.

    Tried: every other candidate whose signature test was significant, except effects that
    contain the named one or that it contains (``Effect.contains``); the report says why each
    other candidate was not tried. Fit on the calibration split only, starting from the named
    effect's fit and the second effect's own fit: with the standard model, the second effect's
    parameters alone (the named fit held), then everything together (nested: the calibration
    cost cannot rise); with a contact model (dearer by ~30x), the second effect's parameters
    alone, with ``options.max_contact_evaluations``. The pair is named by the workflow's rule for
    single effects, with the named effect in place of the baseline: held-out Eq. (49)
    improvement significant (paired sign-flip test over held-out units, one-sided,
    ``options.significance``), BIC lower by more than :data:`BIC_MARGIN`, and every fitted value
    plausible; among such pairs the largest held-out improvement. Fits finished by an earlier
    run are reused.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    baseline : Baseline
    naming : Naming
    options : DiscrepancyOptions
    held_out : callable
        ``held_out(name, model, params) -> HeldOut``.
    echo : callable

    Returns
    -------
    Combination or None
        None when no effect is named.
    """
    named = naming.named
    if not named:
        return None
    robot, data, fit_data, val, units, settings = (setup.robot, setup.data, split.fit_data, split.val, split.units,
                                                   setup.settings)
    candidates = naming.candidates
    first = candidates[named]
    p_first = dict(first.params)
    first_names = reported_parameters(robot, named, data)
    first_held = error_summary(first.held_out.position, first.held_out.angle, first.held_out.seconds,
                               val.n_samples)
    notes = []
    rule = (f"held-out Eq. (49) improvement over {first.label} alone significant at {options.significance} "
            f"(paired sign-flip test), BIC lower by more than {BIC_MARGIN}, fitted values plausible")
    pool = [e for e in candidates if e != named and not _contained(e, named) and candidates[e].signature_significant]
    skipped = [e for e in candidates if e != named and e not in pool]
    if skipped:
        notes.append("not tried on top of " + first.label + ": " + ", ".join(
            f"{candidates[e].label} ("
            + ("contained in it or containing it" if _contained(e, named) else "signature not significant")
            + ")"
            for e in skipped))
    tried = {}
    for e in pool:
        model = combined_model(named, e)
        second_names = tuple(n for n in reported_parameters(robot, e, data) if n not in p_first)
        if not second_names:
            notes.append(f"{candidates[e].label} not tried on top of {first.label}: it adds no parameter to it")
            continue
        init2 = np.array([candidates[e].params[n] for n in second_names], float)
        tag = f"{named}+{e}"
        done = setup.stages.load(f"fit-{tag}")
        if done is not None:
            fit = result_from_dict(done)
        else:
            echo(f"second effect: {candidates[e].label} on top of {first.label} ({model} model) ...")
            budget = options.max_evaluations if model == "standard" else options.max_contact_evaluations
            fit = calibrate(robot, fit_data, model, second_names, fixed=p_first, initial=init2, settings=settings,
                            n_jobs=options.n_jobs, max_evaluations=budget)
            if model == "standard":
                names = tuple(p_first) + second_names
                init = np.concatenate([np.array(list(p_first.values()), float), fit.values])
                joint = calibrate(robot, fit_data, "standard", names, initial=init, settings=settings,
                                  n_jobs=options.n_jobs, max_evaluations=options.max_evaluations)
                if joint.cost <= fit.cost or not fit.converged:
                    fit = joint
            setup.stages.save(f"fit-{tag}", fit.as_dict())
        params = dict(zip(*fit.all_parameters()))
        val_c = held_out(f"combination-{tag}", model, params)
        r = eq49_residuals(val_c.position, val_c.angle)
        shown_names = first_names + tuple(n for n in reported_parameters(robot, e, data) if n not in first_names)
        shown = {n: float(params[n]) for n in shown_names}
        k_total = len(set(setup.base_names) | set(shown_names))
        bic = information_criterion(fit.cost, fit.n_samples, k_total)
        test = paired_improvement(first.r, r, units, seed=options.seed)
        implausible = implausible_values(robot, shown)
        improvement = bool(test["p_value"] < options.significance and test["mean_difference"] > 0)
        bic_better = bool(bic - first.bic < -BIC_MARGIN)
        c = tried[e] = Candidate(
            effects=(named, e), label=f"{first.label} + {candidates[e].label}", model=model, fit=fit,
            params=params, shown=shown, units={n: parameter(robot, n).unit for n in shown},
            implausible=implausible, n_parameters=k_total, bic=bic, delta_bic=bic - first.bic, held_out=val_c,
            r=r, improvement_eq49=test,
            improvement_position=paired_improvement(first.held_out.position, val_c.position, units,
                                                    seed=options.seed),
            fit_note="" if fit.converged else ("its fit did not converge (stopped at the evaluation budget): the "
                                               "pair may be underrated"),
            improvement_significant=improvement, bic_better=bic_better,
            significant=improvement and bic_better and not implausible)
        held = error_summary(val_c.position, val_c.angle, val_c.seconds, val.n_samples)
        echo(f"  {c.label}: " + ", ".join(display_value(n, v, c.units[n]) for n, v in shown.items())
             + f"; held-out mean {held['position_mean_mm']:.3f} mm (alone {first_held['position_mean_mm']:.3f}); "
               f"dBIC {c.delta_bic:.1f}; improvement p = {test['p_value']:.4f}"
             + ("" if fit.converged else "; fit NOT converged"))
    passing = [e for e, c in tried.items() if c.significant]
    second = None
    if passing:
        second = max(passing, key=lambda e: tried[e].improvement_eq49["mean_difference"])
        c = tried[second]
        after = error_summary(c.held_out.position, c.held_out.angle, c.held_out.seconds, val.n_samples)
        echo(f"named combination: {c.label} (held-out mean {first_held['position_mean_mm']:.3f} -> "
             f"{after['position_mean_mm']:.3f} mm, p = {c.improvement_eq49['p_value']:.4f})")
    elif tried:
        notes.append("no second effect improves the held-out error of " + first.label + " significantly: "
                     + "; ".join(f"{c.label}: p = {c.improvement_eq49['p_value']:.4f}, dBIC "
                                 f"{c.delta_bic:.1f}" + ("" if c.plausible else ", implausible")
                                 for c in tried.values()))
    return Combination(first=named, first_label=first.label, named=second, tried=MappingProxyType(tried),
                       notes=tuple(notes), rule=rule)
