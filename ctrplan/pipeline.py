"""The main job: a bound-aware plan for a scenario, ordered, time-parameterized and reported.

``run_plan(scenario)`` composes these stages; each returns a frozen result in SI units (m, rad,
s), and millimetres and degrees appear only in the report stage and in progress messages:

1. :func:`load_setup` -> :class:`PlanSetup`: the scenario, its robot, the model settings, the
   bound map's spec and the output folder;
2. :func:`load_bound_map` -> :class:`BoundMapStage`: the robot's bound map (shipped in
   ``<robot dir>/boundmaps/`` as ``.npz`` or ``.zarr``, or cached) or computed into a zarr store
   (local cores or a Dask cluster; an interrupted computation resumes from its finished chunks);
3. :func:`check_start` -> the search's validity checker, after checking the start;
   :func:`resolve_goals` -> :class:`ResolvedGoals`: each goal as a joint vector (task-space goals
   by inverse kinematics preferring the smallest bound);
4. :func:`aim_goals` -> :class:`AimedGoals`: task-space goals aimed with the tip *predicted*
   after the final approach (``[planner] final_motion``: translation-last, the default, or
   rotation-last; Section V-B of Ha et al. 2019) instead of the standard model's tip
   (:func:`ctrplan.planning.goals.compensate_goal`);
5. :func:`plan_routes` -> :class:`Plans`: every leg planned with the same planner and seed,
   bound-aware (length + weight x integral of the bound) and bound-blind (length only); each
   plan (:class:`RoutePlan`) is ordered into rotations then translations (Section V-B) and both
   phases checked, the phases reaching each goal swapped if the final motion asks for it; the
   exact model re-run at the ordered waypoints gives the bound given the last motion and the tip
   predicted for the history the ordered plan creates (one contact solve at most per waypoint,
   usually none: the bound's own solutions are reused);
6. :func:`time_parameterize` -> the drive trajectory (ruckig, rest-to-rest, stop between
   phases), its samples checked;
7. :func:`path_rows`, :func:`plan_summary` and :func:`write_report`: path.csv, trajectory.csv,
   figures and summary.json, written atomically (mm and degrees only here).

The stages print nothing: they log to ``ctrplan.pipeline`` (:mod:`logging`) the lines ``ctrplan
plan`` shows (scenario, bound map, goals, plans, then the summary) at INFO, the files written at
DEBUG, and a goal planned without its compensation at WARNING. Their ``echo`` parameters are
deprecated.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from ._log import deprecated_echo, progress_level
from .boundmap import MapSpec, default_spec, load_or_compute_bound_map
from .errors import JointLimitError, UnreachableGoalError
from .errors import CtrplanError
from .io.scenario import TaskGoal, load_scenario
from .effects import REGISTRY, robot_effects
from .history import pair_friction
from .mechanics import ModelSettings, evaluate_bound, predict_tip
from .planning import BoundCostObjective, JointStateSpace, bounds_given_last_motion, resolve_goal
from .planning.goals import compensate_goal
from .planning.history import approach_history, approach_rows, end_with, goal_indices, path_history
from .planning.route import DEFAULT_REWIRE_FACTOR, plan_route, route_checks

__all__ = ["run_plan", "plan_stages", "PlanRun", "map_spec", "PlanSetup", "BoundMapStage", "ResolvedGoals", "AimedGoals", "PathBounds",
           "WaypointPredictions", "RoutePlan", "Plans", "load_setup", "load_bound_map", "check_start",
           "resolve_goals", "aim_goals", "plan_routes", "time_parameterize", "path_rows", "plan_summary",
           "write_report"]

# Spacing of interpolated-bound samples along an ordered path for the bound plot and the
# max-bound comparison [m of the weighted joint metric].
PATH_SAMPLE_SPACING = 2e-3

logger = logging.getLogger(__name__)


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


# --------------------------------------------------------------------------- stage results
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


@dataclass(frozen=True, eq=False)
class ResolvedGoals:
    """Stage 3: each scenario goal as a joint vector.

    Attributes
    ----------
    goals : tuple of GoalSolution
        One per scenario goal, in order: ``q`` shape (n_joints,) [rad or m], ``tip_error`` [m],
        ``bound`` (the map's friction bound there) [m], the IK ``candidates`` and
        ``n_model_evaluations``.
    time_s : float
        Inverse-kinematics time [s].
    """

    goals: tuple
    time_s: float


@dataclass(frozen=True, eq=False)
class AimedGoals:
    """Stage 4: the joint vectors the planner goes to.

    Attributes
    ----------
    final_motion : str
        ``"translation-last"`` or ``"rotation-last"`` (``[planner] final_motion``).
    q : tuple of ndarray, shape (n_joints,) each
        Planned goal per scenario goal [rad or m]: the compensated joint vector of a task-space
        goal, else the resolved one.
    compensations : tuple of (CompensatedGoal or None)
        Per goal; None for joint goals and where the compensation raised.
    errors : mapping of int to str
        Goal index -> why it was not compensated (the exception, as text).
    time_s : float
        Compensation time [s].
    aim : dict
        :func:`aim_decision`: the model goals are aimed with and why, with its measured error.
    """

    final_motion: str
    q: tuple
    compensations: tuple
    errors: Mapping[int, str]
    time_s: float
    aim: dict = None


@dataclass(frozen=True, eq=False)
class PathBounds:
    """Interpolated bounds sampled along an ordered path and the exact bound at its waypoints.

    Attributes
    ----------
    dense_q : ndarray, shape (N, n_joints)
        Straight-line samples along each ordered phase, ``PATH_SAMPLE_SPACING`` apart at most
        [rad or m].
    dense_s : ndarray, shape (N,)
        Cumulative joint-space length at the samples [m of the weighted metric].
    dense_motion : list of str, length N
        Motion of the phase each sample lies on.
    dense_friction, dense_translation_last : ndarray, shape (N,)
        The map's friction and translation-last bounds at the samples [m].
    dense_given_last : ndarray, shape (N,)
        The bound given the last motion: translation-last along a translation phase, friction
        along a rotation (Section V-B) [m].
    planned : ndarray, shape (K,)
        The map's value of the quantity the exact bound gives at each waypoint [m].
    exact : LastMotionBounds
        The exact bound given the last motion at the K waypoints (``position`` [m], ``angle``
        [rad], the :class:`~ctrplan.mechanics.BoundResult` per waypoint or None).
    """

    dense_q: np.ndarray
    dense_s: np.ndarray
    dense_motion: list
    dense_friction: np.ndarray
    dense_translation_last: np.ndarray
    dense_given_last: np.ndarray
    planned: np.ndarray
    exact: Any


@dataclass(frozen=True, eq=False)
class WaypointPredictions:
    """Tip predicted at every ordered waypoint for the history the ordered path creates.

    Attributes
    ----------
    tip : ndarray, shape (K, 3)
        Predicted tip position [m]; NaN where the prediction failed.
    offset : ndarray, shape (K,)
        Its distance from the standard model's tip [m]; NaN where it failed.
    eta, translation_last : ndarray, shape (K, n_tubes - 1)
        The path's history per pair (:func:`ctrplan.planning.history.path_history`).
    state : HistoryState
        The whole history state of the path (offsets of the configuration the tubes reach, e.g.
        a drive's backlash; friction state per pair).
    eta_used : ndarray of int, shape (K, n_tubes - 1)
        Friction direction applied per pair (0: frictionless there).
    cases, model, message : list of str, length K
        Per-pair cases joined by ``;``, the model used, and the solver's or the error's message.
    ok : ndarray of bool, shape (K,)
    n_solved : int
        Contact solves made (the others reused the exact bound's solutions).
    time_s : float
        [s]
    shape : tuple of (ndarray, shape (N_k, 3), or None), length K
        Predicted centerline of the innermost tube (base to tip) [m], from the same solution as
        ``tip``; None where the prediction failed.
    """

    tip: np.ndarray
    offset: np.ndarray
    eta: np.ndarray
    translation_last: np.ndarray
    eta_used: np.ndarray
    cases: list
    model: list
    ok: np.ndarray
    message: list
    n_solved: int
    time_s: float
    state: Any = None
    shape: tuple = ()


@dataclass(frozen=True, eq=False)
class RoutePlan:
    """Stage 5, one plan (bound-aware or bound-blind): search, ordering, final check and report.

    Attributes
    ----------
    legs : list of PlanResult
        One planner result per leg (start -> goal 1 -> goal 2 ...).
    ordered : OrderedPath
        The ordered path (pure rotation and pure translation phases) [rad or m].
    bounds : PathBounds
        Bounds along it and at its waypoints [m, rad].
    plan_time_s, exact_time_s : float
        Search and ordering time; exact-bound time [s].
    checks : dict
        The checkers' counters (``RouteChecks.counters``).
    max_body_step_m : float
        The final check's largest body displacement between checked states [m].
    prediction : WaypointPredictions
        Predicted tip at the ordered waypoints.
    goal_indices : list of int
        Waypoint index of each goal.
    final_motion_status : list of str
        Per goal: how the motion reaching it ends (:func:`ctrplan.planning.history.end_with`).
    """

    legs: list
    ordered: Any
    bounds: PathBounds
    plan_time_s: float
    exact_time_s: float
    checks: dict
    max_body_step_m: float
    prediction: WaypointPredictions
    goal_indices: list
    final_motion_status: list


@dataclass(frozen=True, eq=False)
class Plans:
    """Stage 5: the plans of a run.

    Attributes
    ----------
    routes : mapping of str to RoutePlan
        ``"bound_aware"``, then ``"bound_blind"`` when compared.
    in_parallel : bool
        Whether the two plans ran in two processes.
    time_s : float
        Wall time of all plans [s].
    """

    routes: Mapping[str, RoutePlan]
    in_parallel: bool
    time_s: float

    @property
    def aware(self) -> RoutePlan:
        """The bound-aware plan (the one that is executed)."""
        return self.routes["bound_aware"]


@dataclass(frozen=True, eq=False)
class _PlanJob:
    """Inputs of one plan (:func:`_plan_mode`); picklable, to run in another process."""

    robot: Any
    field: Any
    obstacles: list
    check_settings: ModelSettings
    settings: ModelSettings
    start: np.ndarray
    goals: list
    weight: float
    planner: Any
    iterations: int
    final_motion: str


# --------------------------------------------------------------------------- stages 1-4
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


def check_start(setup: PlanSetup, field):
    """Stage 3a: the search's validity checker, after checking the scenario's start with it.

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
        Its validity flags reject states near unstable or failed map nodes.

    Returns
    -------
    BatchValidityChecker
        The planning search's checker (collision with ``setup.obstacles``, elastic stability,
        the map's valid region; ``setup.check_settings``). It counts its calls (``n_calls``,
        ``n_model``, ``seconds_collision``), which the summary reports.

    Raises
    ------
    UnreachableGoalError
        The start is in collision, elastically unstable or outside the map's valid region.
    """
    sc = setup.scenario
    validity = route_checks(setup.robot, list(setup.obstacles), field, setup.check_settings,
                            joint_space=JointStateSpace(setup.robot)).search
    if not validity(sc.start):
        raise UnreachableGoalError(f"{sc.file}: start configuration {sc.joint_dict(sc.start)} is invalid "
                                   "(collision, elastic instability or outside the bound map's valid region)")
    return validity


@deprecated_echo
def resolve_goals(setup: PlanSetup, field, validity, echo=None) -> ResolvedGoals:
    """Stage 3b: each scenario goal as one joint vector.

    Joint goals are checked; task-space goals are solved by inverse kinematics with the standard
    model, keeping every valid solution within the goal's tolerance and taking the one with the
    smallest friction bound in ``field`` (:func:`ctrplan.planning.resolve_goal`, IK seed k + 1
    for goal k).

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
    validity : callable
        State validity (:func:`check_start`'s checker).
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    ResolvedGoals

    Raises
    ------
    UnreachableGoalError
        A joint goal is invalid, or no valid IK solution reaches a task goal within its tolerance.
    """
    t0 = time.perf_counter()
    goals = tuple(resolve_goal(g, setup.robot, validity_fn=validity, field=field, settings=setup.check_settings,
                               seed=k + 1)
                  for k, g in enumerate(setup.scenario.goals))
    seconds = time.perf_counter() - t0
    for k, g in enumerate(goals):
        logger.log(progress_level(), f"goal {k + 1}: q = {np.round(g.q, 4).tolist()}, tip error "
                   f"{g.tip_error * 1e3:.3f} mm, field bound {g.bound * 1e3:.2f} mm ({len(g.candidates)} candidates)")
    return ResolvedGoals(goals=goals, time_s=seconds)


def aim_decision(validation, aim_with: str = "auto") -> dict:
    """Which model task-space goals are aimed with, and why.

    With ``aim_with = "auto"`` the history-aware prediction is used only when the robot file's
    ``[prediction_validation]`` (written by ``ctrplan discrepancy``) records that it beat the
    standard model on measurements (the interval of the per-unit paired difference of their mean
    test-split tip errors lies below zero); otherwise the standard model. ``"history"`` and
    ``"standard"`` force one.

    Parameters
    ----------
    validation : PredictionValidation or None
        The robot file's ``[prediction_validation]`` (``Scenario.calibration.prediction``).
    aim_with : {"auto", "history", "standard"}

    Returns
    -------
    dict
        ``model`` ("history-aware prediction" or "standard model"), ``use_history`` (bool),
        ``reason``, ``measured_mean_mm`` and ``measured_max_mm`` (the measured tip error of the
        model aimed with; None when not measured), ``validation`` (``validation``).

    Raises
    ------
    ValueError
        ``aim_with`` not one of the three.
    """
    if aim_with not in ("auto", "history", "standard"):
        raise ValueError(f"aim_with must be 'auto', 'history' or 'standard', got {aim_with!r}")
    pv = validation
    figures = ""
    if pv is not None:
        figures = (f"on measurements ({pv.data_file or 'unnamed data'}, {pv.test_samples} test samples) "
                   f"the history-aware prediction's tip error is mean {pv.history_mean_m * 1e3:.2f} / max "
                   f"{pv.history_max_m * 1e3:.2f} mm against the standard model's {pv.standard_mean_m * 1e3:.2f}"
                   f" / {pv.standard_max_m * 1e3:.2f} mm")
        if pv.difference_low_m is not None:
            figures += (f" (mean difference {pv.difference_mean_m * 1e3:+.2f} mm, 95 % interval "
                        f"{pv.difference_low_m * 1e3:+.2f}..{pv.difference_high_m * 1e3:+.2f} mm)")
    if aim_with == "history":
        use, reason = True, "[planner] aim_with = \"history\"" + (f"; {figures}" if figures else
                                                                   "; not validated on measurements")
    elif aim_with == "standard":
        use, reason = False, "[planner] aim_with = \"standard\""
    elif pv is None:
        use, reason = False, ("the robot file has no [prediction_validation]: the history-aware prediction is not "
                              "validated on measurements (ctrplan discrepancy writes it)")
    else:
        use = bool(pv.history_beats_standard)
        reason = figures + ("" if use else ": it does not beat the standard model")
    side = "history" if use else "standard"
    return {"model": "history-aware prediction" if use else "standard model", "use_history": use, "reason": reason,
            "measured_mean_mm": None if pv is None else getattr(pv, f"{side}_mean_m") * 1e3,
            "measured_max_mm": None if pv is None else getattr(pv, f"{side}_max_m") * 1e3, "validation": pv}


@deprecated_echo
def aim_goals(setup: PlanSetup, resolved: ResolvedGoals, validity, echo=None) -> AimedGoals:
    """Stage 4: aim task-space goals with the tip predicted after the final approach.

    The approach to goal k is assumed to be one straight segment from the previous planned goal
    (or the start), ordered as ``[planner] final_motion`` asks (relative rotations the short way,
    :func:`ctrplan.planning.history.approach_history`); the joint vector whose predicted tip is on
    the target is found by :func:`ctrplan.planning.goals.compensate_goal` (Section V-B of Ha,
    Fagogenis & Dupont 2019). A goal whose compensation raises is planned to its standard-model
    solution, and the reason is kept. Joint goals are planned as resolved. Where
    :func:`aim_decision` chooses the standard model (``[planner] aim_with``), task-space goals are
    planned to their standard-model solutions.

    Parameters
    ----------
    setup : PlanSetup
    resolved : ResolvedGoals
    validity : callable
        State validity (:func:`check_start`'s checker).
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    AimedGoals
    """
    sc, robot = setup.scenario, setup.robot
    final_motion = sc.planner.final_motion
    t0 = time.perf_counter()
    compensations, goal_q = [], []
    motion = [np.asarray(sc.start, dtype=float)]      # the assumed motion so far (approaches to the goals)
    errors = {}
    aim = aim_decision(sc.calibration.prediction, sc.planner.aim_with)
    if any(isinstance(doc, TaskGoal) for doc in sc.goals):
        logger.log(progress_level(), f"aiming task-space goals with the {aim['model']}: {aim['reason']}")
    for k, (doc, g) in enumerate(zip(sc.goals, resolved.goals)):
        c = None
        if isinstance(doc, TaskGoal) and aim["use_history"]:
            before = np.array(motion)

            def state_at(q, before=before):
                return approach_history(robot, before[-1], q, final_motion, before=before)

            try:
                c = compensate_goal(doc.tip_position, robot, g.q, state_at, setup.settings, tolerance=doc.tolerance,
                                    validity_fn=validity)
            except CtrplanError as exc:   # no prediction at the standard solution: plan to it, say why
                errors[k] = f"{type(exc).__name__}: {exc}"
                logger.warning(f"goal {k + 1}: no compensation ({errors[k]}); planning to the standard-model goal")
        if c is not None:
            logger.log(progress_level(),
                       f"goal {k + 1} ({final_motion}, {c.model} model, eta {_eta_text(c.eta)}): predicted miss of "
                       f"standard-model IK {c.predicted_miss_standard * 1e3:.3f} mm, compensated "
                       f"{c.predicted_miss * 1e3:.3f} mm ({'used' if c.accepted else 'not used: ' + c.message}); "
                       f"q = {np.round(c.q, 4).tolist()}")
        compensations.append(c)
        goal_q.append(c.q if c is not None else g.q)
        motion += list(approach_rows(robot, motion[-1], goal_q[-1], final_motion)[1:])
    return AimedGoals(final_motion=final_motion, q=tuple(goal_q), compensations=tuple(compensations),
                      errors=MappingProxyType(errors), time_s=time.perf_counter() - t0, aim=aim)


# --------------------------------------------------------------------------- stage 5: plans
def _dense_path(ordered_q, motions, joint_space, spacing):
    """Straight-line samples along each ordered phase, with cumulative joint-space length."""
    pts, s, seg_motion = [ordered_q[0]], [0.0], [motions[0]]
    total = 0.0
    for k in range(1, len(ordered_q)):
        a, b = ordered_q[k - 1], ordered_q[k]
        d = joint_space.distance(a, b)
        m = max(1, int(np.ceil(d / spacing)))
        for t in np.arange(1, m + 1) / m:
            pts.append(a + (b - a) * t)
            s.append(total + d * t)
            seg_motion.append(motions[k])
        total += d
    return np.array(pts), np.array(s), seg_motion


def _path_bounds(ordered, robot, field, settings, joint_space) -> PathBounds:
    """Interpolated bounds sampled along an ordered path, and the exact bound at its waypoints."""
    qd, sd, md = _dense_path(ordered.q, ordered.motions, joint_space, PATH_SAMPLE_SPACING)
    friction = np.asarray(field(qd, "position"))
    tlast = np.asarray(field(qd, "translation_last_position"))
    # along a rotation phase the friction bound applies; along (and after) a translation, the
    # translation-last bound (Section V-B)
    given_last = np.where(np.array(md) == "translation", tlast, friction)
    # the map's value of the quantity the exact report gives at each waypoint
    motions = np.array(ordered.motions)
    planned = np.where(motions == "translation", field(ordered.q, "translation_last_position"),
                       field(ordered.q, "position"))
    return PathBounds(dense_q=qd, dense_s=sd, dense_motion=md, dense_friction=friction,
                      dense_translation_last=tlast, dense_given_last=given_last, planned=planned,
                      exact=bounds_given_last_motion(ordered, robot, evaluate_bound, settings))


def _eta_text(eta) -> str:
    """Per-pair directions as text, e.g. ``+1;-1`` (0: no friction on that pair)."""
    return ";".join(f"{int(e):+d}" if e else "0" for e in eta)


def _predictions(ordered, robot, settings, exact) -> WaypointPredictions:
    """Tip predicted at every ordered waypoint for the history the ordered path creates.

    The history (:func:`ctrplan.planning.history.path_history`) gives per pair eta and whether
    a translation followed the last rotation; :func:`ctrplan.mechanics.predict_tip` reuses the
    exact bound's clearance or friction solution at the waypoint when it is the one needed, and
    solves only partial histories. Waypoints where the bound failed, or the prediction raises,
    get NaN."""
    t0 = time.perf_counter()
    hist = path_history(robot, ordered.q)
    mu_robot = robot.friction_coefficients
    K, m = len(ordered), robot.n_tubes - 1
    tips = np.full((K, 3), np.nan)
    offsets = np.full(K, np.nan)
    eta_used = np.zeros((K, m), dtype=int)
    cases, models, messages = [""] * K, [""] * K, [""] * K
    ok = np.zeros(K, dtype=bool)
    shapes = [None] * K
    n_solved = 0
    for k in range(K):
        res = exact.results[k]
        state = hist.at(k)
        try:
            if res is None:
                raise CtrplanError("the exact bound failed here")
            alpha, beta = robot.configuration(ordered.q[k], check_limits=False)
            p = predict_tip(robot, alpha, beta, settings=settings, state=state, bound=res)
        except (CtrplanError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
            messages[k] = f"{type(exc).__name__}: {exc}"
            eta_used[k], _, c = pair_friction(state, mu_robot)
            cases[k] = ";".join(c)
            continue
        n_solved += not p.reused
        tips[k], offsets[k], eta_used[k] = p.tip_position, p.offset, p.eta
        cases[k], models[k], ok[k] = ";".join(p.cases), p.model, p.ok
        shapes[k] = np.asarray(p.solution.centerlines[-1])
        messages[k] = p.solution.diagnostics.message
    return WaypointPredictions(tip=tips, offset=offsets, eta=hist.eta, translation_last=hist.released,
                               eta_used=eta_used, cases=cases, model=models, ok=ok, message=messages,
                               n_solved=n_solved, time_s=time.perf_counter() - t0, state=hist, shape=tuple(shapes))


def _plan_mode(job: _PlanJob) -> RoutePlan:
    """One plan of a scenario (bound-aware or bound-blind): search, ordering, final check and the
    report. Takes and returns only picklable data, so that it can run in another process."""
    robot, field = job.robot, job.field
    joint_space = JointStateSpace(robot)
    checks = route_checks(robot, job.obstacles, field, job.check_settings, joint_space=joint_space)
    p = job.planner
    t0 = time.perf_counter()
    route = plan_route(robot, job.start, job.goals, checks,
                       BoundCostObjective.factory(field, bound_weight=job.weight), planner=p.name,
                       iterations=job.iterations, seed=p.seed, time_limit=p.time_limit, range_=p.range,
                       joint_space=joint_space,
                       rewire_factor=p.rewire_factor if p.rewire_factor is not None else DEFAULT_REWIRE_FACTOR)
    ordered = route.ordered
    # the motion reaching each goal ends as the scenario asks (swap its last two phases if needed
    # and if the swapped phases pass the final check)
    idx = goal_indices(ordered, job.goals, robot)
    final_status = []
    for gi in idx:
        ordered, status = end_with(ordered, gi, job.final_motion, checks.final.check)
        final_status.append(status)
    plan_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    bounds = _path_bounds(ordered, robot, field, job.settings, joint_space)
    exact_time = time.perf_counter() - t0
    pred = _predictions(ordered, robot, job.settings, bounds.exact)
    return RoutePlan(legs=route.legs, ordered=ordered, bounds=bounds, plan_time_s=plan_time,
                     exact_time_s=exact_time, checks=checks.counters(),
                     max_body_step_m=checks.final.max_body_step, prediction=pred, goal_indices=idx,
                     final_motion_status=final_status)


def _compile_before_fork(job) -> None:
    """The standard-model kernels both plans need (the robot bodies of the validity checks, the
    shooting with its multistart search of the exact checks), compiled or loaded here before the
    fork: the forked process inherits them, where on a cold start each process would compile
    them again side by side. Milliseconds when they are cached: two solves at the start."""
    from .mechanics import solve_standard, solve_standard_bodies

    try:
        alpha, beta = job.robot.configuration(job.start)
        solve_standard_bodies(job.robot, np.atleast_2d(alpha), np.atleast_2d(beta), job.check_settings)
        solve_standard(job.robot, alpha, beta, job.settings)
    except (CtrplanError, ValueError):   # only a warm-up: the plans report a bad start themselves
        pass


def _plan_modes(jobs: dict, n_jobs: int) -> tuple[dict, bool]:
    """Run the plans of ``jobs`` ({mode: _PlanJob}); with ``n_jobs`` >= 2 and more than one plan,
    the bound-blind plan runs in a forked process while this one plans bound-aware (the plans are
    independent and seeded, so the result is the same as in series; a failed child process is
    replaced by the same plan here). Returns ({mode: RoutePlan}, whether they ran in parallel)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    modes = list(jobs)
    parallel = n_jobs >= 2 and len(modes) > 1 and "fork" in multiprocessing.get_all_start_methods()
    if not parallel:
        return {m: _plan_mode(jobs[m]) for m in modes}, False
    _compile_before_fork(jobs[modes[0]])
    out = {}
    with ProcessPoolExecutor(max_workers=len(modes) - 1, mp_context=multiprocessing.get_context("fork")) as ex:
        futures = {m: ex.submit(_plan_mode, jobs[m]) for m in modes[1:]}
        out[modes[0]] = _plan_mode(jobs[modes[0]])
        for m, fut in futures.items():
            try:
                out[m] = fut.result()
            except BrokenProcessPool:
                out[m] = _plan_mode(jobs[m])
    return {m: out[m] for m in modes}, True


@deprecated_echo
def plan_routes(setup: PlanSetup, field, aimed: AimedGoals, *, iterations: int | None = None,
                compare_blind: bool = True, n_jobs: int = 1, echo=None) -> Plans:
    """Stage 5: plan start -> goals bound-aware (and bound-blind), order, check and evaluate.

    Each plan runs the scenario's planner and seed on every leg with the cost length + weight x
    integral of the bound (weight ``[planner] bound_weight`` [1/m] bound-aware, 0 bound-blind),
    orders the path into pure rotation and pure translation phases, checks every phase, ends the
    motion reaching each goal as ``aimed.final_motion`` asks, and re-runs the exact model at the
    ordered waypoints (Section V-B of Ha, Fagogenis & Dupont 2019).

    Parameters
    ----------
    setup : PlanSetup
    field : BoundField
    aimed : AimedGoals
        The joint goals planned to, shape (n_joints,) each [rad or m].
    iterations : int, optional, keyword-only
        Planner iterations per leg; default ``[planner] iterations``.
    compare_blind : bool, keyword-only
        Also plan bound-blind.
    n_jobs : int, keyword-only
        With 2 or more, the bound-blind plan runs in a forked process beside the bound-aware one
        (same result as in series).
    echo : callable, optional, keyword-only
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    Plans

    Raises
    ------
    UnreachableGoalError
        No valid path within the planner's budget.
    """
    sc = setup.scenario
    iters = iterations or sc.planner.iterations
    modes = ([("bound_aware", effective_bound_weight(sc.calibration.bound, sc.planner.bound_weight))]
             + ([("bound_blind", 0.0)] if compare_blind else []))
    jobs = {mode: _PlanJob(robot=setup.robot, field=field, obstacles=list(setup.obstacles),
                           check_settings=setup.check_settings, settings=setup.settings, start=sc.start,
                           goals=list(aimed.q), weight=weight, planner=sc.planner, iterations=iters,
                           final_motion=aimed.final_motion)
            for mode, weight in modes}
    t0 = time.perf_counter()
    routes, in_parallel = _plan_modes(jobs, n_jobs)
    seconds = time.perf_counter() - t0
    for mode, r in routes.items():
        lm = r.bounds.exact
        ordered = r.ordered
        logger.log(progress_level(),
                   f"{mode}: {len(ordered)} ordered waypoints, planning {r.plan_time_s:.1f} s "
                   f"({r.checks['search_states_evaluated']} states checked, final check "
                   f"{r.checks['final_check_states']} states, "
                   f"{ordered.n_subdivisions} bisections, {ordered.n_repairs} repairs); exact bound at waypoints: "
                   f"max {np.nanmax(lm.position) * 1e3:.2f} mm, final {lm.position[-1] * 1e3:.2f} mm")
    return Plans(routes=MappingProxyType(routes), in_parallel=in_parallel, time_s=seconds)


# --------------------------------------------------------------------------- stage 6: trajectory
def time_parameterize(setup: PlanSetup, ordered):
    """Stage 6: the drive trajectory along an ordered path, checked against the drive limits.

    Parameters
    ----------
    setup : PlanSetup
        Its scenario's ``[drive]`` limits [rad or m per s, s^2, s^3] and control rate [Hz].
    ordered : OrderedPath
        Waypoints shape (K, n_joints) [rad or m] with their motions.

    Returns
    -------
    Trajectory or None
        Rest-to-rest ruckig segments, stopping between phases
        (:func:`ctrplan.trajectory.time_parameterize_robot`); None when the scenario has no
        ``[drive]`` table.

    Raises
    ------
    JointLimitError
        The sampled trajectory violates a drive limit (the first five violations are named).
    """
    from .trajectory import check_trajectory, time_parameterize_robot

    sc = setup.scenario
    traj = time_parameterize_robot(setup.robot, ordered.q, ordered.motions, **sc.drive.as_kwargs()) \
        if sc.drive is not None else None
    violations = check_trajectory(traj) if traj is not None else []
    if violations:
        raise JointLimitError(f"{sc.file}: the time-parameterized trajectory violates the drive limits: "
                              + "; ".join(str(v) for v in violations[:5]))
    return traj


# --------------------------------------------------------------------------- stage 7: report
def calibrated_bound(calibration, bound) -> np.ndarray:
    """The calibrated bound ``factor (bound + noise_margin_m)`` of the robot file's
    ``[bound_calibration]`` (:mod:`ctrplan.discrepancy.coverage`) [m]; NaN without one.

    Parameters
    ----------
    calibration : CalibratedBound or None
        ``Scenario.calibration.bound``.
    bound : array-like
        The model's bound [m].

    Returns
    -------
    ndarray
        Same shape as ``bound``.
    """
    b = np.asarray(bound, float)
    if calibration is None:
        return np.full_like(b, np.nan)
    return calibration.apply(b)


def effective_bound_weight(calibration, weight: float) -> float:
    """The bound weight that ranks paths by the calibrated bound.

    Planning minimises ``L + w integral(b) ds``; with the calibrated bound ``c (b + m)`` in place
    of ``b`` the cost is ``(1 + w c m) L + w c integral(b) ds``, which has the same minimiser as
    ``L + w' integral(b) ds`` with ``w' = w c / (1 + w c m)``. Without a calibration, ``w``.

    Parameters
    ----------
    calibration : CalibratedBound or None
        ``Scenario.calibration.bound``.
    weight : float
        ``[planner] bound_weight`` [1/m].

    Returns
    -------
    float
        [1/m] (:meth:`ctrplan.calibration.CalibratedBound.effective_weight`).
    """
    if calibration is None:
        return float(weight)
    return calibration.effective_weight(weight)


def path_rows(plan: RoutePlan, calibration=None) -> list[dict]:
    """Rows of ``path.csv`` for a plan, one per ordered waypoint (SI units, as the file stores them).

    Parameters
    ----------
    plan : RoutePlan
    calibration : CalibratedBound, optional
        The robot file's ``[bound_calibration]``; without one ``calibrated_bound_m`` is NaN.

    Returns
    -------
    list of dict
        Keys ``motion``, ``q`` (shape (n_joints,) [rad or m]), ``tip`` (standard model, shape (3,)
        [m]; NaN where the exact bound failed), ``bound_position_m`` and ``planned_bound_m`` [m],
        ``calibrated_bound_m`` [m] (:func:`calibrated_bound`; NaN without a calibration in the
        robot file), ``bound_angle_rad`` [rad], ``bound_kind``, ``predicted_tip`` (shape (3,) [m]),
        ``predicted_offset_m`` [m], ``prediction_eta`` and ``prediction_cases``
        (:func:`ctrplan.report.write_plan_outputs`).
    """
    lm, planned, pred = plan.bounds.exact, plan.bounds.planned, plan.prediction
    calibrated = calibrated_bound(calibration, lm.position)
    rows = []
    for k, w in enumerate(plan.ordered.waypoints):
        res = lm.results[k]
        tip = res.standard.tip_position if res is not None else np.full(3, np.nan)
        rows.append({"motion": w.motion, "q": w.q, "tip": tip, "bound_position_m": float(lm.position[k]),
                     "calibrated_bound_m": float(calibrated[k]),
                     "planned_bound_m": float(planned[k]), "bound_angle_rad": float(lm.angle[k]),
                     "bound_kind": "translation_last" if w.motion == "translation" else "friction",
                     "predicted_tip": pred.tip[k], "predicted_offset_m": float(pred.offset[k]),
                     "prediction_eta": _eta_text(pred.eta_used[k]), "prediction_cases": pred.cases[k]})
    return rows


def _route_summary(r: RoutePlan) -> dict:
    """The summary of one plan (report units: mm, degrees)."""
    lmr, b, pr = r.bounds.exact, r.bounds, r.prediction
    return {
        "cost": float(sum(leg.cost for leg in r.legs)),
        "max_predicted_offset_at_waypoints_mm": float(np.nanmax(pr.offset) * 1e3)
        if np.any(np.isfinite(pr.offset)) else None,
        "final_predicted_offset_mm": float(pr.offset[-1] * 1e3),
        "predictions_failed": int(np.sum(~pr.ok)),
        "prediction_contact_solves": int(pr.n_solved), "prediction_time_s": pr.time_s,
        "final_motion": dict(zip((f"goal_{k + 1}" for k in range(len(r.goal_indices))),
                                 r.final_motion_status)),
        "joint_path_length_m": float(b.dense_s[-1]),
        "n_ordered_waypoints": len(r.ordered),
        "max_bound_at_waypoints_mm": float(np.nanmax(lmr.position) * 1e3),
        "final_bound_mm": float(lmr.position[-1] * 1e3),
        "final_bound_angle_deg": float(np.degrees(lmr.angle[-1])),
        "max_interpolated_friction_bound_along_path_mm": float(np.nanmax(b.dense_friction) * 1e3),
        "max_interpolated_bound_given_last_motion_mm": float(np.nanmax(b.dense_given_last) * 1e3),
        "mean_interpolated_friction_bound_along_path_mm": float(np.nanmean(b.dense_friction) * 1e3),
        "max_planned_bound_at_waypoints_mm": float(np.nanmax(b.planned) * 1e3),
        "max_planned_minus_exact_bound_mm": float(np.nanmax(np.abs(b.planned - lmr.position)) * 1e3),
        "planning_time_s": r.plan_time_s, "exact_model_time_s": r.exact_time_s,
        "checks": r.checks,
        "final_check": {"phases_checked": r.ordered.n_phase_checks, "bisections": r.ordered.n_subdivisions,
                        "repairs": r.ordered.n_repairs, "failures": list(r.ordered.failures),
                        "max_body_step_mm": r.max_body_step_m * 1e3},
        "planner": [{"planner": leg.planner, "iterations": leg.iterations, "n_vertices": leg.n_vertices,
                     "solve_time_s": leg.solve_time, "simplify_time_s": leg.simplify_time,
                     "seed": leg.seed, "status": leg.status, "cost": leg.cost} for leg in r.legs],
    }


def _goal_prediction(goal_docs, aimed: AimedGoals, plan: RoutePlan, robot, validation) -> dict:
    """Per goal: the model it was aimed with and that model's measured tip error (from the robot
    file; None when not measured), the predicted miss of standard-model IK next to the
    compensated one (task-space goals, with the assumed approach), and the tip predicted at the
    goal's waypoint of the plan (with the history the ordered plan creates there). Report units
    (mm)."""
    pred = plan.prediction
    aim = aimed.aim or aim_decision(validation)
    out = {}
    for k, (doc, c, gi) in enumerate(zip(goal_docs, aimed.compensations, plan.goal_indices)):
        planned_eta, _, planned_cases = pair_friction(pred.state.at(gi), robot.friction_coefficients)
        entry = {"waypoint": int(gi), "final_motion_status": plan.final_motion_status[k],
                 "planned_eta": _eta_text(planned_eta), "planned_cases": ";".join(planned_cases),
                 "predicted_offset_at_goal_mm": float(pred.offset[gi] * 1e3)}
        if isinstance(doc, TaskGoal):
            entry.update({"aimed_with": aim["model"], "aim_reason": aim["reason"],
                          "measured_error_of_aiming_model_mean_mm": aim["measured_mean_mm"],
                          "measured_error_of_aiming_model_max_mm": aim["measured_max_mm"],
                          "expected_real_miss_note": (
                              "the predicted miss is the model's own; the real tip lands about the measured error "
                              "of the model aimed with away" if aim["measured_mean_mm"] is not None else
                              "the predicted miss is the model's own; its real error is not measured")})
        if k in aimed.errors:
            entry.update({"compensation_used": False, "compensation_message": aimed.errors[k]})
        if c is not None:
            assumed_eta, _, assumed_cases = pair_friction(c.state, robot.friction_coefficients)
            entry.update({
                "assumed_eta": _eta_text(assumed_eta), "assumed_cases": ";".join(assumed_cases),
                "planned_history_as_assumed": bool(np.array_equal(assumed_eta, planned_eta)
                                                   and assumed_cases == planned_cases),
                "prediction_model": c.model,
                "predicted_miss_standard_ik_mm": c.predicted_miss_standard * 1e3,
                "predicted_miss_compensated_mm": c.predicted_miss * 1e3,
                "standard_tip_error_compensated_mm": c.standard_tip_error * 1e3,
                "compensation_used": c.accepted, "compensation_iterations": c.iterations,
                "compensation_message": c.message,
                "predicted_miss_at_planned_goal_mm": float(np.linalg.norm(pred.tip[gi] - c.target) * 1e3),
                "tolerance_mm": float(doc.tolerance * 1e3),
            })
        out[f"goal_{k + 1}"] = entry
    return out


def _robot_effects(robot) -> dict:
    """The robot file's history and measurement effects (its ``[effects]``) and what planning
    does with each (``Effect.plan``); values under keys with their unit suffix."""
    from .effects import file_key

    out = {}
    effects = robot_effects(robot)
    for name in effects:
        entry = REGISTRY[name]
        specs = {p.name: p for p in entry.parameters(robot)}
        out[name] = {"label": entry.label, **{file_key(specs[p]): v for p, v in effects[name].items()},
                     "planning": entry.plan}
    return out


def _bound_calibration(cal, weight: float) -> dict:
    """What the bound the plan ranks paths by stands for (``summary.json["bound_calibration"]``)."""
    if cal is None:
        return {"calibrated": False, "note": "the bound is the model's (Ha et al. 2019, Sec. III), not validated on "
                                             "measurements: the robot file has no [bound_calibration]"}
    cov = cal.test_coverage
    return {"calibrated": True, "factor": cal.factor, "noise_margin_mm": cal.noise_margin_m * 1e3,
            "target_coverage": cal.target_coverage, "test_coverage": cov,
            "test_coverage_interval": [cal.test_coverage_low, cal.test_coverage_high],
            "failing": bool(cal.failing), "data_file": cal.data_file,
            "effective_bound_weight_per_metre": effective_bound_weight(cal, weight),
            "note": (f"paths ranked by the calibrated bound {cal.factor:.3g} x (bound + "
                     f"{cal.noise_margin_m * 1e3:.2f} mm), validated at "
                     + ("-" if cov is None else f"{100 * cov:.0f} %") + f" coverage of measured tips (target "
                     f"{100 * cal.target_coverage:.0f} %) on {cal.data_file or 'unnamed data'}"
                     + ("; FAILING its target on the test split" if cal.failing else
                        "; conservative on the test split" if cal.status == "conservative" else ""))}


def plan_summary(setup: PlanSetup, bound_map: BoundMapStage, validity, resolved: ResolvedGoals,
                 aimed: AimedGoals, plans: Plans, traj) -> dict:
    """The run's summary as ``summary.json`` stores it (report units: keys ending ``_mm`` in mm,
    ``_deg`` in degrees, ``_m`` in m, ``_s`` in s).

    Parameters
    ----------
    setup, bound_map, resolved, aimed, plans
        The results of stages 1-5.
    validity : BatchValidityChecker
        :func:`check_start`'s checker (its call counters are reported).
    traj : Trajectory or None
        Stage 6's trajectory.

    Returns
    -------
    dict
        Scenario (its name and ``scenario_file``, the resolved path it was read from) and robot,
        the goals (resolved and planned, with the map's bound there), the goal
        predictions, the bound map, the bound-aware plan (and the bound-blind one with a
        ``comparison`` of the headline metrics), the trajectory's duration, model-evaluation
        counts and stage times. ``times_s["total"]`` is None (set by :func:`run_plan` before
        writing).
    """
    sc, robot, field = setup.scenario, setup.robot, bound_map.field
    routes, aware = plans.routes, plans.aware
    summary = {
        "scenario": sc.name, "scenario_file": str(sc.file), "robot": robot.name, "robot_source": robot.source,
        "joints": robot.joint_names,
        "goals": [{"q": g.q.tolist(), "tip_error_mm": g.tip_error * 1e3, "field_bound_mm": g.bound * 1e3,
                   "n_candidates": int(len(g.candidates)), "q_planned": np.asarray(qp).tolist(),
                   "field_bound_planned_mm": float(field(np.asarray(qp))) * 1e3}
                  for g, qp in zip(resolved.goals, aimed.q)],
        "final_motion": aimed.final_motion,
        "robot_effects": _robot_effects(robot),
        "aiming": {k: v for k, v in (aimed.aim or aim_decision(sc.calibration.prediction)).items()
                   if k != "validation"},
        "bound_calibration": _bound_calibration(sc.calibration.bound, sc.planner.bound_weight),
        "goal_prediction": _goal_prediction(sc.goals, aimed, aware, robot, sc.calibration.prediction),
        "bound_map": {"source": bound_map.source, "time_s": bound_map.time_s, "coordinates": field.coordinate_names,
                      "resolution": list(field.shape), "placement": setup.spec.placement, "key": field.key,
                      "mechanics_version": field.metadata.get("mechanics_version"), "ds_m": setup.settings.ds},
        "bound_aware": _route_summary(aware),
        "duration_s": float(traj.duration) if traj is not None else None,
        "model_evaluations": {
            "validity_calls": int(sum(r.checks["validity_calls"] for r in routes.values()) + validity.n_calls),
            "standard_model_solves": int(sum(r.checks["standard_model_solves"] for r in routes.values())
                                         + validity.n_model),
            "collision_time_s": float(sum(r.checks["search_collision_time_s"] for r in routes.values())
                                      + validity.seconds_collision),
            "ik_model_evaluations": int(sum(g.n_model_evaluations for g in resolved.goals)),
            "exact_bound_evaluations": int(sum(len(r.ordered) for r in routes.values())),
        },
        "times_s": {"bound_map": bound_map.time_s, "inverse_kinematics": resolved.time_s,
                    "compensation": aimed.time_s, "prediction_at_waypoints": aware.prediction.time_s,
                    "plans_wall": plans.time_s, "plans_in_parallel": plans.in_parallel, "total": None},
        "bound_weight_per_metre": sc.planner.bound_weight,
    }
    if "bound_blind" in routes:
        blind = _route_summary(routes["bound_blind"])
        summary["bound_blind"] = blind
        a = summary["bound_aware"]
        metrics = ("max_bound_at_waypoints_mm", "max_interpolated_bound_given_last_motion_mm",
                   "max_interpolated_friction_bound_along_path_mm",
                   "mean_interpolated_friction_bound_along_path_mm", "final_bound_mm", "joint_path_length_m")
        # max_bound_at_waypoints_mm is the exact bound given the last motion (friction after a
        # rotation, translation-last after a translation): the headline comparison, since the
        # friction bound at the goal itself is the same for both plans.
        summary["comparison"] = {k: {"bound_aware": a[k], "bound_blind": blind[k]} for k in metrics}
    return summary


@deprecated_echo
def write_report(setup: PlanSetup, plans: Plans, traj, rows, summary: dict, echo=None) -> dict:
    """Write path.csv, trajectory.csv, the figures, the interactive view ``plan.html`` and
    summary.json (last) into ``setup.out_dir``.

    Every file is written atomically (:func:`ctrplan.report.write_plan_outputs`); the figures
    plot bounds in mm. ``plan.html`` (:func:`ctrplan.view.write_plan_view`) shows the bound-aware
    plan at every ordered waypoint (standard, predicted and friction-solution shapes), the
    obstacles and the goal tips (task-space targets; the standard-model tip at a joint goal's
    waypoint), with no further model solves.

    Parameters
    ----------
    setup : PlanSetup
    plans : Plans
    traj : Trajectory or None
    rows : list of dict
        :func:`path_rows` of the bound-aware plan.
    summary : dict
        :func:`plan_summary`, with ``times_s["total"]`` set.
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).

    Returns
    -------
    dict of str to Path
        Written files by name.
    """
    from .plots import plot_bound_along_path, plot_joint_trajectories, plot_robot_shapes
    from .report import format_summary, write_plan_outputs
    from .view import PLAN_VIEW_FILE, write_plan_view

    sc, robot = setup.scenario, setup.robot
    shapes, tips = [], []
    for res in plans.aware.bounds.exact.results:
        if res is None:
            continue
        shapes.append(res.standard.centerline)
        tips.append(np.array([f.tip_position for f in res.friction.values()]))
    obstacles = list(sc.obstacles)
    routes = plans.routes
    labels = [m.replace("_", "-") + " plan" for m in routes]
    bounds = [routes[m].bounds for m in routes]

    def fig_shapes(path):
        plot_robot_shapes(path, shapes, obstacles, tips, title=f"{sc.name}: robot at the ordered waypoints")

    def fig_bound(path):
        plot_bound_along_path(path, [b.dense_s for b in bounds],
                              [np.asarray(b.dense_friction) * 1e3 for b in bounds],
                              [np.asarray(b.dense_translation_last) * 1e3 for b in bounds],
                              [b.dense_motion for b in bounds], labels=labels,
                              s_label="joint-space path length [m, weighted metric]",
                              title=f"{sc.name}: interpolated bound along the ordered path")

    aware = plans.aware
    exact = aware.bounds.exact
    results = exact.results
    targets = []
    for doc, gi in zip(sc.goals, aware.goal_indices):
        tip = getattr(doc, "tip_position", None)
        if tip is None and results[gi] is not None:
            tip = results[gi].standard.tip_position
        targets.append(np.full(3, np.nan) if tip is None else np.asarray(tip, dtype=float))
    pred = aware.prediction

    def view(path):
        write_plan_view(
            path, [None if r is None else r.standard.centerline for r in results],
            friction_tips=[None if r is None else [f.tip_position for f in r.friction.values()]
                           for r in results],
            friction_shapes=[None if r is None else [f.centerlines[-1] for f in r.friction.values()]
                             for r in results],
            predicted_tips=pred.tip, predicted_shapes=pred.shape or None, obstacles=obstacles,
            targets=np.array(targets).reshape(-1, 3),
            step_labels=[str(k) for k in range(len(results))],
            step_notes=[f"{m}, bound {1e3 * b:.2f} mm, predicted offset {1e3 * o:.2f} mm"
                        for m, b, o in zip(aware.ordered.motions, exact.position, pred.offset)],
            title=f"{sc.name} (bound-aware plan)")

    figures = {"robot_shapes.png": fig_shapes, "bound_along_path.png": fig_bound, PLAN_VIEW_FILE: view}
    if traj is not None:
        figures["joint_trajectories.png"] = lambda path: plot_joint_trajectories(
            path, traj, robot.joint_names, [j.kind for j in robot.joints], title=f"{sc.name}: drive trajectory")
    written = write_plan_outputs(setup.out_dir, rows, traj, summary, joint_names=robot.joint_names,
                                 figures=figures)
    logger.debug(f"wrote {', '.join(written)} into {setup.out_dir}")
    logger.log(progress_level(), format_summary(summary))
    return written


# --------------------------------------------------------------------------- the job
@deprecated_echo
def run_plan(scenario_path, out_dir=None, n_jobs: int = 1, iterations: int | None = None,
             compare_blind: bool = True, echo=None, *, progress: bool = False) -> dict:
    """Plan, order, time-parameterize and report one scenario (``ctrplan plan``).

    Parameters
    ----------
    scenario_path : path
        Scenario TOML file.
    out_dir : path, optional
        Output folder (default: the scenario's ``[output] dir``, else ``out/<scenario name>``).
    n_jobs : int
        Worker processes: for a bound map that must be computed, and, with 2 or more, the
        bound-blind plan runs beside the bound-aware one (same results as in series).
    iterations : int, optional
        Overrides the scenario's planner iterations.
    compare_blind : bool
        Also plan bound-blind (length only, same planner and seed) and compare.
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher; configure :mod:`logging` instead (logger ``ctrplan``).
    progress : bool, keyword-only
        tqdm bars while a bound map is computed (default none).

    Returns
    -------
    dict
        The summary written to ``summary.json`` (plus ``output_dir``).

    Raises
    ------
    ModelFileError
        Malformed scenario or robot file.
    UnreachableGoalError
        Invalid start, unreachable goal, or no valid path within the budget.
    JointLimitError
        The time-parameterized trajectory violates the drive limits.
    """
    return plan_stages(scenario_path, out_dir, n_jobs=n_jobs, iterations=iterations,
                       compare_blind=compare_blind, progress=progress).summary


@dataclass(frozen=True, eq=False)
class PlanRun:
    """What :func:`plan_stages` computed: every stage's result and the summary it wrote.

    Attributes
    ----------
    setup : PlanSetup
    bound_map : BoundMapStage
    resolved : ResolvedGoals
    aimed : AimedGoals
    plans : Plans
    trajectory : Trajectory or None
        Stage 6's drive trajectory (None without a ``[drive]`` table).
    rows : list of dict
        :func:`path_rows` of the bound-aware plan (SI units).
    summary : dict
        The summary written to ``summary.json`` (report units), plus ``output_dir``.
    """

    setup: PlanSetup
    bound_map: BoundMapStage
    resolved: ResolvedGoals
    aimed: AimedGoals
    plans: Plans
    trajectory: Any
    rows: list
    summary: dict


@deprecated_echo
def plan_stages(scenario_path, out_dir=None, *, n_jobs: int = 1, iterations: int | None = None,
                compare_blind: bool = True, echo=None, progress: bool = False) -> PlanRun:
    """:func:`run_plan` returning every stage's result as well as the summary.

    Parameters and exceptions as :func:`run_plan`; the same files are written.

    Returns
    -------
    PlanRun
    """
    t_start = time.perf_counter()
    setup = load_setup(scenario_path, out_dir)
    bound_map = load_bound_map(setup, n_jobs, progress=progress)
    validity = check_start(setup, bound_map.field)
    resolved = resolve_goals(setup, bound_map.field, validity)
    aimed = aim_goals(setup, resolved, validity)
    plans = plan_routes(setup, bound_map.field, aimed, iterations=iterations, compare_blind=compare_blind,
                        n_jobs=n_jobs)
    traj = time_parameterize(setup, plans.aware.ordered)
    rows = path_rows(plans.aware, setup.scenario.calibration.bound)
    summary = plan_summary(setup, bound_map, validity, resolved, aimed, plans, traj)
    summary["times_s"]["total"] = time.perf_counter() - t_start
    write_report(setup, plans, traj, rows, summary)
    summary["output_dir"] = str(setup.out_dir)
    return PlanRun(setup=setup, bound_map=bound_map, resolved=resolved, aimed=aimed, plans=plans, trajectory=traj,
                   rows=rows, summary=summary)
