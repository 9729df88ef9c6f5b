"""Stage 2 of the discrepancy workflow: an untouched test split, and blocked cross-validation folds.

The samples are grouped into **units** that are never cut: contiguous time blocks of each
continuous motion (a trajectory), or the rows linked by a shared configuration or sequence
(the paper's protocol: one configuration with its approaches). Before any fit, a share of the
units (spread over the motion) is held back as the **test split**, used once, at the end, to
report the named model's gain. The other units are the **development data**; they are dealt
into folds (scikit-learn's ``GroupKFold`` over the units), and every fold is validated once by
models fitted on the other folds (blocked cross-validation). The selection of an effect reads
only these out-of-fold errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataFileError
from .data import MeasuredData
from .options import DiscrepancyOptions

__all__ = ["DataSplit", "make_split", "split_samples", "configurations_repeat", "sample_units", "subsample"]

#: Shortest time block [samples]: shorter blocks would share too much of their serial
#: correlation with their neighbours to count as separate units.
MIN_BLOCK_SAMPLES = 10


def configurations_repeat(config_id) -> bool:
    """True for a protocol that revisits configurations (the paper's grid approached from several
    directions): at least half the rows share their configuration with another row. A continuous
    trajectory that merely passes a configuration twice (its home, a pause) is not one."""
    _, inverse, counts = np.unique(config_id, return_inverse=True, return_counts=True)
    return bool(np.mean(counts[inverse.ravel()] > 1) >= 0.5) if len(config_id) else False


def _linked_units(data: MeasuredData) -> np.ndarray:
    """Rows linked by a shared configuration group or sequence: one unit (connected components)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    k = data.n_samples
    _, g = np.unique(data.config_id, return_inverse=True)
    _, q = np.unique(data.sequence, return_inverse=True)
    n_g = g.max() + 1
    graph = coo_matrix((np.ones(k), (g.ravel(), n_g + q.ravel())), shape=(n_g + q.max() + 1,) * 2)
    _, labels = connected_components(graph, directed=False)
    return labels[g.ravel()]


def sample_units(data: MeasuredData, n_blocks: int) -> tuple[np.ndarray, str, int | None]:
    """The units of a split, shape (K,), and what they are.

    Linked rows (a shared configuration or sequence) when that gives at least ``n_blocks`` units
    (the paper's protocol); else contiguous time blocks of each sequence, about ``K / n_blocks``
    samples long (at least :data:`MIN_BLOCK_SAMPLES`).

    Returns
    -------
    units : ndarray of int, shape (K,)
    kind : {"configuration group", "time block"}
    block_samples : int or None
        Samples per time block.
    """
    linked = _linked_units(data)
    if np.unique(linked).size >= n_blocks:
        return linked, "configuration group", None
    block = max(MIN_BLOCK_SAMPLES, int(np.ceil(data.n_samples / n_blocks)))
    _, q = np.unique(data.sequence, return_inverse=True)
    units = np.zeros(data.n_samples, dtype=np.int64)
    for s in np.unique(q):
        idx = np.flatnonzero(q == s)
        units[idx] = s * 1_000_000 + np.arange(idx.size) // block
    _, units = np.unique(units, return_inverse=True)
    return units.ravel(), "time block", block


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
class DataSplit:
    """Stage 2: which samples are used for what.

    Attributes
    ----------
    how : str
        One line: the units, the test split and the folds.
    units : ndarray of int, shape (K,)
        Unit of every sample (never cut by the split).
    unit_kind : {"time block", "configuration group"}
    block_samples : int or None
        Samples per time block.
    test_rows : ndarray of bool, shape (K,)
        The untouched test split.
    fold : ndarray of int, shape (K,)
        Cross-validation fold of every development sample, 0..n_folds-1; -1 for test samples.
    n_folds : int
    max_fit_samples : int
        Samples a least-squares fit uses at most (evenly chosen among its calibration rows).
    seed : int
    """

    how: str
    units: np.ndarray
    unit_kind: str
    block_samples: int | None
    test_rows: np.ndarray
    fold: np.ndarray
    n_folds: int
    max_fit_samples: int
    seed: int

    @property
    def dev_rows(self) -> np.ndarray:
        """The development samples (every fold), shape (K,) bool."""
        return ~self.test_rows

    @property
    def n_test(self) -> int:
        return int(self.test_rows.sum())

    @property
    def n_dev(self) -> int:
        return int(self.dev_rows.sum())

    def calibration_rows(self, k: int | None = None) -> np.ndarray:
        """Rows fold ``k``'s model is fitted on (every development fold but ``k``; all of them
        for ``k=None``), shape (K,) bool."""
        return self.dev_rows if k is None else self.dev_rows & (self.fold != k)

    def validation_rows(self, k: int) -> np.ndarray:
        """Rows of fold ``k``, shape (K,) bool."""
        return self.fold == k

    def fit_rows(self, data: MeasuredData, k: int | None = None) -> np.ndarray:
        """The calibration rows a fit uses (at most ``max_fit_samples``), shape (K,) bool."""
        return subsample(data, self.calibration_rows(k), self.max_fit_samples, self.seed)

    def as_dict(self) -> dict:
        """The report's account of the samples: units, sizes, folds and the test split."""
        dev = self.dev_rows
        return {"how": self.how, "unit_kind": self.unit_kind, "block_samples": self.block_samples,
                "n_units": int(np.unique(self.units).size), "n_test": self.n_test, "n_development": self.n_dev,
                "test_units": np.unique(self.units[self.test_rows]).tolist(),
                "n_folds": self.n_folds,
                "fold_samples": [int(np.sum(self.fold == k)) for k in range(self.n_folds)],
                "fold_units": [int(np.unique(self.units[self.fold == k]).size) for k in range(self.n_folds)],
                "max_fit_samples": self.max_fit_samples,
                "development_first_last": [int(np.flatnonzero(dev)[0]), int(np.flatnonzero(dev)[-1])]}


def make_split(data: MeasuredData, *, test_fraction: float = 0.2, n_blocks: int = 20, n_folds: int = 4,
               max_fit_samples: int = 300, seed: int = 0) -> DataSplit:
    """Hold back a test split and deal the rest into cross-validation folds, whole units at a time.

    Parameters
    ----------
    data : MeasuredData
    test_fraction : float
        Share of the units held back for the test split, in (0, 0.5]; for time blocks, every
        ``round(1 / test_fraction)``-th block (the phase seeded), so the test split spans the
        motion; for configuration groups, a seeded choice.
    n_blocks : int
        Time blocks a continuous motion is cut into (>= 2 n_folds / (1 - test_fraction)); 20
        suits 300-2000 samples (blocks of 15-100 samples).
    n_folds : int
        Cross-validation folds of the development units, >= 2 (``sklearn.model_selection.GroupKFold``).
    max_fit_samples : int
        Samples a fit uses at most.
    seed : int

    Returns
    -------
    DataSplit

    Raises
    ------
    DataFileError
        Fewer units than the folds and the test split need.
    ValueError
        Options out of range.
    """
    from sklearn.model_selection import GroupKFold

    if not 0.0 < test_fraction <= 0.5:
        raise ValueError(f"test_fraction must be in (0, 0.5], got {test_fraction!r}")
    if n_folds < 2 or n_blocks < 2:
        raise ValueError(f"n_folds and n_blocks must be >= 2, got {n_folds!r} and {n_blocks!r}")
    units, kind, block = sample_units(data, n_blocks)
    ids = np.unique(units)
    n_test = max(1, int(round(test_fraction * ids.size)))
    if ids.size - n_test < n_folds:
        raise DataFileError(f"{data.file}: {ids.size} units ({kind}s) are too few for a test split of {n_test} and "
                            f"{n_folds} cross-validation folds; give more samples")
    rng = np.random.default_rng(seed)
    if kind == "time block":
        every = ids.size / n_test
        phase = rng.uniform(0, every)
        test_ids = np.unique(np.floor(phase + every * np.arange(n_test)).astype(int) % ids.size)
    else:
        test_ids = rng.choice(ids, size=n_test, replace=False)
    test = np.isin(units, test_ids)
    fold = np.full(data.n_samples, -1, dtype=int)
    dev_idx = np.flatnonzero(~test)
    for k, (_, val) in enumerate(GroupKFold(n_splits=n_folds).split(dev_idx, groups=units[dev_idx])):
        fold[dev_idx[val]] = k
    note = "" if data.subset is None else " (the file's 'subset' column is not used for the split)"
    how = (f"{ids.size} {kind}s" + (f" of {block} samples" if block else "") + f"; test split: {test_ids.size} units "
           f"({int(test.sum())} samples) held back before any fit; development: {ids.size - test_ids.size} units "
           f"({dev_idx.size} samples) in {n_folds} cross-validation folds (GroupKFold){note}")
    return DataSplit(how=how, units=units, unit_kind=kind, block_samples=block, test_rows=test, fold=fold,
                     n_folds=n_folds, max_fit_samples=max_fit_samples, seed=seed)


def split_samples(setup, options: DiscrepancyOptions, echo=print) -> DataSplit:
    """Stage 2: :func:`make_split` of the data with the options' test fraction, blocks and folds.

    Raises
    ------
    DataFileError
        Too few units, or no more samples per fit than the baseline's parameters plus the
        largest effect's.
    """
    from .setup import effect_parameters

    data, robot = setup.data, setup.robot
    split = make_split(data, test_fraction=options.test_fraction, n_blocks=options.n_blocks, n_folds=options.n_folds,
                       max_fit_samples=options.max_calibration_samples, seed=options.seed)
    n_fit = min(int(split.fit_rows(data, k).sum()) for k in range(split.n_folds))
    largest = max((len(effect_parameters(robot, e, data)) for e in setup.effects), default=0)
    if n_fit <= len(setup.base_names) + largest:
        raise DataFileError(f"{data.file}: {n_fit} calibration samples per fold are not more than the "
                            f"{len(setup.base_names)} baseline parameters plus the largest effect's; give more samples")
    echo(f"data: {data.n_samples} samples ({data.frame} frame) from {data.file}; {split.how}")
    return split
