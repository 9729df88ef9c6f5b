"""Arc-length grid shared by the standard and the clearance models.

The whole robot length is discretized first and each tube takes the grid points where it
exists (Section II-C of Ha, Fagogenis & Dupont 2019), so tube i's points are a contiguous run
of the common grid and contact constraints pair points at equal arc length. Tube bases, section
boundaries and tube ends are always grid points, so every segment has constant precurvature.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..constants import GRID_MERGE_TOL
from .packed import pack_robot

__all__ = ["ArcLengthGrid", "build_grid"]


@dataclass(frozen=True)
class ArcLengthGrid:
    """Common arc-length grid of one configuration.

    Attributes
    ----------
    s : ndarray, shape (G,)
        Node arc lengths [m], increasing, from the most proximal base to the distal end.
    first, last : ndarray of int, shape (n,)
        Index of tube i's base node and distal-end node in ``s``.
    present : ndarray of bool, shape (G - 1, n)
        Whether tube i exists on interval j = [s_j, s_(j+1)].
    precurvature : ndarray, shape (G - 1, n, 2)
        Precurvature (u_x, u_y) of tube i on interval j [1/m] (zero where absent).
    """

    s: np.ndarray
    first: np.ndarray
    last: np.ndarray
    present: np.ndarray
    precurvature: np.ndarray

    @property
    def h(self) -> np.ndarray:
        """Interval lengths, shape (G - 1,) [m]."""
        return np.diff(self.s)


def build_grid(robot, beta, ds: float, refine_ratio: float = 1.0, refine_length: float = 0.0) -> ArcLengthGrid:
    """Build the common arc-length grid.

    Between consecutive breakpoints (tube bases, section boundaries, tube ends) the step is at
    most ``ds``. Where at least two tubes overlap (where contacts can be), the step is graded
    towards the breakpoints bordering such a stretch: at distance x from the nearest one it is
    at most ``ds * min(1, refine_ratio + (1 - refine_ratio) * x / refine_length)``. Point
    contacts (the couples at tube ends and precurvature jumps) sit within a few millimetres of
    these breakpoints, and resolving them is what the contact models' accuracy hinges on
    (docs/mechanics.md, Sec. 1). The step profile scales with ``ds``: halving ``ds`` halves
    every step.

    Parameters
    ----------
    robot : Robot
    beta : array-like, shape (n,)
        Base translations [m].
    ds : float
        Largest step [m], > 0.
    refine_ratio : float
        Step at a breakpoint of the overlap as a fraction of ``ds``, in (0, 1]; 1 (default)
        gives the uniform grid of Section II-C of Ha et al. 2019.
    refine_length : float
        Distance from such a breakpoint over which the step grows back to ``ds`` [m], >= 0.

    Returns
    -------
    ArcLengthGrid

    Raises
    ------
    ValueError
        If ``ds`` is not positive, ``refine_ratio`` not in (0, 1] or ``refine_length`` negative.
    """
    if not ds > 0:
        raise ValueError(f"arc-length step ds must be > 0 m, got {ds!r}")
    if not 0.0 < refine_ratio <= 1.0:
        raise ValueError(f"refine_ratio must be in (0, 1], got {refine_ratio!r}")
    if not refine_length >= 0.0:
        raise ValueError(f"refine_length must be >= 0 m, got {refine_length!r}")
    beta = np.ascontiguousarray(beta, dtype=float)
    pk = pack_robot(robot)
    s, first, last, present, uhat = _grid(beta, pk.lengths, pk.breaks, pk.n_breaks, pk.precurvature, float(ds),
                                          GRID_MERGE_TOL, float(refine_ratio), float(refine_length))
    return ArcLengthGrid(s=s, first=first, last=last, present=present, precurvature=uhat)


@njit(cache=True, inline="always")
def _steps_from_end(x, ds, ratio, length):
    """Number of steps F(x) = integral_0^x dt / h(t) covered within distance x of a refined
    breakpoint, h(t) = ds * min(1, ratio + (1 - ratio) t / length) (closed form)."""
    k = (1.0 - ratio) / length
    if x <= length:
        return np.log1p(k * x / ratio) / (ds * k)
    return np.log1p(k * length / ratio) / (ds * k) + (x - length) / ds


@njit(cache=True, inline="always")
def _distance_for_steps(y, ds, ratio, length):
    """Inverse of :func:`_steps_from_end`: the distance covered by y steps."""
    k = (1.0 - ratio) / length
    y_len = np.log1p(k * length / ratio) / (ds * k)
    if y <= y_len:
        return ratio / k * np.expm1(y * ds * k)
    return length + (y - y_len) * ds


@njit(cache=True)
def _interval_nodes(lo, hi, ds, graded, ratio, length, out, q):
    """Write the nodes of (lo, hi] into ``out`` from index ``q``; returns the next index.
    Uniform: the fewest equal steps not longer than ``ds``. Graded: the fewest nodes at equal
    increments, of at most one, of the integral of 1 / h(s),
    h(s) = ds * min(1, ratio + (1 - ratio) * x(s) / length) with x = min(s - lo, hi - s) (both
    ends of an overlap interval are refined breakpoints and no other one is nearer); the
    integral and its inverse are closed forms, symmetric about the interval's middle."""
    if not graded:
        m = max(1, int(np.ceil((hi - lo) / ds - 1e-9)))
        for k in range(1, m + 1):
            out[q] = lo + (hi - lo) * k / m
            q += 1
        return q
    half = _steps_from_end(0.5 * (hi - lo), ds, ratio, length)
    total = 2.0 * half
    m = max(1, int(np.ceil(total - 1e-9)))
    for k in range(1, m):
        y = total * k / m
        if y <= half:
            out[q] = lo + _distance_for_steps(y, ds, ratio, length)
        else:
            out[q] = hi - _distance_for_steps(total - y, ds, ratio, length)
        q += 1
    out[q] = hi
    return q + 1


@njit(cache=True)
def _grid(beta, lengths, brk, nbrk, curv, ds, tol, ratio, length):
    """Compiled body of :func:`build_grid`: the tube bases, section breaks and ends (merged within
    ``tol``) split into steps of at most ``ds``, graded towards the breakpoints that border an
    overlap of two or more tubes (``ratio`` < 1 and ``length`` > 0). Returns nodes s (G,),
    first/last (n,), present (G - 1, n), precurvature (G - 1, n, 2)."""
    n = beta.shape[0]
    total = 0
    for i in range(n):
        total += nbrk[i]
    allb = np.empty(total)
    q = 0
    for i in range(n):
        for j in range(nbrk[i]):
            allb[q] = np.round((beta[i] + brk[i, j]) / tol) * tol
            q += 1
    br = np.unique(allb)
    nb = br.shape[0]
    # breakpoint intervals where two or more tubes overlap (graded towards both their ends)
    multi = np.zeros(max(nb - 1, 0), dtype=np.bool_)
    for a in range(nb - 1):
        mid = 0.5 * (br[a] + br[a + 1])
        count = 0
        for i in range(n):
            if beta[i] < mid < beta[i] + lengths[i]:
                count += 1
        multi[a] = count >= 2
    graded = ratio < 1.0 and length > 0.0
    cap = 1
    for a in range(nb - 1):
        if graded and multi[a]:
            cap += int(np.ceil((br[a + 1] - br[a]) / (ratio * ds))) + 2
        else:
            cap += int(np.ceil((br[a + 1] - br[a]) / ds)) + 2
    buf = np.empty(cap)
    buf[0] = br[0]
    q = int(1)   # a run-time int64 from the start: numba types the call below once, not per literal
    for a in range(nb - 1):
        q = _interval_nodes(br[a], br[a + 1], ds, graded and multi[a], ratio, length, buf, q)
    s = buf[:q].copy()
    G = s.shape[0]
    first = np.empty(n, dtype=np.int64)
    last = np.empty(n, dtype=np.int64)
    for i in range(n):
        first[i] = np.argmin(np.abs(s - beta[i]))
        last[i] = np.argmin(np.abs(s - (beta[i] + lengths[i])))
    present = np.zeros((G - 1, n), dtype=np.bool_)
    uhat = np.zeros((G - 1, n, 2))
    for i in range(n):
        b = brk[i, :nbrk[i]]
        nsec = nbrk[i] - 1
        for j in range(first[i], last[i]):
            present[j, i] = True
            local = 0.5 * (s[j] + s[j + 1]) - beta[i]
            idx = np.searchsorted(b, local, side="right") - 1
            idx = min(max(idx, 0), nsec - 1)
            uhat[j, i, 0] = curv[i, idx, 0]
            uhat[j, i, 1] = curv[i, idx, 1]
    return s, first, last, present, uhat
