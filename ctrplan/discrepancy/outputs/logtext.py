"""How the workflow's log lines print figures the data can leave undefined.

A mean over no finite sample, a maximum of none, an interval over one unit: the results carry them
as None or NaN (:class:`~ctrplan.discrepancy.verdict.statistics.Interval`,
:class:`~ctrplan.discrepancy.verdict.coverage.Coverage`), and a log line prints them as
:data:`UNDEFINED`, never ``nan``, never a made-up ``0``, and never raises on them. The report
(:mod:`ctrplan.discrepancy.outputs.report`) prints them the same way.
"""

from __future__ import annotations

import math

__all__ = ["UNDEFINED", "defined", "figure", "interval"]

#: How an undefined figure (None or NaN) is printed.
UNDEFINED = "undefined"


def defined(x, finite: bool = True) -> float | None:
    """``x`` as a float, or None where it is None, NaN, no number, or (with ``finite``) infinite."""
    if x is None or isinstance(x, (bool, str)):
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(v) or (finite and math.isinf(v)) else v


def figure(x, spec: str, scale: float = 1.0, unit: str = "") -> str:
    """``x * scale`` formatted by ``spec`` followed by ``unit`` (e.g. ``" mm"``), or
    :data:`UNDEFINED` (without the unit) where ``x`` is not a finite number.

    Parameters
    ----------
    x : float or None
        In the unit of the results (SI, e.g. [m]).
    spec : str
        Format spec, e.g. ``".3f"``.
    scale : float
        Factor to the printed unit (e.g. 1e3 from m to mm, 100 to %).
    unit : str
        Printed after the number.

    Returns
    -------
    str
    """
    v = defined(x)
    return UNDEFINED if v is None else f"{v * scale:{spec}}{unit}"


def interval(low, high, spec: str, scale: float = 1.0, unit: str = "") -> str:
    """``low..high`` (each times ``scale``, formatted by ``spec``) followed by ``unit``, or
    :data:`UNDEFINED` where either end is not a finite number (fewer than two units, no samples);
    a log line writes ``f"interval {interval(...)}"``.

    Returns
    -------
    str
    """
    lo, hi = defined(low), defined(high)
    if lo is None or hi is None:
        return UNDEFINED
    return f"{lo * scale:{spec}}..{hi * scale:{spec}}{unit}"
