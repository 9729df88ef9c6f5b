"""Calibration parameters: names, units, bounds, and how each one changes a robot.

A parameter is addressed by a name that says what it is and which tube or pair it belongs to
(1-based, tube 1 outermost, pair k = tubes k and k+1):

=========================  ========  ===========================================================
name                       unit      meaning
=========================  ========  ===========================================================
``precurvature_y_i``       1/m       in-plane precurvature of tube i: the y component of its
                                     first curved section; other curved sections of the tube
                                     are scaled by the same factor (Table VII of Ha et al. 2019)
``precurvature_x_i``       1/m       off-plane precurvature of tube i: the x component of every
                                     curved section of the tube ("x-curvature", Section V-C)
``k_xy_relative_i``        -         bending stiffness of tube i relative to tube 1 (i >= 2);
                                     only ratios matter without external load (Section V-C)
``poisson_ratio_i``        -         Poisson ratio of tube i, k_z = k_xy / (1 + nu) (Sec. II-C)
``mu_k``                   -         Coulomb friction coefficient of pair k (Section III)
``registration_r{x,y,z}``  rad       rotation vector of the tracker frame from the robot base
``registration_t{x,y,z}``  m         translation of the tracker frame: p_tracker = R p_base + t
``backlash_i``             rad       dead band of tube i's rotation drive (:mod:`.history`)
``time_offset``            s         lag of the tracker readings behind the joint readings
``friction_angle``         rad       relative rotation over which friction develops after a
                                     reversal (theta_c of :func:`.history.friction_state`)
=========================  ========  ===========================================================

Registration parameters change no mechanics; they map model outputs to the tracker frame.
History parameters (backlash, time offset, friction angle) change no robot either; they change
the motion history the model is evaluated along (:func:`history_parameters`).

Every parameter has optimizer bounds (``lower``, ``upper``: what the code accepts) and, where
physics says so, a *plausible* range (``plausible``: what a real robot of this kind can have,
with the reason in ``plausible_note``). A fitted value outside the plausible range is reported
as implausible by the discrepancy workflow.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

import numpy as np
from ..errors import CtrplanError
from ..robot import Robot, Section
from .effects import rigid_transform

__all__ = ["Parameter", "parameter", "read_parameters", "apply_parameters", "registration_transform",
           "history_parameters", "REGISTRATION", "HISTORY_KINDS", "PLAUSIBLE", "ParameterError"]

#: Parameters of the motion history (not of the robot, not of the registration).
HISTORY_KINDS = ("backlash", "time_offset", "friction_angle")

# Plausible ranges: kind -> (lower, upper, reason), in the parameter's unit.
PLAUSIBLE = {
    "mu": (0.0, 0.5, "Coulomb friction of NiTi on NiTi (Ha et al. 2019 calibrated 0.22 and 0.12 on the "
                     "three-tube robot, Table VII)"),
    "backlash": (0.0, float(np.deg2rad(5.0)), "dead band of a geared rotation stage: up to a few degrees "
                                              "(0-5 deg)"),
    "time_offset": (-0.3, 0.3, "latency between joint encoders and an EM/optical tracker: tens to a few "
                               "hundred ms (|tau| <= 0.3 s)"),
    "friction_angle": (0.0, float(np.deg2rad(30.0)), "the paper assumes friction develops within its 90 deg "
                                                     "approach rotations (Sec. V-B): 95 % after 3 theta_c <= "
                                                     "90 deg"),
    "poisson_ratio": (-0.99, 0.5, "the paper's calibrated (effective) values are negative for some tubes "
                                  "(Tables V-VII)"),
}

REGISTRATION = ("registration_rx", "registration_ry", "registration_rz",
                "registration_tx", "registration_ty", "registration_tz")

_PATTERN = re.compile(r"^(precurvature_y|precurvature_x|k_xy_relative|poisson_ratio|mu|backlash)_([1-9][0-9]*)$")


class ParameterError(CtrplanError, ValueError):
    """A calibration parameter name or value that does not fit the robot."""


@dataclass(frozen=True)
class Parameter:
    """One calibration parameter.

    Attributes
    ----------
    name : str
        As in the module table, e.g. ``"precurvature_y_3"``.
    kind : str
        The name without its index.
    index : int
        0-based tube, pair or axis index.
    unit : str
    lower, upper : float
        Bounds for the optimizer, in ``unit``.
    scale : float
        Typical size of a change, in ``unit`` (scales the optimizer's steps).
    plausible : tuple of float or None
        ``(lower, upper)`` a real robot can have, in ``unit``; None: no physical limit beyond
        the bounds.
    plausible_note : str
        Why (source or reasoning).
    """

    name: str
    kind: str
    index: int
    unit: str
    lower: float
    upper: float
    scale: float
    plausible: tuple | None = None
    plausible_note: str = ""

    @property
    def history(self) -> bool:
        """True for a parameter of the motion history (backlash, time offset, friction angle)."""
        return self.kind in HISTORY_KINDS

    @property
    def mechanical(self) -> bool:
        """True when the parameter changes the robot (neither registration nor history)."""
        return not self.kind.startswith("registration") and not self.history

    @property
    def needs_solve(self) -> bool:
        """True when a change needs the model solved again (mechanical or history)."""
        return not self.kind.startswith("registration")

    def is_plausible(self, value: float) -> bool:
        """Whether ``value`` lies in the plausible range (True when there is none)."""
        return self.plausible is None or (self.plausible[0] - 1e-12 <= value <= self.plausible[1] + 1e-12)


def parameter(robot: Robot, name: str) -> Parameter:
    """Describe the parameter ``name`` of ``robot``.

    Raises
    ------
    ParameterError
        Unknown name, a tube or pair the robot does not have, a precurvature of a straight tube,
        or ``k_xy_relative_1`` (tube 1 is the stiffness reference).
    """
    if name == "time_offset":
        return Parameter(name, "time_offset", 0, "s", -2.0, 2.0, 0.02, *_plausible("time_offset"))
    if name == "friction_angle":
        return Parameter(name, "friction_angle", 0, "rad", 0.0, np.pi, 0.05, *_plausible("friction_angle"))
    if name in REGISTRATION:
        axis = REGISTRATION.index(name)
        if axis < 3:
            return Parameter(name, "registration_r", axis, "rad", -np.pi, np.pi, 0.01)
        return Parameter(name, "registration_t", axis - 3, "m", -1.0, 1.0, 1e-3)
    m = _PATTERN.match(name)
    if m is None:
        raise ParameterError(
            f"unknown calibration parameter {name!r}; expected precurvature_y_i, precurvature_x_i, "
            f"k_xy_relative_i, poisson_ratio_i, mu_k, backlash_i, time_offset, friction_angle or "
            f"registration_(rx|ry|rz|tx|ty|tz)")
    kind, idx = m.group(1), int(m.group(2)) - 1
    n = robot.n_tubes
    limit = n - 1 if kind == "mu" else n
    if idx >= limit:
        raise ParameterError(f"calibration parameter {name!r}: the robot has "
                             f"{limit} {'pairs' if kind == 'mu' else 'tubes'}")
    if kind in ("precurvature_y", "precurvature_x"):
        if _first_curved(robot, idx) is None:
            raise ParameterError(f"calibration parameter {name!r}: tube {idx + 1} has no curved section")
        return Parameter(name, kind, idx, "1/m", -200.0, 200.0, 0.5)
    if kind == "k_xy_relative":
        if idx == 0:
            raise ParameterError("calibration parameter 'k_xy_relative_1': tube 1 is the stiffness "
                                 "reference (only ratios matter); fit k_xy_relative_2..n")
        return Parameter(name, kind, idx, "-", 1e-3, 1e3, 0.05)
    if kind == "poisson_ratio":
        return Parameter(name, kind, idx, "-", -0.99, 0.5, 0.05, *_plausible(kind))
    if kind == "backlash":
        return Parameter(name, kind, idx, "rad", 0.0, float(np.deg2rad(30.0)), 0.005, *_plausible(kind))
    return Parameter(name, kind, idx, "-", 0.0, 2.0, 0.05, *_plausible(kind))


def _plausible(kind):
    lo, hi, note = PLAUSIBLE[kind]
    return (lo, hi), note


def _first_curved(robot: Robot, i: int):
    for j, sec in enumerate(robot.tubes[i].sections):
        if not sec.is_straight:
            return j
    return None


def read_parameters(robot: Robot, names, registration=None) -> np.ndarray:
    """Current values of the named parameters, shape (m,), in their units.

    ``registration`` is ``(rotation_vector (3,) [rad], translation (3,) [m])`` or None (zero).

    Raises
    ------
    ParameterError
        As :func:`parameter`.
    """
    out = []
    for name in names:
        p = parameter(robot, name)
        if p.kind == "registration_r":
            out.append(0.0 if registration is None else float(registration[0][p.index]))
        elif p.kind == "registration_t":
            out.append(0.0 if registration is None else float(registration[1][p.index]))
        elif p.kind == "precurvature_y":
            out.append(robot.tubes[p.index].sections[_first_curved(robot, p.index)].precurvature[1])
        elif p.kind == "precurvature_x":
            out.append(robot.tubes[p.index].sections[_first_curved(robot, p.index)].precurvature[0])
        elif p.kind == "k_xy_relative":
            out.append(robot.tubes[p.index].k_xy / robot.tubes[0].k_xy)
        elif p.kind == "poisson_ratio":
            out.append(robot.tubes[p.index].poisson_ratio)
        elif p.history:
            out.append(0.0)   # history effects are off on a robot
        else:
            out.append(robot.friction_coefficients[p.index])
    return np.asarray(out, dtype=float)


def apply_parameters(robot: Robot, names, values) -> Robot:
    """A copy of ``robot`` with the named mechanical parameters set (registration ones ignored).

    Parameters
    ----------
    robot : Robot
    names : sequence of str, length m
    values : array-like, shape (m,)
        In the parameters' units.

    Returns
    -------
    Robot

    Raises
    ------
    ParameterError
        Unknown name or a value outside the parameter's bounds.
    PhysicalParameterError
        A resulting tube is physically impossible.
    """
    values = np.asarray(values, dtype=float)
    tubes = list(robot.tubes)
    mu = list(robot.friction_coefficients)
    k_ref = robot.tubes[0].k_xy
    for name, v in zip(names, values):
        p = parameter(robot, name)
        if not (p.lower <= v <= p.upper) or not np.isfinite(v):
            raise ParameterError(f"calibration parameter {name!r} = {v!r} {p.unit} is outside "
                                 f"[{p.lower}, {p.upper}]")
        if not p.mechanical:
            continue   # registration and history parameters: see registration_transform, history_parameters
        i = p.index
        if p.kind == "mu":
            mu[i] = float(v)
            continue
        tube = tubes[i]
        if p.kind == "precurvature_y":
            ref = tube.sections[_first_curved(robot, i)].precurvature[1]
            secs = []
            for sec in tube.sections:
                if sec.is_straight:
                    secs.append(sec)
                elif ref != 0.0:
                    secs.append(Section(sec.length, (sec.precurvature[0], sec.precurvature[1] * v / ref)))
                else:
                    secs.append(Section(sec.length, (sec.precurvature[0], float(v))))
            tube = dataclasses.replace(tube, sections=tuple(secs))
        elif p.kind == "precurvature_x":
            secs = tuple(sec if sec.is_straight else Section(sec.length, (float(v), sec.precurvature[1]))
                         for sec in tube.sections)
            tube = dataclasses.replace(tube, sections=secs)
        elif p.kind == "k_xy_relative":
            tube = dataclasses.replace(tube, k_xy=float(v) * k_ref)
        elif p.kind == "poisson_ratio":
            tube = dataclasses.replace(tube, poisson_ratio=float(v))
        tubes[i] = tube
    return robot.replace(tubes=tuple(tubes), friction_coefficients=tuple(mu))


def history_parameters(robot: Robot, names, values) -> dict:
    """The history effects among ``names``/``values``.

    Returns
    -------
    dict
        ``backlash`` (n,) [rad] (zeros where not named), ``time_offset`` [s] and
        ``friction_angle`` [rad] (None when not named); empty when no history parameter is named.

    Raises
    ------
    ParameterError
        As :func:`parameter`, or a value outside its bounds.
    """
    out: dict = {}
    for name, v in zip(names, values):
        p = parameter(robot, name)
        if not p.history:
            continue
        if not (p.lower <= v <= p.upper) or not np.isfinite(v):
            raise ParameterError(f"calibration parameter {name!r} = {v!r} {p.unit} is outside "
                                 f"[{p.lower}, {p.upper}]")
        if p.kind == "backlash":
            out.setdefault("backlash", np.zeros(robot.n_tubes))[p.index] = float(v)
        else:
            out[p.kind] = float(v)
    return out


def registration_transform(names, values):
    """Registration ``(R (3, 3), t (3,) [m])`` from the registration entries of ``names``/``values``
    (missing entries are zero): ``p_tracker = R p_base + t``."""
    reg = np.zeros(6)
    for name, v in zip(names, values):
        if name in REGISTRATION:
            reg[REGISTRATION.index(name)] = v
    return rigid_transform(reg)
