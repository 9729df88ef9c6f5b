"""Stage 1 of a plan: what a run plans with (:class:`PlanSetup`), from a loaded scenario
(:func:`setup_plan`) or a scenario file (:func:`load_setup`)."""

from __future__ import annotations

import functools

import logging
import os
from dataclasses import dataclass
from pathlib import Path

from .._log import deprecated_echo, progress_level
from ..boundmap import MapSpec, default_spec
from ..calibration import RobotCalibration
from ..io.scenario import Scenario, load_scenario
from ..mechanics import ModelSettings
from ..robot import Robot

__all__ = ["map_spec", "default_out_dir", "PlanSetup", "setup_plan", "load_setup"]

logger = logging.getLogger(__package__)


def map_spec(scenario) -> MapSpec:
    """The bound-map spec of a scenario.

    Parameters
    ----------
    scenario : Scenario
        Loaded scenario (``ctrplan.io.scenario.load_scenario``).

    Returns
    -------
    MapSpec
        Its ``[bound_field]`` resolution (one entry per map coordinate, checked when the scenario
        was loaded) and placement, else :func:`ctrplan.boundmap.default_spec` of its robot with
        that placement.
    """
    bf = scenario.bound_field
    if bf.resolution is None:
        return MapSpec(default_spec(scenario.robot).resolution, bf.placement)
    return MapSpec(tuple(bf.resolution), bf.placement)


def default_out_dir(scenario: Scenario) -> Path:
    """Where ``ctrplan plan`` writes a scenario's outputs by default.

    Parameters
    ----------
    scenario : Scenario

    Returns
    -------
    pathlib.Path
        The scenario's ``[output] dir``, else ``out/<scenario name>`` (relative to the working
        folder).
    """
    return scenario.output_dir or Path("out") / scenario.name


@dataclass(frozen=True, eq=False)
class PlanSetup:
    """Stage 1: what a run plans with.

    Attributes
    ----------
    scenario : Scenario
        The loaded scenario (joint values [rad or m], tip positions and tolerances [m]).
    settings : ModelSettings
        Model settings of the exact model: arc-length step ``ds`` [m] from ``[bound_field] ds_m``,
        else the default.
    check_settings : ModelSettings
        The same without the multistart search (the bound map flags multi-equilibrium regions):
        the settings of every validity check and of the inverse kinematics.
    spec : MapSpec
        The bound map's resolution and placement (:func:`map_spec`).
    obstacles : tuple of Obstacle
        The scenario's obstacles (:mod:`ctrplan.obstacles`) [m, rad].
    out_dir : pathlib.Path or None
        Output folder of the report; None when no file is to be written.
    """

    scenario: Scenario
    settings: ModelSettings
    check_settings: ModelSettings
    spec: MapSpec
    obstacles: tuple
    out_dir: Path | None = None

    @property
    def robot(self) -> Robot:
        """The scenario's :class:`~ctrplan.robot.Robot`."""
        return self.scenario.robot

    @functools.cached_property
    def joint_space(self):
        """The robot's :class:`~ctrplan.planning.JointStateSpace`, built once per plan and process
        (its OMPL objects do not pickle: a copy of the setup in another process builds its own, as
        it does its :meth:`route_checks`)."""
        from .space import JointStateSpace

        return JointStateSpace(self.robot)

    def route_checks(self, field):
        """The search, repair and final checkers of this plan with ``field``'s validity flags
        (:func:`ctrplan.planning.route_checks` of the robot, the obstacles and
        ``check_settings``, on :attr:`joint_space`), built once per map and process and shared by
        every stage that checks states: the start, the goals, the roadmap and both plans; the
        checkers of another map (a refined one) share the collision tests
        (:meth:`~ctrplan.planning.RouteChecks.for_field`). Their counters add up over the stages;
        a stage reports its own share as a difference (:meth:`ctrplan.planning.RouteChecks.counters`).

        Parameters
        ----------
        field : BoundField or None
            The map whose validity flags the checkers read; the checkers of another map are
            built for it.

        Returns
        -------
        ctrplan.planning.RouteChecks
        """
        from .route import route_checks

        built = self.__dict__.setdefault("_route_checks", {})
        hit = built.get(id(field))
        if hit is None or hit[0] is not field:
            other = next(iter(built.values()), None)
            checks = (route_checks(self.robot, list(self.obstacles), field, self.check_settings,
                                   joint_space=self.joint_space) if other is None else other[1].for_field(field))
            hit = built[id(field)] = (field, checks)
        return hit[1]

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("joint_space", None)
        state.pop("_route_checks", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)

    @property
    def calibration(self) -> RobotCalibration:
        """The robot file's records of measurements (``Scenario.calibration``)."""
        return self.scenario.calibration


def setup_plan(scenario: Scenario, out_dir: str | os.PathLike | None = None) -> PlanSetup:
    """Stage 1 from a loaded scenario: the model settings and map spec it asks for.

    Parameters
    ----------
    scenario : Scenario
        As :func:`ctrplan.io.scenario.load_scenario` returns it (SI units).
    out_dir : str or path-like, optional
        Output folder of the report; None (default) for none.

    Returns
    -------
    PlanSetup
    """
    sc = scenario
    settings = ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()
    logger.log(progress_level(), f"scenario {sc.name}: robot {sc.robot.name} ({', '.join(sc.robot.joint_names)})")
    return PlanSetup(scenario=sc, settings=settings, check_settings=settings.replace(multistart=0), spec=map_spec(sc),
                     obstacles=tuple(sc.obstacles), out_dir=None if out_dir is None else Path(out_dir))


@deprecated_echo
def load_setup(scenario_path, out_dir=None, echo=None) -> PlanSetup:
    """Stage 1 from a scenario file: read it and its robot, and derive the model settings and map
    spec (:func:`setup_plan`).

    Parameters
    ----------
    scenario_path : str or path-like
        Scenario TOML file (``docs/file-formats.md``; SI units).
    out_dir : str or path-like, optional
        Output folder; default :func:`default_out_dir`.
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    PlanSetup

    Raises
    ------
    ModelFileError
        Malformed scenario or robot file, or a start or joint goal outside the joint limits.
    """
    sc = load_scenario(scenario_path)
    return setup_plan(sc, out_dir if out_dir else default_out_dir(sc))
