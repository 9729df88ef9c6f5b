"""Stage 2 of the plan: the bound map the planner reads (:class:`BoundMapStage`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

from .._log import deprecated_echo, progress_level
from ..boundmap import load_or_compute_bound_map
from .setup import PlanSetup

__all__ = ["BoundMapStage", "load_bound_map"]

logger = logging.getLogger(__package__)


@dataclass(frozen=True, eq=False)
class BoundMapStage:
    """Stage 2: the bound map the planner reads.

    Attributes
    ----------
    field : BoundField
        Friction and translation-last bounds over the map coordinates [m, rad].
    source : str
        Where it came from (``"shipped"``, ``"cache"``, ``"computed"``, ...).
    time_s : float
        Time to load or compute it [s].
    """

    field: Any
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
