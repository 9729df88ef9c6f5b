"""Scenario files: a robot, a start, goals, obstacles and planner/drive settings (TOML, SI units).

Parsed with pydantic (unknown keys, missing keys and wrong types are errors naming the file and
the dotted key, list indices 1-based), then checked against the robot named in the file (joint
names, joint limits) and turned into frozen dataclasses. Each ``[[obstacles]]`` table is validated
straight into the class its ``type`` names in :data:`ctrplan.obstacles.OBSTACLE_TYPES` (a mesh
file is resolved against the scenario file's folder). The format is documented in
``docs/file-formats.md``.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal, Mapping, Union

import numpy as np
from pydantic import AfterValidator, ConfigDict, Field

from ..choices import AimWith, FinalMotion, FirstPlan, JointKind, MapPlacement
from ..calibration import RobotCalibration
from ..coordinates import map_coordinates
from ..drive import DriveLimits
from ..errors import JointLimitError, ModelFileError
from ..obstacles import OBSTACLE_TYPES, Box, Capsule, Mesh, Sphere  # noqa: F401 (the built-in types, also here)
from ..planner_info import PLANNER_REGISTRY, check_planner, check_planner_options
from ..robot import Robot
from .robot_file import MAX_METRES, _load_robot_file, _Strict, parse_toml, read_text, validate_document

__all__ = [
    "load_scenario",
    "scenario_from_toml_text",
    "Scenario",
    "JointGoal",
    "TaskGoal",
    "PlannerSettings",
    "BoundFieldSettings",
]

Positive = Annotated[float, Field(gt=0.0)]
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


# --------------------------------------------------------------------------- file schema
# A key whose value is one of a string enum's members (ctrplan.choices): the file's string becomes
# the member (the documents are otherwise strict: no coercion of numbers or strings)
_CHOICE = Field(strict=False)


class _QDoc(_Strict):
    q: dict[str, float]


class _JointGoalDoc(_Strict):
    type: Literal["joint"]
    q: dict[str, float]


class _TaskGoalDoc(_Strict):
    type: Literal["task"]
    tip_position_m: Vec3
    tolerance_m: Positive


# Default weight of the bound in the planning cost [1/m]; equal to
# ctrplan.planning.objective.DEFAULT_BOUND_WEIGHT (a test keeps them equal).
DEFAULT_BOUND_WEIGHT = 1000.0


class _PlannerDoc(_Strict):
    # keys beyond these are the named planner's declared parameters, checked against its
    # registry entry once the table is read (scenario_from_toml_text)
    model_config = ConfigDict(extra="allow")
    name: Annotated[str, AfterValidator(check_planner)] = "RRTstar"
    iterations: Annotated[int, Field(ge=1)] = 3000
    time_limit_s: Positive | None = None
    seed: int = 1
    bound_weight: Annotated[float, Field(ge=0.0)] = DEFAULT_BOUND_WEIGHT
    range: Positive | None = None
    rewire_factor: Positive | None = None
    final_motion: Annotated[FinalMotion, _CHOICE] = FinalMotion.TRANSLATION_LAST
    aim_with: Annotated[AimWith, _CHOICE] = AimWith.AUTO
    roadmap: bool | None = None


class _BoundFieldDoc(_Strict):
    resolution: list[Annotated[int, Field(ge=2)]] | None = None
    placement: Annotated[MapPlacement, _CHOICE] = MapPlacement.UNIFORM
    ds_m: Positive | None = None
    first_plan: Annotated[FirstPlan, _CHOICE] = FirstPlan.PREVIEW
    refine_rounds: Annotated[int, Field(ge=0)] | None = None
    refine_tolerance_m: Positive = 0.25e-3


class _DriveDoc(_Strict):
    control_rate_hz: Positive
    max_velocity: dict[str, Positive]
    max_acceleration: dict[str, Positive]
    max_jerk: dict[str, Positive]


class _OutputDoc(_Strict):
    dir: str | None = None


_Goal = Annotated[Union[_JointGoalDoc, _TaskGoalDoc], Field(discriminator="type")]
_GOAL_TAGS = frozenset({"joint", "task"})


@functools.lru_cache(maxsize=16)
def _scenario_document(obstacle_types: tuple) -> type[_Strict]:
    """Schema of a scenario file (see ``docs/file-formats.md``) whose ``[[obstacles]]`` tables
    are validated by ``obstacle_types`` (tagged by their ``type``); one class per tuple.

    Parameters
    ----------
    obstacle_types : tuple of type
        :class:`ctrplan.obstacles.Obstacle` subclasses, e.g.
        ``tuple(ctrplan.obstacles.OBSTACLE_TYPES.values())``.

    Returns
    -------
    type
        A pydantic model of the whole file.
    """
    if len(obstacle_types) > 1:
        obstacle_list = list[Annotated[Union[obstacle_types], Field(discriminator="type")]]
    elif obstacle_types:   # a tagged union needs two members; one type still checks its tag
        obstacle_list = list[obstacle_types[0]]
    else:
        obstacle_list = Annotated[list, Field(max_length=0)]

    class ScenarioDocument(_Strict):
        name: Annotated[str, Field(min_length=1)]
        robot: Annotated[str, Field(min_length=1)]
        start: _QDoc
        goals: Annotated[list[_Goal], Field(min_length=1)]
        obstacles: obstacle_list = []
        planner: _PlannerDoc = _PlannerDoc()
        bound_field: _BoundFieldDoc = _BoundFieldDoc()
        drive: _DriveDoc | None = None
        output: _OutputDoc = _OutputDoc()

    return ScenarioDocument


# --------------------------------------------------------------------------- result types
def _frozen_array(values, dtype=float) -> np.ndarray:
    a = np.array(values, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class JointGoal:
    """Reach a joint configuration: the one joint-goal type of the package (scenario files,
    :func:`ctrplan.planning.resolve_goal`, :class:`ctrplan.Planner`).

    Attributes
    ----------
    q : ndarray, shape (n_joints,)
        Joint values in robot joint order [rad or m] (stored as a read-only float array).

    Raises
    ------
    ValueError
        ``q`` is not a flat vector of finite numbers.
    """

    q: np.ndarray

    def __post_init__(self):
        q = np.array(self.q, dtype=float).reshape(-1)
        if q.size == 0 or not np.all(np.isfinite(q)):
            raise ValueError(f"a joint goal needs finite joint values [rad or m], got {self.q!r}")
        q.setflags(write=False)
        object.__setattr__(self, "q", q)


@dataclass(frozen=True, eq=False)
class TaskGoal:
    """Bring the tip within ``tolerance`` of a position: the one task-space goal type of the
    package (scenario files, :func:`ctrplan.planning.resolve_goal`, :class:`ctrplan.Planner`).

    Attributes
    ----------
    tip_position : ndarray, shape (3,)
        Target tip position in the robot base frame [m] (stored as a read-only float array).
    tolerance : float
        Allowed distance from the target [m] (default 1 mm).

    Raises
    ------
    ValueError
        ``tip_position`` is not 3 finite numbers, or ``tolerance`` is not finite and positive.
    """

    tip_position: np.ndarray
    tolerance: float = 1e-3

    def __post_init__(self):
        p = np.array(self.tip_position, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"tip_position must be 3 finite numbers [m], got {self.tip_position!r}")
        tol = float(self.tolerance)
        if not np.isfinite(tol) or tol <= 0.0:
            raise ValueError(f"tolerance must be a finite distance > 0 [m], got {self.tolerance!r}")
        p.setflags(write=False)
        object.__setattr__(self, "tip_position", p)
        object.__setattr__(self, "tolerance", tol)


@dataclass(frozen=True)
class PlannerSettings:
    """Planner settings.

    Attributes
    ----------
    name : str
        OMPL planner name (default ``"RRTstar"``).
    iterations : int
        Planner iterations (default 3000).
    time_limit : float or None
        Wall-clock limit [s].
    seed : int
        Random seed (default 1).
    bound_weight : float
        Weight w >= 0 of the integral of the friction error bound along the path in the cost
        ``path length + w * integral(bound)`` [1/m] (default 1000 /m, as
        :data:`ctrplan.planning.objective.DEFAULT_BOUND_WEIGHT`).
    range : float or None
        Planner step range in joint space (OMPL ``range``) [m of the weighted joint metric]; None
        for the planner's default.
    rewire_factor : float or None
        RRT* family: OMPL's rewire factor on the k-nearest neighbour count; None for ctrplan's
        default (``ctrplan.planning.route.DEFAULT_REWIRE_FACTOR``).
    final_motion : FinalMotion
        How the motion reaching each goal ends (default ``"translation-last"``): a final
        translation releases the friction-induced twist (clearance model), a final rotation
        leaves the friction solution of its direction (Section V-B of Ha et al. 2019). Task-space
        goals are aimed for the tip predicted after that motion
        (:func:`ctrplan.planning.aiming.compensate_goal`).
    aim_with : AimWith
        The model task-space goals are aimed with (default ``"auto"``): ``"history"`` the
        history-aware prediction (compensated goals), ``"standard"`` the standard model,
        ``"auto"`` the history-aware prediction only where the robot file's
        ``[prediction_validation]`` records that it beat the standard model on measurements in
        mean and max (``ctrplan discrepancy`` writes it), else the standard model.
    roadmap : bool or None
        Plan the legs through the roadmap of :class:`ctrplan.Planner` (built once per robot, map
        and obstacles, stored in the cache; a leg it does not join is planned by ``name``); None
        (the default): when the scenario has two goals or more and its bound map is complete
        (not a preview map, which the plan refines).
    parameters : mapping of str to value
        The named planner's other declared parameters
        (:class:`ctrplan.planner_info.PlannerParameter`) given as keys of ``[planner]``, e.g.
        ``goal_bias`` of the RRT* family; checked against the declaration when the file loads.
    """

    name: str = "RRTstar"
    iterations: int = 3000
    time_limit: float | None = None
    seed: int = 1
    bound_weight: float = DEFAULT_BOUND_WEIGHT
    range: float | None = None
    rewire_factor: float | None = None
    final_motion: FinalMotion = FinalMotion.TRANSLATION_LAST
    aim_with: AimWith = AimWith.AUTO
    roadmap: bool | None = None
    parameters: Mapping = field(default_factory=dict)


@dataclass(frozen=True)
class BoundFieldSettings:
    """The bound map the planner uses (``ctrplan.boundmap``).

    Attributes
    ----------
    resolution : tuple of int or None, shape (d,)
        Grid nodes per map coordinate (base rotations, then translations, of tubes 2..n
        relative to tube 1 that the joints change; ``ctrplan.coordinates.map_coordinates``); None
        for the default.
    placement : MapPlacement
        Node placement along bounded coordinates (``ctrplan.boundmap.MapSpec``).
    ds : float or None
        Arc-length step of the mechanics [m]; None for the default.
    first_plan : FirstPlan
        For a robot whose map is neither shipped nor cached: plan first with a coarse preview map
        refined where the plan goes (``"preview"``; ``ctrplan plan`` then computes the full map),
        or compute the full map first (``"full"``).
    refine_rounds : int or None
        Most re-plans with the map refined where the last plan went (``ctrplan.planning.map_refinement``);
        None: 4 with a preview map, 0 with the full map.
    refine_tolerance : float
        Refinement stops when the map's bound is within this of the exact bound at every
        waypoint [m] (default 0.25 mm: the accuracy budget of the bound itself).
    """

    resolution: tuple[int, ...] | None = None
    placement: MapPlacement = MapPlacement.UNIFORM
    ds: float | None = None
    first_plan: FirstPlan = FirstPlan.PREVIEW
    refine_rounds: int | None = None
    refine_tolerance: float = 0.25e-3


@dataclass(frozen=True, eq=False)
class Scenario:
    """A planning problem read from a scenario file.

    Attributes
    ----------
    name : str
    file : pathlib.Path
        Resolved scenario file ("<memory>" path when read from text).
    robot_file : pathlib.Path
        Resolved robot model file.
    robot : Robot
    start : ndarray, shape (n_joints,)
        Start configuration in robot joint order [rad or m].
    goals : tuple of JointGoal or TaskGoal
        Visited in order.
    obstacles : tuple of Obstacle
        Instances of the registered obstacle types (:mod:`ctrplan.obstacles`), in file order.
    planner : PlannerSettings
    bound_field : BoundFieldSettings
    drive : DriveLimits or None
        None when the file has no ``[drive]`` table (no time parameterization possible).
    output_dir : pathlib.Path or None
        Resolved output directory.
    calibration : RobotCalibration
        What the robot file records about measurements (its ``[bound_calibration]`` and
        ``[prediction_validation]``; :func:`ctrplan.io.robot_file.load_robot_calibration`), which
        planning reads; empty for a robot file without them.
    """

    name: str
    file: Path
    robot_file: Path
    robot: Robot
    start: np.ndarray
    goals: tuple
    obstacles: tuple = ()
    planner: PlannerSettings = field(default_factory=PlannerSettings)
    bound_field: BoundFieldSettings = field(default_factory=BoundFieldSettings)
    drive: DriveLimits | None = None
    output_dir: Path | None = None
    calibration: RobotCalibration = field(default_factory=RobotCalibration)

    @property
    def joint_names(self) -> list[str]:
        """Joint names in robot joint order, e.g. ``["alpha_2", "alpha_3", "beta_3"]``."""
        return self.robot.joint_names

    def joint_array(self, mapping: Mapping[str, float]) -> np.ndarray:
        """Turn a joint-name -> value mapping into an array in robot joint order.

        Parameters
        ----------
        mapping : mapping of str to float
            One value per robot joint [rad or m].

        Returns
        -------
        ndarray, shape (n_joints,)

        Raises
        ------
        KeyError
            Unknown or missing joint name.
        """
        return joint_array(self.robot, mapping)

    def joint_dict(self, q) -> dict[str, float]:
        """Inverse of :meth:`joint_array`: ``{name: value}`` from an array shape (n_joints,)."""
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.size != len(self.joint_names):
            raise ValueError(f"expected {len(self.joint_names)} joint values, got {q.size}")
        return dict(zip(self.joint_names, q.tolist()))


def joint_array(robot: Robot, mapping: Mapping[str, float]) -> np.ndarray:
    """Array shape (n_joints,) in ``robot``'s joint order from ``{joint name: value}``.

    Raises
    ------
    KeyError
        Naming unknown and missing joints.
    """
    names = robot.joint_names
    unknown, missing = _unknown_missing(names, mapping)
    if unknown or missing:
        parts = []
        if unknown:
            parts.append(f"unknown joint(s) {', '.join(unknown)}")
        if missing:
            parts.append(f"missing joint(s) {', '.join(missing)}")
        raise KeyError(f"{'; '.join(parts)}; robot {robot.name!r} has joints {', '.join(names)}")
    return np.array([float(mapping[n]) for n in names])


# --------------------------------------------------------------------------- loading
def load_scenario(path: str | os.PathLike) -> Scenario:
    """Load a scenario file and the robot it names.

    Parameters
    ----------
    path : str or path-like
        TOML scenario file. Relative paths inside it (robot, meshes, output dir) are relative
        to the scenario file's directory.

    Returns
    -------
    Scenario

    Raises
    ------
    ModelFileError
        Malformed scenario (unknown/missing key, wrong type, bad value, an obstacle ``type`` that
        is not registered, unknown or missing joint name, start or goal outside the joint
        limits, missing mesh file). Errors in the robot
        file are raised by :func:`~ctrplan.io.robot_file.load_robot` and name that file.
    PhysicalParameterError
        Physically impossible robot.
    """
    path = Path(path)
    return scenario_from_toml_text(read_text(path), file=str(path), base_dir=path.resolve().parent)


def _planner_parameters(p: _PlannerDoc, file: str) -> dict:
    """The ``[planner]`` keys that are the named planner's parameters, checked against what it
    declares (:func:`ctrplan.planner_info.check_planner_options`); returns the ones beyond
    ``range`` and ``rewire_factor``.

    Raises
    ------
    ModelFileError
        A key the planner does not declare (``range`` on BITstar, a misspelt key), or a value of
        the wrong type or outside the declared limits; naming the file and ``planner.<key>``.
    """
    extra = dict(p.model_extra or {})
    declared = PLANNER_REGISTRY[p.name].parameters
    for key, value in {"range": p.range, "rewire_factor": p.rewire_factor, **extra}.items():
        if value is None:
            continue
        if key not in declared:
            known = ", ".join(declared) or "none"
            if key in _PlannerDoc.model_fields:
                raise ModelFileError(file, f"planner.{key}", f"planner {p.name} does not declare a parameter {key!r} "
                                                              f"(its parameters: {known}); got {value!r}")
            keys = ", ".join(k for k in _PlannerDoc.model_fields)
            raise ModelFileError(file, f"planner.{key}",
                                 f"not a key of [planner] ({keys}) nor a parameter that planner {p.name} declares "
                                 f"({known}); got {value!r}")
        try:
            check_planner_options(p.name, {key: value})
        except ValueError as exc:
            raise ModelFileError(file, f"planner.{key}", str(exc)) from None
    return extra


def scenario_from_toml_text(text: str, file: str = "<memory>",
                            base_dir: str | os.PathLike | None = None) -> Scenario:
    """Build a :class:`Scenario` from TOML text.

    Parameters
    ----------
    text : str
    file : str
        Name used in error messages.
    base_dir : path-like or None
        Directory that relative paths are resolved against (default: current directory).

    Raises
    ------
    ModelFileError, PhysicalParameterError
        As :func:`load_scenario`.
    """
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    types = tuple(OBSTACLE_TYPES.values())
    doc = validate_document(_scenario_document(types), parse_toml(text, file), file,
                            drop_tags=_GOAL_TAGS | frozenset(OBSTACLE_TYPES), context={"base_dir": base})

    robot_file = (base / doc.robot).resolve()
    if not robot_file.is_file():
        raise ModelFileError(file, "robot", f"robot file {doc.robot!r} not found (looked for {robot_file})")
    robot, calibration = _load_robot_file(robot_file)

    start = _joint_values(robot, doc.start.q, file, "start.q")

    goals = []
    for k, g in enumerate(doc.goals, start=1):
        if isinstance(g, _JointGoalDoc):
            goals.append(JointGoal(q=_frozen_array(_joint_values(robot, g.q, file, f"goals[{k}].q"))))
        else:
            _check_metres(g.tip_position_m, file, f"goals[{k}].tip_position_m")
            _check_metres([g.tolerance_m], file, f"goals[{k}].tolerance_m")
            goals.append(TaskGoal(tip_position=_frozen_array(g.tip_position_m), tolerance=g.tolerance_m))

    p = doc.planner
    extra = _planner_parameters(p, file)
    planner = PlannerSettings(name=p.name, iterations=p.iterations, time_limit=p.time_limit_s,
                              seed=p.seed, bound_weight=p.bound_weight, range=p.range,
                              rewire_factor=p.rewire_factor, final_motion=p.final_motion, aim_with=p.aim_with,
                              roadmap=p.roadmap, parameters=extra)

    bf = doc.bound_field
    if bf.resolution is not None:
        names = map_coordinates(robot).names
        if len(bf.resolution) != len(names):
            raise ModelFileError(file, "bound_field.resolution",
                                 f"needs one value per map coordinate ({', '.join(names)}: the base rotations and "
                                 f"translations relative to tube 1 that the joints change), got {bf.resolution!r}")
    bound_field = BoundFieldSettings(resolution=None if bf.resolution is None else tuple(bf.resolution),
                                     placement=bf.placement, ds=bf.ds_m, first_plan=bf.first_plan,
                                     refine_rounds=bf.refine_rounds, refine_tolerance=bf.refine_tolerance_m)

    drive = None
    if doc.drive is not None:
        d = doc.drive
        drive = DriveLimits(
            control_rate_hz=d.control_rate_hz,
            max_velocity=_frozen_array(_named(robot, d.max_velocity, file, "drive.max_velocity")),
            max_acceleration=_frozen_array(_named(robot, d.max_acceleration, file, "drive.max_acceleration")),
            max_jerk=_frozen_array(_named(robot, d.max_jerk, file, "drive.max_jerk")),
            joint_names=tuple(robot.joint_names))

    output_dir = None if doc.output.dir is None else (base / doc.output.dir).resolve()
    scenario_path = Path(file) if file == "<memory>" else Path(file).resolve()
    return Scenario(name=doc.name, file=scenario_path, robot_file=robot_file, robot=robot,
                    start=_frozen_array(start), goals=tuple(goals), obstacles=tuple(doc.obstacles),
                    planner=planner, bound_field=bound_field, drive=drive, output_dir=output_dir,
                    calibration=calibration)


def _unknown_missing(names: list[str], mapping: Mapping[str, float]) -> tuple[list[str], list[str]]:
    """Names in ``mapping`` that are not joints (file order), and joints missing from it."""
    return [n for n in mapping if n not in names], [n for n in names if n not in mapping]


def _named(robot: Robot, mapping: Mapping[str, float], file: str, key: str) -> np.ndarray:
    """Array in joint order from a name->value table; unknown/missing names -> ModelFileError."""
    names = robot.joint_names
    unknown, missing = _unknown_missing(names, mapping)
    if unknown:
        raise ModelFileError(file, f"{key}.{unknown[0]}",
                             f"unknown joint (value {mapping[unknown[0]]!r}); robot {robot.name!r} "
                             f"has joints {', '.join(names)}")
    if missing:
        raise ModelFileError(file, f"{key}.{missing[0]}",
                             f"missing required key: every joint of robot {robot.name!r} needs a "
                             f"value ({', '.join(names)})")
    return np.array([mapping[n] for n in names], dtype=float)


def _joint_values(robot: Robot, mapping: Mapping[str, float], file: str, key: str) -> np.ndarray:
    """Joint array checked against limits and kinematic feasibility."""
    q = _named(robot, mapping, file, key)
    for j, v in zip(robot.joints, q):
        if not j.periodic and not (j.lower <= v <= j.upper):
            unit = "rad" if j.kind == JointKind.ROTATION else "m"
            raise ModelFileError(file, f"{key}.{j.name}",
                                 f"{float(v):.6g} {unit} is outside the joint limits [{float(j.lower):.6g}, "
                                 f"{float(j.upper):.6g}] {unit}")
    try:
        alpha, beta = robot.configuration(q)
        robot.check_configuration(alpha, beta)
    except JointLimitError as exc:
        raise ModelFileError(file, key, f"{exc} (values {dict(mapping)!r})") from None
    return q


def _check_metres(values, file: str, key: str) -> None:
    if max(abs(v) for v in values) > MAX_METRES:
        raise ModelFileError(file, key, f"{values!r} looks like millimetres; positions are in metres")
