"""Compiled forward kinematics of tube chains stored on flat arrays (numba, ``cache=True``).

The n tubes' nodes are stored one after the other: tube t owns global nodes
``node_off[t]:node_off[t + 1]`` and segments ``seg_off[t]:seg_off[t + 1]`` with
``seg_off[t] = node_off[t] - t``. Each segment k has a constant curvature u_k [1/m] over its
length h_k [m], so a frame advances by the exponential of SO(3) and a point by the left Jacobian
V (Eqs. (3), (57) of Ha, Fagogenis & Dupont 2019; ``discrete.py`` has the same kinematics in
plain NumPy). The contact solver (``_contact_kernels``) and anything else that needs the
kinematics of curvatures on a grid share these kernels; they depend on nothing but NumPy.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..constants import SMALL_ANGLE

__all__ = ["chain_kinematics"]

_SMALL = SMALL_ANGLE  # module-level constant, frozen into the compiled code


@njit(cache=True, inline="always")
def _coefficients(t):
    """s1 = sin t / t, a = (1 - cos t)/t^2, b = (t - sin t)/t^3, da = a'(t)/t, db = b'(t)/t
    with Taylor series below ``SMALL_ANGLE`` (same as ``_lie._coefficients``)."""
    t2 = t * t
    if t < _SMALL:
        s1 = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        a = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
        b = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
        da = -1.0 / 12.0 + t2 / 180.0 - t2 * t2 / 6720.0
        db = -1.0 / 60.0 + t2 / 1260.0 - t2 * t2 / 60480.0
    else:
        sn = np.sin(t)
        cs = np.cos(t)
        s1 = sn / t
        a = (1.0 - cs) / t2
        b = (t - sn) / (t2 * t)
        da = sn / (t2 * t) - 2.0 * (1.0 - cs) / (t2 * t2)
        db = (1.0 - cs) / (t2 * t2) - 3.0 * (t - sn) / (t2 * t2 * t)
    return s1, a, b, da, db


@njit(cache=True, inline="always")
def _skew_form(d0, c1, c2, x, y, z, M):
    """``M = d0 I + c1 [phi]x + c2 phi phi^T`` with ``phi = (x, y, z)``, written in place (the
    form of exp(phi) and of the left Jacobian V(phi) of SO(3))."""
    M[0, 0] = d0 + c2 * x * x
    M[1, 1] = d0 + c2 * y * y
    M[2, 2] = d0 + c2 * z * z
    M[0, 1] = -c1 * z + c2 * x * y
    M[1, 0] = c1 * z + c2 * x * y
    M[0, 2] = c1 * y + c2 * x * z
    M[2, 0] = -c1 * y + c2 * x * z
    M[1, 2] = -c1 * x + c2 * y * z
    M[2, 1] = c1 * x + c2 * y * z


@njit(cache=True, inline="always")
def advance(R0, p0, x, y, z, hk, E, vz, R1, p1):
    """One step of Eqs. (3), (57) over a segment of length ``hk`` [m] with rotation vector
    phi = u hk = (x, y, z): R1 = R0 exp([phi]x), p1 = p0 + R0 V(phi) e_z hk, from the frame R0
    (3, 3) and point p0 (3,) [m] into R1, p1 (which must not alias them); E (3, 3) and vz (3,)
    are work space. Shared by :func:`chain_kinematics` and the standard model's tip
    (``standard._tip_frame``), so both give bitwise the same numbers."""
    th = np.sqrt(x * x + y * y + z * z)
    s1, ca_, cb, _, _ = _coefficients(th)
    th2 = th * th
    # exp([phi]x) = (1 - a th^2) I + s1 [phi]x + a phi phi^T
    _skew_form(1.0 - ca_ * th2, s1, ca_, x, y, z, E)
    # V e_z h = ((1 - b th^2) e_z + a phi x e_z + b phi phi_z) h
    vz[0] = (ca_ * y + cb * x * z) * hk
    vz[1] = (-ca_ * x + cb * y * z) * hk
    vz[2] = (1.0 - cb * th2 + cb * z * z) * hk
    for a in range(3):
        acc = p0[a]
        for b in range(3):
            acc += R0[a, b] * vz[b]
        p1[a] = acc
        for b in range(3):
            r = 0.0
            for q in range(3):
                r += R0[a, q] * E[q, b]
            R1[a, b] = r


@njit(cache=True)
def chain_kinematics(u, h, alpha, beta, node_off, R, p):
    """Forward kinematics of all tubes (Eqs. (3), (57)), in place.

    Parameters
    ----------
    u : ndarray, shape (S, 3)
        Segment curvatures of all tubes, tube by tube [1/m].
    h : ndarray, shape (S,)
        Segment lengths [m].
    alpha, beta : ndarray, shape (n,)
        Base rotations [rad] and translations [m].
    node_off : ndarray of int, shape (n + 1,)
        Node offsets of the tubes.
    R : ndarray, shape (N, 3, 3)
        Output body frames at the nodes.
    p : ndarray, shape (N, 3)
        Output centerline points [m].
    """
    n = alpha.shape[0]
    E = np.empty((3, 3))
    vz = np.empty(3)
    for t in range(n):
        j0 = node_off[t]
        k0 = j0 - t
        ca = np.cos(alpha[t])
        sa = np.sin(alpha[t])
        for a in range(3):
            for b in range(3):
                R[j0, a, b] = 0.0
        R[j0, 0, 0] = ca
        R[j0, 0, 1] = -sa
        R[j0, 1, 0] = sa
        R[j0, 1, 1] = ca
        R[j0, 2, 2] = 1.0
        p[j0, 0] = 0.0
        p[j0, 1] = 0.0
        p[j0, 2] = beta[t]
        for m in range(node_off[t + 1] - j0 - 1):
            k = k0 + m
            j = j0 + m
            hk = h[k]
            x = u[k, 0] * hk
            y = u[k, 1] * hk
            z = u[k, 2] * hk
            advance(R[j], p[j], x, y, z, hk, E, vz, R[j + 1], p[j + 1])
