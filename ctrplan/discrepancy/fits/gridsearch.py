"""The friction coefficients by grid search (Section V-C of Ha, Fagogenis & Dupont, IEEE T-RO
35(2) 2019, doi:10.1109/TRO.2018.2878906: "calibrated during a second pass using a 2-D grid search
to avoid local minima").

- :func:`grid_search`: parameters by an m-D grid search on the Eq. (49) residuals of
  :mod:`ctrplan.discrepancy.fits.calibrate`, the other parameters held fixed, made cheaper by a coarse
  grid on a subset of whole configuration groups followed by refinement on the whole calibration
  set;
- :func:`grid_search_friction`: the friction coefficients mu_1..mu_(n-1) so (a 2-D search for
  three tubes, as in the paper; in general (n-1)-D).
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from ...models import check_model
from .calibrate import CalibrationResult, _uncertainty
from .objective import FitObjective
from .fitoptions import FitRun, GridSpec
from ..measured.data import MeasuredData
from .parameters import parameter
from .predictions import FAILED_RESIDUAL

__all__ = ["grid_search", "grid_search_friction"]


def grid_search(robot, data: MeasuredData, fixed: dict, names, model: str, *, grid: GridSpec = GridSpec(),
                start=None, progress=None, run: FitRun = FitRun()) -> CalibrationResult:
    """Parameters by grid search, other parameters ``fixed``: the paper's calibration of the
    friction coefficients (Section V-C: "calibrated during a second pass using a 2-D grid search
    to avoid local minima").

    The coarse grid (``grid.coarse`` per parameter) is scored on at most ``grid.search_samples``
    calibration samples made of whole configuration groups; while its best point lies on the
    upper edge of a parameter's axis, that axis grows by a step that doubles each time, up to the
    parameter's limit (``ParameterSpec.hard``), and the new points are scored with every value of
    the other axes. Then rounds of a 3^m grid with half the previous step around the best point
    are scored on the whole calibration set: ``grid.refinements`` rounds below the coarse step, and
    one more for every doubling of the grid's spacing at the best point.

    Parameters
    ----------
    robot : Robot
    data : MeasuredData
        Calibration samples.
    fixed : dict
        ``{name: value}`` of the other parameters (e.g. the calibrated baseline, registration).
    names : sequence of str
        The m gridded parameters (e.g. ``mu_1``, ``mu_2``).
    model : {"standard", "clearance", "friction"}
    grid : GridSpec
        The coarse grid, the refinements, the coarse search's samples and seed.
    start : array-like, shape (m,), optional
        A point found before: the coarse grid is skipped and the refinements start there.
    progress : callable, optional
        ``progress(done, total)`` after each grid point.
    run : FitRun
        Solver settings, worker processes, and the standard errors and correlations at the best
        point (from one Jacobian of Eq. (49); ``run.uncertainty``), clustered over
        ``run.clusters`` (:func:`~ctrplan.discrepancy.fits.calibrate.covariance`).

    Returns
    -------
    CalibrationResult
        With the score of every grid point in ``message``, the grid's growth in ``widened``; not
        converged, with ``at_bound``, when the best point lies on the grid's upper edge at the
        parameters' limit.

    Raises
    ------
    ValueError
        An unknown model.
    """
    t0 = time.perf_counter()
    check_model(model)
    coarse, refinements, search_samples, seed = grid.coarse, grid.refinements, grid.search_samples, grid.seed
    settings, n_jobs, uncertainty, clusters = run.settings, run.n_jobs, run.uncertainty, run.clusters
    names = tuple(names)
    m = len(names)
    specs = [parameter(robot, n) for n in names]
    lowest = np.array([p.lower for p in specs])
    coarse = np.asarray(sorted(coarse), float)
    groups = np.unique(data.config_id)
    rng = np.random.default_rng(seed)
    rows_per_group = data.n_samples / groups.size
    n_groups = max(1, min(groups.size, int(search_samples // max(rows_per_group, 1))))
    chosen = rng.choice(groups, size=n_groups, replace=False)
    sub = data.take(np.isin(data.config_id, chosen))
    obj_sub = FitObjective(robot, sub, model, names, fixed, settings, n_jobs)
    obj_all = FitObjective(robot, data, model, names, fixed, settings, n_jobs)
    obj_all.warm_starts = obj_sub.warm_starts   # the refinements start from the coarse grid's solutions
    grid = list(itertools.product(coarse, repeat=m))
    step0 = float(np.min(np.diff(coarse))) if coarse.size > 1 else 0.05
    total = len(grid) + refinements * (3 ** m)
    done = [0]

    def scan(obj, points, costs):
        """Cost of every grid point (each distinct point solved once, ``costs`` kept across
        calls); the best point scored so far."""
        for q in points:
            q = tuple(round(float(v), 6) for v in q)
            if q not in costs:
                r = obj.residuals(np.array(q))
                costs[q] = float(r @ r)
            done[0] += 1
            if progress:
                progress(done[0], total)
        best = min(costs, key=costs.get)
        return best, costs[best]

    axes = [list(coarse) for _ in range(m)]
    limits = [p.hard[1] for p in specs]
    widened = []
    if start is None:
        coarse_costs: dict = {}
        best, cost = scan(obj_sub, grid, coarse_costs)
        # a best point on an axis' upper edge is no minimum: grow that axis by a step that
        # doubles each time, up to the parameter's limit
        grow = [step0] * m
        while coarse.size > 1:
            edge = [j for j in range(m) if best[j] >= axes[j][-1] - 1e-9 and axes[j][-1] < limits[j] - 1e-9]
            if not edge:
                break
            new = []
            for j in edge:
                axes[j].append(round(min(limits[j], axes[j][-1] + grow[j]), 6))
                grow[j] *= 2.0
                new += [q for q in itertools.product(*axes) if q[j] >= axes[j][-1] - 1e-9]
            total += len(new)
            best, cost = scan(obj_sub, new, coarse_costs)
        widened = [f"grid of {n} grown to {ax[-1]:g}" for n, ax in zip(names, axes) if ax[-1] > coarse[-1]]
        trail = [f"coarse grid {coarse[0]:g}..{coarse[-1]:g} (step {step0:g})"
                 + (f", grown to {', '.join(f'{ax[-1]:g}' for ax in axes)}" if widened else "")
                 + f" on {sub.n_samples} samples: best {names} {best} cost {cost:.4g}"]
        best_all = np.array(best)
    else:
        best_all = np.asarray(start, float).reshape(m)
        trail = [f"refinements from {tuple(np.round(best_all, 6))}"]
    # refine from half the grid's spacing at the best point down to a quarter of the coarse step
    spacing = step0
    for j in range(m):
        ax = np.asarray(axes[j])
        at = int(np.argmin(np.abs(ax - best_all[j])))
        if ax.size > 1:
            spacing = max(spacing, float(np.max(np.diff(ax)[max(at - 1, 0):at + 1])))
    rounds = refinements + int(round(np.log2(spacing / step0)))
    total = done[0] + rounds * (3 ** m)
    step = spacing
    for _ in range(rounds):
        step /= 2.0
        best, cost = scan(obj_all, (np.clip(best_all + step * np.array(d), lowest, limits)
                                    for d in itertools.product((-1, 0, 1), repeat=m)), {})
        best_all = np.array(best)
        trail.append(f"refined (step {step:.4g}) on {data.n_samples} samples: best {best} cost {cost:.4g}")
    r = obj_all.residuals(best_all)
    # the grid could not grow past the parameters' limit and the minimum lies at (or past) it
    edge = tuple(f"{n} (edge of the grid at its limit {lim:g})" for n, v, lim in zip(names, best_all, limits)
                 if v >= lim - 1e-9)
    if edge:
        trail.append("at the edge of the grid, not converged: " + ", ".join(edge))
    unc = _uncertainty(obj_all, specs, best_all, clusters) if uncertainty else None
    se, corr = (None, None) if unc is None else (unc.stderr, unc.correlation)
    return CalibrationResult(model, names, best_all, np.zeros(m), dict(fixed), float(r @ r),
                             data.n_samples, int((r == FAILED_RESIDUAL).sum()),
                             obj_sub.evaluations + obj_all.evaluations, time.perf_counter() - t0,
                             "; ".join(trail), not edge, se, corr, edge, tuple(widened),
                             n_clusters=None if unc is None else unc.n_clusters)


def grid_search_friction(robot, data: MeasuredData, fixed: dict, **kwargs) -> CalibrationResult:
    """The friction coefficients mu_1..mu_(n-1) by :func:`grid_search` with the friction model
    (keyword arguments as there)."""
    return grid_search(robot, data, fixed, tuple(f"mu_{k + 1}" for k in range(robot.n_tubes - 1)), "friction",
                       **kwargs)
