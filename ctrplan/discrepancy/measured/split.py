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

The buffer is chosen from the residuals of a fit on the development data (the pilot fit), so
after the test split is fixed and before any fold is fitted. When the autocorrelation needs a
buffer longer than half a block, the development stretches between test blocks are re-cut into
fewer, longer blocks and the folds dealt again, as long as the folds keep
:data:`MIN_UNITS_PER_FOLD` units each and every fit more samples than parameters
(:func:`lengthen_blocks`); the test split keeps its blocks and rows.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from ...choices import BlocksKept, BufferReason, SplitUnit
from ...errors import DataFileError
from .data import MeasuredData

__all__ = ["DataSplit", "SplitRule", "BufferChoice", "make_split", "split_samples", "configurations_repeat",
           "sample_units", "subsample", "choose_buffer", "lengthen_blocks", "choose_blocks", "residual_autocorrelation",
           "near_rows",
           "MIN_BLOCK_SAMPLES", "MAX_BLOCKS", "MIN_TEST_UNITS", "MAX_FOLDS", "MIN_UNITS_PER_FOLD",
           "BUFFER_AUTOCORRELATION"]

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
    kind : SplitUnit
    block_samples : int or None
        Samples per time block.
    """
    n_blocks = _auto_blocks(data.n_samples) if n_blocks is None else int(n_blocks)
    linked = _linked_units(data)
    if np.unique(linked).size >= n_blocks:
        return linked, SplitUnit.CONFIGURATION_GROUP, None
    block = max(MIN_BLOCK_SAMPLES, int(np.ceil(data.n_samples / n_blocks)))
    _, q = np.unique(data.sequence, return_inverse=True)
    units = np.zeros(data.n_samples, dtype=np.int64)
    for s in np.unique(q):
        idx = np.flatnonzero(q == s)
        units[idx] = s * 1_000_000 + np.arange(idx.size) // block
    _, units = np.unique(units, return_inverse=True)
    return units.ravel(), SplitUnit.TIME_BLOCK, block


def _development_runs(data: MeasuredData, test_rows: np.ndarray) -> list:
    """The stretches of consecutive development samples of each sequence (between test blocks
    and the sequence's ends): a list of index arrays into ``data``, in record order."""
    _, q = np.unique(data.sequence, return_inverse=True)
    q = q.ravel()
    runs = []
    for s in np.unique(q):
        idx = np.flatnonzero(q == s)
        dev = np.concatenate([[0], (~test_rows[idx]).astype(np.int8), [0]])
        edges = np.flatnonzero(np.diff(dev))
        runs.extend(idx[a:b] for a, b in zip(edges[::2], edges[1::2]))
    return runs


def _count_blocks(runs: list, length: int) -> int:
    """Blocks of at least ``length`` samples the stretches ``runs`` are cut into (a shorter
    stretch is one block)."""
    return int(sum(max(1, r.size // length) for r in runs))


def _recut_development(data: MeasuredData, units: np.ndarray, test_rows: np.ndarray, length: int) -> np.ndarray:
    """Units, shape (K,), with the test units kept and every development stretch cut into
    ``max(1, n // length)`` blocks of equal length (``n`` its samples); numbered in record order
    of their first sample."""
    n = units.size
    first = np.full(int(units.max()) + 1, n, dtype=np.int64)
    np.minimum.at(first, units, np.arange(n))
    key = first[units]
    for run in _development_runs(data, test_rows):
        m = max(1, run.size // length)
        sub = np.arange(run.size) * m // run.size
        key[run] = run[np.searchsorted(sub, sub)]
    _, out = np.unique(key, return_inverse=True)
    return out.ravel()


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


@dataclass(frozen=True)
class BufferChoice:
    """Why the buffer has the length it has (:func:`choose_buffer`, :func:`lengthen_blocks`):
    kinds and numbers, said in words by :func:`ctrplan.discrepancy.outputs.words.buffer_text`.

    Attributes
    ----------
    samples : int
        The buffer [samples].
    reason : BufferReason
    threshold : float
        :data:`BUFFER_AUTOCORRELATION` [-].
    lag_one : float or None
        The residuals' autocorrelation at lag 1 [-] (None for configuration groups).
    still : float or None
        With ``HALF_A_BLOCK``: the autocorrelation left at lag ``samples + 1`` [-].
    lengthened_from, lengthened_to : int or None
        The development blocks' length before and after they were lengthened [samples] (None:
        not lengthened).
    kept : BlocksKept or None
        Why blocks were not lengthened for a buffer capped at half a block.
    min_units, min_fit_samples : int or None
        The minimums the lengthening kept: development units, calibration samples per fit.
    """

    samples: int
    reason: BufferReason
    threshold: float = BUFFER_AUTOCORRELATION
    lag_one: float | None = None
    still: float | None = None
    lengthened_from: int | None = None
    lengthened_to: int | None = None
    kept: BlocksKept | None = None
    min_units: int | None = None
    min_fit_samples: int | None = None

    def as_dict(self) -> dict:
        """JSON form: every attribute, the kinds as their strings."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["reason"] = str(self.reason)
        d["kept"] = None if self.kept is None else str(self.kept)
        return d


@dataclass(frozen=True)
class SplitRule:
    """How the samples were split and why so many (:func:`make_split`): the numbers that
    :func:`ctrplan.discrepancy.outputs.words.split_text` says in words.

    Attributes
    ----------
    n_units : int
    unit_kind : SplitUnit
    block_samples : int or None
        Samples per time block as first cut (None: configuration groups).
    blocks_asked : bool
        The number of blocks was asked for (else at most ``max_blocks`` of at least
        ``min_block_samples`` samples).
    n_test_units, n_test_samples : int
    test_fraction : float
        Share of the units asked for the test split [-].
    test_at_minimum : bool
        The test split holds ``min_test_units`` units, more than ``test_fraction``.
    n_development_units, n_development_samples : int
    recut_block : int or None
        The development stretches re-cut into blocks of at least this many samples (None: not).
    n_folds : int
    folds_asked : bool
        The number of folds was asked for (else at most ``max_folds`` with at least
        ``min_units_per_fold`` development units each).
    subset_ignored : bool
        The data file's ``subset`` column was not used.
    max_blocks, min_block_samples, min_test_units, max_folds, min_units_per_fold : int
        The rules' constants (:data:`MAX_BLOCKS` ...).
    """

    n_units: int
    unit_kind: SplitUnit
    block_samples: int | None
    blocks_asked: bool
    n_test_units: int
    n_test_samples: int
    test_fraction: float
    test_at_minimum: bool
    n_development_units: int
    n_development_samples: int
    recut_block: int | None
    n_folds: int
    folds_asked: bool
    subset_ignored: bool
    max_blocks: int = MAX_BLOCKS
    min_block_samples: int = MIN_BLOCK_SAMPLES
    min_test_units: int = MIN_TEST_UNITS
    max_folds: int = MAX_FOLDS
    min_units_per_fold: int = MIN_UNITS_PER_FOLD

    def as_dict(self) -> dict:
        """JSON form: every attribute, the unit kind as its string."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["unit_kind"] = str(self.unit_kind)
        return d


def choose_buffer(residual, data: MeasuredData, block_samples: int | None) -> BufferChoice:
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
    BufferChoice
        The buffer (``samples``) and why that long.
    """
    if not block_samples:
        return BufferChoice(0, BufferReason.CONFIGURATION_GROUPS)
    cap = block_samples // 2
    acf = residual_autocorrelation(residual, data, max(cap + 1, 1))
    below = np.flatnonzero(np.nan_to_num(acf[1:], nan=0.0) <= BUFFER_AUTOCORRELATION)
    if below.size and below[0] < cap + 1:
        h = int(below[0])          # lag below[0] + 1 is the first at or under the threshold
        return BufferChoice(h, BufferReason.AUTOCORRELATION_FALLS, lag_one=float(acf[1]))
    return BufferChoice(cap, BufferReason.HALF_A_BLOCK, lag_one=float(acf[1]),
                        still=float(acf[min(cap + 1, acf.size - 1)]))


def lengthen_blocks(split: "DataSplit", residual, *, test_fraction: float = 0.2, n_blocks: int | None = None,
                    n_folds: int | None = None, min_fit_samples: int = 1) -> "DataSplit":
    """The split with its buffer, the development blocks lengthened when the residuals'
    autocorrelation needs a buffer longer than half a block.

    The buffer ``h`` the residuals need is the one of :func:`choose_buffer` without its cap. When
    ``h`` exceeds half a block, the stretches of development samples between test blocks are
    re-cut into blocks of at least ``2 h`` samples and the folds dealt again (:func:`make_split`
    with ``development_block``), so that ``h`` is at most half a block. That is done only while
    the blocks stay within the stretches, the split keeps its folds with at least
    :data:`MIN_UNITS_PER_FOLD` development units each (``n_folds`` folds, else as many as
    ``split`` has) and every fit (all development samples, each fold) keeps ``min_fit_samples``
    calibration samples outside the buffers; else the buffer is the longest that keeps them
    (half such a block), and ``buffer_choice`` holds how far the autocorrelation still is from
    :data:`BUFFER_AUTOCORRELATION`.

    The lengthening never costs a fold. The pilot's residual holds whatever effect the baseline
    misses, so a strong effect alone asks for long blocks; bought with folds, they cost the
    comparisons that name it most of their power, and buy no size they need. Measured by the
    simulation of :func:`~ctrplan.discrepancy.verdict.statistics.cv_comparison`'s notes (least
    squares, 400 samples, AR(1) noise, one-sided rejection rates at 0.01 / 0.00125): a real
    square-wave effect as large as the noise (phi 0.6) is found in 0.49 / 0.095 of records with
    10 blocks of 40 samples in 5 folds, in 0.80 / 0.36 with 20 blocks of 20 samples in 10 folds;
    a random walk in 0.17 / 0.024 against 0.42 / 0.081. With 20 blocks in 10 folds every null
    measured holds its level (8000 records each, at 0.01, 0.00143 and 0.00018: two equally
    good non-nested models, and a useless extra regressor beside a slow unmodelled discrepancy,
    noise phi 0.6 and 0.9); with 40 blocks of 10 samples the latter two exceed it up to fourfold,
    which the level of :func:`~ctrplan.discrepancy.verdict.decision.folds_kept_apart` covers.

    The test split keeps its blocks and rows: it was chosen before the residuals, which come from a fit that never saw it.

    Parameters
    ----------
    split : DataSplit
        Made by :func:`make_split` with the arguments below; its buffer is replaced.
    residual : array-like, shape (N, 3)
        Residual vectors at the N development samples of ``split``, in order [m] (of a fit on the
        development data, e.g. the pilot fit; rows with NaN are left out).
    test_fraction, n_blocks, n_folds
        The arguments ``split`` was made with. Blocks asked for (``n_blocks``) are not lengthened.
    min_fit_samples : int
        Calibration samples every fit keeps at least when the blocks are lengthened.

    Returns
    -------
    DataSplit
        With ``buffer``, ``buffer_choice`` and ``buffer_autocorrelation``; when lengthened, with the
        development units re-cut, the folds dealt again and ``block_samples`` the development
        blocks' length.

    Raises
    ------
    ValueError
        ``residual`` not of shape (N, 3), or arguments that do not give back ``split``'s test
        split.
    """
    dev_data = split.data.take(split.dev_rows)
    residual = np.asarray(residual, float)
    if residual.shape != (dev_data.n_samples, 3):
        raise ValueError(f"residual must have shape ({dev_data.n_samples}, 3) (the development samples), "
                         f"got {residual.shape}")
    block = split.block_samples
    if not block:
        return split.with_buffer(choose_buffer(residual, dev_data, None))
    runs = _development_runs(split.data, split.test_rows)
    longest = max(max((r.size for r in runs), default=0), block)
    acf = residual_autocorrelation(residual, dev_data, longest // 2 + 1)
    below = np.flatnonzero(np.nan_to_num(acf[1:], nan=0.0) <= BUFFER_AUTOCORRELATION)
    needed = int(below[0]) if below.size else None     # buffer reaching the threshold; None: none within a stretch
    if needed is not None and needed <= block // 2:
        choice = choose_buffer(residual, dev_data, block)
        return split.with_buffer(choice, acf[choice.samples + 1])
    min_units = MIN_UNITS_PER_FOLD * (n_folds if n_folds is not None else split.n_folds)

    def lengthened(h: int) -> DataSplit | None:
        """The split re-cut for a buffer of ``h`` samples, or None when it breaks a minimum."""
        if _count_blocks(runs, 2 * h) < min_units:
            return None
        new = make_split(split.data, test_fraction=test_fraction, n_blocks=n_blocks, n_folds=n_folds,
                         max_fit_samples=split.max_fit_samples, seed=split.seed, development_block=2 * h)
        if not np.array_equal(new.test_rows, split.test_rows):
            raise ValueError("test_fraction, n_blocks and n_folds must be the ones the split was made with "
                             "(they give another test split)")
        new = new.with_buffer(BufferChoice(h, BufferReason.HALF_A_BLOCK))
        fits = min(int(new.calibration_rows(k).sum()) for k in [None, *range(new.n_folds)])
        return new if fits >= min_fit_samples else None

    # the longest buffer in (block // 2, top] whose split keeps the minimums (bisection: a longer
    # buffer only removes samples from the fits and units from the folds)
    top = longest // 2 if needed is None else min(needed, longest // 2)
    best, lo, hi = None, block // 2, top
    if n_blocks is None and top > block // 2:
        best = lengthened(top)
        lo = top if best is not None else lo
        while hi - lo > 1:
            mid = (lo + hi) // 2
            found = lengthened(mid)
            lo, hi, best = (mid, hi, found) if found is not None else (lo, mid, best)
    if best is None:
        choice = replace(choose_buffer(residual, dev_data, block),
                         kept=BlocksKept.ASKED if n_blocks is not None else BlocksKept.MINIMUMS,
                         min_units=min_units, min_fit_samples=min_fit_samples)
        return split.with_buffer(choice, acf[choice.samples + 1])
    buffer = best.buffer
    grown = {"lengthened_from": block, "lengthened_to": best.block_samples, "min_units": min_units,
             "min_fit_samples": min_fit_samples, "lag_one": float(acf[1])}
    if buffer == needed:
        choice = BufferChoice(buffer, BufferReason.AUTOCORRELATION_FALLS, **grown)
    else:
        choice = BufferChoice(buffer, BufferReason.HALF_A_BLOCK, still=float(acf[buffer + 1]), **grown)
    return best.with_buffer(choice, acf[buffer + 1])


def choose_blocks(setup, split: "DataSplit", residual, options) -> "DataSplit":
    """Stage 3a, after the pilot fit: the buffer and the development blocks' length
    (:func:`lengthen_blocks`, every fit keeping more samples than the baseline's parameters plus
    the two largest effects', :func:`_fit_minimum`) from the pilot fit's residuals. The pilot fit uses neither the folds
    nor the buffer, so nothing fitted before is redone.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
        Of :func:`split_samples`.
    residual : array-like, shape (N, 3)
        The pilot fit's residual vectors at the N development samples of ``split`` [m] (the
        baseline fitted on the development samples without a prior,
        :func:`~ctrplan.discrepancy.fits.baseline.pilot_fit`).
    options : DiscrepancyOptions
        The ones ``split`` was made with.

    Returns
    -------
    DataSplit
        With the buffer; with longer development blocks and the folds dealt again when lengthened.
    """
    return lengthen_blocks(split, residual, test_fraction=options.test_fraction, n_blocks=options.n_blocks,
                           n_folds=options.n_folds, min_fit_samples=_fit_minimum(setup) + 1)


@dataclass(frozen=True, eq=False)
class DataSplit:
    """Stage 2: which samples are used for what.

    Attributes
    ----------
    rule : SplitRule
        The units, the test split and the folds, and why so many.
    units : ndarray of int, shape (K,)
        Unit of every sample (never cut by the split).
    unit_kind : SplitUnit
        Contiguous time blocks of a motion or groups of samples at one configuration.
    block_samples : int or None
        Samples per development time block (at least; a shorter stretch between test blocks is
        one block). The test split's blocks keep the length they were chosen with (``rule``).
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
    buffer_choice : BufferChoice or None
        Why that many (None until :meth:`with_buffer`).
    buffer_autocorrelation : float
        The residuals' autocorrelation at lag ``buffer + 1``, the nearest samples a fit keeps to
        the blocks it is judged on [-]; NaN when not known (configuration groups, no buffer
        chosen from residuals).
    data : MeasuredData
        The samples (for the buffers' record positions).
    """

    rule: SplitRule
    units: np.ndarray
    unit_kind: SplitUnit
    block_samples: int | None
    test_rows: np.ndarray
    fold: np.ndarray
    n_folds: int
    max_fit_samples: int
    seed: int
    data: MeasuredData
    buffer: int = 0
    buffer_choice: BufferChoice | None = None
    buffer_autocorrelation: float = float("nan")

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

    def with_buffer(self, choice: BufferChoice, autocorrelation: float = float("nan")) -> "DataSplit":
        """The same split with the buffer ``choice`` (:func:`choose_buffer`; ``choice.samples``
        samples) and the residuals' ``autocorrelation`` at lag ``choice.samples + 1``."""
        return replace(self, buffer=int(choice.samples), buffer_choice=choice,
                       buffer_autocorrelation=float(autocorrelation))

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
        return {"rule": self.rule.as_dict(), "unit_kind": self.unit_kind, "block_samples": self.block_samples,
                "n_units": int(np.unique(self.units).size), "n_test": self.n_test, "n_development": self.n_dev,
                "n_test_units": self.n_test_units, "n_development_units": self.n_dev_units,
                "test_units": np.unique(self.units[self.test_rows]).tolist(),
                "n_folds": self.n_folds,
                "fold_samples": [int(np.sum(self.fold == k)) for k in range(self.n_folds)],
                "fold_units": [int(np.unique(self.units[self.fold == k]).size) for k in range(self.n_folds)],
                "fit_samples": [int(self.fit_rows(self.data, k).sum()) for k in [None, *range(self.n_folds)]],
                "max_fit_samples": self.max_fit_samples, "buffer_samples": self.buffer,
                "buffer": None if self.buffer_choice is None else self.buffer_choice.as_dict(),
                "buffer_autocorrelation": (None if not np.isfinite(self.buffer_autocorrelation)
                                           else float(self.buffer_autocorrelation)),
                "development_first_last": [int(np.flatnonzero(dev)[0]), int(np.flatnonzero(dev)[-1])]}


def make_split(data: MeasuredData, *, test_fraction: float = 0.2, n_blocks: int | None = None,
               n_folds: int | None = None, max_fit_samples: int = 300, seed: int = 0,
               development_block: int | None = None) -> DataSplit:
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
    development_block : int, optional
        For time blocks longer than the ones the test split is chosen with: every stretch of
        development samples between test blocks is cut into blocks of at least this many
        samples (a shorter stretch is one block) before the folds are dealt; the test split is
        the one chosen without it (:func:`lengthen_blocks`).

    Returns
    -------
    DataSplit
        Without a buffer (:meth:`DataSplit.with_buffer` sets it once residuals exist).

    Raises
    ------
    DataFileError
        Fewer units than the test split and two folds need (also after ``development_block``).
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
    if kind == SplitUnit.TIME_BLOCK:
        every = ids.size / n_test
        phase = rng.uniform(0, every)
        test_ids = np.unique(np.floor(phase + every * np.arange(n_test)).astype(int) % ids.size)
    else:
        test_ids = rng.choice(ids, size=n_test, replace=False)
    test = np.isin(units, test_ids)
    recut = kind == SplitUnit.TIME_BLOCK and development_block is not None and development_block > block
    if recut:
        units = _recut_development(data, units, test, int(development_block))
        n_dev_units = int(np.unique(units[~test]).size)
        folds = n_folds if n_folds is not None else min(MAX_FOLDS, n_dev_units // MIN_UNITS_PER_FOLD)
        if folds < 2 or n_dev_units < folds:
            raise DataFileError(f"{data.file}: development blocks of at least {development_block} samples leave "
                                f"{n_dev_units} development units, too few for {max(folds, 2)} cross-validation folds")
    fold = np.full(data.n_samples, -1, dtype=int)
    dev_idx = np.flatnonzero(~test)
    for k, (_, val) in enumerate(GroupKFold(n_splits=folds).split(dev_idx, groups=units[dev_idx])):
        fold[dev_idx[val]] = k
    rule = SplitRule(n_units=int(ids.size), unit_kind=kind, block_samples=block, blocks_asked=n_blocks is not None,
                     n_test_units=int(test_ids.size), n_test_samples=int(test.sum()),
                     test_fraction=float(test_fraction),
                     test_at_minimum=not (n_test > MIN_TEST_UNITS or round(test_fraction * ids.size) == n_test),
                     n_development_units=int(n_dev_units), n_development_samples=int(dev_idx.size),
                     recut_block=int(development_block) if recut else None, n_folds=int(folds),
                     folds_asked=n_folds is not None, subset_ignored=data.subset is not None)
    block = int(development_block) if recut else block
    return DataSplit(rule=rule, units=units, unit_kind=kind, block_samples=block, test_rows=test, fold=fold,
                     n_folds=folds, max_fit_samples=max_fit_samples, seed=seed, data=data)


def _fit_minimum(setup) -> int:
    """The baseline's parameters plus the two largest effects' (a pair of stage 8 fits both with the
    baseline): every fit of the run needs more samples than that."""
    from ..setup import effect_parameters

    sizes = sorted((len(effect_parameters(setup.robot, e, setup.data)) for e in setup.effects), reverse=True)
    return len(setup.base_names) + sum(sizes[:2])


def split_samples(setup, options) -> DataSplit:
    """Stage 2: :func:`make_split` of the data with the options' test fraction, blocks and folds.

    Parameters
    ----------
    setup : DiscrepancySetup
    options : DiscrepancyOptions

    Returns
    -------
    DataSplit
        Without a buffer (:func:`~ctrplan.discrepancy.fits.baseline.pilot_fit` chooses it).

    Raises
    ------
    DataFileError
        Too few units, or no more samples per fit than the baseline's parameters plus the two
        largest effects'.
    """
    data = setup.data
    split = make_split(data, test_fraction=options.test_fraction, n_blocks=options.n_blocks, n_folds=options.n_folds,
                       max_fit_samples=options.max_calibration_samples, seed=options.seed)
    n_fit = min(int(split.fit_rows(data, k).sum()) for k in range(split.n_folds))
    if n_fit <= _fit_minimum(setup):
        raise DataFileError(f"{data.file}: {n_fit} calibration samples per fold are not more than the "
                            f"{len(setup.base_names)} baseline parameters plus the two largest effects'; give more "
                            f"samples")
    return split
