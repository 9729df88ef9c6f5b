"""Interactive planning: one goal after another from the current configuration, on a roadmap built
once (:class:`Planner`).

For a robot, its bound map and a fixed set of obstacles, the roadmap of
:mod:`ctrplan.planning.roadmap` (valid states joined by valid straight motions, each costing its
length plus the weighted integral of the bound along the motion as executed, rotations first) is
built once and stored in the cache,
keyed by the robot file, the map, the obstacles' geometry and the settings. Each
:meth:`Planner.plan_to` then does what ``ctrplan plan`` does after its search, for one goal:

1. the goal as a joint vector (a task-space goal by inverse kinematics, the smallest map bound
   among the solutions; :func:`ctrplan.planning.resolve_goal`);
2. the cheapest path through the roadmap (:meth:`~ctrplan.planning.roadmap.Roadmap.query`); if
   none joins the current configuration and the goal, a single-query search with the scenario's
   planner (``via = "search"``);
3. rotate-then-translate ordering with the final check of every phase (exact standard model and
   exact obstacles; bisection and repair as in :func:`ctrplan.planning.plan_route`), and the
   motion reaching the goal ended as ``[planner] final_motion`` asks;
4. the exact friction bound at the ordered waypoints given the last motion (Section V-B of Ha,
   Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906);
5. the drive trajectory (``[drive]``), checked against every limit.

Units: SI throughout (rad, m, s).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass

import numpy as np

from .._log import progress_level
from ..errors import UnreachableGoalError
from .roadmap import load_roadmap

__all__ = ["Planner", "GoalPlan"]

logger = logging.getLogger(__package__)


@dataclass(frozen=True, eq=False)
class GoalPlan:
    """One goal planned by :meth:`Planner.plan_to`.

    Attributes
    ----------
    start, goal : ndarray, shape (n_joints,)
        Where the motion starts and the joint goal it reaches [rad or m].
    ordered : OrderedPath
        Pure rotation and pure translation phases, every one checked [rad or m].
    bounds : LastMotionBounds
        The exact bound at the ordered waypoints given the last motion [m, rad].
    trajectory : Trajectory or None
        The drive trajectory; None without a ``[drive]`` table.
    cost : float
        Cost of the path the search returned [m]: through the roadmap ``sum L + w I`` over its
        motions as executed (:func:`ctrplan.planning.roadmap.motion_terms`); by the single-query
        planner, its objective (``L + w integral(b) dl`` along straight segments).
    via : str
        ``"roadmap"`` or ``"search"`` (the scenario's single-query planner, when the roadmap did
        not join the start and the goal).
    times_s : dict
        ``goal``, ``search``, ``order_and_check``, ``exact_bound``, ``trajectory``, ``total`` [s].
    """

    start: np.ndarray
    goal: np.ndarray
    ordered: object
    bounds: object
    trajectory: object
    cost: float
    via: str
    times_s: dict

    @property
    def max_bound_m(self) -> float:
        """Largest exact bound at the ordered waypoints given the last motion [m]."""
        return float(np.nanmax(self.bounds.position))

    @property
    def final_bound_m(self) -> float:
        """Exact bound at the goal given the motion that reaches it [m]."""
        return float(self.bounds.position[-1])


class Planner:
    """Plans one goal after another for a scenario's robot, map and obstacles, on a roadmap built
    once (module docstring).

    Parameters
    ----------
    setup : PlanSetup
        The scenario's robot, settings and obstacles (:func:`ctrplan.planning.setup_plan`).
    field : BoundField
        The bound map of the edge costs and of the valid region.
    n_nodes : int, optional, keyword-only
        Roadmap states (default :data:`~ctrplan.planning.roadmap.DEFAULT_NODES_PER_JOINT` per joint).
    neighbours : int, optional, keyword-only
        Neighbours per state (default PRM*'s).
    seed : int, optional, keyword-only
        Sampling seed (default the scenario's planner seed).
    cache_dir : path, optional, keyword-only
        Where roadmaps are stored and looked up (default ``roadmaps`` in
        :func:`ctrplan.cache.cache_dir`); unused with ``store=False``.
    store : bool, keyword-only
        Read and write the roadmap in ``cache_dir``.
    n_jobs : int, keyword-only
        Processes that build the roadmap (the result does not depend on it).

    Attributes
    ----------
    current : ndarray, shape (n_joints,)
        The configuration the next goal is planned from: the scenario's start, then each goal
        reached [rad or m].
    roadmap : Roadmap
    roadmap_source : str
        ``"built"`` or ``"cache"``.
    roadmap_path : pathlib.Path or None

    Raises
    ------
    UnreachableGoalError
        The scenario's start is invalid, or too few valid states for a roadmap.
    """

    def __init__(self, setup, field, *, n_nodes: int | None = None, neighbours: int | None = None,
                 seed: int | None = None, cache_dir: str | os.PathLike | None = None, store: bool = True,
                 n_jobs: int = 1):
        from .plans import effective_bound_weight
        from .roadmap import motion_terms

        sc = setup.scenario
        self.setup, self.field = setup, field
        self.robot = setup.robot
        self.joint_space = setup.joint_space
        self.checks = setup.route_checks(field)
        self.bound_weight = effective_bound_weight(sc.calibration.bound, sc.planner.bound_weight)
        self.terms = motion_terms(self.joint_space, field)
        self.current = np.array(sc.start, dtype=float)
        if not self.checks.search(self.current):
            raise UnreachableGoalError(f"{sc.file}: start configuration {sc.joint_dict(self.current)} is invalid "
                                       "(collision, elastic instability or outside the bound map's valid region)")
        self.roadmap, self.roadmap_source, self.roadmap_path = load_roadmap(
            setup, field, self.checks.search, self.joint_space, n_nodes=n_nodes, neighbours=neighbours, seed=seed,
            cache_dir=cache_dir, store=store, n_jobs=n_jobs)

    @classmethod
    def from_scenario(cls, scenario, *, bound_map=None, n_jobs: int = 1, **kwargs) -> "Planner":
        """A planner for a scenario file (or a loaded :class:`~ctrplan.io.scenario.Scenario`).

        Parameters
        ----------
        scenario : path or Scenario
        bound_map : BoundField, optional, keyword-only
            Default: the shipped or cached map of the scenario's robot, else its preview map
            (computed, :func:`ctrplan.planning.prepare_bound_map`).
        n_jobs : int, keyword-only
            Worker processes for a map that must be computed and for the roadmap.
        **kwargs
            As :class:`Planner`.

        Returns
        -------
        Planner

        Raises
        ------
        ModelFileError
            Malformed scenario or robot file.
        UnreachableGoalError
            As :class:`Planner`.
        """
        from ..io.scenario import load_scenario
        from .bound_map import prepare_bound_map
        from .setup import setup_plan

        sc = scenario if hasattr(scenario, "robot") else load_scenario(scenario)
        setup = setup_plan(sc)
        field = bound_map if bound_map is not None else prepare_bound_map(setup, n_jobs).field
        return cls(setup, field, n_jobs=n_jobs, **kwargs)

    def resolve(self, goal, *, seed: int = 1) -> np.ndarray:
        """A goal as a valid joint vector [rad or m].

        Parameters
        ----------
        goal : array-like of shape (n_joints,), dict, JointGoal or TaskGoal
            A joint vector (robot joint order), ``{joint name: value}``, or a tip position with
            a tolerance (``{"tip_position_m": [x, y, z], "tolerance_m": t}`` [m]).
        seed : int, keyword-only
            Seed of the inverse kinematics' starts.

        Returns
        -------
        ndarray, shape (n_joints,)
            In robot joint order [rad or m].

        Raises
        ------
        UnreachableGoalError
            An invalid joint goal, or no valid inverse-kinematics solution within tolerance.
        ValueError
            A malformed goal.
        """
        from .goals import IKSearch, resolve_goal

        names = self.robot.joint_names
        if isinstance(goal, dict) and set(goal) <= set(names) and goal:
            missing = [nm for nm in names if nm not in goal]
            if missing:
                raise ValueError(f"joint goal misses {', '.join(missing)}")
            goal = np.array([goal[nm] for nm in names], dtype=float)
        sol = resolve_goal(goal, self.robot, validity_fn=self.checks.search, field=self.field,
                           settings=self.setup.check_settings, search=IKSearch(seed=seed))
        return np.asarray(sol.q, dtype=float)

    def plan_to(self, goal, *, start=None, move: bool = True) -> GoalPlan:
        """Plan, order, check, bound and time-parameterize the motion to one goal.

        Parameters
        ----------
        goal
            As :meth:`resolve`.
        start : array-like, shape (n_joints,), optional, keyword-only
            Default :attr:`current` [rad or m].
        move : bool, keyword-only
            Make the goal the new :attr:`current`.

        Returns
        -------
        GoalPlan

        Raises
        ------
        UnreachableGoalError
            Invalid start or goal, or no path passes the final check.
        JointLimitError
            The drive trajectory violates a drive limit.
        """
        from ..mechanics import evaluate_bound
        from .approach import end_with
        from .objective import BoundCostObjective
        from .ordering import bounds_given_last_motion
        from .planners import SearchSettings
        from .route import plan_route
        from .waypoints import drive_trajectory

        t_all = time.perf_counter()
        sc, robot, js, checks = self.setup.scenario, self.robot, self.joint_space, self.checks
        q0 = self.current.copy() if start is None else np.asarray(start, dtype=float).reshape(-1)
        t0 = time.perf_counter()
        q1 = self.resolve(goal)
        t_goal = time.perf_counter() - t0
        p = sc.planner
        t0 = time.perf_counter()
        route = plan_route(robot, q0, [q1], checks, BoundCostObjective.factory(self.field, bound_weight=self.bound_weight),
                           SearchSettings.from_scenario(p), joint_space=js,
                           roadmap=(self.roadmap, self.terms, self.bound_weight))
        leg = route.legs[0]
        via = "roadmap" if leg.planner == "roadmap" else "search"
        if via == "search":
            logger.log(progress_level(), f"the roadmap does not join {np.round(q0, 4).tolist()} and "
                                         f"{np.round(q1, 4).tolist()}: planned with {p.name}")
        t_search = leg.solve_time + leg.simplify_time
        ordered, _ = end_with(route.ordered, len(route.ordered.q) - 1, p.final_motion, checks.final.check)
        t_order = time.perf_counter() - t0 - t_search
        cost = leg.cost
        t0 = time.perf_counter()
        bounds = bounds_given_last_motion(ordered, robot, evaluate_bound, self.setup.settings)
        t_exact = time.perf_counter() - t0
        t0 = time.perf_counter()
        trajectory = drive_trajectory(self.setup, ordered)
        t_traj = time.perf_counter() - t0
        if move:
            self.current = q1.copy()
        return GoalPlan(start=q0, goal=q1, ordered=ordered, bounds=bounds, trajectory=trajectory, cost=float(cost),
                        via=via, times_s={"goal": t_goal, "search": t_search, "order_and_check": t_order,
                                          "exact_bound": t_exact, "trajectory": t_traj,
                                          "total": time.perf_counter() - t_all})
