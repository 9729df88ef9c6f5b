"""A sufficient condition for a unique equilibrium of the standard model (stability screen).

The standard model's torsion equations (``standard`` module docstring) are the Euler-Lagrange
equations of the elastic energy, per unit length

    e(psi) = sum_i k_(i,z) / 2 psi_i'^2  -  |sum_i k_(i,xy) R_z(psi_i) uhat_i|^2 / (2 K),

with K = sum_i k_(i,xy) over the tubes present at s, psi_i fixed at tube i's base and free at
its tip. Its second variation is

    d2E[delta] = int sum_i k_(i,z) delta_i'^2 ds
                 + int sum_(i<j) (w_ij / K) cos(theta_ij) (delta_i - delta_j)^2 ds,
    w_ij = k_(i,xy) k_(j,xy) |uhat_i| |uhat_j|,

where theta_ij is the angle between the rotated precurvatures of tubes i and j. Whatever the
angles, cos(theta_ij) >= -1, so d2E >= Q with the configuration-independent form

    Q[delta] = int sum_i k_(i,z) delta_i'^2 ds - int sum_(i<j) (w_ij / K) (delta_i - delta_j)^2 ds.

If Q is positive definite, the energy is strictly convex over all tube angles and the
boundary-value problem has exactly one equilibrium, which is stable: the multistart search and
the determinant test of ``solve_standard`` cannot flag it. Q depends on the translations beta
only (which sections overlap where), not on the rotations alpha. For two fully overlapping
tubes of constant precurvature over a length L, Q is positive definite exactly when
L sqrt(c (1/k_(1,z) + 1/k_(2,z))) < pi/2, c = w_12 / K: the classical two-tube condition
(Dupont, Lock, Itkowitz & Butler, IEEE T-RO 26(2) 2010; Gilbert, Hendrick & Webster,
IEEE T-RO 32(1) 2016), whose worst case is the anti-aligned configuration.

**With the base rotations (``unique_equilibrium_certified_at``).** Every equilibrium twists
each tube by a bounded amount: k_(i,z) psi_i'' = sum_(l != i) (w_il / K) sin(theta_il) and
psi_i' = 0 at the free tip give |psi_i'(s)| <= int_s^tip sum_(l != i) w_il / K ds / k_(i,z),
and psi_i(beta_i) = alpha_i then bounds |psi_i(s) - alpha_i| by Delta_i(s), the integral of
that from the base. So at every equilibrium theta_ij(s) lies within Delta_i(s) + Delta_j(s) of
theta0_ij(s) = alpha_i - alpha_j + (angle between uhat_i and uhat_j), and over that box of tube
angles cos(theta_ij) >= c_ij(s) = min of cos over the interval (-1 only where it contains pi).
The box is convex and holds every equilibrium; if the form with cos(theta_ij) replaced by c_ij
is positive definite, the energy is strictly convex on the box, so there is exactly one
equilibrium, and it is stable (two critical points of a strictly convex function on a convex set
cannot exist: along the segment joining them the directional derivative would be strictly
increasing yet zero at both ends). Where the tubes' precurvatures are not nearly opposed this
certifies far past the worst-case form: on the 1307 rows of the measured trajectory with the
Table II robot, 1219 instead of 803 (issue 14; the multistart search found a single equilibrium
at all 1307). The twist bounds are widened by the same margin as the coupling.

The test is made on the model's own grid: linear finite elements for the twist, the coupling
lumped at the interval ends (trapezoidal rule), the coupling scaled up by
``1 + UNIQUENESS_SCREEN_MARGIN`` so that the O(h^2) discretization error of the smallest
eigenvalue cannot turn a marginal case into a certificate. The matrix is block tridiagonal
(one n x n block per grid node); a block Cholesky factorization succeeds exactly when it is
positive definite. Cost: O(G n^3) with no allocation per node: 59 us per configuration on the
trajectory rows of the Table VII robot, 57 us with the Table II robot (G about 148), against 122
and 120 us when each node allocated its blocks (both versions in one process, median of 5,
idle, 22 November 2026; a slow day for this machine).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["unique_equilibrium_certified"]


@njit(cache=True)
def _cholesky_in_place(A):
    """Lower Cholesky factor of the small symmetric matrix A (n, n), in place; False if A is
    not positive definite (or not finite)."""
    n = A.shape[0]
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= A[j, k] * A[j, k]
        if not d > 0.0:
            return False
        d = np.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, n):
            v = A[i, j]
            for k in range(j):
                v -= A[i, k] * A[j, k]
            A[i, j] = v / d
    return True


@njit(cache=True)
def _inverse_from_cholesky(L, out, y):
    """out = (L L^T)^-1 for a lower Cholesky factor L (n, n); ``y`` (n,) is work space."""
    n = L.shape[0]
    for c in range(n):
        for i in range(n):          # L y = e_c
            v = 1.0 if i == c else 0.0
            for k in range(i):
                v -= L[i, k] * y[k]
            y[i] = v / L[i, i]
        for i in range(n - 1, -1, -1):   # L^T x = y
            v = y[i]
            for k in range(i + 1, n):
                v -= L[k, i] * y[k]
            y[i] = v / L[i, i]
        for i in range(n):
            out[i, c] = y[i]


@njit(cache=True)
def _twist_bounds(s, first, last, present, uhat, kxy, kz, Delta):
    """A priori bound on the twist of every equilibrium, |psi_i(s_j) - alpha_i| <= Delta[j, i].

    At an equilibrium k_(i,z) psi_i'' = sum_(l != i) (w_il / K) sin(theta_il) with
    psi_i'(tip) = 0 (free tip), so |psi_i'(s)| <= int_s^tip sum_(l != i) w_il / K / k_(i,z) and
    |psi_i(s) - alpha_i| <= int_base^s of that. The first bound is piecewise linear in s on the
    grid (w / K constant per interval), so the trapezoidal rule integrates it exactly. Writes
    ``Delta`` (G, n) [rad] on each tube's nodes (others untouched)."""
    n = kxy.shape[0]
    smax = np.zeros(s.shape[0])
    for i in range(n):
        smax[last[i]] = 0.0
        for j in range(last[i] - 1, first[i] - 1, -1):
            t = 0.0
            if present[j, i]:
                K = 0.0
                for l in range(n):
                    if present[j, l]:
                        K += kxy[l]
                ui = np.sqrt(uhat[j, i, 0] ** 2 + uhat[j, i, 1] ** 2)
                for l in range(n):
                    if l != i and present[j, l]:
                        t += kxy[i] * kxy[l] * ui * np.sqrt(uhat[j, l, 0] ** 2 + uhat[j, l, 1] ** 2)
                if K > 0.0:
                    t /= K
            smax[j] = smax[j + 1] + t * (s[j + 1] - s[j]) / kz[i]
        Delta[first[i], i] = 0.0
        for j in range(first[i], last[i]):
            Delta[j + 1, i] = Delta[j, i] + 0.5 * (s[j + 1] - s[j]) * (smax[j] + smax[j + 1])


@njit(cache=True)
def _worst_cos(theta0, half_width):
    """Smallest cos(theta) over |theta - theta0| <= half_width [rad]."""
    if half_width >= np.pi:
        return -1.0
    x = theta0 - np.pi
    d = abs(x - 2.0 * np.pi * np.floor(x / (2.0 * np.pi) + 0.5))   # distance of theta0 from pi (mod 2 pi)
    if d <= half_width:
        return -1.0
    return -np.cos(d - half_width)


@njit(cache=True)
def unique_equilibrium_certified(s, first, last, present, uhat, kxy, kz, margin):
    """Whether the worst-case second variation Q of the standard model's energy is positive
    definite on the grid (module docstring): then the configuration has one equilibrium.

    Parameters
    ----------
    s : ndarray, shape (G,)
        Grid nodes [m] (``grid._grid``).
    first, last : ndarray of int, shape (n,)
        First (base) and last (tip) node of each tube.
    present : ndarray of bool, shape (G - 1, n)
        Tube present on each interval.
    uhat : ndarray, shape (G - 1, n, 2)
        Precurvatures on each interval [1/m].
    kxy, kz : ndarray, shape (n,)
        Bending and torsional stiffnesses [N m^2].
    margin : float
        Relative inflation of the coupling term (>= 0).

    Returns
    -------
    bool
        True: Q (with the coupling times 1 + margin) is positive definite, so the equilibrium
        is unique and stable. False: not certified (the configuration may still be stable).
    """
    return _certified(s, first, last, present, uhat, kxy, kz, margin, np.empty(0))


@njit(cache=True)
def unique_equilibrium_certified_at(s, first, last, present, uhat, kxy, kz, margin, alpha):
    """The screen of :func:`unique_equilibrium_certified` with the base rotations ``alpha``
    (n,) [rad]: every cos(theta_ij) is bounded below over the twists that an equilibrium can
    have (module docstring) instead of by -1, so it certifies every configuration that one
    does, and more. Same parameters and result."""
    return _certified(s, first, last, present, uhat, kxy, kz, margin, alpha)


@njit(cache=True)
def _certified(s, first, last, present, uhat, kxy, kz, margin, alpha):
    """Both screens: ``alpha`` of size n uses the twist bounds, of size 0 the worst case -1."""
    G = s.shape[0]
    n = kxy.shape[0]
    box = alpha.shape[0] == n
    Delta = np.zeros((G, n))
    if box:
        _twist_bounds(s, first, last, present, uhat, kxy, kz, Delta)
    # unknown (node j, tube i) is free iff tube i has node j and it is not its base
    free = np.zeros((G, n), dtype=np.bool_)
    for i in range(n):
        for j in range(first[i] + 1, last[i] + 1):
            free[j, i] = True
    D = np.zeros((G, n, n))
    Bd = np.zeros((G, n))     # diagonal coupling between node j and j + 1 (stiffness only)
    for j in range(G - 1):
        h = s[j + 1] - s[j]
        if not h > 0.0:
            continue
        K = 0.0
        for i in range(n):
            if present[j, i]:
                K += kxy[i]
        for i in range(n):
            if present[j, i]:
                a = kz[i] / h
                D[j, i, i] += a
                D[j + 1, i, i] += a
                Bd[j, i] -= a
        if K <= 0.0:
            continue
        for i in range(n):
            if not present[j, i]:
                continue
            ui = np.sqrt(uhat[j, i, 0] ** 2 + uhat[j, i, 1] ** 2)
            for l in range(i + 1, n):
                if not present[j, l]:
                    continue
                ul = np.sqrt(uhat[j, l, 0] ** 2 + uhat[j, l, 1] ** 2)
                g = kxy[i] * kxy[l] * ui * ul / K      # coupling times -cos(theta), worst case -1
                if box:
                    g *= -_worst_cos(alpha[i] - alpha[l] + np.arctan2(uhat[j, i, 1], uhat[j, i, 0])
                                     - np.arctan2(uhat[j, l, 1], uhat[j, l, 0]),
                                     (1.0 + margin) * (Delta[j + 1, i] + Delta[j + 1, l]))
                c = (1.0 + margin if g > 0.0 else 1.0 - margin) * g * 0.5 * h
                for t in (j, j + 1):
                    D[t, i, i] -= c
                    D[t, l, l] -= c
                    D[t, i, l] += c
                    D[t, l, i] += c
    # eliminate the fixed and absent unknowns (identity rows)
    for j in range(G):
        for i in range(n):
            if not free[j, i]:
                for k in range(n):
                    D[j, i, k] = 0.0
                    D[j, k, i] = 0.0
                D[j, i, i] = 1.0
                Bd[j, i] = 0.0
                if j > 0:
                    Bd[j - 1, i] = 0.0
    # block Cholesky: S_0 = D_0, S_j = D_j - B_(j-1) S_(j-1)^-1 B_(j-1) (B diagonal); no
    # allocation per node (allocations were 90 % of the screen's time)
    S = np.empty((n, n))
    Sinv = np.zeros((n, n))
    y = np.empty(n)
    for j in range(G):
        for a in range(n):
            for b in range(n):
                v = D[j, a, b]
                if j > 0:
                    v -= Bd[j - 1, a] * Sinv[a, b] * Bd[j - 1, b]
                if not np.isfinite(v):
                    return False
                S[a, b] = v
        if not _cholesky_in_place(S):
            return False
        _inverse_from_cholesky(S, Sinv, y)
    return True
