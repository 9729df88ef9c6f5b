"""FROZEN REFERENCE COPY of ctrplan/mechanics/discrete.py as of commit d2d3ee6 (before the
speed work of issue 4). Slow and simple on purpose: tests/test_mechanics_fast_vs_reference.py
holds the fast path in ctrplan.mechanics to it. Do not optimise; only imports were changed.

Original module docstring follows.

Discretized tubes: forward kinematics and the analytic Jacobians J_p and J_omega.

Each tube i has nodes at the common grid points where it exists (``N_i`` nodes) and one
curvature vector ``u`` per segment between consecutive nodes (``N_i - 1`` segments), integrated
by Euler steps in the exponential coordinates of SE(3) (Eq. (57) of Ha, Fagogenis & Dupont 2019):

    R_(k+1) = R_k exp([u_k]^ h_k),     p_(k+1) = p_k + R_k V(u_k h_k) e_z h_k,

from the clamped base ``R_0 = Rz(alpha_i)``, ``p_0 = (0, 0, beta_i)`` (Eq. (3)). The paper
attaches one curvature to each point; attaching it to the segment between points is the same
Euler scheme with the last point's (unused) curvature dropped.

Jacobians (Appendix B, Eqs. (59)-(72)), derived here for this scheme: a change ``du_k`` of
segment k rotates everything distal to node k+1 by the spatial rotation
``Omega_k du_k`` with ``Omega_k = R_k V(u_k h_k) h_k`` and moves node k+1 by
``R_k dV(u_k h_k) e_z h_k^2 du_k``, so for nodes j >= k+1

    dp_j / du_k     = R_k (d(V e_z)/dphi) h_k^2 - [p_j - p_(k+1)]x Omega_k     (cf. Eq. (69))
    domega_j / du_k = R_j^T Omega_k                                           (cf. Eq. (70))

with ``omega_j`` the body-frame angular displacement, ``R_j = R_j* exp([omega_j]x)`` (Eq. (65)).
Blocks with j <= k vanish.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctrplan.mechanics._lie import d_left_jacobian_ez, exp_so3, left_jacobian_so3, rot_z, skew

__all__ = ["TubeChain", "forward_kinematics", "chain_jacobians"]


@dataclass
class TubeChain:
    """Discretization of one tube.

    Attributes
    ----------
    first : int
        Index of the tube's base node in the common grid.
    s : ndarray, shape (N,)
        Node arc lengths [m].
    h : ndarray, shape (N - 1,)
        Segment lengths [m].
    uhat : ndarray, shape (N - 1, 3)
        Precurvature of each segment [1/m] (z component zero).
    stiffness : ndarray, shape (N - 1, 3)
        Diagonal of K for the segment: (k_xy h, k_xy h, k_z h) [N m^3] (Eq. (10)).
    alpha, beta : float
        Base rotation [rad] and translation [m].
    """

    first: int
    s: np.ndarray
    h: np.ndarray
    uhat: np.ndarray
    stiffness: np.ndarray
    alpha: float
    beta: float

    @property
    def n_nodes(self) -> int:
        return self.s.size

    @property
    def n_segments(self) -> int:
        return self.h.size


def forward_kinematics(chain: TubeChain, u):
    """Frames and centerline of a tube from its segment curvatures (Eqs. (2), (3), (57)).

    Parameters
    ----------
    chain : TubeChain
    u : array-like, shape (N - 1, 3)
        Segment curvatures [1/m].

    Returns
    -------
    R : ndarray, shape (N, 3, 3)
        Body frames at the nodes.
    p : ndarray, shape (N, 3)
        Centerline at the nodes [m].
    """
    u = np.asarray(u, dtype=float)
    h = chain.h
    phi = u * h[:, None]
    E = exp_so3(phi)
    Vz = left_jacobian_so3(phi)[:, :, 2] * h[:, None]
    N = chain.n_nodes
    R = np.empty((N, 3, 3))
    p = np.empty((N, 3))
    R[0] = rot_z(chain.alpha)
    p[0] = (0.0, 0.0, chain.beta)
    for k in range(N - 1):
        Rk = R[k]
        p[k + 1] = p[k] + Rk @ Vz[k]
        R[k + 1] = Rk @ E[k]
    return R, p


def chain_jacobians(chain: TubeChain, u, R, p, rows=None):
    """Analytic J_p and J_omega of one tube (Appendix B, Eqs. (59)-(72) re-derived above).

    Parameters
    ----------
    chain : TubeChain
    u : array-like, shape (N - 1, 3)
        Segment curvatures of the linearization point [1/m].
    R : ndarray, shape (N, 3, 3)
    p : ndarray, shape (N, 3)
        Frames and centerline from :func:`forward_kinematics` at ``u``.
    rows : array-like of int, optional
        Node indices whose rows are wanted (default: all nodes).

    Returns
    -------
    Jp : ndarray, shape (len(rows), 3, N - 1, 3)
        d p_j / d u_k [m^2].
    Jw : ndarray, shape (len(rows), 3, N - 1, 3)
        d omega_j / d u_k, body frame at node j [m].
    """
    u = np.asarray(u, dtype=float)
    h = chain.h
    N = chain.n_nodes
    rows = np.arange(N) if rows is None else np.asarray(rows, dtype=int)
    phi = u * h[:, None]
    Rk = R[:-1]
    Omega = Rk @ left_jacobian_so3(phi) * h[:, None, None]            # (N-1, 3, 3)
    Apos = Rk @ d_left_jacobian_ez(phi) * (h * h)[:, None, None]       # (N-1, 3, 3)
    # dp_j/du_k = Apos_k + [p_(k+1)]x Omega_k - [p_j]x Omega_k  for j >= k+1
    base = Apos + skew(p[1:]) @ Omega                                  # (N-1, 3, 3)
    Sp = skew(p[rows])                                                 # (m, 3, 3)
    Jp = base[None, :, :, :] - np.einsum("jab,kbc->jkac", Sp, Omega)   # (m, N-1, 3, 3)
    Jw = np.einsum("jba,kbc->jkac", R[rows], Omega)                    # R_j^T Omega_k
    mask = (rows[:, None] >= np.arange(1, N)[None, :])                 # j >= k+1
    Jp *= mask[:, :, None, None]
    Jw *= mask[:, :, None, None]
    return Jp.transpose(0, 2, 1, 3), Jw.transpose(0, 2, 1, 3)
