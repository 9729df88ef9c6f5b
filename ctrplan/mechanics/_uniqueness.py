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
Table II robot, 1219 instead of 803 (the multistart search found a single equilibrium
at all 1307). The twist bounds are widened by the same margin as the coupling.

The test is made on the model's own grid: linear finite elements for the twist, the coupling
lumped at the interval ends (trapezoidal rule), the coupling scaled up by
``1 + UNIQUENESS_SCREEN_MARGIN`` so that the O(h^2) discretization error of the smallest
eigenvalue cannot turn a marginal case into a certificate. The matrix is block tridiagonal
(one n x n block per grid node); a block Cholesky factorization succeeds exactly when it is
positive definite. Cost: O(G n^3) with no allocation per node, assembled and factored node by
node, with a closed-form 3 x 3 factorization (leading minors and adjugate) for three tubes: on
the 1307 trajectory rows, Table II robot, the screen with the base rotations takes 34 us and the
worst-case one 18 us per configuration beyond building the grid, against 86 and 53 us for the
previous version (assembled arrays, general Cholesky factor and inverse per node); both in one
process, best of 4, nothing else running (load not recorded), 22 November 2026; identical
results on those rows and on 3000 random configurations of the Table II, VII and I robots.

**Grid.** ``solve_standard_batch`` runs the screen on the predictor's coarse grid
(``PREDICTOR_STEP_FACTOR`` = 4 times the step, same breakpoints; about 37 instead of 146
intervals on the Ha trajectory). The discretization error of the smallest eigenvalue there is
still far below the margin: for linear elements it is about lambda h^2 / 12 relative, 0.3 % for
the shortest critical length of these robots (0.1 m) at h = 12 mm, against the 10 % margin.
Measured against the screen on the model's grid: on 20000 seeded random
configurations each of the Table II, VII, I and six-joint robots and on the 1307 trajectory rows
of the Table II and VII robots, the coarse screen certified no configuration the fine one did
not (it certified 12 and 10 fewer of the 20000 Table II and six-joint ones: the coupling bound
of a longer interval is taken at its distal end, where the twist bound is largest), and none
that the multistart search flags. The batch's stability flags are unchanged on those sets; the
screen's time per trajectory row fell from 11.7 to 3.7 us (compiled loop over every 13th row).
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


@njit(cache=True, inline="always")
def _same_interval(present, uhat, j, k):
    """Intervals ``j`` and ``k`` have the same tubes present and the same precurvatures (so every
    per-interval constant of the screen is the same on both)."""
    for i in range(present.shape[1]):
        if present[j, i] != present[k, i] or uhat[j, i, 0] != uhat[k, i, 0] or uhat[j, i, 1] != uhat[k, i, 1]:
            return False
    return True


@njit(cache=True)
def _twist_bounds(s, first, last, present, uhat, kxy, kz, Delta):
    """A priori bound on the twist of every equilibrium, |psi_i(s_j) - alpha_i| <= Delta[j, i].

    At an equilibrium k_(i,z) psi_i'' = sum_(l != i) (w_il / K) sin(theta_il) with
    psi_i'(tip) = 0 (free tip), so |psi_i'(s)| <= int_s^tip sum_(l != i) w_il / K / k_(i,z) and
    |psi_i(s) - alpha_i| <= int_base^s of that. The first bound is piecewise linear in s on the
    grid (w / K constant per interval), so the trapezoidal rule integrates it exactly. Writes
    ``Delta`` (G, n) [rad] on each tube's nodes (others untouched). The torque densities
    sum_(l != i) w_il / K are computed once per run of intervals with the same data."""
    n = kxy.shape[0]
    G1 = present.shape[0]
    rate = np.zeros((G1, n))     # sum_(l != i) w_il / K on interval j (0 where tube i is absent)
    un = np.zeros(n)
    for j in range(G1):
        if j > 0 and _same_interval(present, uhat, j, j - 1):
            for i in range(n):
                rate[j, i] = rate[j - 1, i]
            continue
        K = 0.0
        for l in range(n):
            if present[j, l]:
                K += kxy[l]
            un[l] = np.sqrt(uhat[j, l, 0] ** 2 + uhat[j, l, 1] ** 2)
        for i in range(n):
            if not present[j, i]:
                continue
            t = 0.0
            for l in range(n):
                if l != i and present[j, l]:
                    t += kxy[i] * kxy[l] * un[i] * un[l]
            if K > 0.0:
                t /= K
            rate[j, i] = t
    smax = np.zeros(s.shape[0])
    for i in range(n):
        smax[last[i]] = 0.0
        for j in range(last[i] - 1, first[i] - 1, -1):
            smax[j] = smax[j + 1] + rate[j, i] * (s[j + 1] - s[j]) / kz[i]
        Delta[first[i], i] = 0.0
        for j in range(first[i], last[i]):
            Delta[j + 1, i] = Delta[j, i] + 0.5 * (s[j + 1] - s[j]) * (smax[j] + smax[j + 1])


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
def _factor_3(S, Sinv):
    """Positive definiteness (leading minors) and inverse (adjugate) of the symmetric 3 x 3
    matrix S; False if it is not positive definite or not finite. A closed form: the general
    Cholesky factorization and inverse took most of the screen's time at n = 3."""
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 1], S[1, 2], S[2, 2]
    m2 = a * d - b * b
    i00 = d * f - e * e
    i01 = c * e - b * f
    i02 = b * e - c * d
    det = a * i00 + b * i01 + c * i02
    if not (a > 0.0 and m2 > 0.0 and det > 0.0 and np.isfinite(det)):
        return False
    r = 1.0 / det
    Sinv[0, 0] = i00 * r
    Sinv[0, 1] = Sinv[1, 0] = i01 * r
    Sinv[0, 2] = Sinv[2, 0] = i02 * r
    Sinv[1, 1] = (a * f - c * c) * r
    Sinv[1, 2] = Sinv[2, 1] = (b * c - a * e) * r
    Sinv[2, 2] = m2 * r
    return True


@njit(cache=True)
def _certified(s, first, last, present, uhat, kxy, kz, margin, alpha):
    """Both screens: ``alpha`` of size n uses the twist bounds, of size 0 the worst case -1.

    Assembles the block-tridiagonal form node by node (linear elements for the twist, the
    coupling lumped at the interval ends) and factors it as it goes: S_0 = D_0,
    S_j = D_j - B_(j-1) S_(j-1)^-1 B_(j-1) (B diagonal), positive definite iff every S_j is.
    Unknowns that are fixed (a tube's base) or absent are identity rows. No allocation per node."""
    G = s.shape[0]
    n = kxy.shape[0]
    box = alpha.shape[0] == n
    Delta = np.zeros((G, n))
    ca = np.empty(n)
    sa = np.empty(n)
    if box:
        _twist_bounds(s, first, last, present, uhat, kxy, kz, Delta)
        for i in range(n):
            ca[i] = np.cos(alpha[i])
            sa[i] = np.sin(alpha[i])
    un = np.zeros(n)
    ex = np.zeros(n)
    ey = np.zeros(n)
    Dcur = np.zeros((n, n))     # node j: contributions of intervals j - 1 and j
    Dnext = np.zeros((n, n))    # node j + 1: contribution of interval j
    bprev = np.zeros(n)         # diagonal coupling of nodes j - 1 and j (stiffness only)
    bcur = np.zeros(n)
    S = np.empty((n, n))
    Sinv = np.zeros((n, n))
    y = np.empty(n)
    K = 0.0
    held = -1
    for j in range(G):
        for i in range(n):
            bcur[i] = 0.0
        h = s[j + 1] - s[j] if j < G - 1 else 0.0
        if h > 0.0:
            # K, |uhat_i| and the precurvature directions depend on the interval's data only:
            # kept from interval ``held``, the last one they were computed for
            same = held >= 0 and _same_interval(present, uhat, j, held)
            if not same:
                K = 0.0
                held = j
            for i in range(n):
                if present[j, i]:
                    a = kz[i] / h
                    Dcur[i, i] += a
                    Dnext[i, i] += a
                    bcur[i] = -a
                    if same:
                        continue
                    K += kxy[i]
                    u0 = uhat[j, i, 0]
                    u1 = uhat[j, i, 1]
                    un[i] = np.sqrt(u0 * u0 + u1 * u1)
                    if box and un[i] > 0.0:   # direction of the rotated precurvature at the base angle
                        ex[i] = (ca[i] * u0 - sa[i] * u1) / un[i]
                        ey[i] = (sa[i] * u0 + ca[i] * u1) / un[i]
            for i in range(n):
                if K <= 0.0 or not present[j, i] or un[i] == 0.0:
                    continue
                for l in range(i + 1, n):
                    if not present[j, l] or un[l] == 0.0:
                        continue
                    g = kxy[i] * kxy[l] * un[i] * un[l] / K      # coupling times -cos(theta), worst case -1
                    if box:
                        # theta0 = alpha_i - alpha_l + angle(uhat_i, uhat_l) is at distance d from
                        # pi (mod 2 pi), cos d = -cos(theta0); over |theta - theta0| <= H the
                        # smallest cos(theta) is -cos(d - H), or -1 if d <= H
                        H = (1.0 + margin) * (Delta[j + 1, i] + Delta[j + 1, l])
                        if H < np.pi:
                            cd = -(ex[i] * ex[l] + ey[i] * ey[l])
                            cH = np.cos(H)
                            if cd < cH:
                                g *= cd * cH + np.sqrt(max(0.0, 1.0 - cd * cd)) * np.sin(H)
                    c = (1.0 + margin if g > 0.0 else 1.0 - margin) * g * 0.5 * h
                    Dcur[i, i] -= c
                    Dcur[l, l] -= c
                    Dcur[i, l] += c
                    Dcur[l, i] += c
                    Dnext[i, i] -= c
                    Dnext[l, l] -= c
                    Dnext[i, l] += c
                    Dnext[l, i] += c
        # node j: unknown (j, i) is free iff tube i has node j and it is not its base
        for a in range(n):
            fa = first[a] < j and j <= last[a]
            if not fa:
                bcur[a] = 0.0
                bprev[a] = 0.0
            for b in range(n):
                if fa and first[b] < j and j <= last[b]:
                    v = Dcur[a, b] - bprev[a] * Sinv[a, b] * bprev[b]
                    if not np.isfinite(v):
                        return False
                    S[a, b] = v
                else:
                    S[a, b] = 1.0 if a == b else 0.0
        if n == 3:
            if not _factor_3(S, Sinv):
                return False
        else:
            if not _cholesky_in_place(S):
                return False
            _inverse_from_cholesky(S, Sinv, y)
        for a in range(n):
            bprev[a] = bcur[a]
            for b in range(n):
                Dcur[a, b] = Dnext[a, b]
                Dnext[a, b] = 0.0
    return True
