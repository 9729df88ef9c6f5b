"""The registry of OMPL planners: the one list of planner names the package accepts.

A name here is what a scenario file's ``[planner] name`` and :func:`ctrplan.planning.plan`
accept; a scenario naming another one is refused when it loads. Each entry says in one line
what the planner does. The OMPL classes are bound in :data:`ctrplan.planning.PLANNERS`.

This module imports nothing heavy (no OMPL), so that file validation and the command line can
check a name without loading the planners.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

__all__ = ["PlannerInfo", "PLANNER_INFO", "PLANNER_NAMES", "check_planner"]


@dataclass(frozen=True)
class PlannerInfo:
    """One planner of the registry.

    Attributes
    ----------
    name : str
        Its name in scenario files and results.
    ompl_class : str
        The class of ``ompl.geometric`` that implements it.
    description : str
        One line: how it searches.
    """

    name: str
    ompl_class: str
    description: str


#: The planners, by name, in the order the package lists them (read-only mapping). All are
#: asymptotically optimal for the bound-aware cost; PRM and PRM* are left out (they deadlock with
#: Python callbacks, docs/planning.md).
PLANNER_INFO = MappingProxyType({
    "RRTstar": PlannerInfo("RRTstar", "RRTstar", "RRT* (Karaman & Frazzoli 2011): rewires a tree toward lower cost"),
    "InformedRRTstar": PlannerInfo("InformedRRTstar", "InformedRRTstar",
                                   "RRT* sampling only where a better path can exist once one is found"),
    "SORRTstar": PlannerInfo("SORRTstar", "SORRTstar", "informed RRT* that samples in order of heuristic cost"),
    "BITstar": PlannerInfo("BITstar", "BITstar", "batch informed trees: a graph search over batches of samples"),
})

#: Names of the planners, in registry order.
PLANNER_NAMES: tuple[str, ...] = tuple(PLANNER_INFO)


def check_planner(name: str) -> str:
    """Return ``name`` if it names a registered planner.

    Parameters
    ----------
    name : str
        A planner name (case-sensitive, as OMPL spells it).

    Returns
    -------
    str
        ``name`` unchanged.

    Raises
    ------
    ValueError
        ``name`` is not one of :data:`PLANNER_NAMES`; the message lists them.
    """
    if name not in PLANNER_INFO:
        raise ValueError(f"unknown planner {name!r}; planners: {', '.join(PLANNER_NAMES)}")
    return name
