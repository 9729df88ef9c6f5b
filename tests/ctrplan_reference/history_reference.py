"""Motion-history rules written again from their definitions, for tests.

An independent statement of the rules of ``docs/discrepancy.md`` (section "Motion history") and
of the docstrings of ``ctrplan/history/_operators.py`` and ``ctrplan/history/_state.py``. It
imports nothing from ``ctrplan.history``, ``ctrplan.effects`` or ``ctrplan.discrepancy`` and is
written in another form than they are, so that a sign or convention error there cannot hide in
a test that checks them against this module:

- drive backlash (play operator, Brokate & Sprekels, *Hysteresis and Phase Transitions*,
  Springer 1996, Sec. 2.3) as the explicit position of a dead band around the tube
  (:func:`play_band`), meant for a fine time grid of an analytic motion;
- tracker time offset as the exact evaluation time ``t - tau`` of an analytic motion, held at
  the motion's first and last times (:func:`tracker_times`); no interpolation of samples;
- the friction state of every tube pair (direction eta_k with hysteresis, rotation, release by
  a translation, gradually developing friction; Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019,
  Eqs. (38)-(39) and Section V-B, doi:10.1109/TRO.2018.2878906) as an event loop per pair
  (:func:`pair_history`), and the friction it applies (:func:`applied_friction`).

Pure numerics, SI units (rad, m, s). Slow and simple on purpose: per-sample Python loops.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ROTATION_TOL", "TRANSLATION_TOL", "play_band", "tracker_times", "PairHistory", "pair_history",
           "applied_friction"]

#: Smallest change of a pair's relative angle that counts as a rotation, and the hysteresis of
#: its direction [rad] (docs/discrepancy.md, "Motion history": 1 mrad).
ROTATION_TOL = 1e-3
#: Smallest change of a base translation since a pair's last rotation that releases the pair
#: [m] (docs/discrepancy.md, "Motion history": 0.1 mm).
TRANSLATION_TOL = 1e-4


def play_band(drive, widths) -> np.ndarray:
    """Tube base angles behind a dead band in each rotation drive, along one continuous motion.

    The band of tube i has width ``widths[i]`` and is carried by the drive: the tube's base
    angle is the band's centre ``c``. While the drive angle ``d`` stays inside
    ``[c - b/2, c + b/2]`` the band (and the tube) does not move; when the drive reaches an
    edge it pushes the band, so the tube follows at distance ``b/2`` behind the drive. The
    motion starts centred (``c = d`` at the first row).

    The operator is rate independent and exact at any grid that holds every turning point of
    the drive; on a fine grid of a smooth motion it is the continuous-time play operator.

    Parameters
    ----------
    drive : array-like, shape (N, n)
        Drive (motor side) base angles [rad] in time order, one continuous motion.
    widths : array-like, shape (n,)
        Dead band width of each drive [rad], >= 0.

    Returns
    -------
    ndarray, shape (N, n)
        Tube base angles [rad].

    Raises
    ------
    ValueError
        ``drive`` not 2-D, ``widths`` not of shape (n,), negative or not finite.
    """
    drive = np.asarray(drive, dtype=float)
    if drive.ndim != 2:
        raise ValueError(f"drive angles must have shape (N, n), got {drive.shape}")
    b = np.asarray(widths, dtype=float).reshape(-1)
    if b.shape != (drive.shape[1],) or not np.all(np.isfinite(b)) or np.any(b < 0):
        raise ValueError(f"widths must be {drive.shape[1]} finite values >= 0 rad, got {b.tolist()}")
    out = np.empty_like(drive)
    if drive.shape[0] == 0:
        return out
    centre = drive[0].copy()
    for k, d in enumerate(drive):
        upper_edge = centre + 0.5 * b
        lower_edge = centre - 0.5 * b
        push_up = d > upper_edge             # the drive pushes the band's upper edge ahead of it
        push_down = d < lower_edge
        centre = np.where(push_up, d - 0.5 * b, centre)
        centre = np.where(push_down, d + 0.5 * b, centre)
        out[k] = centre
    return out


def tracker_times(times, tau: float, start: float | None = None, end: float | None = None) -> np.ndarray:
    """The times of the motion a tracker reading at ``times`` shows when it lags by ``tau``.

    The tip measured at time t belongs to the joints at ``t - tau``; outside the motion
    ``[start, end]`` the motion is held at its first / last value.

    Parameters
    ----------
    times : array-like, shape (K,)
        Reading times [s].
    tau : float
        Lag of the tracker behind the joint readings [s]; negative: the tracker leads.
    start, end : float, optional
        Time span of the motion [s]; default the first and last of ``times``.

    Returns
    -------
    ndarray, shape (K,)
        Times [s] at which to evaluate the (analytic) motion.

    Raises
    ------
    ValueError
        ``tau`` not finite.
    """
    t = np.asarray(times, dtype=float)
    if not np.isfinite(tau):
        raise ValueError(f"time offset must be finite, got {tau!r} s")
    lo = t.min() if start is None else start
    hi = t.max() if end is None else end
    return np.minimum(np.maximum(t - tau, lo), hi)


@dataclass(frozen=True, eq=False)
class PairHistory:
    """Friction state of every adjacent tube pair at every sample of one continuous motion.

    Attributes
    ----------
    eta : ndarray of int, shape (K, n - 1)
        Direction of the last change of ``alpha_(k+1) - alpha_k`` (+1 increasing, -1
        decreasing, 0 before the pair has rotated), with hysteresis :data:`ROTATION_TOL`.
    rotated : ndarray of bool, shape (K, n - 1)
        The pair rotates at this sample (relative angle moved more than :data:`ROTATION_TOL`
        since its previous rotation or the start of the motion).
    released : ndarray of bool, shape (K, n - 1)
        Translation-last: some base translation moved more than :data:`TRANSLATION_TOL` since
        the pair's last rotation (since the motion started if it has not rotated).
    friction : ndarray, shape (K, n - 1)
        Signed friction state e_k in [-1, 1]: ``eta`` where not released (abrupt), the
        developing state with a friction angle; 0 where released.
    """

    eta: np.ndarray
    rotated: np.ndarray
    released: np.ndarray
    friction: np.ndarray


def pair_history(alpha, beta, *, friction_angle: float = 0.0, rotation_tol: float = ROTATION_TOL,
                 translation_tol: float = TRANSLATION_TOL) -> PairHistory:
    """The friction state of each tube pair along one continuous motion, sample by sample.

    Per pair k (tubes k and k+1), from the words of docs/discrepancy.md ("Motion history"):

    - eta_k follows the relative angle ``r = alpha_(k+1) - alpha_k``: it becomes +1 (-1) once
      r has risen (fallen) by more than ``rotation_tol`` from its value at the start, and
      flips once r has come back by more than ``rotation_tol`` from its latest extreme;
    - the pair rotates at a sample when r moved more than ``rotation_tol`` since the pair's
      previous rotation; a rotation ends a release, and a translation at the same sample does
      not release (the two were concurrent, the rotation is still the last motion);
    - the pair is released once some base translation differs by more than
      ``translation_tol`` from its value at the pair's last rotation;
    - gradual friction (``friction_angle`` theta_c > 0): ``de = (sign(dr) - e) |dr| / theta_c``
      between samples (solved exactly over each sample step, in which r is monotone), reset to
      0 at every released sample; abrupt (theta_c = 0): ``e = eta`` unless released.

    Parameters
    ----------
    alpha : array-like, shape (K, n)
        Base angles the tubes reach [rad], rows in time order.
    beta : array-like, shape (K, n)
        Base translations [m].
    friction_angle : float
        theta_c [rad], >= 0.
    rotation_tol, translation_tol : float
        [rad], [m], > 0.

    Returns
    -------
    PairHistory

    Raises
    ------
    ValueError
        Shapes that do not match, tolerances <= 0, a negative or non-finite friction angle.
    """
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    if alpha.ndim != 2 or beta.shape != alpha.shape:
        raise ValueError(f"alpha and beta must have the same shape (K, n), got {alpha.shape} and {beta.shape}")
    if not (rotation_tol > 0 and translation_tol > 0):
        raise ValueError(f"tolerances must be > 0, got {rotation_tol!r} rad and {translation_tol!r} m")
    if not (np.isfinite(friction_angle) and friction_angle >= 0):
        raise ValueError(f"friction angle must be finite and >= 0 rad, got {friction_angle!r}")
    K, n = alpha.shape
    m = n - 1
    eta = np.zeros((K, m), dtype=int)
    rotated = np.zeros((K, m), dtype=bool)
    released = np.zeros((K, m), dtype=bool)
    friction = np.zeros((K, m))
    for k in range(m):
        r = alpha[:, k + 1] - alpha[:, k]
        direction, extreme = 0, r[0] if K else 0.0       # extreme: start value until the first rotation
        at_rotation_r, at_rotation_beta = (r[0], beta[0]) if K else (0.0, None)
        free = False
        e = 0.0
        for j in range(K):
            # direction with hysteresis
            if direction == 0:
                if r[j] > extreme + rotation_tol:
                    direction, extreme = 1, r[j]
                elif r[j] < extreme - rotation_tol:
                    direction, extreme = -1, r[j]
            elif direction == 1:
                if r[j] >= extreme:
                    extreme = r[j]
                elif r[j] < extreme - rotation_tol:
                    direction, extreme = -1, r[j]
            else:
                if r[j] <= extreme:
                    extreme = r[j]
                elif r[j] > extreme + rotation_tol:
                    direction, extreme = 1, r[j]
            eta[j, k] = direction
            # rotation event, then release by a translation since it
            if abs(r[j] - at_rotation_r) > rotation_tol:
                rotated[j, k] = True
                at_rotation_r, at_rotation_beta = r[j], beta[j]
                free = False
            if np.max(np.abs(beta[j] - at_rotation_beta)) > translation_tol:
                free = True
            released[j, k] = free
            # friction state
            if friction_angle > 0.0:
                if j > 0:
                    step = r[j] - r[j - 1]
                    target = float(np.sign(step))
                    e = target - (target - e) * np.exp(-abs(step) / friction_angle)
                if free:
                    e = 0.0
                friction[j, k] = e
            else:
                friction[j, k] = 0.0 if free else float(direction)
    return PairHistory(eta=eta, rotated=rotated, released=released, friction=friction)


def applied_friction(friction, mu) -> tuple[np.ndarray, np.ndarray]:
    """Friction direction and coefficient the friction model applies per pair and sample.

    Direction ``sign(e_k)``, coefficient ``|e_k| mu_k``; a pair with coefficient 0 (released,
    no history, or a frictionless pair) carries no friction and gets direction 0.

    Parameters
    ----------
    friction : array-like, shape (K, n - 1)
        Signed friction state e_k in [-1, 1] (:attr:`PairHistory.friction`).
    mu : array-like, shape (n - 1,)
        Friction coefficient of each pair [-], >= 0.

    Returns
    -------
    eta : ndarray of int, shape (K, n - 1)
        +1, -1, or 0 where no friction acts.
    mu : ndarray, shape (K, n - 1)
        Applied coefficient [-].

    Raises
    ------
    ValueError
        ``mu`` of the wrong length, negative or not finite.
    """
    e = np.atleast_2d(np.asarray(friction, dtype=float))
    mu = np.asarray(mu, dtype=float).reshape(-1)
    if mu.shape != (e.shape[1],) or not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise ValueError(f"mu must hold {e.shape[1]} finite values >= 0, got {mu.tolist()}")
    coeff = np.abs(e) * mu[None, :]
    direction = np.where(coeff > 0.0, np.sign(e), 0.0).astype(int)
    return direction, coeff
