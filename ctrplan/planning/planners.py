"""Sampling-based planning in the joint space with OMPL (asymptotically optimal planners).

:func:`plan_leg` runs one OMPL planner from :data:`PLANNERS` with a Python optimization objective
(e.g. :class:`~ctrplan.planning.objective.BoundCostObjective`) and a Python validity function,
terminates on an iteration count for reproducibility (``ou.RNG.setSeed`` is called before any
planner or sampler is created), shortcuts the path with the cost-aware
``og.PathSimplifier(si, goal, objective).partialShortcutPath`` and returns numpy waypoints.

Only planners known to work with Python callbacks in OMPL 2.0.1 are registered (project notes
``ompl-ruckig.md``): ``PRM``/``PRMstar`` deadlock with a Python cost or validity checker.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from ompl import base as ob, geometric as og, util as ou

from ..choices import JointKind
from ..errors import CtrplanError, UnreachableGoalError
from ..planner_info import PLANNER_REGISTRY, check_planner_options
from .space import JointStateSpace
from .validity import DEFAULT_VALIDITY_RESOLUTION, use_motion_validator

__all__ = ["PLANNERS", "SearchResult", "SearchSettings", "ValidityChecker", "plan_leg", "DEFAULT_ITERATIONS",
           "DEFAULT_VALIDITY_RESOLUTION"]


class _Allocators(Mapping):
    """``{name: allocator}`` over :data:`ctrplan.planner_info.PLANNER_REGISTRY`, read live: the
    allocator takes an ``ob.SpaceInformation`` and returns the planner (the entry's ``make``, or
    its class of ``ompl.geometric``)."""

    def __getitem__(self, name):
        info = PLANNER_REGISTRY[name]
        return info.make if info.make is not None else getattr(og, info.ompl_class)

    def __iter__(self):
        return iter(PLANNER_REGISTRY)

    def __len__(self):
        return len(PLANNER_REGISTRY)


#: The registered planners' allocators by name (a live read-only mapping over
#: :data:`ctrplan.planner_info.PLANNER_REGISTRY`, which users extend with
#: :func:`ctrplan.planner_info.register_planner`). BITstar segfaulted with a *time-based*
#: termination condition in a probe (OMPL 2.0.1 wheels); :func:`plan_leg` always terminates it on an
#: iteration count, which ran fine.
PLANNERS: Mapping = _Allocators()

# Default planner iterations (RRT* finds a first solution on the paper's 3-joint space within a
# few hundred iterations; more iterations only improve the cost).
DEFAULT_ITERATIONS = 2000

# Rounds of cost-aware partial shortcutting after planning.
DEFAULT_SHORTCUT_ROUNDS = 5


class ValidityChecker:
    """Joint limits, kinematic feasibility, elastic stability and collisions, cached per state.

    A configuration is valid when ``robot.configuration(q)`` and ``robot.check_configuration``
    accept it, the bound field (if given) is valid there, the standard model (if a solver is
    given) converges to a unique, stable equilibrium (``diagnostics.ok``) and its body does not
    touch an obstacle (if a collision checker is given).

    Parameters
    ----------
    robot : Robot
    collision : CollisionChecker, optional
    field : BoundField, optional
        Its :meth:`~ctrplan.planning.BoundField.is_valid` flag rejects configurations near
        unstable or non-converged grid nodes.
    solve_standard : callable, optional
        ``solve_standard(robot, alpha, beta, settings) -> StandardSolution``; required when
        ``collision`` is given or ``check_stability`` is True. Default:
        :func:`ctrplan.mechanics.solve_standard` when needed.
    settings : ModelSettings, optional
    check_stability : bool, keyword-only
        Reject states whose standard solution has ``diagnostics.ok`` False.

    Attributes
    ----------
    n_calls, n_evaluations : int
        Calls and cache misses.
    """

    def __init__(self, robot, collision=None, field=None, solve_standard=None, settings=None, *,
                 check_stability: bool = True):
        self.robot = robot
        self.collision = collision
        self.field = field
        self.settings = settings
        self.check_stability = bool(check_stability)
        need_model = collision is not None or self.check_stability
        if need_model and solve_standard is None:
            from ..mechanics import solve_standard as _solve  # noqa: PLC0415 (optional, heavy)
            solve_standard = _solve
        self.solve_standard = solve_standard if need_model else None
        self._cache: dict[bytes, bool] = {}
        self.n_calls = 0
        self.n_evaluations = 0

    def __call__(self, q) -> bool:
        self.n_calls += 1
        q = np.asarray(q, dtype=float)
        k = q.tobytes()
        v = self._cache.get(k)
        if v is None:
            self.n_evaluations += 1
            v = self._evaluate(q)
            self._cache[k] = v
        return v

    def _evaluate(self, q) -> bool:
        try:
            alpha, beta = self.robot.configuration(q)
            self.robot.check_configuration(alpha, beta)
        except CtrplanError:
            return False
        if self.field is not None and not self.field.is_valid(q):
            return False
        if self.solve_standard is None:
            return True
        try:
            sol = self.solve_standard(self.robot, alpha, beta, self.settings)
        except (CtrplanError, np.linalg.LinAlgError, FloatingPointError):
            return False
        if self.check_stability and not sol.diagnostics.ok:
            return False
        if self.collision is not None and self.collision.collides(sol, self.robot):
            return False
        return True


@dataclass
class SearchResult:
    """Outcome of one planner search (:func:`plan_leg`): one leg's path and the planner's counters.
    The user-facing result of planning a scenario is :class:`ctrplan.PlanResult`.

    Attributes
    ----------
    waypoints : ndarray, shape (K, n_joints)
        Path in robot joint order [rad or m]; periodic angles are continuous (unwrapped) and the
        first row equals ``start_q``.
    cost : float
        Objective cost of the returned (shortcut) path [objective units, m for
        :class:`BoundCostObjective`].
    cost_before_simplification : float
    solved : bool
        An exact solution was found (always True for a returned result).
    approximate : bool
    planner : str
    iterations : int
        Planner iterations run.
    n_vertices : int
        Vertices in the planner's graph.
    solve_time : float
        Wall time of ``solve`` [s].
    simplify_time : float
        Wall time of shortcutting [s].
    seed : int
    status : str
        OMPL planner status.
    extra : dict
        Counters of the validity function when it has them (``n_calls``, ``n_evaluations``).
    """

    waypoints: np.ndarray
    cost: float
    cost_before_simplification: float
    solved: bool
    approximate: bool
    planner: str
    iterations: int
    n_vertices: int
    solve_time: float
    simplify_time: float
    seed: int
    status: str
    extra: dict = field(default_factory=dict)


def _set_seed(seed: int) -> None:
    # OMPL logs an error when the seed changes after sampling started; in OMPL 2.0.1 the new seed
    # is nevertheless applied to RNGs created afterwards (checked: equal seeds give equal plans
    # in one process, different seeds different plans), so silence that message.
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed))
    finally:
        ou.setLogLevel(level)


def _path_to_numpy(joint_space, path) -> np.ndarray:
    return np.array([joint_space.to_numpy(path.getState(i)) for i in range(path.getStateCount())])


#: Planner parameters that :func:`plan_leg` and :func:`~ctrplan.planning.plan_route` also take as keywords,
#: by their keyword (``range`` is a builtin, hence ``range_``).
_PARAMETER_KEYWORDS = {"range_": "range", "goal_bias": "goal_bias", "rewire_factor": "rewire_factor"}


@dataclass(frozen=True)
class SearchSettings:
    """How one planner search runs: which planner, its budget, its seed and its parameters.

    Attributes
    ----------
    planner : str
        A registered planner (:data:`ctrplan.planner_info.PLANNER_REGISTRY`).
    iterations : int
        Planner iterations (termination condition, reproducible); >= 1.
    time_limit : float or None
        Additional wall-time limit [s]; runs stopped by it are not reproducible.
    seed : int
        OMPL RNG seed (> 0), set before any planner or sampler is created.
    options : mapping of str to value
        Parameters the planner declares (:class:`ctrplan.planner_info.PlannerParameter`), by name
        (``range``: maximum motion length [m of the weighted joint metric]; ``goal_bias``; and
        ``rewire_factor``: OMPL's ``setRewireFactor``, the factor on the k-nearest neighbour count
        ``k = factor * 2^(d+1) e (1 + 1/d) log(n)`` whose motions a new state is connected and
        rewired through); None values count as not given.
    validity_resolution : float
        Spacing of validity checks along motions [m of the weighted metric] (a
        ``BatchValidityChecker`` uses its own ``resolution``).
    shortcut_rounds : int
        Rounds of cost-aware ``partialShortcutPath``; 0 disables.
    """

    planner: str = "RRTstar"
    iterations: int = DEFAULT_ITERATIONS
    time_limit: float | None = None
    seed: int = 1
    options: Mapping = field(default_factory=dict)
    validity_resolution: float = DEFAULT_VALIDITY_RESOLUTION
    shortcut_rounds: int = DEFAULT_SHORTCUT_ROUNDS

    def replace(self, **changes) -> "SearchSettings":
        """A copy with ``changes`` (field names)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def of(cls, settings: "SearchSettings | None" = None, **keywords) -> "SearchSettings":
        """``settings`` (default: the defaults) with keyword values on top.

        Parameters
        ----------
        settings : SearchSettings, optional
        **keywords
            Field names (a field keyword replaces the field; ``options`` entries are added to
            the settings' options), and the planner parameters ``range_``, ``goal_bias`` and
            ``rewire_factor`` (added to ``options``). A planner parameter whose value is None
            counts as not given.

        Raises
        ------
        TypeError
            A keyword that is neither.
        ValueError
            A planner parameter given twice in one call, as a keyword and in ``options``.
        """
        base = cls() if settings is None else settings
        if not isinstance(base, cls):
            raise TypeError(f"settings must be a SearchSettings, got {type(base).__name__} ({base!r})")
        names = set(cls.__dataclass_fields__)
        unknown = sorted(set(keywords) - names - set(_PARAMETER_KEYWORDS))
        if unknown:
            raise TypeError(f"unknown search keyword(s) {', '.join(unknown)}; known: "
                            f"{', '.join(sorted(names | set(_PARAMETER_KEYWORDS)))}")
        fields = {k: v for k, v in keywords.items() if k in names}
        given = {k: v for k, v in dict(fields.pop("options", None) or {}).items() if v is not None}
        for keyword, name in _PARAMETER_KEYWORDS.items():
            value = keywords.get(keyword)
            if value is None:
                continue
            if given.get(name, value) != value:
                raise ValueError(f"planner parameter {name!r} given twice (as a keyword and in options)")
            given[name] = value
        return base.replace(**fields, options={**base.options, **given})

    @classmethod
    def from_scenario(cls, planner_settings, **changes) -> "SearchSettings":
        """The search of a scenario's ``[planner]`` table, with ``changes`` on top.

        Parameters
        ----------
        planner_settings : ctrplan.io.scenario.PlannerSettings
            Its name, iterations, time limit [s], seed, ``range`` [m of the weighted joint metric],
            ``rewire_factor`` and the planner's other declared parameters.
        **changes
            Keywords of :meth:`of`.

        Returns
        -------
        SearchSettings

        Raises
        ------
        TypeError, ValueError
            As :meth:`of`.
        """
        p = planner_settings
        options = {"range": p.range, "rewire_factor": p.rewire_factor, **dict(p.parameters)}
        base = cls(planner=p.name, iterations=p.iterations, time_limit=p.time_limit, seed=p.seed,
                   options={k: v for k, v in options.items() if v is not None})
        return cls.of(base, **changes)


def plan_leg(robot, start_q, goal_q, validity_fn, objective, settings: SearchSettings | None = None, *,
             joint_space: JointStateSpace | None = None, quiet: bool = True, **keywords) -> SearchResult:
    """Plan a valid, low-cost joint-space path from ``start_q`` to ``goal_q``.

    Parameters
    ----------
    robot : Robot
    start_q, goal_q : array-like, shape (n_joints,)
        Joint vectors in robot joint order [rad or m].
    validity_fn : callable
        ``validity_fn(q (n_joints,)) -> bool`` (e.g. a :class:`ValidityChecker`); wrapped so OMPL
        receives a real ``bool``. Checked along motions every ``settings.validity_resolution``. A
        :class:`~ctrplan.planning.validity.BatchValidityChecker` also checks OMPL's motions,
        all states of a motion in a few compiled calls
        (:func:`~ctrplan.planning.validity.use_motion_validator`), at its own ``resolution``.
    objective : callable or ob.OptimizationObjective
        ``objective(si, joint_space) -> ob.OptimizationObjective`` (e.g.
        ``BoundCostObjective.factory(field)``), or an objective already built on
        ``joint_space`` (then ``joint_space`` must be passed and its space information is
        re-used).
    settings : SearchSettings, optional
        Planner, iterations, time limit, seed, the planner's parameters, validity resolution,
        shortcut rounds (default: :class:`SearchSettings` ``()``).
    joint_space : JointStateSpace, optional, keyword-only
        Default ``JointStateSpace(robot)``.
    quiet : bool, keyword-only
        Raise OMPL's log level to warnings during this call (restored afterwards).
    **keywords
        Fields of :class:`SearchSettings` on top of ``settings`` (``iterations=300, seed=3``), and
        the planner parameters ``range_``, ``goal_bias``, ``rewire_factor``
        (:meth:`SearchSettings.of`).

    Returns
    -------
    SearchResult

    Raises
    ------
    TypeError
        A keyword that is neither a field of :class:`SearchSettings` nor a planner parameter.
    ValueError
        Unknown planner name (:class:`ctrplan.registry.UnknownNameError`), a parameter the
        planner does not declare, a parameter value of the wrong type or outside its limits,
        or bad arguments.
    UnreachableGoalError
        Start or goal invalid, or no exact solution within the iterations.
    """
    s = SearchSettings.of(settings, **keywords)
    parameters = check_planner_options(s.planner, s.options)
    if int(s.iterations) < 1:
        raise ValueError(f"iterations must be >= 1, got {s.iterations!r}")
    if int(s.seed) <= 0:
        raise ValueError(f"seed must be a positive integer (OMPL treats 0 as 'random'), got {s.seed!r}")
    level = ou.getLogLevel()
    if quiet:
        ou.setLogLevel(ou.LOG_WARN)
    try:
        return _plan(robot, start_q, goal_q, validity_fn, objective, s.planner, s.iterations, s.time_limit, s.seed,
                     joint_space, s.validity_resolution, parameters, s.shortcut_rounds)
    finally:
        ou.setLogLevel(level)


def _plan(robot, start_q, goal_q, validity_fn, objective, planner, iterations, time_limit, seed,
          joint_space, validity_resolution, parameters, shortcut_rounds):
    _set_seed(seed)
    prebuilt = isinstance(objective, ob.OptimizationObjective)
    if prebuilt and joint_space is None:
        joint_space = getattr(objective, "joint_space", None)
        if joint_space is None:
            raise ValueError("a pre-built objective needs the joint_space it was built on")
    js = joint_space if joint_space is not None else JointStateSpace(robot)
    start_q = js._check_q(start_q)
    goal_q = js._check_q(goal_q)
    for label, q in (("start", start_q), ("goal", goal_q)):
        if not bool(validity_fn(q)):
            raise UnreachableGoalError(
                f"{label} configuration {_fmt_q(robot, q)} is invalid (joint limits, elastic "
                "stability, collision or bound field validity)")

    si = objective.getSpaceInformation() if prebuilt else ob.SpaceInformation(js.space)
    if hasattr(validity_fn, "check_motion") and hasattr(validity_fn, "motion_states"):
        use_motion_validator(si, js, validity_fn)
    else:
        si.setStateValidityChecker(lambda s: bool(validity_fn(js.to_numpy(s))))
        extent = js.space.getMaximumExtent()
        si.setStateValidityCheckingResolution(min(1.0, float(validity_resolution) / extent))
    si.setup()
    obj = objective if prebuilt else objective(si, js)

    start = js.from_numpy(start_q)
    goal = js.from_numpy(goal_q)
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(start, goal)
    pdef.setOptimizationObjective(obj)
    pl = PLANNERS[planner](si)
    declared = PLANNER_REGISTRY[planner].parameters
    for key, value in parameters.items():
        declared[key].apply(pl, value)
    pl.setProblemDefinition(pdef)
    pl.setup()

    n_iter = int(iterations)
    ptc = ob.PlannerTerminationCondition(lambda: pl.numIterations() >= n_iter)
    if time_limit is not None:
        ptc = ob.plannerOrTerminationCondition(ptc, ob.timedPlannerTerminationCondition(float(time_limit)))
    t0 = time.perf_counter()
    status = pl.solve(ptc)
    solve_time = time.perf_counter() - t0

    pd = ob.PlannerData(si)
    pl.getPlannerData(pd)
    n_vertices = int(pd.numVertices())
    exact = bool(pdef.hasExactSolution())
    if not exact:
        raise UnreachableGoalError(
            f"{planner} found no exact path from {_fmt_q(robot, start_q)} to {_fmt_q(robot, goal_q)} in "
            f"{pl.numIterations()} iterations ({n_vertices} vertices, status '{status}'); the goal may be "
            "disconnected by obstacles, joint limits or unstable regions: raise iterations or check the goal")
    path = pdef.getSolutionPath()
    cost0 = float(path.cost(obj).value())
    t1 = time.perf_counter()
    if shortcut_rounds > 0 and path.getStateCount() > 2:
        simplifier = og.PathSimplifier(si, pdef.getGoal(), obj)
        for _ in range(int(shortcut_rounds)):
            if not simplifier.partialShortcutPath(path):
                break
    simplify_time = time.perf_counter() - t1
    cost = float(path.cost(obj).value())
    w = _path_to_numpy(js, path)
    # continuous angles starting exactly at start_q
    for j in np.flatnonzero(js.periodic):
        w[:, j] = np.unwrap(w[:, j])
    w += np.where(js.periodic, start_q - w[0], 0.0)[None, :]
    w[0] = start_q
    w[-1] = np.where(js.periodic, w[-1], goal_q)
    return SearchResult(waypoints=w, cost=cost, cost_before_simplification=cost0, solved=True,
                      approximate=bool(pdef.hasApproximateSolution()), planner=planner,
                      iterations=int(pl.numIterations()), n_vertices=n_vertices, solve_time=solve_time,
                      simplify_time=simplify_time, seed=int(seed), status=str(status),
                      extra={"n_validity_calls": getattr(validity_fn, "n_calls", None),
                             "n_validity_evaluations": getattr(validity_fn, "n_evaluations", None),
                             "n_motions": getattr(validity_fn, "n_motions", None)})


def _fmt_q(robot, q) -> str:
    parts = []
    for j, v in zip(robot.joints, np.asarray(q, dtype=float)):
        parts.append(f"{j.name}={v:.4g} rad" if j.kind == JointKind.ROTATION else f"{j.name}={v * 1e3:.4g} mm")
    return "(" + ", ".join(parts) + ")"
