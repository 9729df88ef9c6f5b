"""How the discrepancy workflow fits an effect: fit strategies as objects (``Effect.fit``).

A :class:`FitStrategy` is a name, a function that fits one candidate from a fit context, and the
properties the workflow asks of it (whether it starts from the clearance-model refit of the tube
parameters, whether its model contains the baseline's, whether it adds parameters, how a second
effect of a pair places it). The context is the workflow's
:class:`~ctrplan.discrepancy.fits.fitting.FitContext`: the fit's samples, its starting fits and the
solvers (``calibrate``, ``scan``, ``grid``, ``refine_contact``), so that a strategy is written
without importing the workflow. The built-in strategies (:data:`NESTED`, :data:`GRID`,
:data:`NO_FIT`, :data:`SCAN`) follow Section V-C and Table VII of Ha, Fagogenis & Dupont, IEEE
T-RO 35(2) 2019 for the friction coefficients (a grid search on the clearance-model tube
parameters) and refit everything else together with the baseline's parameters.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

__all__ = ["FitStrategy", "NESTED", "GRID", "NO_FIT", "SCAN", "FIT_STRATEGIES"]


@dataclass(frozen=True)
class FitStrategy:
    """How one effect's parameters are fitted by the discrepancy workflow.

    Attributes
    ----------
    name : str
        Its name in reports and logs.
    fit : callable
        ``fit(ctx) -> CalibrationResult``: the candidate's fit on ``ctx.fit_data`` (development
        samples, or without fold ``ctx.k``); ``ctx`` is a
        :class:`~ctrplan.discrepancy.fits.fitting.FitContext`.
    description : str
        One sentence for the docs and reports.
    from_contact_baseline : bool
        It starts from the clearance-model refit of the baseline's tube parameters (stage 6a).
    contains_baseline : bool
        Its fit contains the baseline's (every baseline parameter refitted with the effect's from
        the baseline's fit): a cost above the baseline's is a failed fit.
    adds_parameters : bool
        It fits parameters of its own (False: the effect is evaluated with fitted tube
        parameters only).
    pair_grid : bool
        As the second effect of a pair, its parameters are placed by a grid search on the
        clearance-model tube parameters (else by a fit of them alone, started from its own fit).
    needs_scan : bool
        The effect needs ``scan`` values and the effect it follows (``after``).
    """

    name: str
    fit: Callable[[Any], Any]
    description: str = ""
    from_contact_baseline: bool = False
    contains_baseline: bool = False
    adds_parameters: bool = True
    pair_grid: bool = False
    needs_scan: bool = False

    def __str__(self) -> str:
        return self.name


def _fit_nested(ctx):
    """Its parameters with the baseline's, from the effect switched off (or a start scan)."""
    entry, base, options, extra = ctx.entry, ctx.base, ctx.options, ctx.extra
    base_all = dict(zip(*base.all_parameters()))
    names = tuple(base.names) + extra
    init = np.concatenate([base.values, ctx.read_parameters(extra)])
    before = []
    if entry.scan is not None and extra:
        # best of a 1-D scan, then the effect's own parameters alone with the baseline held
        # (a few parameters: cheap steps), then everything together
        best = ctx.scan(entry.model, base_all, extra, entry.scan, uncertainty=False)
        alone = ctx.calibrate(entry.model, extra, fixed=base_all, initial=best.values,
                              max_evaluations=options.max_evaluations, uncertainty=False)
        init[len(base.names):] = alone.values
        before = [best, alone]
    fit = ctx.calibrate(entry.model, names, fixed=base.fixed, initial=init, max_evaluations=options.max_evaluations,
                        uncertainty=ctx.k is None, prior=ctx.prior, clusters=ctx.units)
    # the result's time and work include the start scan's and the effect's own fit
    return ctx.with_work(fit, before)


def _fit_grid(ctx):
    """A grid search of its parameters on the clearance-model tube parameters, then those
    parameters refitted together with the baseline's (``ctx.refine_contact``)."""
    g = ctx.grid(ctx.contact, ctx.extra, ctx.entry.model, uncertainty=False, clusters=ctx.units)
    return ctx.refine_contact(g, tuple(ctx.extra))


def _fit_none(ctx):
    """Nothing to fit: evaluated with the clearance-model tube parameters."""
    return ctx.calibrate(ctx.entry.model, (), fixed=ctx.contact)


def _fit_scan(ctx):
    """A 1-D scan on top of the fit of the effect it follows; with a contact model, then its
    parameters and those of the effect it follows refitted together with the baseline's
    (``ctx.refine_contact``)."""
    entry = ctx.entry
    contact = ctx.needs_contact(entry.model)
    s = ctx.scan(entry.model, ctx.after, ctx.extra, entry.scan, uncertainty=ctx.k is None and not contact,
                 clusters=ctx.units)
    if not contact:
        return s
    followed = ctx.effect_parameters(entry.after)
    return ctx.refine_contact(s, tuple(followed) + tuple(ctx.extra))


#: Its parameters refitted together with the baseline's, started from the effect switched off or,
#: with a start scan (``Effect.scan``), from the best scanned value refined alone with the
#: baseline held.
NESTED = FitStrategy("nested", _fit_nested, "its parameters refitted together with the baseline's",
                     contains_baseline=True)
#: A grid search of its parameters with the tube parameters refitted with the clearance model (the
#: paper's friction calibration, Section V-C and Table VII), then refitted together with the
#: baseline's parameters.
GRID = FitStrategy("grid", _fit_grid, "a grid search on the clearance-model tube parameters, then a joint refit",
                   from_contact_baseline=True, pair_grid=True)
#: Nothing to fit: evaluated with the clearance-model tube parameters.
NO_FIT = FitStrategy("none", _fit_none, "nothing to fit: the clearance-model tube parameters",
                     from_contact_baseline=True, adds_parameters=False)
#: A 1-D scan of its parameters on top of the fit of the effect it follows.
SCAN = FitStrategy("scan", _fit_scan, "a 1-D scan on top of the fit of the effect it follows", needs_scan=True)

#: The built-in strategies by name.
FIT_STRATEGIES = {s.name: s for s in (NESTED, GRID, NO_FIT, SCAN)}
