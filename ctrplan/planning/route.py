"""A route through several goals: batched search, rotate-then-translate ordering, final check.

:func:`plan_route` is what ``ctrplan plan`` runs for each of its plans (bound-aware and
bound-blind):

1. every leg (start -> goal 1 -> goal 2 ...) is planned by OMPL (:func:`~ctrplan.planning.plan_leg`)
   with the **search checker** (:class:`~ctrplan.planning.validity.BatchValidityChecker`):
   all states of a motion in a few compiled calls, at the search's resolution, on the standard
   model's uniform arc-length grid at twice the step, with bodies inflated as in the final check;
2. the whole route is split into rotation and translation phases
   (:func:`~ctrplan.planning.order_path`, Section V-B of Ha, Fagogenis & Dupont 2019), and every
   phase passes the **final check** (:class:`~ctrplan.planning.verify.MotionVerifier`: exact
   standard model, exact obstacles, states no sparser than OMPL's at 2 mm, refined until no body
   point moves more than 0.5 mm between them, bodies inflated by half that);
3. a phase that fails is bisected when its straight segment passes; a straight segment that
   fails (the search missed something between its states, e.g. a thin wall) is **repaired**: the
   segment is planned again with motions checked ``repair_factor`` times more finely, and the new
   sub-path is ordered and checked in turn. If that fails too, :class:`UnreachableGoalError`.

No path leaves :func:`plan_route` that has not passed the final check.
"""

from __future__ import annotations

from dataclasses import dataclass, field as dc_field

import numpy as np

from ..planner_info import PLANNER_REGISTRY
from .collision import CollisionChecker
from .ordering import OrderedPath, order_path
from .planners import SearchResult, SearchSettings, plan_leg
from .validity import BatchValidityChecker
from .verify import DEFAULT_MAX_BODY_STEP, DEFAULT_VERIFY_RESOLUTION, MotionVerifier

__all__ = ["RouteChecks", "Route", "CheckResolution", "route_checks", "plan_route", "DEFAULT_SEARCH_RESOLUTION",
           "DEFAULT_REWIRE_FACTOR", "DEFAULT_SEARCH_REFINE_RATIO", "DEFAULT_REPAIR_FACTOR", "DEFAULT_REPAIR_ITERATIONS",
           "DEFAULT_COLLISION_SEGMENT"]

# Validity-checking resolution of the search [m of the weighted joint metric] (OMPL's rule,
# JointStateSpace.segment_count). See docs/planning.md for how it was chosen.
DEFAULT_SEARCH_RESOLUTION = 4e-3
# The search solves the standard model on the paper's uniform arc-length grid (Section II-C;
# refine_ratio 1) at twice the step (6 mm for the default 3 mm): 0.10 against 0.2-0.25 ms per
# state; on 1000 random configurations of each shipped robot the tips are within 2.0 um (Table
# VII) and 2.4 um (six joints) of the graded 3 mm grid, with the same convergence and stability
# flags, against the bodies' 0.25 mm inflation. The final check uses the settings as given.
DEFAULT_SEARCH_REFINE_RATIO = 1.0
DEFAULT_SEARCH_DS_FACTOR = 2.0
# A segment that fails the final check is planned again with motions checked this many times
# more finely, for this many planner iterations.
# RRT*'s rewire factor: OMPL's k-nearest count is factor * 2^(d+1) e (1 + 1/d) log(n), 64 log(n)
# at its default 1.1 for three joints, so every node of a tree below ~1000 nodes is a neighbour
# whose motion cost is evaluated (157 000 of them in 600 iterations on the obstacles scenario).
# At 0.1 (k = 37 at 600 nodes) the four shipped scenarios give the same plans; one run each took
# 9.9 -> 5.7 s (obstacles), 2.6 -> 1.8 s (task-target), 4.3 -> 4.3 s (sequence), 17.4 -> 15.0 s
# (six joints).
DEFAULT_REWIRE_FACTOR = 0.1
DEFAULT_REPAIR_FACTOR = 4
DEFAULT_REPAIR_ITERATIONS = 300
# Length of the capsules that sweep the robot body for collision checking [m]: chord error
# 0.06 mm on the tightest precurvature radius of the shipped robots (55 mm).
DEFAULT_COLLISION_SEGMENT = 5e-3


@dataclass
class RouteChecks:
    """The three checkers of :func:`plan_route` (built by :func:`route_checks`).

    Attributes
    ----------
    search : BatchValidityChecker
        States and motions during planning.
    repair_search : BatchValidityChecker
        The same, ``repair_factor`` times finer, for re-planning a failed segment.
    final : MotionVerifier
        Every ordered phase.
    """

    search: BatchValidityChecker
    repair_search: BatchValidityChecker
    final: MotionVerifier

    def for_field(self, field) -> "RouteChecks":
        """The same checks with ``field``'s validity flags: new search, repair and final checkers
        (their caches and counters start empty) sharing these ones' collision tests and joint space.

        Parameters
        ----------
        field : BoundField or None

        Returns
        -------
        RouteChecks
        """
        def batch(c):
            return BatchValidityChecker(c.robot, c.collision, field, c.settings, check_stability=c.check_stability,
                                        joint_space=c.joint_space, resolution=c.resolution, batch_size=c.batch_size)

        f = self.final
        final = MotionVerifier(f.robot, (), field, f.settings, joint_space=f.joint_space, resolution=f.resolution,
                               max_body_step=f.max_body_step, max_refinements=f.max_refinements,
                               collision=f.collision)
        return RouteChecks(batch(self.search), batch(self.repair_search), final)

    def counters(self, since: dict | None = None) -> dict:
        """Work of the three checkers (states, motions, model and collision seconds).

        Parameters
        ----------
        since : dict, optional
            An earlier result of this method: the work done after it is returned (checkers
            shared by several stages count for all of them).

        Returns
        -------
        dict
            ``validity_calls``, ``standard_model_solves``, ``search_states_evaluated``,
            ``search_motions_checked``, ``final_check_motions``, ``final_check_states`` (int) and
            ``search_standard_model_time_s``, ``search_collision_time_s``,
            ``final_check_time_s`` [s].
        """
        now = self._counters()
        if since is None:
            return now
        return {k: v - since[k] for k, v in now.items()}

    def _counters(self) -> dict:
        c = self.search.counters()
        r = self.repair_search.counters()
        return {"validity_calls": c["n_calls"] + r["n_calls"],
                "standard_model_solves": c["n_model"] + r["n_model"] + self.final.n_states,
                "search_states_evaluated": c["n_evaluations"] + r["n_evaluations"],
                "search_motions_checked": c["n_motions"] + r["n_motions"],
                "search_standard_model_time_s": c["seconds_model"] + r["seconds_model"],
                "search_collision_time_s": c["seconds_collision"] + r["seconds_collision"],
                "final_check_motions": self.final.n_motions, "final_check_states": self.final.n_states,
                "final_check_time_s": self.final.seconds}


@dataclass(frozen=True)
class CheckResolution:
    """How finely :func:`route_checks`' checkers look at a motion.

    Attributes
    ----------
    search : float
        OMPL validity-checking resolution of the search [m of the weighted metric].
    search_refine_ratio : float
        ``ModelSettings.refine_ratio`` of the search's standard model [-].
    search_ds_factor : float
        The search's arc-length step is this times ``settings.ds`` [-].
    final, max_body_step : float
        See :class:`~ctrplan.planning.verify.MotionVerifier` [m].
    repair_factor : int
        The repair search checks motions this many times more finely than the search.
    segment_length : float
        Capsule length of the collision bodies [m].
    """

    search: float = DEFAULT_SEARCH_RESOLUTION
    search_refine_ratio: float = DEFAULT_SEARCH_REFINE_RATIO
    search_ds_factor: float = DEFAULT_SEARCH_DS_FACTOR
    final: float = DEFAULT_VERIFY_RESOLUTION
    max_body_step: float = DEFAULT_MAX_BODY_STEP
    repair_factor: int = DEFAULT_REPAIR_FACTOR
    segment_length: float = DEFAULT_COLLISION_SEGMENT


def route_checks(robot, obstacles=(), field=None, settings=None, *, joint_space=None,
                 resolution: CheckResolution = CheckResolution()) -> RouteChecks:
    """The search, repair and final checkers of a planning problem.

    Parameters
    ----------
    robot : Robot
    obstacles : sequence of Obstacle or dict
        As for :class:`~ctrplan.planning.CollisionChecker`.
    field : BoundField, optional
        Its validity flags reject states near unstable or failed map nodes.
    settings : ModelSettings, optional
        Standard-model settings of the final check (``multistart`` is not run: the map flags
        multi-equilibrium regions).
    joint_space : JointStateSpace, optional, keyword-only
    resolution : CheckResolution, keyword-only
        Resolutions of the search, repair and final checks, the search's model steps, the
        collision bodies' length.

    Returns
    -------
    RouteChecks
    """
    from ..mechanics import ModelSettings
    from .space import JointStateSpace

    settings = (settings or ModelSettings()).replace(multistart=0)
    js = joint_space if joint_space is not None else JointStateSpace(robot)
    obstacles = list(obstacles)
    # the search avoids what the final check inflates
    r = resolution
    collision = CollisionChecker(obstacles, segment_length=r.segment_length, padding=0.5 * r.max_body_step) \
        if obstacles else None
    search_settings = settings.replace(refine_ratio=r.search_refine_ratio, ds=settings.ds * r.search_ds_factor)
    search = BatchValidityChecker(robot, collision, field, search_settings, joint_space=js, resolution=r.search)
    repair = BatchValidityChecker(robot, collision, field, search_settings, joint_space=js,
                                  resolution=r.search / int(r.repair_factor))
    final = MotionVerifier(robot, obstacles, field, settings, joint_space=js, resolution=r.final,
                           max_body_step=r.max_body_step, segment_length=r.segment_length)
    return RouteChecks(search, repair, final)


@dataclass
class Route:
    """Outcome of :func:`plan_route`.

    Attributes
    ----------
    legs : list of SearchResult
        One per goal, as planned (before ordering).
    ordered : OrderedPath
        The whole route in rotation and translation phases, every phase checked.
    repairs : list of SearchResult
        The re-planned segments.
    """

    legs: list
    ordered: OrderedPath
    repairs: list = dc_field(default_factory=list)


def plan_route(robot, start_q, goals_q, checks: RouteChecks, objective, settings: SearchSettings | None = None, *,
               joint_space=None, repair_iterations: int = DEFAULT_REPAIR_ITERATIONS, roadmap=None,
               **keywords) -> Route:
    """Plan start -> goals, order into rotate-then-translate phases and check every phase.

    Parameters
    ----------
    robot : Robot
    start_q : array-like, shape (n_joints,)
        [rad or m].
    goals_q : sequence of array-like, shape (n_joints,)
        Visited in order [rad or m].
    checks : RouteChecks
    objective : callable
        ``objective(si, joint_space) -> ob.OptimizationObjective``, e.g.
        ``BoundCostObjective.factory(field, bound_weight=w)``.
    settings : SearchSettings, optional
        The search of each leg (:func:`~ctrplan.planning.plan_leg`); leg k uses ``seed + k``. Its
        ``rewire_factor``, when not given and the planner declares it, is
        :data:`DEFAULT_REWIRE_FACTOR`.
    joint_space : JointStateSpace, optional, keyword-only
    repair_iterations : int, keyword-only
        Planner iterations of a repair.
    roadmap : tuple, optional, keyword-only
        ``(Roadmap, terms, bound_weight)``: each leg is the cheapest path through the roadmap
        (:meth:`~ctrplan.planning.roadmap.Roadmap.query` with ``terms`` and the weight [1/m]; its
        :class:`SearchResult` has ``planner == "roadmap"``); a leg the roadmap does not join is
        planned by ``settings.planner``.
    **keywords
        Fields of :class:`SearchSettings` on top of ``settings``, and the planner parameters
        ``range_``, ``goal_bias``, ``rewire_factor`` (:meth:`SearchSettings.of`).

    Returns
    -------
    Route

    Raises
    ------
    TypeError
        A keyword that is neither a field of :class:`SearchSettings` nor a planner parameter.
    UnreachableGoalError
        A leg has no path within the budget, or a segment fails the final check and cannot be
        bisected or repaired (the message names the segment and what failed).
    """
    search = SearchSettings.of(settings, **keywords)
    if search.options.get("rewire_factor") is None and "rewire_factor" in PLANNER_REGISTRY[search.planner].parameters:
        search = search.replace(options={**search.options, "rewire_factor": DEFAULT_REWIRE_FACTOR})
    js = joint_space if joint_space is not None else checks.search.joint_space
    legs: list[SearchResult] = []
    q_prev = np.asarray(start_q, dtype=float)
    waypoints = [q_prev]
    for gi, q_goal in enumerate(goals_q):
        res = None
        if roadmap is not None:
            res = _roadmap_leg(roadmap, q_prev, q_goal, checks.search, js, search.seed + gi)
        if res is None:
            res = plan_leg(robot, q_prev, q_goal, checks.search, objective, search.replace(seed=search.seed + gi),
                           joint_space=js)
        legs.append(res)
        wp = np.array(res.waypoints)
        offset = waypoints[-1] - wp[0]   # continue from where the previous leg ended (unwrapped angles)
        waypoints.extend(list(wp[1:] + offset))
        q_prev = waypoints[-1]
    repairs: list[SearchResult] = []

    def repair(a, b):
        res = plan_leg(robot, a, b, checks.repair_search, objective,
                       search.replace(iterations=repair_iterations, seed=search.seed + 1000 + len(repairs),
                                      time_limit=None),
                       joint_space=js)
        repairs.append(res)
        return res.waypoints

    ordered = order_path(np.array(waypoints), robot, motion_check=checks.final.check, repair=repair,
                         joint_space=js)
    return Route(legs, ordered, repairs)



def _roadmap_leg(roadmap, q0, q1, checker, joint_space, seed: int) -> SearchResult | None:
    """A leg through the roadmap as a :class:`SearchResult`, or None when the roadmap does not join
    its ends (the caller then plans it by search)."""
    from ..errors import UnreachableGoalError

    rm, terms, weight = roadmap
    try:
        path = rm.query(q0, q1, checker, terms, joint_space, bound_weight=weight)
    except UnreachableGoalError:
        if not (checker(q0) and checker(q1)):
            raise
        return None
    wp = path.waypoints.copy()
    # continuous angles from the leg's start, as the planners return them
    wp = np.asarray(q0, dtype=float) + np.cumsum(
        np.vstack([np.zeros(wp.shape[1]), joint_space.difference(wp[:-1], wp[1:])]), axis=0)
    return SearchResult(waypoints=wp, cost=path.cost, cost_before_simplification=path.cost_before_shortcut, solved=True,
                      approximate=False, planner="roadmap", iterations=0, n_vertices=rm.n_nodes,
                      solve_time=path.seconds, simplify_time=0.0, seed=seed, status="Exact solution",
                      extra={"roadmap_states_on_path": path.roadmap_states, "motions_checked": path.motions_checked})
