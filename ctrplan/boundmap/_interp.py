"""Compiled multilinear interpolation on a tensor grid with uniform periodic and nonuniform
bounded axes (the kernel of :meth:`ctrplan.boundmap.BoundField.interpolate`)."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["multilinear"]


@njit(cache=True)
def multilinear(u, axes, start, size, periodic, strides, values, valid, columns, eps, out, ok):
    """Interpolate ``values`` at the points ``u`` (m, d).

    Parameters
    ----------
    u : (m, d) query points; periodic coordinates wrap, others are clamped to their axis.
    axes : (sum n_k,) node coordinates of all axes, concatenated; axis k is
        ``axes[start[k]:start[k] + size[k]]`` (increasing; uniform with spacing 2 pi / n when
        periodic, starting at its first node).
    periodic : (d,) bool.
    strides : (d,) flat-index strides of the C-ordered grid.
    values : (N, Q) node values (0 where invalid); valid : (N,) bool.
    columns : (c,) columns of ``values`` to interpolate.
    eps : weights at or below this do not count for validity.
    out : (m, c) results; ok : (m,) False where a node of weight > eps is invalid.
    """
    m, d = u.shape
    lo = np.empty(d, dtype=np.int64)
    hi = np.empty(d, dtype=np.int64)
    t = np.empty(d)
    nc = columns.shape[0]
    for p in range(m):
        for k in range(d):
            a0 = start[k]
            n = size[k]
            x = u[p, k]
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
            else:
                first = axes[a0]
                last = axes[a0 + n - 1]
                if x <= first:
                    lo[k] = 0
                    hi[k] = 1
                    t[k] = 0.0
                elif x >= last:
                    lo[k] = n - 2
                    hi[k] = n - 1
                    t[k] = 1.0
                else:
                    i = np.searchsorted(axes[a0:a0 + n], x, side="right") - 1
                    if i > n - 2:
                        i = n - 2
                    lo[k] = i
                    hi[k] = i + 1
                    t[k] = (x - axes[a0 + i]) / (axes[a0 + i + 1] - axes[a0 + i])
        for c in range(nc):
            out[p, c] = 0.0
        good = True
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
                good = False
            for c in range(nc):
                out[p, c] += w * values[flat, columns[c]]
        ok[p] = good


@njit(cache=True)
def point_value(u, axes, start, size, periodic, strides, values, valid, column, eps):
    """Multilinear value of one column at one point ``u`` (d,); returns (value, ok) as
    :func:`multilinear` computes them (ok False where an invalid node carries weight)."""
    d = u.shape[0]
    value = 0.0
    good = True
    lo = np.empty(d, dtype=np.int64)
    hi = np.empty(d, dtype=np.int64)
    t = np.empty(d)
    for k in range(d):
        a0 = start[k]
        n = size[k]
        x = u[k]
        if periodic[k]:
            h = 2.0 * np.pi / n
            y = (x - axes[a0]) / h
            y = y - n * np.floor(y / n)
            i = int(np.floor(y))
            if i >= n:
                i = n - 1
            lo[k] = i
            hi[k] = (i + 1) % n
            t[k] = y - i
        else:
            first = axes[a0]
            last = axes[a0 + n - 1]
            if x <= first:
                lo[k], hi[k], t[k] = 0, 1, 0.0
            elif x >= last:
                lo[k], hi[k], t[k] = n - 2, n - 1, 1.0
            else:
                i = np.searchsorted(axes[a0:a0 + n], x, side="right") - 1
                if i > n - 2:
                    i = n - 2
                lo[k] = i
                hi[k] = i + 1
                t[k] = (x - axes[a0 + i]) / (axes[a0 + i + 1] - axes[a0 + i])
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
            good = False
        value += w * values[flat, column]
    return value, good
