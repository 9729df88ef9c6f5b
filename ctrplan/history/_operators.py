"""Operators that change a recorded motion into the motion the robot or the tracker saw.

- :func:`play`: a dead band (backlash) in each rotation drive, the play operator of hysteresis
  theory (Brokate & Sprekels, *Hysteresis and Phase Transitions*, Springer 1996, Sec. 2.3);
- :func:`time_shift`: the joint record read at ``t - tau``, for a tracker whose readings lag the
  joint readings by ``tau``, through :func:`joints_at`, a shape-preserving C1 interpolant of
  each continuous motion.

Both run along each continuous motion of the whole record: a state (the play's position in the
band) or an interpolation never crosses from one motion into another, and a caller that needs
a subset of samples applies the operator to the whole record first and takes the rows after.
"""

from __future__ import annotations

import numpy as np

from ._record import MotionRecord

__all__ = ["play", "play_side", "time_shift", "joints_at"]


def _widths(record: MotionRecord, widths) -> np.ndarray:
    b = np.asarray(widths, dtype=float).reshape(-1)
    if b.shape != (record.n_tubes,):
        raise ValueError(f"backlash widths must have shape ({record.n_tubes},) (one per tube), got {b.shape}")
    if not np.all(np.isfinite(b)) or np.any(b < 0):
        raise ValueError(f"backlash widths must be finite and >= 0 rad, got {b.tolist()}")
    return b


def play(record: MotionRecord, widths) -> MotionRecord:
    """The motion of the tubes behind a dead band of width ``widths[i]`` in each rotation drive.

    The tube's base angle stays put while the drive moves within the band and is dragged at half
    the band's distance otherwise (play operator):
    ``a_k = min(max(a_(k-1), alpha_k - b/2), alpha_k + b/2)``. After a rotation in one direction
    longer than the band the tube lags the drive by ``b/2``; across a reversal the lag changes
    sign, so the offset between the two sides of a reversal is ``b``.

    Parameters
    ----------
    record : MotionRecord
        Drive (motor side) base rotations [rad] and translations [m]. Each continuous motion
        starts centred (tube angle = drive angle).
    widths : array-like, shape (n,)
        Dead band of each tube's rotation drive [rad], >= 0.

    Returns
    -------
    MotionRecord
        The same samples with the tubes' base rotations [rad]; translations unchanged.

    Raises
    ------
    ValueError
        ``widths`` not of shape (n,), negative or not finite.
    """
    b = _widths(record, widths)
    if not np.any(b > 0):
        return record
    half = 0.5 * b
    alpha = record.alpha
    out = alpha.copy()
    for idx in record.segments():
        a = alpha[idx[0]].copy()
        for k in idx[1:]:
            a = np.minimum(np.maximum(a, alpha[k] - half), alpha[k] + half)
            out[k] = a
    return record.replace(alpha=out)


def play_side(record: MotionRecord, seen: MotionRecord, widths) -> np.ndarray:
    """Where each drive sits within its dead band, shape (K, n), in [-1, 1].

    ``(alpha_drive - alpha_tube) / (b / 2)``: +1 after a rotation in the + direction longer than
    the band (the tube lags by ``b/2``), -1 after one in the - direction, in between after a
    shorter move, 0 centred or without backlash (``b = 0``).

    Parameters
    ----------
    record, seen : MotionRecord
        The drive motion and the tube motion (:func:`play`) [rad].
    widths : array-like, shape (n,)
        [rad], >= 0.
    """
    b = _widths(record, widths)
    half = 0.5 * b
    side = np.divide(record.alpha - seen.alpha, half, out=np.zeros_like(record.alpha), where=half > 0)
    return np.clip(side, -1.0, 1.0)


def joints_at(record: MotionRecord, times) -> tuple[np.ndarray, np.ndarray]:
    """The joint values of each continuous motion read at other times, with a smooth interpolant.

    Within each motion the joints are interpolated by the piecewise-cubic Hermite interpolant
    that preserves monotonicity (PCHIP: Fritsch & Carlson, SIAM J. Numer. Anal. 17(2):238, 1980;
    ``scipy.interpolate.PchipInterpolator``). It has a continuous first derivative, so a cost
    read along ``time - tau`` has no kink at multiples of the sample period (linear
    interpolation puts one at every sample); it does not overshoot, so a joint at rest between
    two equal samples stays at rest, and it passes through every sample. Outside a motion's
    time span a joint is held at the motion's first or last sample.

    Parameters
    ----------
    record : MotionRecord
        Needs ``time`` [s].
    times : array-like, shape (K,)
        Time [s] at which each sample's joints are read, within the sample's own motion.

    Returns
    -------
    alpha : ndarray, shape (K, n)
        [rad].
    beta : ndarray, shape (K, n)
        [m].

    Raises
    ------
    ValueError
        A record without times, or ``times`` not finite or not of shape (K,).
    """
    from scipy.interpolate import PchipInterpolator

    if record.time is None:
        raise ValueError("reading joints at other times needs sample times (a 'time' column)")
    q = np.asarray(times, dtype=float)
    if q.shape != (record.n_samples,) or not np.all(np.isfinite(q)):
        raise ValueError(f"times must hold {record.n_samples} finite values [s], got shape {q.shape}")
    joints = np.concatenate([record.alpha, record.beta], axis=1)
    out = joints.copy()
    t = record.time
    for idx in record.segments():
        if idx.size < 2:
            continue
        ts = t[idx]
        at = np.clip(q[idx], ts[0], ts[-1])
        out[idx] = PchipInterpolator(ts, joints[idx], axis=0)(at)
    n = record.n_tubes
    return out[:, :n], out[:, n:]


def time_shift(record: MotionRecord, tau: float) -> MotionRecord:
    """The joint record read at ``time - tau``: the configuration a tracker reading lagging by
    ``tau`` shows.

    Parameters
    ----------
    record : MotionRecord
        Needs ``time`` [s].
    tau : float
        Lag of the tracker readings behind the joint readings [s]; negative: the tracker leads.

    Returns
    -------
    MotionRecord
        Joints read at ``time - tau`` within each continuous motion by :func:`joints_at` (a C1,
        shape-preserving interpolant of the samples), held at the motion's first / last sample
        outside it.

    Raises
    ------
    ValueError
        A record without times, or ``tau`` not finite.
    """
    if record.time is None:
        raise ValueError("a time offset needs sample times (a 'time' column)")
    if not np.isfinite(tau):
        raise ValueError(f"time offset must be finite, got {tau!r} s")
    if tau == 0.0:
        return record
    alpha, beta = joints_at(record, record.time - tau)
    return record.replace(alpha=alpha, beta=beta)
