"""Candidate model effects as modifications of a robot description.

An :class:`Effects` value says which physical effects (beyond the standard zero-clearance model)
act on a robot and how strongly: inter-tube friction, clearances, off-plane precurvature,
Poisson ratios, and the rigid registration between the robot base frame and the tracker frame.
:func:`apply_effects` turns the mechanical ones into a modified :class:`~ctrplan.robot.Robot`;
:func:`apply_registration` maps computed tip poses into the tracker frame.

Effects from Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906:
clearance (Section II, Eq. (15)), Coulomb friction (Section III, Eqs. (37)-(43)), off-plane
("x") precurvature and Poisson ratio as calibrated in Section V-C (Tables VI and VII).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ModelFileError, PhysicalParameterError
from ..robot import Robot

__all__ = ["Effects", "HISTORY_FIELDS", "apply_effects", "apply_registration", "registration_matrix", "rigid_transform",
           "transform_poses"]

# Field name -> (expected length as a function of the tube count n, unit, meaning).
_FIELDS = {
    "friction_coefficients": (lambda n: n - 1, "-", "Coulomb friction coefficient of each pair"),
    "clearances": (lambda n: n - 1, "m", "radial clearance of each pair (override)"),
    "offplane_precurvature": (lambda n: n, "1/m", "x precurvature added to curved sections"),
    "poisson_ratios": (lambda n: n, "-", "Poisson ratio of each tube"),
    "registration": (lambda n: 6, "rad, m", "rotation vector and translation, p_tracker = R p + t"),
    "backlash": (lambda n: n, "rad", "dead band of each tube's rotation drive (history effect)"),
    "time_offset": (lambda n: 1, "s", "lag of the tracker readings behind the joint readings (history effect)"),
    "friction_angle": (lambda n: 1, "rad", "relative rotation over which friction develops after a reversal"),
}
#: Fields that change the motion history, not the robot (:mod:`ctrplan.discrepancy.history`).
HISTORY_FIELDS = ("backlash", "time_offset", "friction_angle")


def _as_tuple(name, value):
    if value is None:
        return None
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.size == 0:
        raise PhysicalParameterError(f"effect {name!r}: needs at least one value, got none")
    if not np.all(np.isfinite(arr)):
        raise PhysicalParameterError(f"effect {name!r}: values must be finite, got {arr.tolist()}")
    return tuple(float(x) for x in arr)


@dataclass(frozen=True)
class Effects:
    """Effects acting on a robot, all optional (``None``: effect absent, the robot's own value).

    Parameters
    ----------
    friction_coefficients : tuple of float, shape (n - 1,), optional
        Coulomb friction coefficient mu of each adjacent pair (i, i+1), >= 0 (Section III,
        Eq. (38)). Replaces the robot's.
    clearances : tuple of float, shape (n - 1,), optional
        Radial clearance c_i of each pair [m], > 0 (Eq. (15)). Replaces the clearance from
        the diameters (``Robot.clearances_override``).
    offplane_precurvature : tuple of float, shape (n,), optional
        Off-plane precurvature [1/m] added to the x component of every curved section of tube
        i (straight sections such as collars stay straight): the "x-curvature" calibrated in
        Tables VI and VII (Section V-C).
    poisson_ratios : tuple of float, shape (n,), optional
        Poisson ratio nu of each tube, in (-1, 0.5] (``k_z = k_xy / (1 + nu)``, Section II-C).
        Replaces the robot's.
    registration : tuple of float, shape (6,), optional
        ``(r_x, r_y, r_z, t_x, t_y, t_z)``: rotation vector [rad] and translation [m] of the
        rigid map from the robot base frame to the tracker frame, ``p_tracker = R p_robot + t``
        with ``R = exp([r]x)``.
    backlash : tuple of float, shape (n,), optional
        Dead band of each tube's rotation drive [rad], >= 0: after a reversal the base angle
        lags the recorded one by up to half of it (:func:`~ctrplan.discrepancy.history.apply_backlash`).
    time_offset : tuple of float, shape (1,), optional
        Lag of the tracker readings behind the joint readings [s]
        (:func:`~ctrplan.discrepancy.history.apply_time_offset`).
    friction_angle : tuple of float, shape (1,), optional
        Relative rotation over which friction develops after a reversal [rad], >= 0 (theta_c of
        :func:`~ctrplan.discrepancy.history.friction_state`); needs friction coefficients.

    Raises
    ------
    PhysicalParameterError
        Non-finite value, negative friction coefficient, non-positive clearance, Poisson ratio
        outside (-1, 0.5], registration without 6 values. The message names the field.
    """

    friction_coefficients: tuple[float, ...] | None = None
    clearances: tuple[float, ...] | None = None
    offplane_precurvature: tuple[float, ...] | None = None
    poisson_ratios: tuple[float, ...] | None = None
    registration: tuple[float, ...] | None = None
    backlash: tuple[float, ...] | None = None
    time_offset: tuple[float, ...] | None = None
    friction_angle: tuple[float, ...] | None = None

    def __post_init__(self):
        for name in _FIELDS:
            object.__setattr__(self, name, _as_tuple(name, getattr(self, name)))
        if self.friction_coefficients is not None and min(self.friction_coefficients) < 0.0:
            raise PhysicalParameterError(
                f"effect 'friction_coefficients': must be >= 0, got {list(self.friction_coefficients)}")
        if self.clearances is not None and min(self.clearances) <= 0.0:
            raise PhysicalParameterError(
                f"effect 'clearances': must be > 0 m, got {list(self.clearances)}")
        if self.poisson_ratios is not None and not all(-1.0 < v <= 0.5 for v in self.poisson_ratios):
            raise PhysicalParameterError(
                f"effect 'poisson_ratios': must lie in (-1, 0.5], got {list(self.poisson_ratios)}")
        for name in ("backlash", "friction_angle"):
            v = getattr(self, name)
            if v is not None and min(v) < 0.0:
                raise PhysicalParameterError(f"effect {name!r}: must be >= 0 rad, got {list(v)}")
        for name in ("time_offset", "friction_angle"):
            v = getattr(self, name)
            if v is not None and len(v) != 1:
                raise PhysicalParameterError(f"effect {name!r}: needs 1 value, got {len(v)}: {list(v)}")
        if self.registration is not None and len(self.registration) != 6:
            raise PhysicalParameterError(
                f"effect 'registration': needs 6 values (rotation vector [rad], translation [m]), "
                f"got {len(self.registration)}")

    # ------------------------------------------------------------------ queries
    @property
    def friction_on(self) -> bool:
        """True when a friction coefficient is set and at least one is positive."""
        return self.friction_coefficients is not None and max(self.friction_coefficients) > 0.0

    @property
    def clearance_on(self) -> bool:
        """True when clearances are set (the clearance model applies)."""
        return self.clearances is not None

    @property
    def history_on(self) -> bool:
        """True when an effect on the motion history is set."""
        return any(getattr(self, name) is not None for name in HISTORY_FIELDS)

    def active(self) -> list[str]:
        """Names of the fields that are set, in field order."""
        return [name for name in _FIELDS if getattr(self, name) is not None]

    def replace(self, **changes) -> "Effects":
        """Copy with fields replaced (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def check(self, robot: Robot) -> None:
        """Raise if a field's length does not fit ``robot``.

        Raises
        ------
        PhysicalParameterError
            Naming the field, the expected and the given count.
        """
        n = robot.n_tubes
        for name, (size, unit, meaning) in _FIELDS.items():
            v = getattr(self, name)
            if v is not None and len(v) != size(n):
                raise PhysicalParameterError(
                    f"effect {name!r} ({meaning} [{unit}]): robot {robot.name!r} with {n} tubes needs "
                    f"{size(n)} values, got {len(v)}: {list(v)}")

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict:
        """Plain dict of the set fields (lists of floats), for JSON; SI units."""
        return {name: list(getattr(self, name)) for name in self.active()}

    @classmethod
    def from_dict(cls, data: dict, source: str = "<memory>") -> "Effects":
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict
            Keys among the field names; values lists of numbers or null.
        source : str
            File the dict came from, for error messages.

        Raises
        ------
        ModelFileError
            Unknown key or a value that is not a list of numbers or that the constructor
            rejects (the message names ``source`` and the key).
        """
        if not isinstance(data, dict):
            raise ModelFileError(source, "effects", f"expected a table of effects, got {type(data).__name__}")
        kwargs = {}
        for key, value in data.items():
            if key not in _FIELDS:
                raise ModelFileError(source, key, f"unknown effect; known: {', '.join(_FIELDS)}")
            if value is None:
                continue
            if not isinstance(value, (list, tuple)) or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
                raise ModelFileError(source, key, f"expected a list of numbers, got {value!r}")
            kwargs[key] = value
        try:
            return cls(**kwargs)
        except PhysicalParameterError as exc:
            raise ModelFileError(source, next(iter(kwargs), "effects"), str(exc)) from None


def apply_effects(robot: Robot, effects: Effects) -> Robot:
    """Robot with the mechanical effects applied (friction, clearance, precurvature, Poisson).

    The registration is not a property of the robot; see :func:`apply_registration`. Nor are
    the history effects (backlash, time offset, friction angle): see
    :mod:`ctrplan.discrepancy.history`.

    Parameters
    ----------
    robot : Robot
    effects : Effects

    Returns
    -------
    Robot
        A copy: friction coefficients and clearances replaced (``clearances_override``), the
        off-plane precurvature added to ``precurvature[0]`` of every curved section of each tube,
        Poisson ratios replaced. Unset effects leave the robot's values.

    Raises
    ------
    PhysicalParameterError
        A field's length does not fit the robot, or the modified robot is impossible.
    """
    effects.check(robot)
    changes = {}
    if effects.friction_coefficients is not None:
        changes["friction_coefficients"] = effects.friction_coefficients
    if effects.clearances is not None:
        changes["clearances_override"] = effects.clearances
    if effects.offplane_precurvature is not None or effects.poisson_ratios is not None:
        tubes = []
        for i, tube in enumerate(robot.tubes):
            if effects.offplane_precurvature is not None:
                dx = effects.offplane_precurvature[i]
                sections = tuple(
                    sec if sec.is_straight else
                    dataclasses.replace(sec, precurvature=(sec.precurvature[0] + dx, sec.precurvature[1]))
                    for sec in tube.sections)
                tube = dataclasses.replace(tube, sections=sections)
            if effects.poisson_ratios is not None:
                tube = dataclasses.replace(tube, poisson_ratio=effects.poisson_ratios[i])
            tubes.append(tube)
        changes["tubes"] = tuple(tubes)
    return robot.replace(**changes) if changes else robot


def rigid_transform(registration) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R, shape (3, 3), and translation t, shape (3,) [m], of a registration given as
    ``(rx, ry, rz, tx, ty, tz)`` (rotation vector [rad], translation [m]); identity for None."""
    if registration is None:
        return np.eye(3), np.zeros(3)
    reg = np.asarray(registration, dtype=float)
    return Rotation.from_rotvec(reg[:3]).as_matrix(), reg[3:].copy()


def registration_matrix(effects: Effects) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R, shape (3, 3), and translation t, shape (3,) [m], of the registration
    (identity and zero when unset)."""
    return rigid_transform(effects.registration)


def transform_poses(tip, tangent, R, t) -> tuple[np.ndarray, np.ndarray | None]:
    """``p' = R p + t`` and ``t' = R t`` for tip positions (K, 3) or (3,) [m] and unit tangents
    of the same shape (or None); R (3, 3), t (3,) [m]."""
    tip = np.asarray(tip, dtype=float) @ R.T + t
    if tangent is not None:
        tangent = np.asarray(tangent, dtype=float) @ R.T
    return tip, tangent


def apply_registration(tip, tangent, effects: Effects) -> tuple[np.ndarray, np.ndarray]:
    """Map tip poses from the robot base frame to the tracker frame.

    ``p_tracker = R p_robot + t``, ``t_tracker = R t_robot``.

    Parameters
    ----------
    tip : array-like, shape (K, 3) or (3,)
        Tip positions in the robot frame [m].
    tangent : array-like, shape (K, 3) or (3,), or None
        Unit tip tangents in the robot frame.
    effects : Effects

    Returns
    -------
    tip : ndarray, same shape as the input [m]
    tangent : ndarray or None, same shape as the input
    """
    return transform_poses(tip, tangent, *registration_matrix(effects))
