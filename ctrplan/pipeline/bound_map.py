"""Stage 2 of a plan: the bound map the planner reads (:class:`BoundMapStage`), looked up or
computed for the scenario's robot file (:func:`load_bound_map`), or handed in (:func:`given_bound_map`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from .._log import deprecated_echo, progress_level
from ..boundmap import BoundField, load_or_compute_bound_map
from ..coordinates import map_coordinates
from .setup import PlanSetup

__all__ = ["BoundMapStage", "load_bound_map", "given_bound_map", "GIVEN"]

#: ``BoundMapStage.source`` of a map handed to the plan (:func:`given_bound_map`).
GIVEN = "given"

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
    """

    field: BoundField
    source: str
    time_s: float


@deprecated_echo
def load_bound_map(setup: PlanSetup, n_jobs: int = 1, echo=None, *, progress: bool = False) -> BoundMapStage:
    """Stage 2: the robot's bound map for the scenario's spec and model settings.

    A shipped or cached map with the same key is read; otherwise the map is computed into a
    zarr store, and a computation interrupted earlier resumes from its finished chunks
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
    field, source, seconds = load_or_compute_bound_map(setup.scenario.robot_file, setup.robot, setup.spec,
                                                       setup.settings, n_jobs=n_jobs, progress=progress)
    logger.log(progress_level(), f"bound map: {source} in {seconds:.1f} s")
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
