"""Effects that change the recorded motion history rather than the robot.

- :func:`apply_backlash`: a dead band (play) in each rotation drive. The tube's base angle
  follows the recorded (motor) angle only once the motor has taken up the play, so after every
  reversal it lags the recorded angle by up to half the band (the play operator of hysteresis
  theory; Brokate & Sprekels, *Hysteresis and Phase Transitions*, Springer 1996, Sec. 2.3).
- :func:`apply_time_offset`: the joint readings and the tracker readings are offset in time;
  the tip measured at time t belongs to the joints recorded at t - tau (tau > 0: the tracker
  lags), found by linear interpolation of the joint record within each sequence.
- :func:`friction_state`: friction that develops gradually after a reversal. Ha, Fagogenis &
  Dupont (IEEE T-RO 35(2) 2019, Section III) assume rotations "of sufficient angle", so that
  the maximal friction torque of the new direction has developed; here the signed state
  e_k in [-1, 1] of pair k moves towards the direction of rotation exponentially with the
  relative rotation angle (a Dahl-type friction law, Dahl, "A solid friction model", Aerospace
  Corp. TOR-0158(3107-18)-1, 1968):

  .. math:: de_k = (\\operatorname{sign}(dr_k) - e_k)\\, |dr_k| / \\theta_c,

  so after a reversal from a developed state e = 1 - 2 exp(-|r - r_rev| / theta_c). A
  translation after the last relative rotation releases the twist (Section V-B): e = 0 there
  (and the state restarts from 0). The friction model is then solved with eta_k = sign(e_k)
  and mu_k |e_k| (the friction torque of Eq. (41) scales with eta_k mu_k).

All functions are pure: arrays in, arrays out, SI units. Rows of one ``sequence`` id are one
continuous motion in table order (as :func:`ctrplan.discrepancy.simulate.motion_history`); a
sequence of one sample has no history (the play and the time offset change nothing there, the
friction state is taken as fully developed in the recorded direction eta).
"""

from __future__ import annotations

import numpy as np

from ..constants import HISTORY_ROTATION_TOL, HISTORY_TRANSLATION_TOL
from .simulate import _sequence_groups, motion_history

__all__ = ["apply_backlash", "apply_time_offset", "friction_state", "rotation_direction",
           "rotation_since_reversal", "tip_velocity"]


def _groups(sequence, K):
    groups = _sequence_groups(sequence, K)
    return groups if groups is not None else [np.arange(K)]


def apply_backlash(alpha, widths, sequence=None) -> np.ndarray:
    """Base angles behind a dead band of width ``widths[i]`` in the drive of tube i.

    Parameters
    ----------
    alpha : array-like, shape (K, n)
        Recorded (motor side) base rotations [rad], rows in time order within each sequence.
    widths : array-like, shape (n,)
        Dead band of each rotation drive [rad], >= 0. The tube's angle stays put while the motor
        moves within the band and is dragged at half the band's distance otherwise:
        ``a_k = min(max(a_(k-1), alpha_k - b/2), alpha_k + b/2)``.
    sequence : array-like of int, shape (K,), optional
        Continuous-motion ids (None: one motion). Each sequence starts centred (a = alpha).

    Returns
    -------
    ndarray, shape (K, n)
        Tube base angles [rad].

    Raises
    ------
    ValueError
        Shapes that do not match, a negative or non-finite width.
    """
    alpha = np.asarray(alpha, dtype=float)
    b = np.asarray(widths, dtype=float).reshape(-1)
    if alpha.ndim != 2 or b.shape != (alpha.shape[1],):
        raise ValueError(f"backlash widths must have shape ({alpha.shape[-1]},) for alpha of shape "
                         f"{alpha.shape}, got {b.shape}")
    if not np.all(np.isfinite(b)) or np.any(b < 0):
        raise ValueError(f"backlash widths must be finite and >= 0 rad, got {b.tolist()}")
    out = alpha.copy()
    if not np.any(b > 0):
        return out
    half = 0.5 * b
    for idx in _groups(sequence, alpha.shape[0]):
        a = alpha[idx[0]].copy()
        for k in idx[1:]:
            a = np.minimum(np.maximum(a, alpha[k] - half), alpha[k] + half)
            out[k] = a
    return out


def apply_time_offset(alpha, beta, time, tau: float, sequence=None) -> tuple[np.ndarray, np.ndarray]:
    """Joint values at ``time - tau``: the configuration a tracker reading lagging by ``tau`` shows.

    Parameters
    ----------
    alpha, beta : array-like, shape (K, n)
        Recorded joints [rad], [m].
    time : array-like, shape (K,)
        Sample times [s], increasing within each sequence.
    tau : float
        Tracker lag behind the joint readings [s] (negative: the tracker leads).
    sequence : array-like of int, shape (K,), optional

    Returns
    -------
    alpha, beta : ndarray, shape (K, n)
        Linear interpolation of the joint record of the row's sequence at ``time - tau``, held
        at the first / last sample outside the record.

    Raises
    ------
    ValueError
        No times, shapes that do not match, times not increasing within a sequence.
    """
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    if time is None:
        raise ValueError("a time offset needs sample times (a 'time' column)")
    t = np.asarray(time, dtype=float)
    if t.shape != (alpha.shape[0],):
        raise ValueError(f"time must have shape ({alpha.shape[0]},), got {t.shape}")
    if not np.isfinite(tau):
        raise ValueError(f"time offset must be finite, got {tau!r}")
    a_out, b_out = alpha.copy(), beta.copy()
    if tau == 0.0:
        return a_out, b_out
    for idx in _groups(sequence, alpha.shape[0]):
        ts = t[idx]
        if idx.size < 2:
            continue
        if np.any(np.diff(ts) <= 0):
            bad = int(np.flatnonzero(np.diff(ts) <= 0)[0])
            raise ValueError(f"time must increase within a sequence; row {idx[bad + 1] + 1} has "
                             f"{ts[bad + 1]!r} s after {ts[bad]!r} s")
        q = ts - tau
        for arr, out in ((alpha, a_out), (beta, b_out)):
            for j in range(arr.shape[1]):
                out[idx, j] = np.interp(q, ts, arr[idx, j])
    return a_out, b_out


def friction_state(alpha, beta, theta_c: float, sequence=None, *, eta=None, rotation_tol: float = HISTORY_ROTATION_TOL,
                   translation_tol: float = HISTORY_TRANSLATION_TOL) -> np.ndarray:
    """Signed friction state e in [-1, 1] of every pair along the motion (Dahl-type development).

    Parameters
    ----------
    alpha, beta : array-like, shape (K, n)
        Base rotations [rad] and translations [m] (after any history effect).
    theta_c : float
        Characteristic relative rotation angle over which friction develops [rad], >= 0; 0
        gives the abrupt switch of the paper's model (e = eta).
    sequence : array-like of int, shape (K,), optional
    eta : array-like of int, shape (K, n - 1), optional
        Directions for one-sample sequences (no history to develop over): e = eta there.
    rotation_tol, translation_tol : float
        As :func:`~ctrplan.discrepancy.simulate.motion_history` (translation-last resets e to 0).

    Returns
    -------
    ndarray, shape (K, n - 1)
        e_k; the friction model uses eta_k = sign(e_k), mu_k |e_k|.

    Raises
    ------
    ValueError
        Negative or non-finite ``theta_c``, shapes that do not match.
    """
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    if not np.isfinite(theta_c) or theta_c < 0:
        raise ValueError(f"friction angle theta_c must be finite and >= 0 rad, got {theta_c!r}")
    K, n = alpha.shape
    hist = motion_history(alpha, beta, sequence if sequence is not None else np.zeros(K, int),
                          rotation_tol=rotation_tol, translation_tol=translation_tol)
    if theta_c == 0.0:
        e = hist.eta.astype(float)
        e[hist.translation_last] = 0.0
    else:
        rel = np.diff(alpha, axis=1)
        e = np.zeros((K, n - 1))
        for idx in _groups(sequence, K):
            state = np.zeros(n - 1)
            for j, k in enumerate(idx):
                if j > 0:
                    dr = rel[k] - rel[idx[j - 1]]
                    state = np.sign(dr) + (state - np.sign(dr)) * np.exp(-np.abs(dr) / theta_c)
                if hist.translation_last[k]:
                    state = np.zeros(n - 1)
                e[k] = state
    if eta is not None:
        eta = np.asarray(eta, dtype=float).reshape(K, n - 1)
        single = np.zeros(K, dtype=bool)
        for idx in _groups(sequence, K):
            single[idx] = idx.size == 1
        e[single] = eta[single]
    return e


def rotation_direction(alpha, sequence=None, tol: float = 1e-3) -> np.ndarray:
    """Direction of the last absolute rotation of every tube, shape (K, n), in {-1, 0, +1}.

    The sign of the play of :func:`apply_backlash`: after a rotation in direction s the tube
    lags by -s b/2. With hysteresis ``tol`` [rad] like the relative directions of
    :func:`~ctrplan.discrepancy.simulate.motion_history`; 0 before the tube has moved.
    """
    from ..io.tables import rotation_directions

    alpha = np.asarray(alpha, dtype=float)
    K, n = alpha.shape
    out = np.zeros((K, n), dtype=int)
    # rotation_directions reads relative angles alpha_(i+1) - alpha_i: prepend a fixed zero tube
    padded = np.concatenate([np.zeros((K, 1)), alpha], axis=1)
    for idx in _groups(sequence, K):
        out[idx] = rotation_directions(padded[idx], tol=tol)
    return out


def tip_velocity(tip, time, sequence=None) -> np.ndarray:
    """Tip velocity along each sequence by central differences in time, shape (K, 3) [m/s].

    Within runs of contiguous samples (a gap longer than 1.5 median steps, e.g. between the
    held-out blocks of a trajectory, starts a new run); one-sided at run ends; NaN for runs of
    one sample, NaN tips, or without times.
    """
    tip = np.asarray(tip, dtype=float)
    K = tip.shape[0]
    v = np.full((K, 3), np.nan)
    if time is None:
        return v
    t = np.asarray(time, dtype=float)
    for idx in _groups(sequence, K):
        if idx.size < 2:
            continue
        dt = np.diff(t[idx])
        step = np.median(dt[dt > 0]) if np.any(dt > 0) else 0.0
        cuts = np.flatnonzero((dt > 1.5 * step) | (dt <= 0)) + 1
        for run in np.split(idx, cuts):
            if run.size >= 2:
                v[run] = np.gradient(tip[run], t[run], axis=0)
    return v


def rotation_since_reversal(alpha, sequence=None, tol: float = 1e-3) -> np.ndarray:
    """Relative rotation of every pair since its last reversal, shape (K, n - 1) [rad], >= 0.

    Measured from the relative angle ``alpha_(i+1) - alpha_i`` at which the direction of
    :func:`~ctrplan.io.tables.rotation_directions` last changed (or the sequence started);
    the distance over which gradually developing friction builds up (:func:`friction_state`).
    """
    from ..io.tables import rotation_directions

    alpha = np.asarray(alpha, dtype=float)
    K, n = alpha.shape
    rel = np.diff(alpha, axis=1)
    out = np.zeros((K, n - 1))
    for idx in _groups(sequence, K):
        eta = rotation_directions(alpha[idx], tol=tol)
        anchor = rel[idx[0]].copy()
        for j, k in enumerate(idx):
            if j > 0:
                flip = eta[j] != eta[j - 1]
                anchor[flip] = rel[idx[j - 1]][flip]
            out[k] = np.abs(rel[k] - anchor)
    return out
