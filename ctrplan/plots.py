"""Figure helpers shared by every report: a figure on the Agg canvas (:func:`new_figure`: no
pyplot, no window, no change to the user's backend), written as PNG atomically
(:func:`save_figure`: a temporary file in the same folder, then ``os.replace``, so an interrupted
run never leaves a half-written figure), and a generic line plot (:func:`plot_xy`). A plan's own
figures are in :mod:`ctrplan.planning.outputs.figures`, a discrepancy run's in
:mod:`ctrplan.discrepancy.outputs`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .io.atomic import atomic_path

__all__ = ["new_figure", "save_figure", "plot_xy", "DPI", "M_TO_MM"]

#: Millimetres per metre: figures show lengths in mm.
M_TO_MM = 1e3
#: Resolution of the PNG files [dots per inch].
DPI = 120


def plot_xy(path, x, ys, *, xlabel: str, ylabel: str, labels: Sequence[str] | None = None,
            title: str = "", style: str = "-") -> Path:
    """Generic line plot of one or more curves against a common x.

    Parameters
    ----------
    path : str or Path
        Output PNG.
    x : array-like, shape (N,)
        In the unit named by ``xlabel``.
    ys : array-like, shape (N,) or (M, N)
        One or M curves, in the unit named by ``ylabel``.
    xlabel, ylabel : str
        Axis labels with units, e.g. ``"time t [s]"``.
    labels : sequence of str, length M, optional
    title, style : str

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        If a curve's length differs from ``x``.
    """
    x = np.asarray(x, dtype=float)
    ys = np.atleast_2d(np.asarray(ys, dtype=float))
    if ys.shape[1] != x.size:
        raise ValueError(f"ys needs shape ({x.size},) or (M, {x.size}), got {ys.shape}")
    fig = new_figure((6.5, 4.0))
    ax = fig.subplots()
    for m, y in enumerate(ys):
        ax.plot(x, y, style, label=None if labels is None else labels[m])
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if labels is not None:
        ax.legend(fontsize="small")
    if title:
        ax.set_title(title)
    return save_figure(fig, path)


def new_figure(size) -> Figure:
    """A figure attached to an Agg canvas: not registered with pyplot (nothing to close) and the
    user's matplotlib backend untouched.

    Parameters
    ----------
    size : tuple of float, length 2
        Width and height [inch].

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path) -> Path:
    """Write ``fig`` as PNG at :data:`DPI` (tight layout), atomically: an interrupted write leaves
    the previous file.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        From :func:`new_figure`.
    path : str or os.PathLike

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OSError
        The folder cannot be written.
    """
    path = Path(path)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI)
    return path
