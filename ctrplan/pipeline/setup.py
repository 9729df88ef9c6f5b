"""Stage 1 of the plan: what a run plans with (:class:`PlanSetup`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._log import deprecated_echo, progress_level
from ..boundmap import MapSpec, default_spec
from ..io.scenario import load_scenario
from ..mechanics import ModelSettings

__all__ = ["map_spec", "PlanSetup", "load_setup"]

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
    out_dir : pathlib.Path
        Output folder.
    """

    scenario: Any
    settings: ModelSettings
    check_settings: ModelSettings
    spec: MapSpec
    obstacles: tuple
    out_dir: Path

    @property
    def robot(self):
        """The scenario's :class:`~ctrplan.robot.Robot`."""
        return self.scenario.robot


@deprecated_echo
def load_setup(scenario_path, out_dir=None, echo=None) -> PlanSetup:
    """Stage 1: read a scenario and its robot, and derive the model settings and map spec.

    Parameters
    ----------
    scenario_path : str or path-like
        Scenario TOML file (``docs/file-formats.md``; SI units).
    out_dir : str or path-like, optional
        Output folder; default the scenario's ``[output] dir``, else ``out/<scenario name>``.
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
    settings = ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()
    spec = map_spec(sc)
    out = Path(out_dir) if out_dir else (sc.output_dir or Path("out") / sc.name)
    logger.log(progress_level(), f"scenario {sc.name}: robot {sc.robot.name} ({', '.join(sc.robot.joint_names)})")
    return PlanSetup(scenario=sc, settings=settings, check_settings=settings.replace(multistart=0), spec=spec,
                     obstacles=tuple(sc.obstacles), out_dir=out)
