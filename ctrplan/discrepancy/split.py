"""Stage 2 of the discrepancy workflow: an untouched test split, blocked cross-validation folds, and
the buffers that keep a fit away from the samples it is judged on.

The samples are grouped into **units** that are never cut: contiguous time blocks of each
continuous motion (a trajectory), or the rows linked by a shared configuration or sequence
(the paper's protocol: one configuration with its approaches). Before any fit, units spread over
the motion are held back as the **test split** (at least :data:`MIN_TEST_UNITS`), used once, at
the end, for the figures of the final model. The other units are the **development data**,
dealt into folds (scikit-learn's ``GroupKFold`` over the units); every fold is validated once by
models fitted on the other folds (blocked cross-validation). How many blocks and folds follows
the record's length (:func:`make_split`).

Along a continuous motion the residuals are serially correlated, so a fit whose calibration
samples sit next to a validated (or test) block would see part of that block's error. A
**buffer** of ``h`` samples on each side of every validation and test block is left out of the
fits that are judged there (hv-block cross-validation: Burman, Chow & Nolan, Biometrika
81(2):351, 1994; Racine, J. Econometrics 99:39, 2000). ``h`` is the lag at which the residuals'
autocorrelation has fallen to :data:`BUFFER_AUTOCORRELATION` (:func:`choose_buffer`), at most
half a block.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from .._log import progress_level
from ..errors import DataFileError
from .data import MeasuredData

__all__ = ["DataSplit", "make_split", "split_samples", "configurations_repeat", "sample_units", "subsample",
           "choose_buffer", "residual_autocorrelation", "near_rows", "MIN_BLOCK_SAMPLES", "MAX_BLOCKS",
           "MIN_TEST_UNITS", "MAX_FOLDS", "MIN_UNITS_PER_FOLD", "BUFFER_AUTOCORRELATION"]

logger = logging.getLogger(__name__)

#: Shortest time block [samples]: shorter blocks would share too much of their serial
#: correlation with their neighbours to count as separate units.
MIN_BLOCK_SAMPLES = 10
#: Time blocks a record is cut into at most (a longer record gets longer blocks): 50 blocks give
#: 10 test units and 40 development units at the default test fraction.
MAX_BLOCKS = 50
#: Units the test split holds at least: its figures have intervals over units (t with units - 1
#: degrees of freedom), and fewer than 8 make them uninformative.
MIN_TEST_UNITS = 8
#: Cross-validation folds at most; the comparison of two models has folds - 1 degrees of freedom.
MAX_FOLDS = 10
#: Development units per fold at least.
MIN_UNITS_PER_FOLD = 2
#: The buffer is the lag beyond which the residuals' autocorrelation is at most this (a sample
#: further away shares at most 1 % of its variance with the validated one).
BUFFER_AUTOCORRELATION = 0.1


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


def _auto_blocks(n_samples: int) -> int:
    """Time blocks of a record of ``n_samples``: :data:`MAX_BLOCKS`, fewer when blocks would be
    shorter than :data:`MIN_BLOCK_SAMPLES`."""
    return int(max(2, min(MAX_BLOCKS, n_samples // MIN_BLOCK_SAMPLES)))


def sample_units(data: MeasuredData, n_blocks: int | None = None) -> tuple[np.ndarray, str, int | None]:
    """The units of a split, shape (K,), and what they are.

    Linked rows (a shared configuration or sequence) when that gives at least as many units as
    time blocks would (the paper's protocol); else contiguous time blocks of each sequence, about
    ``K / n_blocks`` samples long (at least :data:`MIN_BLOCK_SAMPLES`).

    Parameters
    ----------
    data : MeasuredData
    n_blocks : int, optional
        Time blocks; default from the record's length (:data:`MAX_BLOCKS` at most).

    Returns
    -------
    units : ndarray of int, shape (K,)
    kind : {"configuration group", "time block"}
    block_samples : int or None
        Samples per time block.
    """
    n_blocks = _auto_blocks(data.n_samples) if n_blocks is None else int(n_blocks)
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


def _positions(data: MeasuredData) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's sequence (as 0..S-1) and position along it (record order)."""
    _, q = np.unique(data.sequence, return_inverse=True)
    q = q.ravel()
    pos = np.zeros(data.n_samples, dtype=np.int64)
    for s in np.unique(q):
        idx = np.flatnonzero(q == s)
        pos[idx] = data.rows[idx] - data.rows[idx].min()
    return q, pos


def near_rows(data: MeasuredData, mask, h: int) -> np.ndarray:
    """Samples within ``h`` record positions of a sample of ``mask`` (K,) in the same sequence
    (``mask`` included), shape (K,) bool; ``mask`` itself for ``h`` = 0."""
    mask = np.asarray(mask, bool)
    if h <= 0 or not mask.any():
        return mask.copy()
    q, pos = _positions(data)
    out = mask.copy()
    for s in np.unique(q[mask]):
        on = q == s
        marked = np.zeros(int(pos[on].max()) + 1, bool)
        marked[pos[on & mask]] = True
        # dilation by h: a position is near when a marked one lies within h of it
        c = np.concatenate([[0], np.cumsum(marked)])
        p = pos[on]
        lo = np.clip(p - h, 0, marked.size)
        hi = np.clip(p + h + 1, 0, marked.size)
        out[on] |= (c[hi] - c[lo]) > 0
    return out


def residual_autocorrelation(residual, data: MeasuredData, max_lag: int) -> np.ndarray:
    """Autocorrelation of residual vectors along each motion, pooled over components and motions.

    Parameters
    ----------
    residual : array-like, shape (K, 3)
        Residual vectors at the samples of ``data`` [m] (rows with NaN are left out).
    data : MeasuredData
        Gives each sample's motion and record position; pairs of samples ``lag`` positions apart
        in one motion are used.
    max_lag : int

    Returns
    -------
    ndarray, shape (max_lag + 1,)
        Lag 0..max_lag; 1 at lag 0; NaN at a lag without pairs.
    """
    r = np.asarray(residual, float)
    q, pos = _positions(data)
    ok = np.all(np.isfinite(r), axis=1)
    num = np.zeros(max_lag + 1)
    cnt = np.zeros(max_lag + 1)
    var = 0.0
    n = 0
    for s in np.unique(q[ok]):
        on = np.flatnonzero(ok & (q == s))
        x = r[on] - r[on].mean(axis=0)
        var += float(np.sum(x * x))
        n += on.size
        grid = np.full((int(pos[on].max()) + 1, 3), np.nan)
        grid[pos[on]] = x
        for lag in range(1, min(max_lag, grid.shape[0] - 1) + 1):
            prod = np.sum(grid[lag:] * grid[:-lag], axis=1)
            fin = np.isfinite(prod)
            num[lag] += prod[fin].sum()
            cnt[lag] += fin.sum()
    acf = np.full(max_lag + 1, np.nan)
    acf[0] = 1.0
    if var > 0:
        with np.errstate(invalid="ignore", divide="ignore"):
            acf[1:] = (num[1:] / cnt[1:]) / (var / n)
    return acf


def choose_buffer(residual, data: MeasuredData, block_samples: int | None) -> tuple[int, str]:
    """The buffer [samples] on each side of a validation or test block: the lag before the one at
    which the residuals' autocorrelation (:func:`residual_autocorrelation`) first falls to
    :data:`BUFFER_AUTOCORRELATION`, at most half a block; 0 for configuration groups (no serial
    order between them).

    Parameters
    ----------
    residual : array-like, shape (K, 3)
        Residual vectors at the samples of ``data`` [m] (e.g. of a fit on the development data).
    data : MeasuredData
    block_samples : int or None
        Samples per time block (None: configuration groups).

    Returns
    -------
    buffer : int
    why : str
        One line for the report.
    """
    if not block_samples:
        return 0, "no buffer: the units are configuration groups, not blocks of a continuous motion"
    cap = block_samples // 2
    acf = residual_autocorrelation(residual, data, max(cap + 1, 1))
    below = np.flatnonzero(np.nan_to_num(acf[1:], nan=0.0) <= BUFFER_AUTOCORRELATION)
    if below.size and below[0] < cap + 1:
        h = int(below[0])          # lag below[0] + 1 is the first at or under the threshold
        return h, (f"{h} samples: the residuals' autocorrelation falls to {BUFFER_AUTOCORRELATION:g} at lag {h + 1} "
                   f"(lag 1: {acf[1]:.2f})")
    return cap, (f"{cap} samples (half a block, the most allowed): the residuals' autocorrelation is still "
                 f"{acf[min(cap + 1, acf.size - 1)]:.2f} at lag {cap + 1} (lag 1: {acf[1]:.2f})")


@dataclass(frozen=True, eq=False)
class DataSplit:
    """Stage 2: which samples are used for what.

    Attributes
    ----------
    how : str
        The units, the test split and the folds, and why so many.
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
    buffer : int
        Samples left out of a fit on each side of the blocks it is judged on (validation and
        test); 0 until :meth:`with_buffer`.
    buffer_note : str
        Why that many.
    data : MeasuredData
        The samples (for the buffers' record positions).
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
    data: MeasuredData
    buffer: int = 0
    buffer_note: str = "not yet chosen"

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

    @property
    def n_test_units(self) -> int:
        return int(np.unique(self.units[self.test_rows]).size)

    @property
    def n_dev_units(self) -> int:
        return int(np.unique(self.units[self.dev_rows]).size)

    def with_buffer(self, buffer: int, note: str) -> "DataSplit":
        """The same split with a buffer of ``buffer`` samples (:func:`choose_buffer`)."""
        return replace(self, buffer=int(buffer), buffer_note=note)

    def calibration_rows(self, k: int | None = None) -> np.ndarray:
        """Rows fold ``k``'s model may be fitted on, shape (K,) bool: every development fold but
        ``k`` (all of them for ``k=None``), without the buffers around the test split and around
        fold ``k``'s blocks."""
        rows = self.dev_rows & ~near_rows(self.data, self.test_rows, self.buffer)
        if k is not None:
            rows &= ~near_rows(self.data, self.fold == k, self.buffer)
        return rows

    def validation_rows(self, k: int) -> np.ndarray:
        """Rows of fold ``k``, shape (K,) bool."""
        return self.fold == k

    def fit_rows(self, data: MeasuredData, k: int | None = None) -> np.ndarray:
        """The calibration rows a fit uses (at most ``max_fit_samples``), shape (K,) bool."""
        return subsample(data, self.calibration_rows(k), self.max_fit_samples, self.seed)

    def as_dict(self) -> dict:
        """The report's account of the samples: units, sizes, folds, buffer and the test split."""
        dev = self.dev_rows
        return {"how": self.how, "unit_kind": self.unit_kind, "block_samples": self.block_samples,
                "n_units": int(np.unique(self.units).size), "n_test": self.n_test, "n_development": self.n_dev,
                "n_test_units": self.n_test_units, "n_development_units": self.n_dev_units,
                "test_units": np.unique(self.units[self.test_rows]).tolist(),
                "n_folds": self.n_folds,
                "fold_samples": [int(np.sum(self.fold == k)) for k in range(self.n_folds)],
                "fold_units": [int(np.unique(self.units[self.fold == k]).size) for k in range(self.n_folds)],
                "fit_samples": [int(self.fit_rows(self.data, k).sum()) for k in [None, *range(self.n_folds)]],
                "max_fit_samples": self.max_fit_samples, "buffer_samples": self.buffer,
                "buffer_note": self.buffer_note,
                "development_first_last": [int(np.flatnonzero(dev)[0]), int(np.flatnonzero(dev)[-1])]}


def make_split(data: MeasuredData, *, test_fraction: float = 0.2, n_blocks: int | None = None,
               n_folds: int | None = None, max_fit_samples: int = 300, seed: int = 0) -> DataSplit:
    """Hold back a test split and deal the rest into cross-validation folds, whole units at a time.

    Parameters
    ----------
    data : MeasuredData
    test_fraction : float
        Share of the units held back for the test split, in (0, 0.5], at least
        :data:`MIN_TEST_UNITS` units; for time blocks, blocks evenly spread over the motion (the
        phase seeded); for configuration groups, a seeded choice.
    n_blocks : int, optional
        Time blocks a continuous motion is cut into; default from its length (:data:`MAX_BLOCKS`
        blocks of at least :data:`MIN_BLOCK_SAMPLES` samples).
    n_folds : int, optional
        Cross-validation folds of the development units, >= 2 (``sklearn.model_selection.GroupKFold``);
        default :data:`MAX_FOLDS`, fewer when there are fewer than :data:`MIN_UNITS_PER_FOLD`
        development units per fold.
    max_fit_samples : int
        Samples a fit uses at most.
    seed : int

    Returns
    -------
    DataSplit
        Without a buffer (:meth:`DataSplit.with_buffer` sets it once residuals exist).

    Raises
    ------
    DataFileError
        Fewer units than the test split and two folds need.
    ValueError
        Options out of range.
    """
    from sklearn.model_selection import GroupKFold

    if not 0.0 < test_fraction <= 0.5:
        raise ValueError(f"test_fraction must be in (0, 0.5], got {test_fraction!r}")
    if (n_folds is not None and n_folds < 2) or (n_blocks is not None and n_blocks < 2):
        raise ValueError(f"n_folds and n_blocks must be >= 2, got {n_folds!r} and {n_blocks!r}")
    units, kind, block = sample_units(data, n_blocks)
    ids = np.unique(units)
    n_test = max(MIN_TEST_UNITS, int(round(test_fraction * ids.size)))
    n_dev_units = ids.size - n_test
    folds = n_folds if n_folds is not None else min(MAX_FOLDS, n_dev_units // MIN_UNITS_PER_FOLD)
    if folds < 2 or n_dev_units < folds:
        raise DataFileError(f"{data.file}: {ids.size} units ({kind}s) are too few for a test split of {n_test} units "
                            f"and {max(folds, 2)} cross-validation folds; give more samples")
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
    for k, (_, val) in enumerate(GroupKFold(n_splits=folds).split(dev_idx, groups=units[dev_idx])):
        fold[dev_idx[val]] = k
    note = "" if data.subset is None else " (the file's 'subset' column is not used for the split)"
    why_blocks = ("" if kind != "time block" else
                  f" ({'as asked' if n_blocks is not None else f'{MAX_BLOCKS} at most, of at least {MIN_BLOCK_SAMPLES} samples'})")
    why_test = (f"{test_fraction:.0%} of the units" if n_test > MIN_TEST_UNITS or round(test_fraction * ids.size) == n_test
                else f"at least {MIN_TEST_UNITS} units, more than {test_fraction:.0%}")
    why_folds = ("as asked" if n_folds is not None else
                 f"{MAX_FOLDS} at most, with at least {MIN_UNITS_PER_FOLD} development units each")
    how = (f"{ids.size} {kind}s" + (f" of {block} samples" if block else "") + why_blocks
           + f"; test split: {test_ids.size} units ({int(test.sum())} samples; {why_test}) held back before any fit; "
             f"development: {ids.size - test_ids.size} units ({dev_idx.size} samples) in {folds} cross-validation "
             f"folds (GroupKFold; {why_folds}){note}")
    return DataSplit(how=how, units=units, unit_kind=kind, block_samples=block, test_rows=test, fold=fold,
                     n_folds=folds, max_fit_samples=max_fit_samples, seed=seed, data=data)


def split_samples(setup, options) -> DataSplit:
    """Stage 2: :func:`make_split` of the data with the options' test fraction, blocks and folds.

    Parameters
    ----------
    setup : DiscrepancySetup
    options : DiscrepancyOptions

    Returns
    -------
    DataSplit
        Without a buffer (:func:`~ctrplan.discrepancy.baseline.pilot_fit` chooses it).

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
    logger.log(progress_level(), f"data: {data.n_samples} samples ({data.frame} frame) from {data.file}; {split.how}")
    if data.source is not None:
        from ..io.ros2 import describe_bag_summary

        for line in describe_bag_summary(data.source):
            logger.log(progress_level(), f"  {line}")
    return split
