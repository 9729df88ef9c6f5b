"""The friction state of every tube pair along a motion: one rule for measured and planned motions.

Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906: the torsional
friction of a contacting pair acts against its last relative rotation, direction eta_k
(Eqs. (38)-(39)); a translation after that rotation releases the friction-induced twist
("translation-last", Section V-B). The rule, per pair k (tubes k and k+1), along each
continuous motion:

- **direction** eta_k: the direction of the last change of the relative angle
  ``alpha_(k+1) - alpha_k``, with hysteresis ``rotation_tol`` (:func:`rotation_directions`);
  0 until the pair has rotated;
- **rotation**: the pair rotates at a sample when its relative angle has moved more than
  ``rotation_tol`` since its previous rotation (or since the motion started);
- **release**: the pair is released once some base translation differs by more than
  ``translation_tol`` from its value at the pair's last rotation; a later rotation of the
  same pair ends the release, a rotation of another pair does not. A sample at which the pair
  rotates is not released by a translation at the same sample (the two were concurrent: the
  rotation is still the last motion);
- **never rotated**: a pair without a rotation in the motion carries no friction (mu = 0),
  unless the caller gives the direction of the approach before the record (``given_eta``,
  e.g. the approach of the paper's protocol, which the record does not hold);
- **development** (gradual friction): the signed state ``e_k`` in [-1, 1] moves towards the
  direction of rotation exponentially with the relative rotation angle, a Dahl-type law (Dahl,
  "A solid friction model", Aerospace Corp. TOR-0158(3107-18)-1, 1968):
  ``de = (sign(dr) - e) |dr| / theta_c``, so after a reversal from a developed state
  ``e = 1 - 2 exp(-|r - r_rev| / theta_c)``; a release sets ``e = 0``, from which it develops
  again. ``theta_c = 0`` is the paper's abrupt switch: ``e = eta`` while not released.

The friction model is then solved per pair with direction ``sign(e_k)`` and coefficient
``|e_k| mu_k`` (the friction torque of Eq. (41) scales with eta_k mu_k).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..constants import HISTORY_ROTATION_TOL, HISTORY_TRANSLATION_TOL
from ._record import MotionRecord

__all__ = ["HistoryState", "PairState", "PAIR_CASES", "rotation_directions", "drive_directions",
           "rotation_since_reversal", "motion_state", "pair_friction"]

#: What governs a pair at a sample (``HistoryState.cases``, ``Prediction.cases``).
PAIR_CASES = {
    "friction": "last motion of the pair a relative rotation: torsional friction in direction eta "
                "(maximal once developed)",
    "translation_last": "a translation followed the pair's last relative rotation: released (mu = 0)",
    "no_history": "the pair has not rotated yet (eta 0): taken frictionless (mu = 0)",
    "frictionless": "the robot's friction coefficient of the pair is 0",
}


def _directions(x: np.ndarray, tol: float) -> np.ndarray:
    """Direction of the last change of each column of ``x`` (K, m), hysteresis ``tol``."""
    out = np.zeros(x.shape, dtype=np.int64)
    _directions_into(np.ascontiguousarray(x, dtype=float), float(tol), out)
    return out


@njit(cache=True)
def _directions_into(x, tol, out):
    """:func:`_directions` of ``x`` (K, m), written into ``out`` (K, m) int."""
    for i in range(x.shape[1]):
        state, anchor = 0, x[0, i] if x.shape[0] else 0.0
        for k in range(x.shape[0]):
            v = x[k, i]
            if state >= 0 and v > anchor and (state == 1 or v - anchor > tol):
                state, anchor = 1, v
            elif state <= 0 and v < anchor and (state == -1 or anchor - v > tol):
                state, anchor = -1, v
            elif state == 1 and anchor - v > tol:
                state, anchor = -1, v
            elif state == -1 and v - anchor > tol:
                state, anchor = 1, v
            out[k, i] = state


@njit(cache=True)
def _friction_rows(rel, beta, rows, offsets, rotation_tol, translation_tol, friction_angle, eta, released,
                   friction):
    """The loop of :func:`motion_state` over each motion (rows ``rows[offsets[g]:offsets[g + 1]]``
    in order): ``released`` and ``friction`` (K, m), written in place from the relative
    rotations ``rel`` (K, m) [rad], the translations ``beta`` (K, n) [m] and the directions
    ``eta`` (K, m) of :func:`_directions`."""
    m = rel.shape[1]
    n = beta.shape[1]
    for g in range(offsets.shape[0] - 1):
        idx = rows[offsets[g]:offsets[g + 1]]
        if idx.shape[0] == 0:
            continue
        ref_rel = rel[idx[0]].copy()
        ref_beta = np.empty((m, n))     # bases at each pair's last rotation
        for i in range(m):
            ref_beta[i] = beta[idx[0]]
        free = np.zeros(m, dtype=np.bool_)
        e = np.zeros(m)
        for j in range(idx.shape[0]):
            k = idx[j]
            if j > 0:
                for i in range(m):
                    if np.abs(rel[k, i] - ref_rel[i]) > rotation_tol:
                        ref_rel[i] = rel[k, i]
                        ref_beta[i] = beta[k]
                        free[i] = False
                for i in range(m):
                    if np.max(np.abs(beta[k] - ref_beta[i])) > translation_tol:
                        free[i] = True
                if friction_angle > 0.0:
                    for i in range(m):
                        dr = rel[k, i] - rel[idx[j - 1], i]
                        sg = np.sign(dr)
                        e[i] = sg + (e[i] - sg) * np.exp(-np.abs(dr) / friction_angle)
            for i in range(m):
                released[k, i] = free[i]
                if friction_angle > 0.0:
                    if free[i]:
                        e[i] = 0.0
                    friction[k, i] = e[i]
                else:
                    friction[k, i] = 0.0 if free[i] else eta[k, i]


def _check_tol(rotation_tol, translation_tol=1.0):
    if not rotation_tol > 0 or not translation_tol > 0:
        raise ValueError(f"tolerances must be > 0, got rotation_tol={rotation_tol!r} rad, "
                         f"translation_tol={translation_tol!r} m")


def rotation_directions(alpha, tol: float = HISTORY_ROTATION_TOL, sequence=None) -> np.ndarray:
    """Direction of the last relative rotation of each adjacent tube pair along a motion.

    ``eta[k, i]`` is +1 if ``alpha_(i+1) - alpha_i`` was last increasing (CCW about +z by the
    right-hand rule), -1 if decreasing, 0 if it has not yet moved in its motion, with
    hysteresis ``tol``: the direction flips only once the relative angle has come back more than
    ``tol`` from its latest extreme (encoder jitter does not flip it). The eta_k of Eq. (38) of
    Ha, Fagogenis & Dupont 2019.

    Parameters
    ----------
    alpha : array-like, shape (K, n)
        Base rotations [rad], rows in time order within each motion.
    tol : float
        Hysteresis [rad], > 0.
    sequence : array-like of int, shape (K,), optional
        Motion id of each row (each motion starts without history); None: one motion.

    Returns
    -------
    ndarray of int, shape (K, n - 1)

    Raises
    ------
    ValueError
        ``alpha`` not 2-D, ``tol`` <= 0, bad ``sequence``.
    """
    alpha = np.asarray(alpha, dtype=float)
    if alpha.ndim != 2:
        raise ValueError(f"alpha must have shape (K, n), got {alpha.shape}")
    _check_tol(tol)
    rel = np.diff(alpha, axis=1)
    out = np.zeros(rel.shape, dtype=int)
    for idx in MotionRecord(alpha, np.zeros_like(alpha), sequence=sequence).segments():
        out[idx] = _directions(rel[idx], tol)
    return out


def drive_directions(alpha, tol: float = HISTORY_ROTATION_TOL, sequence=None) -> np.ndarray:
    """Direction of the last rotation of each tube's drive, shape (K, n), in {-1, 0, +1}.

    As :func:`rotation_directions` for the absolute base angles: the side of its dead band a
    drive with backlash sits on (:func:`~ctrplan.history.play_side`); 0 before the drive moved.
    """
    alpha = np.asarray(alpha, dtype=float)
    padded = np.concatenate([np.zeros((alpha.shape[0], 1)), alpha], axis=1)
    return rotation_directions(padded, tol, sequence)


def rotation_since_reversal(alpha, tol: float = HISTORY_ROTATION_TOL, sequence=None) -> np.ndarray:
    """Relative rotation of every pair since its last reversal, shape (K, n - 1) [rad], >= 0.

    Measured from the relative angle at which the direction of :func:`rotation_directions`
    last changed (or the motion started): the distance over which gradually developing
    friction builds up.
    """
    alpha = np.asarray(alpha, dtype=float)
    rel = np.diff(alpha, axis=1)
    eta = rotation_directions(alpha, tol, sequence)
    out = np.zeros(rel.shape)
    for idx in MotionRecord(alpha, np.zeros_like(alpha), sequence=sequence).segments():
        anchor = rel[idx[0]].copy()
        for j, k in enumerate(idx):
            if j > 0:
                flip = eta[k] != eta[idx[j - 1]]
                anchor[flip] = rel[idx[j - 1]][flip]
            out[k] = np.abs(rel[k] - anchor)
    return out


@dataclass(frozen=True, eq=False)
class PairState:
    """The friction-relevant history of one configuration.

    Attributes
    ----------
    alpha_offset, beta_offset : ndarray, shape (n,)
        Base rotation [rad] and translation [m] the tubes reach minus the commanded ones (e.g.
        the lag of a drive with backlash); zero without history effects.
    eta : ndarray of int, shape (n - 1,)
        Direction of the last relative rotation of each pair (+1, -1, 0 none).
    released : ndarray of bool, shape (n - 1,)
        A translation followed the pair's last relative rotation (translation-last).
    friction : ndarray, shape (n - 1,)
        Signed friction state e_k in [-1, 1]: the friction model acts in direction sign(e_k)
        with coefficient |e_k| mu_k.
    """

    alpha_offset: np.ndarray
    beta_offset: np.ndarray
    eta: np.ndarray
    released: np.ndarray
    friction: np.ndarray

    @classmethod
    def abrupt(cls, eta, released, n_tubes: int | None = None) -> "PairState":
        """The paper's abrupt model for given directions and release flags (no offsets).

        Parameters
        ----------
        eta : array-like of int, shape (m,)
            +1, -1 or 0 (no history) per pair.
        released : bool or array-like of bool, shape (m,)
        n_tubes : int, optional
            n (default m + 1).

        Raises
        ------
        ValueError
            ``eta`` not in {-1, 0, +1}, ``released`` not one bool or shape (m,).
        """
        e = np.asarray(eta)
        if e.ndim == 0:
            e = e.reshape(1)
        ef = e.astype(float).reshape(-1)
        if not np.all(np.isin(ef, (-1.0, 0.0, 1.0))):
            raise ValueError(f"eta values must be -1, 0 or +1 (0: the pair has not rotated yet), got {e.tolist()}")
        m = ef.size
        r = np.asarray(released)
        if r.shape == ():
            r = np.full(m, r)
        if r.shape != (m,):
            raise ValueError(f"translation_last must be one bool or shape ({m},), got shape {r.shape}")
        if r.dtype != bool and not np.all(np.isin(r.astype(float), (0.0, 1.0))):
            raise ValueError(f"translation_last must hold booleans, got {r.tolist()}")
        r = r.astype(bool)
        n = m + 1 if n_tubes is None else n_tubes
        return cls(np.zeros(n), np.zeros(n), ef.astype(int), r, np.where(r, 0.0, ef))


def pair_friction(state: PairState, mu_robot) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Friction applied per pair for a state: (eta applied (m,) int, mu applied (m,), cases).

    ``mu_k = |e_k| mu_robot_k``, direction ``sign(e_k)`` (0 where mu_k = 0); ``cases[k]`` is a
    key of :data:`PAIR_CASES`.
    """
    mu_robot = np.asarray(mu_robot, dtype=float)
    cases = []
    for ek, rk, fk, mk in zip(state.eta, state.released, state.friction, mu_robot):
        if not mk > 0.0:
            cases.append("frictionless")
        elif rk:
            cases.append("translation_last")
        elif fk == 0.0:
            cases.append("no_history")
        else:
            cases.append("friction")
    f = np.asarray(state.friction, dtype=float)
    mu = np.where(mu_robot > 0.0, np.abs(f) * mu_robot, 0.0)
    eta = np.where(mu > 0.0, np.sign(f), 0.0).astype(int)
    return eta, mu, tuple(cases)


@dataclass(frozen=True, eq=False)
class HistoryState:
    """The friction-relevant history at every sample of a motion (:func:`motion_state`).

    Attributes
    ----------
    alpha, beta : ndarray, shape (K, n)
        Base rotations [rad] and translations [m] the tubes reach (after the history effects),
        the configuration to solve the model at.
    alpha_offset, beta_offset : ndarray, shape (K, n)
        ``alpha`` and ``beta`` minus the commanded record [rad], [m].
    eta : ndarray of int, shape (K, n - 1)
        Direction of the last relative rotation per pair (+1 CCW, -1 CW, 0 none yet), Eq. (38).
    released : ndarray of bool, shape (K, n - 1)
        A translation followed the pair's last relative rotation (Section V-B).
    friction : ndarray, shape (K, n - 1)
        Signed friction state e_k in [-1, 1] (see the module docstring).
    """

    alpha: np.ndarray
    beta: np.ndarray
    alpha_offset: np.ndarray
    beta_offset: np.ndarray
    eta: np.ndarray
    released: np.ndarray
    friction: np.ndarray

    @property
    def n_samples(self) -> int:
        return self.alpha.shape[0]

    def at(self, k: int) -> PairState:
        """The state of sample ``k``."""
        return PairState(self.alpha_offset[k].copy(), self.beta_offset[k].copy(), self.eta[k].copy(),
                         self.released[k].copy(), self.friction[k].copy())

    def take(self, rows) -> "HistoryState":
        """The state at ``rows`` (index array or boolean mask), computed on the whole motion."""
        rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, dtype=int)
        return HistoryState(*(getattr(self, f)[rows] for f in
                              ("alpha", "beta", "alpha_offset", "beta_offset", "eta", "released", "friction")))

    def applied(self, mu_robot) -> tuple[np.ndarray, np.ndarray]:
        """Per sample and pair, the friction direction (K, n - 1) int and coefficient (K, n - 1)
        the friction model applies (:func:`pair_friction`) for the robot's coefficients."""
        mu_robot = np.asarray(mu_robot, dtype=float)[None, :]
        mu = np.where(mu_robot > 0.0, np.abs(self.friction) * mu_robot, 0.0)
        return np.where(mu > 0.0, np.sign(self.friction), 0.0).astype(int), mu


def motion_state(record: MotionRecord, seen: MotionRecord | None = None, *, friction_angle: float = 0.0,
                 given_eta=None, rotation_tol: float = HISTORY_ROTATION_TOL,
                 translation_tol: float = HISTORY_TRANSLATION_TOL) -> HistoryState:
    """The friction state of every pair at every sample (the rule of the module docstring).

    Parameters
    ----------
    record : MotionRecord
        The commanded motion (base rotations [rad], translations [m]).
    seen : MotionRecord, optional
        The motion the tubes made (after history effects such as drive backlash,
        :func:`~ctrplan.history.apply_history`); default ``record``. The state follows it.
    friction_angle : float
        theta_c [rad], >= 0: relative rotation over which friction develops after a reversal;
        0 (default) is the paper's abrupt switch.
    given_eta : array-like of int, shape (K, n - 1), optional
        Directions of the approach before the record (e.g. the ``eta_*`` columns of the paper's
        protocol, one sample per motion): used where the pair has not rotated within the record,
        as a developed friction state unless a translation released it.
    rotation_tol : float
        [rad], > 0 (hysteresis of the direction and smallest rotation).
    translation_tol : float
        [m], > 0 (smallest translation that releases).

    Returns
    -------
    HistoryState

    Raises
    ------
    ValueError
        Tolerances <= 0, ``friction_angle`` < 0 or not finite, shapes that do not match.
    """
    _check_tol(rotation_tol, translation_tol)
    if not np.isfinite(friction_angle) or friction_angle < 0:
        raise ValueError(f"friction angle theta_c must be finite and >= 0 rad, got {friction_angle!r}")
    seen = record if seen is None else seen
    if seen.alpha.shape != record.alpha.shape:
        raise ValueError(f"seen motion of shape {seen.alpha.shape} does not match the record {record.alpha.shape}")
    alpha, beta = seen.alpha, seen.beta
    K, n = alpha.shape
    m = n - 1
    eta = np.zeros((K, m), dtype=np.int64)
    released = np.zeros((K, m), dtype=bool)
    friction = np.zeros((K, m))
    rel = np.ascontiguousarray(np.diff(alpha, axis=1), dtype=float)
    segments = seen.segments()
    for idx in segments:
        eta[idx] = _directions(rel[idx], rotation_tol)
    rows = np.concatenate(segments).astype(np.int64) if segments else np.zeros(0, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum([len(idx) for idx in segments])]).astype(np.int64)
    _friction_rows(rel, np.ascontiguousarray(beta, dtype=float), rows, offsets, float(rotation_tol),
                   float(translation_tol), float(friction_angle), eta, released, friction)
    if given_eta is not None:
        g = np.asarray(given_eta, dtype=float).reshape(K, m)
        if not np.all(np.isin(g, (-1.0, 0.0, 1.0))):
            raise ValueError("given_eta values must be -1, 0 or +1")
        use = (eta == 0) & (g != 0)
        eta[use] = g[use].astype(int)
        friction[use & ~released] = g[use & ~released]
    return HistoryState(alpha=alpha, beta=beta, alpha_offset=alpha - record.alpha, beta_offset=beta - record.beta,
                        eta=eta, released=released, friction=friction)
