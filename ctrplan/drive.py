"""The joints as the drive moves them: their position limits and the drive's limits.

Two records that the time parameterization (:mod:`ctrplan.trajectory`), its checks and the
scenario file (``[drive]``, :mod:`ctrplan.io.scenario`) share:

- :class:`JointLimits`: the joints' names, kinds (base rotation alpha or translation beta) and
  position limits, in the robot's joint order (:meth:`JointLimits.of_robot`);
- :class:`DriveLimits`: the drive's control rate and its velocity, acceleration and jerk limits
  per joint.

SI units throughout: rad and m, per s, s^2, s^3; Hz for the control rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from .choices import JointKind

__all__ = ["JointLimits", "DriveLimits"]


def _vector(values, n: int, name: str) -> np.ndarray:
    v = np.asarray(values, dtype=float).reshape(-1)
    if v.shape != (n,):
        raise ValueError(f"{name} needs shape ({n},), got {v.shape}")
    return v


@dataclass(frozen=True, eq=False)
class JointLimits:
    """The joints' names, kinds and position limits.

    Attributes
    ----------
    names : tuple of str, length n_joints
        E.g. ``("alpha_2", "alpha_3", "beta_3")``.
    kinds : tuple of JointKind, length n_joints
        Base rotation or translation per joint.
    lower, upper : ndarray, shape (n_joints,)
        Position limits [rad or m] (ignored for periodic joints).
    periodic : ndarray of bool, shape (n_joints,)
        Rotations without limits.

    Raises
    ------
    ValueError
        Entries of unequal length, or a kind that is neither rotation nor translation (naming the
        joint).
    """

    names: tuple[str, ...]
    kinds: tuple[JointKind, ...]
    lower: np.ndarray
    upper: np.ndarray
    periodic: np.ndarray

    def __post_init__(self):
        n = len(self.names)
        kinds = tuple(self.kinds)
        if len(kinds) != n:
            raise ValueError(f"joint kinds need {n} entries (one per joint name), got {len(kinds)}")
        for name, kind in zip(self.names, kinds):
            if kind not in tuple(JointKind):
                raise ValueError(f"joint {name}: kind must be 'rotation' or 'translation', got {kind!r}")
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "kinds", tuple(JointKind(k) for k in kinds))
        object.__setattr__(self, "lower", _vector(self.lower, n, "lower"))
        object.__setattr__(self, "upper", _vector(self.upper, n, "upper"))
        periodic = np.asarray(self.periodic, dtype=bool).reshape(-1)
        if periodic.shape != (n,):
            raise ValueError(f"periodic needs shape ({n},), got {periodic.shape}")
        object.__setattr__(self, "periodic", periodic)

    @classmethod
    def of_robot(cls, robot) -> "JointLimits":
        """The joints of ``robot`` (:class:`ctrplan.robot.Robot`), in its joint order: names,
        kinds, ``robot.joint_lower`` / ``joint_upper`` [rad or m], shape (n_joints,) each, and
        which rotations are periodic."""
        return cls(names=tuple(j.name for j in robot.joints), kinds=tuple(j.kind for j in robot.joints),
                   lower=robot.joint_lower, upper=robot.joint_upper,
                   periodic=[j.periodic for j in robot.joints])

    @classmethod
    def unnamed(cls, kinds: Sequence[str], lower=None, upper=None, periodic=None) -> "JointLimits":
        """Joints named ``"joint 0"``, ``"joint 1"``, ... of the given ``kinds`` (length
        n_joints); ``lower``/``upper`` shape (n_joints,) [rad or m], default no position limits
        (-inf, inf); ``periodic`` shape (n_joints,) bool, default none periodic.

        Raises
        ------
        ValueError
            As the class: a kind that is neither rotation nor translation, or arrays of
            another length.
        """
        n = len(kinds)
        return cls(names=tuple(f"joint {i}" for i in range(n)), kinds=tuple(kinds),
                   lower=np.full(n, -np.inf) if lower is None else lower,
                   upper=np.full(n, np.inf) if upper is None else upper,
                   periodic=np.zeros(n, bool) if periodic is None else periodic)

    @property
    def n_joints(self) -> int:
        """Number of joints."""
        return len(self.names)


@dataclass(frozen=True, eq=False)
class DriveLimits:
    """Limits of the joint drives for time parameterization (ruckig).

    Attributes
    ----------
    control_rate_hz : float
        Control rate [Hz].
    max_velocity, max_acceleration, max_jerk : ndarray, shape (n_joints,)
        In joint order; rad/s^k for rotations, m/s^k for translations (k = 1, 2, 3).
    joint_names : tuple of str
        Joint names, the order of the arrays (empty: the order of the joints they are used
        with).
    """

    control_rate_hz: float
    max_velocity: np.ndarray
    max_acceleration: np.ndarray
    max_jerk: np.ndarray
    joint_names: tuple[str, ...] = ()

    @classmethod
    def by_joint(cls, names: Sequence[str], *, max_velocity: Mapping[str, float],
                 max_acceleration: Mapping[str, float], max_jerk: Mapping[str, float],
                 control_rate_hz: float) -> "DriveLimits":
        """Limits given as ``{joint name: value}`` tables (as in a scenario file's ``[drive]``),
        arranged in the order of ``names``.

        Parameters
        ----------
        names : sequence of str, length n_joints
            The joints, in the order of the arrays.
        max_velocity, max_acceleration, max_jerk : mapping of str to float, keyword-only
            [rad/s or m/s, per s^2, per s^3] by joint name.
        control_rate_hz : float, keyword-only
            [Hz].

        Returns
        -------
        DriveLimits
            Arrays shape (n_joints,), ``joint_names == tuple(names)``.

        Raises
        ------
        ValueError
            A joint of ``names`` without a value in one of the tables (naming the table and the
            joints).
        """
        names = tuple(names)
        limits = []
        for label, table in (("max_velocity", max_velocity), ("max_acceleration", max_acceleration),
                             ("max_jerk", max_jerk)):
            missing = [nm for nm in names if nm not in table]
            if missing:
                raise ValueError(f"{label} has no value for joint(s) {', '.join(missing)}")
            limits.append(np.array([float(table[nm]) for nm in names]))
        return cls(float(control_rate_hz), *limits, joint_names=names)

    def in_order(self, names: Sequence[str]) -> "DriveLimits":
        """These limits arranged in the order of ``names`` (as they are when the limits carry no
        names, or the same names in the same order).

        Parameters
        ----------
        names : sequence of str, length n_joints

        Returns
        -------
        DriveLimits
            Arrays shape (n_joints,) in the order of ``names``.

        Raises
        ------
        ValueError
            Named limits that lack a joint of ``names`` (naming it).
        """
        names = tuple(names)
        if not self.joint_names or tuple(self.joint_names) == names:
            return self
        missing = [nm for nm in names if nm not in self.joint_names]
        if missing:
            raise ValueError(f"the drive limits have no value for joint(s) {', '.join(missing)} "
                             f"(they name {', '.join(self.joint_names)})")
        index = [self.joint_names.index(nm) for nm in names]
        return DriveLimits(self.control_rate_hz, np.asarray(self.max_velocity, float)[index],
                           np.asarray(self.max_acceleration, float)[index], np.asarray(self.max_jerk, float)[index],
                           names)

    def scaled(self, speed: float) -> "DriveLimits":
        """The limits of a motion at ``speed`` times the drive's pace: velocity times ``speed``,
        acceleration times ``speed**2``, jerk times ``speed**3`` (a time scaling of the same
        profile).

        Parameters
        ----------
        speed : float
            Time-scaling factor [-], > 0 (e.g. 0.25 for a slow motion).

        Returns
        -------
        DriveLimits
            Same control rate and joint names.
        """
        return DriveLimits(self.control_rate_hz, np.asarray(self.max_velocity, float) * speed,
                           np.asarray(self.max_acceleration, float) * speed ** 2,
                           np.asarray(self.max_jerk, float) * speed ** 3, self.joint_names)
