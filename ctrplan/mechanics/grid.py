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


def build_grid(robot, beta, ds: float) -> ArcLengthGrid:
    """Build the common arc-length grid.

    Parameters
    ----------
    robot : Robot
    beta : array-like, shape (n,)
        Base translations [m].
    ds : float
        Largest step [m], > 0.

    Returns
    -------
    ArcLengthGrid

    Raises
    ------
    ValueError
        If ``ds`` is not positive.
    """
    if not ds > 0:
        raise ValueError(f"arc-length step ds must be > 0 m, got {ds!r}")
    beta = np.ascontiguousarray(beta, dtype=float)
    brk, nbrk, curv = packed_sections(robot)
    lengths = np.array([t.length for t in robot.tubes])
    s, first, last, present, uhat = _grid(beta, lengths, brk, nbrk, curv, float(ds), GRID_MERGE_TOL)
    return ArcLengthGrid(s=s, first=first, last=last, present=present, precurvature=uhat)


def packed_sections(robot):
    """Section breaks and precurvatures of every tube as padded arrays for the compiled grid:
    ``brk`` (n, B) [m] (tube-local, from 0 to the length), ``nbrk`` (n,) breaks per tube,
    ``curv`` (n, B - 1, 2) [1/m]."""
    n = robot.n_tubes
    nb = max(len(t.sections) + 1 for t in robot.tubes)
    brk = np.zeros((n, nb))
    curv = np.zeros((n, nb - 1, 2))
    nbrk = np.zeros(n, dtype=np.int64)
    for i, t in enumerate(robot.tubes):
        b = t.section_breaks()
        brk[i, :b.size] = b
        nbrk[i] = b.size
        curv[i, :len(t.sections)] = [sec.precurvature for sec in t.sections]
    return brk, nbrk, curv


@njit(cache=True)
def _grid(beta, lengths, brk, nbrk, curv, ds, tol):
    """Compiled body of :func:`build_grid`: the tube bases, section breaks and ends (merged within
    ``tol``) split into equal steps of at most ``ds``. Returns nodes s (G,), first/last (n,),
    present (G - 1, n), precurvature (G - 1, n, 2)."""
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
    count = 1
    for a in range(br.shape[0] - 1):
        m = max(1, int(np.ceil((br[a + 1] - br[a]) / ds - 1e-9)))
        count += m
    s = np.empty(count)
    s[0] = br[0]
    q = 1
    for a in range(br.shape[0] - 1):
        lo = br[a]
        hi = br[a + 1]
        m = max(1, int(np.ceil((hi - lo) / ds - 1e-9)))
        for k in range(1, m + 1):
            s[q] = lo + (hi - lo) * k / m
            q += 1
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
