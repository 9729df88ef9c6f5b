"""A recorded or planned joint motion: base rotations and translations in time order."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MotionRecord", "sequence_segments"]


def sequence_segments(sequence, n_samples: int) -> list[np.ndarray]:
    """Row indices of each continuous motion, ascending sequence id, rows in table order.

    Parameters
    ----------
    sequence : array-like of int, shape (K,), or None
        Motion id of each row; rows of one id form one continuous motion in table order (the ids
        need not be contiguous). None: all rows are one motion.
    n_samples : int
        K.

    Returns
    -------
    list of ndarray of int

    Raises
    ------
    ValueError
        ``sequence`` not of shape (K,), or an id that is not an integer (the row is named).
    """
    if sequence is None:
        return [np.arange(n_samples)]
    seq = np.asarray(sequence)
    if seq.shape != (n_samples,):
        raise ValueError(f"sequence must have shape ({n_samples},), got {seq.shape}")
    seqf = seq.astype(float)
    bad = ~np.isfinite(seqf) | (seqf != np.round(np.nan_to_num(seqf)))
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"sequence ids must be integers; row {k + 1} has {seq[k]!r}")
    ids = seqf.astype(np.int64)
    order = np.argsort(ids, kind="stable")
    cuts = np.flatnonzero(np.diff(ids[order])) + 1
    return np.split(order, cuts)


@dataclass(frozen=True, eq=False)
class MotionRecord:
    """Joint values along one or more continuous motions, as commanded (encoders, a plan).

    Parameters
    ----------
    alpha : array-like, shape (K, n)
        Base rotations [rad] of the drives, rows in time order within each motion; periodic
        angles continuous (not wrapped: a wrap would look like a full turn).
    beta : array-like, shape (K, n)
        Base translations [m].
    time : array-like, shape (K,), optional
        Sample times [s], increasing within each motion (needed by a time offset).
    sequence : array-like of int, shape (K,), optional
        Motion id of each row (:func:`sequence_segments`); None: one continuous motion.

    Raises
    ------
    ValueError
        Shapes that do not match, non-finite joints or times, non-integer sequence ids, times
        that do not increase within a motion.
    """

    alpha: np.ndarray
    beta: np.ndarray
    time: np.ndarray | None = None
    sequence: np.ndarray | None = None

    def __post_init__(self):
        alpha = np.array(self.alpha, dtype=float)
        beta = np.array(self.beta, dtype=float)
        if alpha.ndim != 2 or beta.shape != alpha.shape or alpha.shape[1] < 1:
            raise ValueError(f"alpha and beta must both have shape (K, n), got {alpha.shape} and {beta.shape}")
        for name, arr in (("alpha", alpha), ("beta", beta)):
            if not np.all(np.isfinite(arr)):
                k = int(np.argwhere(~np.isfinite(arr))[0][0])
                raise ValueError(f"{name} must be finite; row {k + 1} has {arr[k].tolist()}")
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "beta", beta)
        K = alpha.shape[0]
        if self.sequence is not None:
            seq = np.asarray(self.sequence)
            sequence_segments(seq, K)    # validates
            object.__setattr__(self, "sequence", seq.astype(np.int64))
        if self.time is not None:
            t = np.array(self.time, dtype=float)
            if t.shape != (K,) or not np.all(np.isfinite(t)):
                raise ValueError(f"time must hold {K} finite values [s], got shape {t.shape}")
            for idx in self.segments():
                dt = np.diff(t[idx])
                if np.any(dt <= 0):
                    j = int(np.flatnonzero(dt <= 0)[0])
                    raise ValueError(f"time must increase within a motion; row {idx[j + 1] + 1} has "
                                     f"{t[idx[j + 1]]!r} s after {t[idx[j]]!r} s")
            object.__setattr__(self, "time", t)

    @property
    def n_samples(self) -> int:
        return self.alpha.shape[0]

    @property
    def n_tubes(self) -> int:
        return self.alpha.shape[1]

    def segments(self) -> list[np.ndarray]:
        """Row indices of each continuous motion (:func:`sequence_segments`)."""
        return sequence_segments(self.sequence, self.n_samples)

    def replace(self, *, alpha=None, beta=None) -> "MotionRecord":
        """The same samples with other joint values (times and sequences kept)."""
        return MotionRecord(self.alpha if alpha is None else alpha, self.beta if beta is None else beta,
                            self.time, self.sequence)

    def take(self, rows) -> "MotionRecord":
        """The rows ``rows`` (index array or boolean mask) in their order: a record of its own,
        whose motion history restarts at the first row (use a state computed on the full record
        and take its rows to keep the history)."""
        rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, dtype=int)
        return MotionRecord(self.alpha[rows], self.beta[rows], None if self.time is None else self.time[rows],
                            None if self.sequence is None else self.sequence[rows])
