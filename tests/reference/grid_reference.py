"""FROZEN REFERENCE COPY of ctrplan/mechanics/grid.py as of commit d2d3ee6 (before the
speed work of issue 4). Slow and simple on purpose: tests/test_mechanics_fast_vs_reference.py
holds the fast path in ctrplan.mechanics to it. Do not optimise; only imports were changed.

Original module docstring follows.

Arc-length grid shared by the standard and the clearance models.

The whole robot length is discretized first and each tube takes the grid points where it
exists (Section II-C of Ha, Fagogenis & Dupont 2019), so tube i's points are a contiguous run
of the common grid and contact constraints pair points at equal arc length. Tube bases, section
boundaries and tube ends are always grid points, so every segment has constant precurvature.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctrplan.constants import GRID_MERGE_TOL

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
    beta = np.asarray(beta, dtype=float)
    breaks = []
    for i, t in enumerate(robot.tubes):
        breaks.extend(beta[i] + t.section_breaks())
    breaks = np.unique(np.round(np.asarray(breaks) / GRID_MERGE_TOL) * GRID_MERGE_TOL)
    nodes = [breaks[0]]
    for a, b in zip(breaks[:-1], breaks[1:]):
        m = max(1, int(np.ceil((b - a) / ds - 1e-9)))
        nodes.extend(a + (b - a) * np.arange(1, m + 1) / m)
    s = np.asarray(nodes)
    n = robot.n_tubes
    ends = robot.tube_ends(beta)
    first = np.array([int(np.argmin(np.abs(s - beta[i]))) for i in range(n)])
    last = np.array([int(np.argmin(np.abs(s - ends[i]))) for i in range(n)])
    mid = 0.5 * (s[:-1] + s[1:])
    present = np.zeros((s.size - 1, n), dtype=bool)
    uhat = np.zeros((s.size - 1, n, 2))
    for i, t in enumerate(robot.tubes):
        present[first[i]:last[i], i] = True
        local = mid - beta[i]
        br = t.section_breaks()
        idx = np.clip(np.searchsorted(br, local, side="right") - 1, 0, len(t.sections) - 1)
        curv = np.array([sec.precurvature for sec in t.sections], dtype=float)
        uhat[:, i, :] = np.where(present[:, i, None], curv[idx], 0.0)
    return ArcLengthGrid(s=s, first=first, last=last, present=present, precurvature=uhat)
