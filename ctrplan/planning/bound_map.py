"""Stage 2 of a plan: the bound map the planner reads (:class:`BoundMapStage`), looked up or
computed for the scenario's robot file (:func:`prepare_bound_map`; a coarse preview map for a robot
whose map is not computed yet, and :func:`complete_bound_map` after the plan), or handed in
(:func:`given_bound_map`)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

from ..choices import FirstPlan, MapSource
from .._log import deprecated_echo, progress_level
from ..boundmap import BoundField, find_bound_map, load_or_compute_bound_map, preview_spec
from ..coordinates import map_coordinates
from .setup import PlanSetup

__all__ = ["BoundMapStage", "prepare_bound_map", "complete_bound_map", "given_bound_map", "GIVEN"]

#: ``BoundMapStage.source`` of a map handed to the plan (:func:`given_bound_map`).
GIVEN = MapSource.GIVEN

logger = logging.getLogger(__package__)


@dataclass(frozen=True, eq=False)
class BoundMapStage:
    """Stage 2: the bound map the planner reads.

    Attributes
    ----------
    field : BoundField
        Friction and translation-last bounds over the map coordinates [m, rad].
    source : str
        Where it came from: ``"shipped"``, ``"cache"``, ``"computed"`` or ``"given"``
        (:data:`GIVEN`).
    time_s : float
        Time to load or compute it [s] (0 for a given map).
    preview : bool
        It is the coarse preview map (:func:`ctrplan.boundmap.preview_spec` of the scenario's
        spec): the robot's map for the scenario's spec is not computed yet.
    """

    field: BoundField
    source: str
    time_s: float
    preview: bool = False


@deprecated_echo
def prepare_bound_map(setup: PlanSetup, n_jobs: int = 1, echo=None, *, progress: bool = False) -> BoundMapStage:
    """Stage 2: the robot's bound map for the scenario's spec and model settings.

    A shipped or cached map with the same key is read. Otherwise, with ``[bound_field]
    first_plan = "preview"`` (the default), the preview map (half the nodes per coordinate) is
    read or computed, and the plan refines it where it goes (:mod:`ctrplan.planning.map_refinement`);
    with ``"full"`` the map is computed. Maps are computed into zarr stores, and a computation
    interrupted earlier resumes from its finished chunks
    (:func:`ctrplan.boundmap.load_or_compute_bound_map`).

    Parameters
    ----------
    setup : PlanSetup
    n_jobs : int
        Worker processes for a map that must be computed.
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).
    progress : bool, keyword-only
        tqdm bars while a map is computed (default none; ``ctrplan plan`` shows them).

    Returns
    -------
    BoundMapStage

    Raises
    ------
    BoundMapMismatchError
        A store to resume was made for another robot, spec or mechanics version.
    """
    robot_file = setup.scenario.robot_file
    if setup.scenario.bound_field.first_plan == FirstPlan.PREVIEW:
        t0 = time.perf_counter()
        found = find_bound_map(robot_file, setup.robot, setup.spec, setup.settings)
        if found is None:
            spec = preview_spec(setup.spec, map_coordinates(setup.robot).periodic)
            logger.log(progress_level(), f"no bound map of {robot_file.name} for {list(setup.spec.resolution)} nodes "
                       f"yet: planning with the preview map of {list(spec.resolution)} nodes, refined where the "
                       f"plan goes")
            field, source, _ = load_or_compute_bound_map(robot_file, setup.robot, spec, setup.settings,
                                                         n_jobs=n_jobs, progress=progress)
            seconds = time.perf_counter() - t0
            logger.log(progress_level(), f"preview bound map: {source} in {seconds:.1f} s")
            return BoundMapStage(field=field, source=source, time_s=seconds, preview=True)
        field, source = found
        seconds = time.perf_counter() - t0
    else:
        field, source, seconds = load_or_compute_bound_map(robot_file, setup.robot, setup.spec, setup.settings,
                                                           n_jobs=n_jobs, progress=progress)
    logger.log(progress_level(), f"bound map: {source} in {seconds:.1f} s")
    return BoundMapStage(field=field, source=source, time_s=seconds)


def complete_bound_map(setup: PlanSetup, n_jobs: int = 1, *, progress: bool = False) -> BoundMapStage:
    """The robot's full map for the scenario's spec, computed if it is not shipped or cached (after
    a plan with the preview map; resumable, so an interrupted computation goes on at the next
    call).

    Parameters
    ----------
    setup : PlanSetup
    n_jobs : int
        Worker processes.
    progress : bool, keyword-only
        tqdm bars while it is computed.

    Returns
    -------
    BoundMapStage
        Not a preview.

    Raises
    ------
    BoundMapMismatchError
        A store to resume was made for another robot, spec or mechanics version.
    """
    field, source, seconds = load_or_compute_bound_map(setup.scenario.robot_file, setup.robot, setup.spec,
                                                       setup.settings, n_jobs=n_jobs, progress=progress)
    logger.log(progress_level(), f"full bound map: {source} in {seconds:.1f} s")
    return BoundMapStage(field=field, source=source, time_s=seconds)


def given_bound_map(setup: PlanSetup, field: BoundField) -> BoundMapStage:
    """Stage 2 with a map handed in: checked against the robot's map coordinates, not looked up.

    The map is used as it is: that it was computed for this robot file, these model settings and
    this spec is the caller's word (its ``key`` is reported in the summary).

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
        Bounds over the robot's map coordinates (:func:`ctrplan.coordinates.map_coordinates`)
        [m, rad].

    Returns
    -------
    BoundMapStage
        Source :data:`GIVEN`, time 0 s.

    Raises
    ------
    TypeError
        ``field`` is not a :class:`~ctrplan.boundmap.BoundField`.
    ValueError
        Its coordinates are not the robot's map coordinates (names both).
    """
    if not isinstance(field, BoundField):
        raise TypeError(f"bound_map must be a BoundField, got {type(field).__name__}")
    names = list(map_coordinates(setup.robot).names)
    if field.coordinates is not None and list(field.coordinate_names) != names:
        raise ValueError(f"the bound map's coordinates {field.coordinate_names} are not the map coordinates "
                         f"{names} of robot {setup.robot.name!r}")
    if len(field.axes) != len(names):
        raise ValueError(f"the bound map has {len(field.axes)} coordinates, robot {setup.robot.name!r} has "
                         f"{len(names)} ({', '.join(names)})")
    logger.log(progress_level(), f"bound map: {GIVEN} in 0.0 s")
    return BoundMapStage(field=field, source=GIVEN, time_s=0.0)
