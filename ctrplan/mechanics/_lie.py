"""SO(3) and SE(3) helpers, vectorized over leading axes.

The exponential coordinates follow Eq. (57) of Ha, Fagogenis & Dupont 2019: a segment of
constant body curvature ``u`` and length ``h`` maps the frame by ``exp([u]^ h)`` and moves the
position by ``R V(u h) e_z h`` where ``V`` is the left Jacobian of SO(3).
"""

from __future__ import annotations

import numpy as np

from ..constants import SMALL_ANGLE

__all__ = ["skew", "rot_z", "exp_so3", "left_jacobian_so3", "d_left_jacobian_ez", "angle_between"]


def skew(v):
    """Skew-symmetric matrix ``[v]x``.

    Parameters
    ----------
    v : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def rot_z(theta):
    """Rotation about z by ``theta`` [rad], shape (..., 3, 3) (the paper's R_z, Eq. (3))."""
    theta = np.asarray(theta, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    out = np.zeros(theta.shape + (3, 3))
    out[..., 0, 0] = c
    out[..., 0, 1] = -s
    out[..., 1, 0] = s
    out[..., 1, 1] = c
    out[..., 2, 2] = 1.0
    return out


def _coefficients(theta):
    """Scalar coefficient functions of theta with series fallbacks.

    Returns s1 = sin t / t, a = (1 - cos t)/t^2, b = (t - sin t)/t^3,
    da = a'(t)/t, db = b'(t)/t.
    """
    t = np.asarray(theta, dtype=float)
    small = t < SMALL_ANGLE
    t2 = t * t
    ts = np.where(small, 1.0, t)  # safe denominators
    ts2 = ts * ts
    sin, cos = np.sin(ts), np.cos(ts)
    s1 = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, sin / ts)
    a = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - cos) / ts2)
    b = np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (ts - sin) / (ts2 * ts))
    da = np.where(small, -1.0 / 12.0 + t2 / 180.0 - t2 * t2 / 6720.0,
                  sin / (ts2 * ts) - 2.0 * (1.0 - cos) / (ts2 * ts2))
    db = np.where(small, -1.0 / 60.0 + t2 / 1260.0 - t2 * t2 / 60480.0,
                  (1.0 - cos) / (ts2 * ts2) - 3.0 * (ts - sin) / (ts2 * ts2 * ts))
    return s1, a, b, da, db


def _quadratic_in_skew(phi, which):
    """``I + c1 [phi]x + c2 [phi]x^2`` with coefficients chosen by ``which`` ("exp" or "V")."""
    phi = np.asarray(phi, dtype=float)
    s1, a, b, _, _ = _coefficients(np.linalg.norm(phi, axis=-1))
    c1, c2 = (s1, a) if which == "exp" else (a, b)
    P = skew(phi)
    return np.eye(3) + c1[..., None, None] * P + c2[..., None, None] * (P @ P)


def exp_so3(phi):
    """Rodrigues' formula ``exp([phi]x)``.

    Parameters
    ----------
    phi : array-like, shape (..., 3)
        Rotation vector [rad].

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    return _quadratic_in_skew(phi, "exp")


def left_jacobian_so3(phi):
    """Left Jacobian of SO(3), ``V(phi) = I + a [phi]x + b [phi]x^2``.

    It maps a perturbation of the rotation vector to the spatial rotation it causes,
    ``exp([phi + dphi]x) = exp([V dphi]x) exp([phi]x)``, and gives the translation of a
    constant-twist segment, ``p(h) = V(u h) e_z h`` (the paper's dexp, Eq. (73)).

    Parameters
    ----------
    phi : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    return _quadratic_in_skew(phi, "V")


def d_left_jacobian_ez(phi):
    """Derivative of ``V(phi) e_z`` with respect to ``phi`` (3x3).

    Used for the position part of J_p (the role of C(u) in Eq. (74) of Ha et al. 2019, derived
    here directly from ``V e_z = e_z + a phi x e_z + b phi x (phi x e_z)``).

    Parameters
    ----------
    phi : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    phi = np.asarray(phi, dtype=float)
    th = np.linalg.norm(phi, axis=-1)
    _, a, b, da, db = _coefficients(th)
    w = np.array([0.0, 0.0, 1.0])
    pxw = np.cross(phi, w)
    pxpxw = np.cross(phi, pxw)
    phiw = phi[..., 2]
    I = np.eye(3)
    term_a = a[..., None, None] * (-skew(np.broadcast_to(w, phi.shape))) \
        + da[..., None, None] * pxw[..., :, None] * phi[..., None, :]
    dpp = phiw[..., None, None] * I + phi[..., :, None] * w[None, :] - 2.0 * w[:, None] * phi[..., None, :]
    term_b = b[..., None, None] * dpp + db[..., None, None] * pxpxw[..., :, None] * phi[..., None, :]
    return term_a + term_b


def angle_between(t1, t2):
    """Angle between unit vectors [rad], robust near 0 and pi (atan2 form).

    Parameters
    ----------
    t1, t2 : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (...)
    """
    t1 = np.asarray(t1, dtype=float)
    t2 = np.asarray(t2, dtype=float)
    c = np.linalg.norm(np.cross(t1, t2), axis=-1)
    d = np.sum(t1 * t2, axis=-1)
    return np.arctan2(c, d)
