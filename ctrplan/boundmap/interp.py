"""Compiled multilinear interpolation on a tensor grid with uniform periodic and nonuniform
bounded axes (the kernels of :meth:`ctrplan.boundmap.BoundField.interpolate` and of the
planner's motion cost, ``ctrplan.planning.objective``).

Arguments shared by the kernels:

- ``axes`` (sum n_k,): node coordinates of all axes, concatenated; axis k is
  ``axes[start[k]:start[k] + size[k]]``, increasing; a periodic axis is uniform with spacing
  2 pi / n starting at its first node;
- ``periodic`` (d,) bool; ``strides`` (d,): flat-index strides of the C-ordered grid;
- ``values`` (N, Q): node values (0 where invalid); ``valid`` (N,) bool;
- ``eps``: weights at or below this do not count (a query on a valid node is valid).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["locate", "corner_sum", "multilinear", "cell_corners"]


@njit(cache=True, inline="always")
def locate(u, axes, start, size, periodic, lo, hi, t):
    """Cell of the point ``u`` (d,): lower and upper node index and fraction along each axis,
    written into ``lo``, ``hi`` (d,) int and ``t`` (d,). Periodic coordinates wrap; the others
    are clamped to their axis."""
    for k in range(u.shape[0]):
        a0 = start[k]
        n = size[k]
        x = u[k]
        if periodic[k]:
            h = 2.0 * np.pi / n
            y = (x - axes[a0]) / h
            y = y - n * np.floor(y / n)      # in [0, n)
            i = int(np.floor(y))
            if i >= n:                       # rounding
                i = n - 1
            lo[k] = i
            hi[k] = (i + 1) % n
            t[k] = y - i
        elif x <= axes[a0]:
            lo[k], hi[k], t[k] = 0, 1, 0.0
        elif x >= axes[a0 + n - 1]:
            lo[k], hi[k], t[k] = n - 2, n - 1, 1.0
        else:
            i = np.searchsorted(axes[a0:a0 + n], x, side="right") - 1
            if i > n - 2:
                i = n - 2
            lo[k] = i
            hi[k] = i + 1
            t[k] = (x - axes[a0 + i]) / (axes[a0 + i + 1] - axes[a0 + i])


@njit(cache=True, inline="always")
def corner_sum(lo, hi, t, strides, values, valid, column, eps):
    """Weighted sum of column ``column`` over the 2^d corners of the cell (``locate``'s output);
    returns (value, ok), ok False where an invalid node carries weight (value then incomplete)."""
    d = lo.shape[0]
    value = 0.0
    for corner in range(1 << d):
        w = 1.0
        flat = 0
        for k in range(d):
            if (corner >> k) & 1:
                w *= t[k]
                flat += hi[k] * strides[k]
            else:
                w *= 1.0 - t[k]
                flat += lo[k] * strides[k]
        if w <= eps:
            continue
        if not valid[flat]:
            return value, False
        value += w * values[flat, column]
    return value, True


@njit(cache=True)
def multilinear(u, axes, start, size, periodic, strides, values, valid, columns, eps, out, ok):
    """Interpolate the columns ``columns`` (c,) of ``values`` at the points ``u`` (m, d) into
    ``out`` (m, c); ``ok`` (m,) is False where an invalid node carries weight."""
    m, d = u.shape
    lo = np.empty(d, dtype=np.int64)
    hi = np.empty(d, dtype=np.int64)
    t = np.empty(d)
    for p in range(m):
        locate(u[p], axes, start, size, periodic, lo, hi, t)
        good = True
        for c in range(columns.shape[0]):
            out[p, c], cok = corner_sum(lo, hi, t, strides, values, valid, columns[c], eps)
            good = good and cok
        ok[p] = good


@njit(cache=True)
def cell_corners(u, axes, start, size, periodic, strides, index, weight):
    """The 2^d corners of each point's cell and their multilinear weights: for the points ``u``
    (m, d), flat node indices into ``index`` (m, 2^d) and weights into ``weight`` (m, 2^d), in
    the corner order of :func:`corner_sum` (the weights of a point sum to 1)."""
    m, d = u.shape
    lo = np.empty(d, dtype=np.int64)
    hi = np.empty(d, dtype=np.int64)
    t = np.empty(d)
    for p in range(m):
        locate(u[p], axes, start, size, periodic, lo, hi, t)
        for corner in range(1 << d):
            w = 1.0
            flat = 0
            for k in range(d):
                if (corner >> k) & 1:
                    w *= t[k]
                    flat += hi[k] * strides[k]
                else:
                    w *= 1.0 - t[k]
                    flat += lo[k] * strides[k]
            index[p, corner] = flat
            weight[p, corner] = w
