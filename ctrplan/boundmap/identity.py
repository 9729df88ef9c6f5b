"""What a bound map was computed for, and its key.

A map is valid only for the robot file, the model settings, the grid spec, the evaluator and the
mechanics version it was computed with. :func:`field_key` hashes all five; a store records them
one by one (:class:`MapIdentity`), so that resuming into, or loading, a map made for anything
else names the attribute that differs instead of silently using the wrong map. The mechanics
version (:data:`ctrplan.constants.MECHANICS_VERSION`) makes a map computed by older mechanics
stale: its key no longer matches.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass

import numpy as np

from ..cache import content_key, mechanics_version as current_mechanics_version
from ..errors import CtrplanError
from .axes import MapSpec
from ..coordinates import map_coordinates

__all__ = ["FORMAT_VERSION", "BoundFieldKeyError", "BoundMapMismatchError", "MapIdentity", "map_identity",
           "field_key", "evaluator_name", "as_spec", "settings_dict", "canonical_robot"]

# Version of the key's payload layout (bumped when the payload changes).
FORMAT_VERSION = 2


class BoundFieldKeyError(CtrplanError, ValueError):
    """A map belongs to another robot, model setting, grid, evaluator or mechanics version."""


class BoundMapMismatchError(BoundFieldKeyError):
    """A store holds a map of another robot file, settings, grid, evaluator or mechanics version.

    Attributes
    ----------
    store : str
        Path of the store (or map file).
    key : str
        Attribute that differs (``robot_sha256``, ``spec``, ``settings.ds``,
        ``mechanics_version``, ...).
    stored, requested
        The map's value and this run's value.
    """

    def __init__(self, store, key, stored, requested):
        self.store, self.key, self.stored, self.requested = str(store), str(key), stored, requested
        super().__init__(
            f"{self.store}: key '{self.key}' is {stored!r} in the map but {requested!r} for this run; "
            "the map was computed for another robot file, model settings, grid, evaluator or mechanics version "
            "and maps are never mixed: use another output path, delete the store, or recompute the map")


def evaluator_name(evaluator) -> str:
    """Stable name of an evaluator: its ``name`` attribute, else ``module.qualname``."""
    name = getattr(evaluator, "name", None)
    if isinstance(name, str):
        return name
    mod = getattr(evaluator, "__module__", "") or ""
    qual = getattr(evaluator, "__qualname__", None) or type(evaluator).__qualname__
    return f"{mod}.{qual}"


def canonical_robot(robot) -> str:
    """Canonical JSON of a robot built in code (its dataclass fields, metadata excluded)."""
    d = dataclasses.asdict(robot)
    d.pop("metadata", None)
    return json.dumps(d, sort_keys=True, default=repr)


def settings_dict(settings) -> dict:
    """Model settings as a dict (None: the default :class:`~ctrplan.mechanics.ModelSettings`)."""
    if settings is None:
        from ..mechanics.results import ModelSettings
        settings = ModelSettings()
    return settings.as_dict() if hasattr(settings, "as_dict") else dict(settings)


def as_spec(robot, spec) -> MapSpec:
    """A :class:`MapSpec` checked against the robot's map coordinates.

    Parameters
    ----------
    robot : Robot
    spec : MapSpec, int or sequence of int
        A spec, or nodes per map coordinate (uniform placement).

    Raises
    ------
    ValueError
        Wrong number of values (the message names the map coordinates) or values below 2.
    """
    if not isinstance(spec, MapSpec):
        spec = MapSpec(tuple(np.atleast_1d(np.asarray(spec, dtype=int)).tolist()))
    return spec.for_coordinates(map_coordinates(robot))


def _json_roundtrip(x):
    return json.loads(json.dumps(x, sort_keys=True, default=repr))


def _version(mechanics_version):
    """The given mechanics version, or the running code's (read at call time)."""
    return current_mechanics_version() if mechanics_version is None else str(mechanics_version)


def field_key(robot, settings, spec, evaluator, robot_file_text: str | None = None, *,
              mechanics_version: str | None = None) -> str:
    """Key of a bound map: sha256 over robot, settings, grid spec, evaluator and mechanics version.

    Parameters
    ----------
    robot : Robot
        Hashed through :func:`canonical_robot` unless ``robot_file_text`` is given.
    settings : ModelSettings, dict or None
    spec : MapSpec, int or sequence of int
        Grid spec, or nodes per map coordinate (uniform).
    evaluator : callable or str
    robot_file_text : str, optional
        Content of the robot file, hashed instead of the canonical description.
    mechanics_version : str, optional, keyword-only
        Default: the running code's :data:`~ctrplan.constants.MECHANICS_VERSION`.

    Returns
    -------
    str
        64 hex digits.
    """
    coords = map_coordinates(robot)
    payload = {
        "format": FORMAT_VERSION,
        "robot": robot_file_text if robot_file_text is not None else canonical_robot(robot),
        "settings": settings_dict(settings),
        "spec": as_spec(robot, spec).as_dict(),
        "coordinates": list(coords.names),
        "evaluator": evaluator if isinstance(evaluator, str) else evaluator_name(evaluator),
        "mechanics_version": _version(mechanics_version),
    }
    return content_key(payload)


@dataclass(frozen=True)
class MapIdentity:
    """What a bound map was computed for; stored with the map and compared before use.

    Attributes
    ----------
    key : str
        :func:`field_key` (64 hex digits), the hash of all the fields below.
    robot_sha256 : str
        sha256 of the robot file's text, or of :func:`canonical_robot` when
        ``robot_hash_of == "robot description"``.
    robot_hash_of : str
        ``"robot file"`` or ``"robot description"``.
    spec : dict
        :meth:`MapSpec.as_dict`.
    settings : dict
        Model settings.
    evaluator : str
    mechanics_version : str
    joint_names : tuple of str
    coordinate_names : tuple of str
    robot_name : str
        Informative only (not compared).
    """

    key: str
    robot_sha256: str
    robot_hash_of: str
    spec: dict
    settings: dict
    evaluator: str
    mechanics_version: str
    joint_names: tuple
    coordinate_names: tuple
    robot_name: str = ""

    # attributes compared when a map is resumed or loaded, in this order (settings are compared one
    # by one after them): a map of other mechanics is named as such first
    COMPARED = ("mechanics_version", "spec", "robot_sha256", "robot_hash_of", "evaluator", "joint_names",
                "coordinate_names")

    def as_attrs(self) -> dict:
        """JSON attributes of a store."""
        return _json_roundtrip({
            "key": self.key, "robot_sha256": self.robot_sha256, "robot_hash_of": self.robot_hash_of,
            "spec": self.spec, "settings": self.settings, "evaluator": self.evaluator,
            "mechanics_version": self.mechanics_version, "joint_names": list(self.joint_names),
            "coordinate_names": list(self.coordinate_names), "robot": self.robot_name,
        })

    def check(self, stored: dict, where: str) -> None:
        """Raise if the attributes ``stored`` of a map at ``where`` were made for another map.

        Raises
        ------
        BoundMapMismatchError
            Naming the first attribute that differs and both values.
        """
        want = self.as_attrs()
        for name in self.COMPARED:
            if stored.get(name) != want[name]:
                raise BoundMapMismatchError(where, name, stored.get(name), want[name])
        s_stored, s_want = stored.get("settings", {}) or {}, want["settings"]
        for name in sorted(set(s_stored) | set(s_want)):
            if s_stored.get(name) != s_want.get(name):
                raise BoundMapMismatchError(where, f"settings.{name}", s_stored.get(name), s_want.get(name))
        if stored.get("key") != want["key"]:
            raise BoundMapMismatchError(where, "key", stored.get("key"), want["key"])


def map_identity(robot, settings, spec, evaluator, robot_file_text: str | None = None, *,
                 mechanics_version: str | None = None) -> MapIdentity:
    """Identity of the bound map of ``robot`` (see :class:`MapIdentity`).

    Parameters
    ----------
    robot : Robot
    settings : ModelSettings, dict or None
    spec : MapSpec, int or sequence of int
    evaluator : callable or str
    robot_file_text : str, optional
    mechanics_version : str, optional, keyword-only
        Default: the running code's :data:`~ctrplan.constants.MECHANICS_VERSION`.

    Returns
    -------
    MapIdentity

    Raises
    ------
    ValueError
        A spec that does not fit the robot's map coordinates.
    """
    spec = as_spec(robot, spec)
    if robot_file_text is not None:
        digest, of = hashlib.sha256(robot_file_text.encode()).hexdigest(), "robot file"
    else:
        digest, of = hashlib.sha256(canonical_robot(robot).encode()).hexdigest(), "robot description"
    return MapIdentity(
        key=field_key(robot, settings, spec, evaluator, robot_file_text, mechanics_version=mechanics_version),
        robot_sha256=digest, robot_hash_of=of, spec=_json_roundtrip(spec.as_dict()),
        settings=_json_roundtrip(settings_dict(settings)),
        evaluator=evaluator if isinstance(evaluator, str) else evaluator_name(evaluator),
        mechanics_version=_version(mechanics_version), joint_names=tuple(robot.joint_names),
        coordinate_names=tuple(map_coordinates(robot).names), robot_name=robot.name)
