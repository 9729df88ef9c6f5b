"""Calibration parameters: names, units, bounds, and how each one changes a robot.

A parameter is addressed by a name that says what it is and which tube or pair it belongs to
(1-based, tube 1 outermost, pair k = tubes k and k+1). The baseline calibration fits the tube
parameters of Tables VI and VII of Ha, Fagogenis & Dupont 2019 (doi:10.1109/TRO.2018.2878906):

=========================  ========  ===========================================================
name                       unit      meaning
=========================  ========  ===========================================================
``precurvature_y_i``       1/m       in-plane precurvature of tube i: the y component of its
                                     first curved section; other curved sections of the tube
                                     are scaled by the same factor (Table VII)
``k_xy_relative_i``        -         bending stiffness of tube i relative to tube 1 (i >= 2);
                                     only ratios matter without external load (Section V-C)
=========================  ========  ===========================================================

Every other parameter belongs to an effect of the registry (:mod:`ctrplan.effects`: friction
``mu_k``, ``clearance_k``, ``precurvature_x_i``, ``poisson_ratio_i``, ``registration_*``,
``backlash_i``, ``time_offset``, ``friction_angle``, and any registered later), whose entry
gives its unit, optimizer bounds and typical range. A baseline parameter's typical range
is a stated relative change from the robot file's value (:data:`BASELINE_TYPICAL_CHANGE`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...effects import REGISTRY, EffectSet, ParameterSpec, apply_robot_effects, effect_of_parameter, parameter_spec
from ...errors import CtrplanError
from ...robot import Robot, Section

__all__ = ["parameter", "needs_solve", "read_parameters", "apply_parameters", "REGISTRATION", "BASELINE_KINDS",
           "BASELINE_TYPICAL_CHANGE", "BASELINE_BOUND_FACTOR", "ParameterError"]

#: Kinds of baseline (tube) parameters.
BASELINE_KINDS = ("precurvature_y", "k_xy_relative")
#: Names of the registration parameters (rotation vector [rad], translation [m]).
REGISTRATION = ("registration_rx", "registration_ry", "registration_rz",
                "registration_tx", "registration_ty", "registration_tz")
#: Typical relative change of a baseline parameter from the robot file's value: the paper's
#: calibration (Table VII against Table II) moved precurvatures by 6-25 % and relative stiffnesses
#: by 1-30 %; a fit that needs more than +-50 % describes another tube set, or trades one
#: parameter against a correlated one.
BASELINE_TYPICAL_CHANGE = 0.5
#: Optimizer bounds of a baseline parameter: this factor below and above the robot file's value
#: (strictly wider than the typical range; a fit that ends there is reported at its bound).
BASELINE_BOUND_FACTOR = 5.0


class ParameterError(CtrplanError, ValueError):
    """A calibration parameter name or value that does not fit the robot."""


def _first_curved(robot: Robot, i: int):
    for j, sec in enumerate(robot.tubes[i].sections):
        if not sec.is_straight:
            return j
    return None


def _baseline(robot: Robot, name: str) -> ParameterSpec | None:
    kind, _, idx = name.rpartition("_")
    if kind not in BASELINE_KINDS or not idx.isdigit() or int(idx) < 1:
        return None
    i = int(idx) - 1
    if i >= robot.n_tubes:
        raise ParameterError(f"calibration parameter {name!r}: the robot has {robot.n_tubes} tubes")
    if kind == "precurvature_y":
        j = _first_curved(robot, i)
        if j is None:
            raise ParameterError(f"calibration parameter {name!r}: tube {i + 1} has no curved section")
        v = robot.tubes[i].sections[j].precurvature[1]
        if v == 0.0:
            return ParameterSpec(name, kind, i, "1/m", -200.0, 200.0, 0.5)
        lo, hi = sorted((v * (1 - BASELINE_TYPICAL_CHANGE), v * (1 + BASELINE_TYPICAL_CHANGE)))
        blo, bhi = sorted((v / BASELINE_BOUND_FACTOR, v * BASELINE_BOUND_FACTOR))
        return ParameterSpec(name, kind, i, "1/m", blo, bhi, 0.5, (lo, hi),
                             f"within +-{BASELINE_TYPICAL_CHANGE:.0%} of the robot file's {v:.4g} 1/m",
                             check=f"tube {i + 1}'s precurvature in the robot file, and the parameters it trades "
                                   f"off against (its correlations)")
    if i == 0:
        raise ParameterError("calibration parameter 'k_xy_relative_1': tube 1 is the stiffness reference "
                             "(only ratios matter); fit k_xy_relative_2..n")
    v = robot.tubes[i].k_xy / robot.tubes[0].k_xy
    return ParameterSpec(name, kind, i, "-", v / BASELINE_BOUND_FACTOR, v * BASELINE_BOUND_FACTOR, 0.05,
                         (v * (1 - BASELINE_TYPICAL_CHANGE), v * (1 + BASELINE_TYPICAL_CHANGE)),
                         f"within +-{BASELINE_TYPICAL_CHANGE:.0%} of the robot file's {v:.4g}",
                         check=f"tube {i + 1}'s bending stiffness in the robot file, and the parameters it trades "
                               f"off against (its correlations)")


def parameter(robot: Robot, name: str) -> ParameterSpec:
    """Describe the parameter ``name`` of ``robot`` (a baseline or an effect parameter).

    Returns
    -------
    ParameterSpec
        Unit, optimizer bounds, typical step, typical range (for a baseline parameter, about
        the robot file's value).

    Raises
    ------
    ParameterError
        Unknown name, a tube or pair the robot does not have, a precurvature of a straight tube,
        or ``k_xy_relative_1`` (tube 1 is the stiffness reference).
    """
    spec = _baseline(robot, name)
    if spec is None:
        spec = parameter_spec(robot, name)
    if spec is None:
        known = ", ".join(f"{k}_i" for k in BASELINE_KINDS)
        effects = "; ".join(f"{e.name}: {', '.join(e.parameter_names(robot))}" for e in REGISTRY.values())
        raise ParameterError(f"unknown calibration parameter {name!r} for robot {robot.name!r}; expected {known}, "
                             f"or a parameter of an effect ({effects})")
    return spec


def needs_solve(robot: Robot, name: str) -> bool:
    """A change of the parameter needs the model solved again (it is not an output effect's,
    such as the registration's)."""
    e = effect_of_parameter(robot, name)
    return True if e is None else e.needs_solve


def read_parameters(robot: Robot, names) -> np.ndarray:
    """Values of the named parameters on ``robot``, shape (m,), in their units: baseline
    parameters and the effect parameters stored in the robot (friction coefficients,
    precurvatures, Poisson ratios); the others at the value that switches their effect off (0),
    or the robot file's ``[effects]`` value.

    Raises
    ------
    ParameterError
        As :func:`parameter`.
    """
    from ...effects import robot_effects

    file_effects = robot_effects(robot)
    out = []
    for name in names:
        spec = parameter(robot, name)
        if spec.kind == "precurvature_y":
            out.append(robot.tubes[spec.index].sections[_first_curved(robot, spec.index)].precurvature[1])
        elif spec.kind == "k_xy_relative":
            out.append(robot.tubes[spec.index].k_xy / robot.tubes[0].k_xy)
        else:
            e = effect_of_parameter(robot, name)
            if e.store == "robot":
                off = e.off_values(robot)
                out.append(robot.friction_coefficients[spec.index] if spec.kind == "mu" else off[name])
            else:
                out.append(file_effects[e.name].get(name, 0.0) if e.name in file_effects else 0.0)
    return np.asarray(out, dtype=float)


def apply_parameters(robot: Robot, names, values) -> Robot:
    """A copy of ``robot`` with the named baseline parameters and robot effects set.

    Parameters of history and output effects (backlash, time offset, registration, ...) change
    the motion or the measurement, not the robot: they are checked and otherwise ignored here
    (:func:`ctrplan.effects.history_state`, :func:`ctrplan.effects.apply_output_effects`).

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
        Unknown name or a value outside the parameter's limits (``ParameterSpec.hard``).
    PhysicalParameterError
        A resulting tube is physically impossible.
    """
    values = np.asarray(values, dtype=float)
    tubes = list(robot.tubes)
    k_ref = robot.tubes[0].k_xy
    effect_names, effect_values = [], []
    for name, v in zip(names, values):
        p = parameter(robot, name)
        if not p.within_limit(v):
            raise ParameterError(f"calibration parameter {name!r} = {v!r} {p.unit} is outside "
                                 f"[{p.hard[0]}, {p.hard[1]}]")
        i = p.index
        if p.kind == "precurvature_y":
            tube = tubes[i]
            ref = tube.sections[_first_curved(robot, i)].precurvature[1]
            secs = []
            for sec in tube.sections:
                if sec.is_straight:
                    secs.append(sec)
                elif ref != 0.0:
                    secs.append(Section(sec.length, (sec.precurvature[0], sec.precurvature[1] * v / ref)))
                else:
                    secs.append(Section(sec.length, (sec.precurvature[0], float(v))))
            tubes[i] = dataclasses.replace(tube, sections=tuple(secs))
        elif p.kind == "k_xy_relative":
            tubes[i] = dataclasses.replace(tubes[i], k_xy=float(v) * k_ref)
        else:
            effect_names.append(name)
            effect_values.append(v)
    out = robot.replace(tubes=tuple(tubes))
    effects, _ = EffectSet.from_parameters(robot, effect_names, effect_values)
    return apply_robot_effects(out, effects)
