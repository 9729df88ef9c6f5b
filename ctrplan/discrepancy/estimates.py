"""Fitted parameter values as a report reads them: value, standard error and interval, the robot
file's value, and the parameter's typical range with its source (:mod:`ctrplan.discrepancy.parameters`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from .calibrate import CalibrationResult
from .options import CONFIDENCE
from .parameters import parameter

__all__ = ["ParameterEstimate", "AtypicalValue", "parameter_table", "atypical_values", "display_value"]


@dataclass(frozen=True)
class ParameterEstimate:
    """One fitted (or held) parameter of a fit.

    Attributes
    ----------
    name : str
        Its name (:mod:`ctrplan.discrepancy.parameters`).
    unit : str
        Its SI unit (``"1/m"``, ``"rad"``, ``"m"``, ``"s"``, ``"-"``).
    value : float
        The value [unit]; NaN when the fit neither fitted nor held it.
    stderr : float or None
        Standard error [unit] (clustered over units where the fit computed it so; inf when the
        data do not determine it); None when the fit computed none.
    ci : tuple of float, or None
        Normal-approximation interval (low, high) [unit] at
        :data:`~ctrplan.discrepancy.options.CONFIDENCE`; None without a finite standard error.
    typical : tuple of float, or None
        Typical range (low, high) [unit]; None when any value is typical.
    in_typical_range : bool
    typical_source : str or None
        Where the typical range comes from.
    check : str or None
        What to check on the robot when the value is outside its typical range.
    at_bound : bool
        The fit flagged the value at a bound or a scan's or grid's end it could not widen.
    resolution : float or None
        Step of a scan or grid that sets it [unit].
    fitted : bool
        Fitted (False: held at a fixed value).
    reference : float or None
        The robot file's value [unit], when given.
    relative_change : float or None
        ``(value - reference) / reference`` [-]; None without a reference or for a reference of 0.
    """

    name: str
    unit: str
    value: float
    stderr: float | None
    ci: tuple | None
    typical: tuple | None
    in_typical_range: bool
    typical_source: str | None
    check: str | None
    at_bound: bool
    resolution: float | None
    fitted: bool
    reference: float | None = None
    relative_change: float | None = None

    def as_dict(self) -> dict:
        """Plain JSON form (SI; intervals and ranges as lists; ``reference`` and
        ``relative_change`` only with a reference)."""
        out = {"name": self.name, "unit": self.unit, "value": self.value, "stderr": self.stderr,
               "ci": None if self.ci is None else list(self.ci),
               "typical": None if self.typical is None else list(self.typical),
               "in_typical_range": self.in_typical_range, "typical_source": self.typical_source, "check": self.check,
               "at_bound": self.at_bound, "resolution": self.resolution, "fitted": self.fitted}
        if self.reference is not None:
            out.update(reference=self.reference, relative_change=self.relative_change)
        return out


@dataclass(frozen=True)
class AtypicalValue:
    """A fitted value outside its parameter's typical range.

    Attributes
    ----------
    name : str
    value : float
        [unit]
    typical : tuple of float
        The typical range (low, high) [unit].
    typical_text : str
        The range as a report prints it.
    unit : str
    why : str
        The range's source.
    check : str or None
        What to check on the robot.
    """

    name: str
    value: float
    typical: tuple
    typical_text: str
    unit: str
    why: str
    check: str | None

    def as_dict(self) -> dict:
        """Plain JSON form (SI; the range as a list)."""
        return {"name": self.name, "value": self.value, "typical": list(self.typical),
                "typical_text": self.typical_text, "unit": self.unit, "why": self.why, "check": self.check}


def display_value(name: str, value: float, unit: str) -> str:
    """A parameter for a printed report or message: rad as deg, m as mm, others in their SI unit."""
    if unit == "rad":
        return f"{name} = {np.rad2deg(value):.4g} deg"
    if unit == "m":
        return f"{name} = {value * 1e3:.4g} mm"
    return f"{name} = {value:.4g}" + ("" if unit == "-" else f" {unit}")


def atypical_values(robot, params: Mapping) -> tuple:
    """The values of ``params`` ({name: value} [SI]) outside their typical range.

    Returns
    -------
    tuple of AtypicalValue
    """
    out = []
    for name, value in params.items():
        p = parameter(robot, name)
        if not p.is_typical(value):
            out.append(AtypicalValue(name=name, value=float(value), typical=tuple(p.typical), unit=p.unit,
                                     typical_text=p.typical_text(), why=p.typical_source, check=p.check))
    return tuple(out)


def parameter_table(robot, fit: CalibrationResult, names, *, reference: Mapping | None = None) -> tuple:
    """The parameters ``names`` of ``fit`` with their uncertainty and typical range.

    Parameters
    ----------
    robot : Robot
        Gives each parameter's unit and typical range.
    fit : CalibrationResult
        Fitted and fixed values [SI] and standard errors.
    names : sequence of str
    reference : mapping of str to float, optional
        E.g. the robot file's values [SI]: each estimate's ``reference`` and ``relative_change``.

    Returns
    -------
    tuple of ParameterEstimate
        In the order of ``names``.
    """
    from scipy import stats

    z = float(stats.norm.ppf(0.5 + CONFIDENCE / 2))
    values = dict(zip(fit.names, fit.values))
    errors = dict(zip(fit.names, fit.stderr)) if fit.stderr is not None else {}
    flagged = {b.split(" ")[0] for b in fit.at_bound}
    out = []
    for n in names:
        v = float(values.get(n, fit.fixed.get(n, np.nan)))
        p = parameter(robot, n)
        se = errors.get(n)
        row = ParameterEstimate(
            name=n, unit=p.unit, value=v, stderr=None if se is None else float(se),
            ci=None if se is None or not np.isfinite(se) else (v - z * se, v + z * se),
            typical=None if p.typical is None else tuple(p.typical), in_typical_range=p.is_typical(v),
            typical_source=p.typical_source, check=p.check, at_bound=n in flagged, resolution=p.resolution,
            fitted=n in values)
        if reference is not None and n in reference:
            ref = float(reference[n])
            row = replace(row, reference=ref, relative_change=(v - ref) / ref if ref else None)
        out.append(row)
    return tuple(out)
