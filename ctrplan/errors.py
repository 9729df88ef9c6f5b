"""Exceptions raised by ctrplan.

Every error that comes from user input names where the input came from (file, key, value) so
that a user can fix it without reading the code.
"""

from __future__ import annotations

__all__ = [
    "CtrplanError",
    "ModelFileError",
    "PhysicalParameterError",
    "JointLimitError",
    "ConvergenceError",
    "ElasticInstabilityError",
    "UnreachableGoalError",
    "DataFileError",
]


class CtrplanError(Exception):
    """Base class of every error raised on purpose by ctrplan."""


class ModelFileError(CtrplanError, ValueError):
    """A robot, scenario or data file is malformed: unknown or missing key, wrong type or value.

    Parameters
    ----------
    file : str
        Path of the offending file (or ``"<memory>"``).
    key : str
        Dotted key inside the file, e.g. ``"tubes[2].sections[1].length"``.
    message : str
        What is wrong, with the offending value.
    """

    def __init__(self, file: str, key: str, message: str):
        self.file = str(file)
        self.key = str(key)
        self.detail = message
        super().__init__(f"{self.file}: key '{self.key}': {message}")


class PhysicalParameterError(CtrplanError, ValueError):
    """Physically impossible tube set (negative length, non-positive clearance, ...)."""


class JointLimitError(CtrplanError, ValueError):
    """A joint value lies outside its limits or the configuration is kinematically impossible."""


class ConvergenceError(CtrplanError, RuntimeError):
    """A solver did not converge (shooting, contact complementarity, outer re-linearization)."""


class ElasticInstabilityError(CtrplanError, RuntimeError):
    """The configuration has more than one elastic equilibrium (snapping possible)."""


class UnreachableGoalError(CtrplanError, RuntimeError):
    """A planning goal cannot be reached (no inverse-kinematics solution or no valid path)."""


class DataFileError(CtrplanError, ValueError):
    """A measured-data or configuration CSV is malformed (missing column, NaN, wrong units)."""
