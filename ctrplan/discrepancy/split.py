"""Stage 2 of the discrepancy workflow: calibration and held-out samples, whole units at a time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataFileError
from .data import MeasuredData, split_data
from .options import DiscrepancyOptions
from .setup import DiscrepancySetup, effect_parameters

__all__ = ["SampleSplit", "split_samples", "configurations_repeat", "exchangeable_units", "subsample"]


def configurations_repeat(config_id) -> bool:
    """True for a protocol that revisits configurations (the paper's grid approached from several
    directions): at least half the rows share their configuration with another row. A continuous
    trajectory that merely passes a configuration twice (its home, a pause) is not one."""
    _, inverse, counts = np.unique(config_id, return_inverse=True, return_counts=True)
    return bool(np.mean(counts[inverse.ravel()] > 1) >= 0.5) if len(config_id) else False


def exchangeable_units(data: MeasuredData, block: int = 50) -> np.ndarray:
    """Exchangeable units of held-out data, shape (K,): configuration groups when configurations
    repeat, else time blocks of ``block`` samples within each sequence."""
    if configurations_repeat(data.config_id):
        return data.config_id
    _, q = np.unique(data.sequence, return_inverse=True)
    pos = np.zeros(data.n_samples, int)
    for s in np.unique(q):
        idx = np.flatnonzero(q == s)
        pos[idx] = np.arange(idx.size) // block
    return q.ravel() * 100000 + pos


def subsample(data: MeasuredData, rows: np.ndarray, limit: int, seed: int) -> np.ndarray:
    """At most ``limit`` of ``rows`` (boolean mask, shape (K,)): whole configuration groups when
    they repeat, else evenly spaced rows (keeping the time order)."""
    if rows.sum() <= limit:
        return rows
    sub = data.take(rows)
    idx = np.flatnonzero(rows)
    if configurations_repeat(sub.config_id):
        groups = np.unique(sub.config_id)
        per = sub.n_samples / groups.size
        chosen = np.random.default_rng(seed).choice(groups, size=max(1, int(limit // per)), replace=False)
        keep = idx[np.isin(sub.config_id, chosen)]
    else:
        keep = idx[np.linspace(0, idx.size - 1, limit).round().astype(int)]
    out = np.zeros_like(rows)
    out[keep] = True
    return out


@dataclass(frozen=True, eq=False)
class SampleSplit:
    """Stage 2: calibration and held-out samples.

    Attributes
    ----------
    how : str
        One line saying how the split was made (:func:`~ctrplan.discrepancy.data.split_data`).
    calibration_rows, validation_rows, fit_rows : ndarray of bool, shape (N,)
        Rows of ``setup.data`` in the calibration split, the held-out split, and the
        calibration rows the least-squares fits use (at most ``max_calibration_samples``).
    n_calibration : int
        Samples in the calibration split.
    fit_data : MeasuredData
        The fitted rows.
    val : MeasuredData
        The held-out rows (K samples), the only ones any held-out statistic reads.
    units : ndarray of int, shape (K,)
        Exchangeable unit of each held-out sample for the paired tests (:func:`exchangeable_units`).
    """

    how: str
    calibration_rows: np.ndarray
    validation_rows: np.ndarray
    fit_rows: np.ndarray
    n_calibration: int
    fit_data: MeasuredData
    val: MeasuredData
    units: np.ndarray

    @property
    def n_fit(self) -> int:
        """Samples the fits use."""
        return self.fit_data.n_samples


def split_samples(setup: DiscrepancySetup, options: DiscrepancyOptions, echo=print) -> SampleSplit:
    """Stage 2: split the data into calibration and held-out samples, whole units at a time.

    Parameters
    ----------
    setup : DiscrepancySetup
    options : DiscrepancyOptions
        ``calibration_fraction``, ``block_samples``, ``max_calibration_samples``, ``seed``.
    echo : callable
        Progress messages.

    Returns
    -------
    SampleSplit

    Raises
    ------
    DataFileError
        Either split empty, or no more fitted samples than the baseline's parameters plus the
        largest effect's.
    """
    data, robot, base_names = setup.data, setup.robot, setup.base_names
    cal_rows, val_rows, how = split_data(data, options.calibration_fraction, block_samples=options.block_samples,
                                         seed=options.seed)
    fit_rows = subsample(data, cal_rows, options.max_calibration_samples, options.seed)
    cal, fit_data, val = data.take(cal_rows), data.take(fit_rows), data.take(val_rows)
    n_fit = fit_data.n_samples
    largest = max((len(effect_parameters(robot, e, data)) for e in setup.effects), default=0)
    if n_fit <= len(base_names) + largest:
        raise DataFileError(f"{data.file}: {n_fit} calibration samples are not more than the "
                            f"{len(base_names)} baseline parameters plus the largest effect's; "
                            f"give more samples")
    echo(f"data: {data.n_samples} samples ({data.frame} frame) from {data.file}; split {how}; "
         f"fitting on {n_fit} calibration samples, validating on {val.n_samples}")
    return SampleSplit(how=how, calibration_rows=cal_rows, validation_rows=val_rows, fit_rows=fit_rows,
                       n_calibration=cal.n_samples, fit_data=fit_data, val=val, units=exchangeable_units(val))
