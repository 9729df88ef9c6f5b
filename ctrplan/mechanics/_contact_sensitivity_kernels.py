"""Compiled kernels of the contact models' parameter derivatives (``contact_sensitivity``).

Chains on flat arrays as in ``_contact_kernels``: tube t owns global nodes
``node_off[t]:node_off[t + 1]`` and segments ``node_off[t] - t`` onwards.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _contact_kernels as ck
from ._chain_kernels import chain_kinematics

__all__ = ["jacobian_rows", "equilibrium_residual"]


@njit(cache=True)
def jacobian_rows(nodes, p, Omega, base, node_off):
    """Position and rotation Jacobians of the nodes ``nodes`` (K,) with respect to all segment
    curvatures (Appendix B of Ha, Fagogenis & Dupont 2019, as in ``_contact_kernels``):

        dp_j/du_k = base_k - [p_j]x Omega_k,   domega_j/du_k = Omega_k   (k before j, same tube)

    Returns (Jp, Jw), each shape (K, 3, 3 S): [m^2] and [m] (spatial rotation per unit
    curvature)."""
    K = nodes.shape[0]
    S = Omega.shape[0]
    n = node_off.shape[0] - 1
    Jp = np.zeros((K, 3, 3 * S))
    Jw = np.zeros((K, 3, 3 * S))
    for i in range(K):
        j = nodes[i]
        t = 0
        while not (node_off[t] <= j < node_off[t + 1]):
            t += 1
            if t >= n:
                break
        k0 = node_off[t] - t
        P0 = p[j, 0]
        P1 = p[j, 1]
        P2 = p[j, 2]
        for m in range(j - node_off[t]):
            k = k0 + m
            for b in range(3):
                o0 = Omega[k, 0, b]
                o1 = Omega[k, 1, b]
                o2 = Omega[k, 2, b]
                Jw[i, 0, 3 * k + b] = o0
                Jw[i, 1, 3 * k + b] = o1
                Jw[i, 2, 3 * k + b] = o2
                Jp[i, 0, 3 * k + b] = base[k, 0, b] - (P1 * o2 - P2 * o1)
                Jp[i, 1, 3 * k + b] = base[k, 1, b] - (P2 * o0 - P0 * o2)
                Jp[i, 2, 3 * k + b] = base[k, 2, b] - (P0 * o1 - P1 * o0)
    return Jp, Jw


@njit(cache=True)
def equilibrium_residual(u, lam, act, arr, scr, F1, F2):
    """The equilibrium F1 = u - uhat - K^-1 (A(u)^T phi + Z(u)^T lam) (S, 3) [1/m] and the active
    constraints F2_a = (|d_a|^2 - c_a^2) / 2 (m,) [m^2] at curvatures ``u`` (S, 3) and multipliers
    ``lam`` (M,) (``contact_sensitivity``), with phi_c = -lam_c M_c d_c and d_c = B_c^T
    (p_(jo, c) - p_(ji, c)) from the kinematics at ``u``; ``arr``, ``scr`` the problem's
    ``OuterArrays`` and ``OuterScratch`` (overwritten)."""
    N = arr.node_off[-1]
    M = arr.c.shape[0]
    R = np.empty((N, 3, 3))
    p = np.empty((N, 3))
    chain_kinematics(u, arr.h, arr.alpha, arr.beta, arr.node_off, R, p)
    ck.linearize(u, arr.uhat, arr.kinv, arr.h, arr.node_off, R, p, scr.Omega, scr.base, scr.H1, scr.H2, scr.F3,
                 scr.Jpv)
    d = np.empty((M, 2))
    for c in range(M):
        a = arr.jo[c]
        b = arr.ji[c]
        for q in range(2):
            s = 0.0
            for r in range(3):
                scr.B[c, r, q] = R[a, r, q]
                s += R[a, r, q] * (p[a, r] - p[b, r])
            d[c, q] = s
    geometry = ck.ContactGeometry(arr.pair, arr.jo, arr.ji, scr.B, scr.Pc, R, p, scr.H1, scr.H2, scr.F3,
                                  scr.Omega, scr.base, arr.kinv, arr.node_off)
    law = ck.ContactLaw(arr.c, arr.Mblk, 1.0, arr.tq_out, arr.tq_in, arr.friction)
    ck._curvature_change(lam, d, geometry, law, True, F1)
    for k in range(u.shape[0]):
        for q in range(3):
            F1[k, q] = u[k, q] - arr.uhat[k, q] - F1[k, q]
    for i in range(act.shape[0]):
        c = act[i]
        F2[i] = 0.5 * (d[c, 0] * d[c, 0] + d[c, 1] * d[c, 1] - arr.c[c] * arr.c[c])
