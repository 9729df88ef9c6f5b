"""How a fit of the discrepancy workflow starts and runs: :class:`FitStart` (the starting values,
a closed-form registration, a warm start), :class:`FitRun` (solver settings, worker processes,
standard errors and their clusters) and :class:`GridSpec` (the grid of a grid search), taken by
:func:`~ctrplan.discrepancy.fits.calibrate.calibrate`,
:func:`~ctrplan.discrepancy.fits.gridsearch.grid_search` and
:func:`~ctrplan.discrepancy.fits.fitting.scan_fit`."""

from __future__ import annotations

from dataclasses import dataclass

from ...mechanics import ModelSettings

__all__ = ["FitRun", "FitStart", "GridSpec"]


@dataclass(frozen=True, eq=False)
class FitRun:
    """How a fit evaluates its model and what it reports besides the values
    (:func:`~ctrplan.discrepancy.fits.calibrate.calibrate`,
    :func:`~ctrplan.discrepancy.fits.gridsearch.grid_search`,
    :func:`~ctrplan.discrepancy.fits.fitting.scan_fit`).

    Attributes
    ----------
    settings : ModelSettings or None
        Solver settings of the model evaluations (None: the defaults).
    n_jobs : int
        Worker processes of the model evaluations.
    uncertainty : bool
        Compute the standard errors and correlations of the fitted values (from the last
        Jacobian: no extra evaluation).
    clusters : array-like, shape (K,), or None
        Unit of each sample: the standard errors are clustered over units, neighbouring units of
        one motion merged until their seams are nearly uncorrelated
        (:func:`~ctrplan.discrepancy.fits.estimates.covariance`; ``n_clusters`` of the result).
    """

    settings: ModelSettings | None = None
    n_jobs: int = 1
    uncertainty: bool = True
    clusters: object = None


@dataclass(frozen=True, eq=False)
class FitStart:
    """Where a least-squares fit (:func:`~ctrplan.discrepancy.fits.calibrate.calibrate`) starts.

    Attributes
    ----------
    values : array-like, shape (m,), or None
        Starting values of the fitted parameters (None: the robot's, zero registration).
    register : bool
        Start registration parameters from the closed-form (Kabsch) registration of the initial
        model (only without ``values``).
    warm : bool
        ``values`` are already close to the minimum (a continuation of a fit of the same samples,
        e.g. with another prior): stage 1 is skipped.
    """

    values: object = None
    register: bool = False
    warm: bool = False


@dataclass(frozen=True)
class GridSpec:
    """The grid of :func:`~ctrplan.discrepancy.fits.gridsearch.grid_search`.

    Attributes
    ----------
    coarse : tuple of float
        Coarse grid values of every parameter, increasing, >= their lower bound [unit].
    refinements : int
        Rounds of a 3^m grid of half the previous step below the coarse step.
    search_samples : int
        At most this many calibration samples (whole configuration groups) score the coarse grid.
    seed : int
        Choice of the coarse-search subset.
    """

    coarse: tuple = (0.0, 0.1, 0.2, 0.3, 0.4)
    refinements: int = 2
    search_samples: int = 96
    seed: int = 0
