"""The registry of planners: names, how each is made, and the parameters each declares.

A name here is what a scenario file's ``[planner] name`` and :func:`ctrplan.planning.plan_leg`
accept; a scenario naming another one is refused when it loads, naming the file and the key. A
planner declares its parameters (:class:`PlannerParameter`: type, default, range, how it is set),
as OMPL planners do with ``declareParam``: a scenario key or a :func:`~ctrplan.planning.plan_leg`
option that the named planner does not declare is an error, never silently ignored.

Users add a planner with :func:`register_planner` (or ``with PLANNER_REGISTRY.registered(...)``),
giving a ``make(space_information)`` that returns an ``ompl.base.Planner``; the built-in ones are
classes of ``ompl.geometric`` named by ``ompl_class`` (bound in :mod:`ctrplan.planning.planners`).

This module imports nothing heavy (no OMPL), so that file validation and the command line can
check a name and its parameters without loading the planners.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Mapping

from .registry import Registry

__all__ = ["PlannerParameter", "PlannerInfo", "PLANNER_REGISTRY", "PLANNER_INFO", "PLANNER_NAMES",
           "register_planner", "check_planner", "check_planner_options", "planner_table"]


@dataclass(frozen=True)
class PlannerParameter:
    """One parameter a planner declares.

    Attributes
    ----------
    name : str
        Its key in a scenario's ``[planner]`` table and in ``plan_leg(..., options={name: value})``.
    kind : type
        ``float``, ``int`` or ``bool``; an int is accepted for a float.
    description : str
        One line, with the unit.
    setter : str or callable
        How the value reaches the planner object: the name of its method (OMPL's setter, e.g.
        ``"setRange"``) or ``setter(planner, value)``.
    low, high : float or None
        Inclusive limits (None: unbounded).
    default : value or None
        The value used when none is given; None leaves the planner's own default.
    """

    name: str
    kind: type
    description: str
    setter: str | Callable[[Any, Any], None]
    low: float | None = None
    high: float | None = None
    default: Any = None

    def check(self, value):
        """``value`` converted to :attr:`kind` if it is of that type and inside the limits.

        Raises
        ------
        ValueError
            Wrong type, not finite, or outside ``[low, high]``; the message names the parameter.
        """
        ok_type = (isinstance(value, bool) if self.kind is bool
                   else isinstance(value, int) and not isinstance(value, bool) if self.kind is int
                   else isinstance(value, (int, float)) and not isinstance(value, bool))
        if not ok_type:
            raise ValueError(f"{self.name} must be a {self.kind.__name__}, got {value!r}")
        value = self.kind(value)
        if self.kind is not bool:
            if not math.isfinite(value):
                raise ValueError(f"{self.name} must be finite, got {value!r}")
            if (self.low is not None and value < self.low) or (self.high is not None and value > self.high):
                raise ValueError(f"{self.name} must be in [{_limit(self.low, '-inf')}, {_limit(self.high, 'inf')}], "
                                 f"got {value!r}")
        return value

    def apply(self, planner, value) -> None:
        """Set ``value`` on an OMPL planner object through :attr:`setter`.

        Raises
        ------
        TypeError
            The planner object has no such setter method (a declaration that does not match its
            class).
        """
        if callable(self.setter):
            self.setter(planner, value)
            return
        method = getattr(planner, self.setter, None)
        if method is None:
            raise TypeError(f"planner {type(planner).__name__} has no method {self.setter} that its declared "
                            f"parameter {self.name!r} needs")
        method(value)


@dataclass(frozen=True)
class PlannerInfo:
    """One planner of the registry.

    Attributes
    ----------
    name : str
        Its name in scenario files and results.
    description : str
        One line: how it searches.
    ompl_class : str or None
        The class of ``ompl.geometric`` that implements it (the built-in planners).
    make : callable or None
        ``make(space_information) -> ompl.base.Planner`` for a planner that is not one class of
        ``ompl.geometric`` called with the space information (exactly one of ``ompl_class`` and
        ``make`` is given).
    parameters : mapping of str to PlannerParameter
        The parameters it declares, by name.
    """

    name: str
    description: str
    ompl_class: str | None = None
    make: Callable | None = None
    parameters: Mapping[str, PlannerParameter] = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "parameters", MappingProxyType(dict(self.parameters)))

    def __reduce__(self):   # a mappingproxy does not pickle; worker processes get the entry
        return (type(self), (self.name, self.description, self.ompl_class, self.make, dict(self.parameters)))


def _check_entry(name: str, info) -> None:
    """A registry entry: a :class:`PlannerInfo` of the same name, made one way, with parameters
    keyed by their own names."""
    if not isinstance(info, PlannerInfo) or info.name != name:
        raise TypeError(f"a planner entry must be a PlannerInfo named {name!r}, got {info!r}")
    if (info.ompl_class is None) == (info.make is None):
        raise ValueError(f"planner {name!r}: give exactly one of ompl_class (a class of ompl.geometric) and "
                         f"make(space_information)")
    for key, p in info.parameters.items():
        if not isinstance(p, PlannerParameter) or p.name != key:
            raise TypeError(f"planner {name!r}: parameter {key!r} must be a PlannerParameter named {key!r}")
        if p.kind not in (float, int, bool):
            raise TypeError(f"planner {name!r}: parameter {key!r} has kind {p.kind!r}; float, int or bool")
        if p.default is not None:
            p.check(p.default)


def _rrt_parameters() -> dict:
    """The parameters of OMPL's RRT* family that ctrplan sets."""
    return {
        "range": PlannerParameter("range", float, "maximum length of a motion added to the tree [m of the "
                                  "weighted joint metric]", "setRange", low=0.0),
        "goal_bias": PlannerParameter("goal_bias", float, "probability of sampling the goal", "setGoalBias",
                                      low=0.0, high=1.0),
        "rewire_factor": PlannerParameter("rewire_factor", float, "factor on the k-nearest neighbour count "
                                          "through which a new state is connected and rewired", "setRewireFactor",
                                          low=0.0),
    }


#: The planners by name, in the order the package lists them. All the built-in ones are
#: asymptotically optimal for the bound-aware cost; PRM and PRM* are left out (they deadlock with
#: Python callbacks, docs/planning.md).
PLANNER_REGISTRY: Registry[PlannerInfo] = Registry("planner", check=_check_entry)
for _info in (
        PlannerInfo("RRTstar", "RRT* (Karaman & Frazzoli 2011): rewires a tree toward lower cost", "RRTstar",
                    parameters=_rrt_parameters()),
        PlannerInfo("InformedRRTstar", "RRT* sampling only where a better path can exist once one is found",
                    "InformedRRTstar", parameters=_rrt_parameters()),
        PlannerInfo("SORRTstar", "informed RRT* that samples in order of heuristic cost", "SORRTstar",
                    parameters=_rrt_parameters()),
        PlannerInfo("BITstar", "batch informed trees: a graph search over batches of samples", "BITstar",
                    parameters={"rewire_factor": PlannerParameter(
                        "rewire_factor", float, "factor on the k-nearest neighbour count of each batch's graph",
                        "setRewireFactor", low=0.0)})):
    PLANNER_REGISTRY.register(_info.name, _info)
del _info

#: A live read-only view of :data:`PLANNER_REGISTRY`: ``{name: PlannerInfo}``.
PLANNER_INFO = PLANNER_REGISTRY.view

#: Names of the built-in planners, in registry order (:meth:`PLANNER_REGISTRY.names()
#: <ctrplan.registry.Registry.names>` includes the ones users register).
PLANNER_NAMES: tuple[str, ...] = PLANNER_REGISTRY.names()


def register_planner(info: PlannerInfo, *, replace: bool = False) -> PlannerInfo:
    """Add a planner to :data:`PLANNER_REGISTRY` under ``info.name``.

    After this, scenario files accept ``[planner] name = "<name>"`` with the parameters it
    declares as keys of ``[planner]``, and :func:`ctrplan.planning.plan_leg` (and so
    :func:`ctrplan.plan`) plans with it.

    Parameters
    ----------
    info : PlannerInfo
        With ``make`` (or ``ompl_class``) and its declared parameters.
    replace : bool, keyword-only
        Replace a planner registered under the same name.

    Returns
    -------
    PlannerInfo
        ``info``.

    Raises
    ------
    TypeError, ValueError
        A malformed entry, or a name taken and ``replace`` false.
    """
    return PLANNER_REGISTRY.register(getattr(info, "name", None), info, replace=replace)


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
    ctrplan.registry.UnknownNameError
        ``name`` is not registered (a :class:`ValueError`; the message lists the planners).
    """
    return PLANNER_REGISTRY.check(name)


def check_planner_options(name: str, options: Mapping[str, Any]) -> dict:
    """The options of planner ``name`` checked against its declared parameters, with the
    declared defaults of the parameters not given.

    Parameters
    ----------
    name : str
        A registered planner.
    options : mapping of str to value
        Parameter values; a value None counts as not given.

    Returns
    -------
    dict
        ``{parameter name: value}`` of every parameter given or with a declared default, each
        converted to its kind.

    Raises
    ------
    ctrplan.registry.UnknownNameError
        ``name`` is not registered.
    ValueError
        An option the planner does not declare (the message lists the ones it does), or a value
        of the wrong type or outside its limits.
    """
    info = PLANNER_REGISTRY.get(name)
    out = {k: p.default for k, p in info.parameters.items() if p.default is not None}
    for key, value in options.items():
        if value is None:
            continue
        p = info.parameters.get(key)
        if p is None:
            declared = ", ".join(info.parameters) or "none"
            raise ValueError(f"planner {name} does not declare a parameter {key!r} (its parameters: {declared})")
        out[key] = p.check(value)
    return out


def planner_table() -> str:
    """The registered planners and their declared parameters as a Markdown table (the one in
    ``docs/planning.md``, which a test keeps equal to this).

    Returns
    -------
    str
        One row per planner: name, how it searches, and each parameter as
        ``name (kind, [low, high]): description``.
    """
    rows = ["| planner | how it searches | parameters (keys of `[planner]`, `plan_leg(..., options=...)`) |",
            "|---|---|---|"]
    for name, info in PLANNER_REGISTRY.items():
        params = "; ".join(f"`{p.name}` ({p.kind.__name__}, [{_limit(p.low, '-inf')}, {_limit(p.high, 'inf')}]"
                           + (f", default {p.default!r}" if p.default is not None else "") + f"): {p.description}"
                           for p in info.parameters.values()) or "none"
        rows.append(f"| `{name}` | {info.description} | {params} |")
    return "\n".join(rows) + "\n"


def _limit(x, none: str) -> str:
    return none if x is None else f"{x:g}"

