"""Plan a scenario from Python: :func:`plan`, the entry point, and :func:`plan_scenario`, what
``ctrplan plan`` does with one scenario file.

:func:`plan` takes its inputs as objects (a loaded scenario, optionally a robot and its bound
map) and writes no file unless given ``out_dir``; it returns a frozen :class:`PlanResult` in SI
units (m, rad, s), for scripts and for the assertions of :mod:`ctrplan.testing`, which also holds
every stage's result (:class:`ctrplan.planning.PlanRun`). Neither prints anything: the lines
``ctrplan plan`` shows are logged at INFO under the ``ctrplan`` logger
(``logging.basicConfig(level=logging.INFO)`` shows them).
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ._log import deprecated_echo
from .boundmap import BoundField
from .calibration import RobotCalibration
from .io.scenario import Scenario, load_scenario
from .planning import (BoundMapStage, PlanRun, default_out_dir, given_bound_map, prepare_bound_map, log_summary,
                       plan_summary, run_stages, setup_plan, write_plan_report)
from .robot import Robot
from .trajectory import Trajectory

__all__ = ["PlanResult", "plan", "plan_scenario", "write_plan_ros2"]


@dataclass(frozen=True, eq=False)
class PlanResult:
    """The bound-aware plan of a scenario, ordered and time-parameterized.

    K is the number of ordered waypoints (the rows of ``path.csv``).

    Attributes
    ----------
    scenario : Scenario
        The scenario planned (:func:`ctrplan.io.scenario.load_scenario`).
    robot : Robot
        Its robot.
    joint_names : tuple of str
        Robot joint names, the order of the columns of ``q``.
    q : ndarray, shape (K, n_joints)
        Ordered waypoints [rad or m]; periodic angles continuous along the path.
    motion : ndarray of str, shape (K,)
        The phase that ends at each waypoint: ``"start"``, ``"rotation"`` or ``"translation"``.
    tip : ndarray, shape (K, 3)
        Standard-model tip position [m]; NaN where the exact bound failed.
    bound_position_m : ndarray, shape (K,)
        Exact tip-error bound given the last motion [m]: the friction bound after the start and
        a rotation, the translation-last bound after a translation (Section V-B of Ha, Fagogenis &
        Dupont 2019); NaN where it failed.
    calibrated_bound_m : ndarray, shape (K,)
        The robot file's calibrated bound ``factor (bound + noise margin)`` [m]
        (``[bound_calibration]``, :meth:`ctrplan.calibration.CalibratedBound.apply`); NaN without
        one.
    bound_kind : ndarray of str, shape (K,)
        ``"friction"`` or ``"translation_last"``.
    predicted_tip : ndarray, shape (K, 3)
        Tip predicted for the motion history the ordered plan creates [m]; NaN where the
        prediction failed.
    goal_waypoints : tuple of int
        Index of the waypoint where each scenario goal is reached, in the scenario's order.
    trajectory : ctrplan.trajectory.Trajectory or None
        The drive trajectory (ruckig, rest to rest at every waypoint); None when the scenario has
        no ``[drive]`` table.
    output_dir : pathlib.Path or None
        Folder of ``path.csv``, ``trajectory.csv``, ``summary.json`` and the figures; None when
        no file was written.
    timings_s : dict of str to float
        Stage times [s] (``bound_map``, ``inverse_kinematics``, ``compensation``,
        ``prediction_at_waypoints``, ``plans_wall``, ``refinement``, ``plans_in_parallel`` (bool),
        ``total``).
    run : ctrplan.planning.PlanRun
        Every stage's result (SI units): the bound map, the resolved and aimed goals, both plans
        with their exact bounds and predictions, the map's refinement (``run.refinement``), the
        comparison of the bound-aware plan with the bound-blind one (``run.comparison``), the
        outcome at each goal (``run.goals``).
    """

    scenario: Scenario
    robot: Robot
    joint_names: tuple
    q: np.ndarray
    motion: np.ndarray
    tip: np.ndarray
    bound_position_m: np.ndarray
    calibrated_bound_m: np.ndarray
    bound_kind: np.ndarray
    predicted_tip: np.ndarray
    goal_waypoints: tuple
    trajectory: Trajectory | None
    output_dir: Path | None
    timings_s: dict
    run: PlanRun

    @cached_property
    def summary(self) -> dict:
        """The content of ``summary.json`` (report units: keys ending ``_mm`` in mm, ``_deg`` in
        degrees, ``_s`` in s; :func:`ctrplan.planning.plan_summary`), plus ``output_dir`` when
        files were written."""
        out = plan_summary(self.run)
        if self.output_dir is not None:
            out["output_dir"] = str(self.output_dir)
        return out

    def write(self, out_dir: str | os.PathLike) -> dict:
        """Write the files of ``ctrplan plan`` (``path.csv``, ``trajectory.csv``, the figures,
        ``plan.html``, ``summary.json`` last, each atomically) into a folder.

        Parameters
        ----------
        out_dir : str or path-like
            Output folder (created if missing).

        Returns
        -------
        dict of str to pathlib.Path
            Written files by name.
        """
        return write_plan_report(self.run, out_dir)


def _result(run: PlanRun, output_dir: Path | None) -> PlanResult:
    table, aware, robot = run.waypoints, run.plans.aware, run.setup.robot
    return PlanResult(
        scenario=run.setup.scenario, robot=robot, joint_names=tuple(robot.joint_names), q=table.q,
        motion=table.motion, tip=table.tip, bound_position_m=table.bound_position_m,
        calibrated_bound_m=table.calibrated_bound_m, bound_kind=table.bound_kind, predicted_tip=table.predicted_tip,
        goal_waypoints=tuple(int(g) for g in aware.goal_indices), trajectory=run.trajectory,
        output_dir=output_dir, timings_s=run.timings_s, run=run)


def plan(scenario: Scenario | str | os.PathLike, *, bound_map: BoundField | BoundMapStage | None = None,
         robot: Robot | None = None, calibration: RobotCalibration | None = None,
         out_dir: str | os.PathLike | None = None, n_jobs: int = 1, iterations: int | None = None,
         compare_blind: bool = True, progress: bool = False) -> PlanResult:
    """Plan, order and time-parameterize one scenario, bound-aware (and bound-blind to compare).

    The stages of :mod:`ctrplan.planning`: the start and the goals checked, task-space goals
    resolved and aimed, every leg planned with the bound as a cost (length + weight x integral
    of the bound), ordered into rotations then translations, checked, the exact bound and the
    predicted tip evaluated at its waypoints, the drive trajectory computed (Ha, Fagogenis &
    Dupont 2019, Section V-B).

    Parameters
    ----------
    scenario : Scenario or str or path-like
        A loaded scenario (:func:`ctrplan.io.scenario.load_scenario`), or its TOML file (SI units).
    bound_map : BoundField or BoundMapStage, keyword-only, optional
        The bound map to plan with, over the robot's map coordinates [m, rad]; default the robot
        file's shipped or cached map for the scenario's ``[bound_field]``; if there is none, a
        preview map (computed and cached) refined where the plan goes (``[bound_field]
        first_plan``, ``refine_rounds``; docs/boundmaps.md), or with ``first_plan = "full"`` the
        map computed (and cached).
    robot : Robot, keyword-only, optional
        Plan for this robot instead of the scenario's (same joint names, in the same order); its
        bound map must then be given (maps on disk are keyed by the robot file's bytes).
    calibration : RobotCalibration, keyword-only, optional
        The robot's records of measurements (calibrated bound, validated prediction); default the
        scenario's (``Scenario.calibration``), none with a given ``robot``.
    out_dir : str or path-like, keyword-only, optional
        Write the files of ``ctrplan plan`` there (created if missing); default none written
        (:meth:`PlanResult.write` writes them later).
    n_jobs : int, keyword-only
        Worker processes: for a bound map that must be computed, and, with 2 or more, the
        bound-blind plan runs beside the bound-aware one (same result as in series).
    iterations : int, keyword-only, optional
        Overrides the scenario's planner iterations.
    compare_blind : bool, keyword-only
        Also plan bound-blind (length only, same planner and seed) and compare.
    progress : bool, keyword-only
        tqdm bars while a bound map is computed (default none).

    Returns
    -------
    PlanResult
        The bound-aware plan; ``result.run`` holds every stage's result.

    Raises
    ------
    ModelFileError
        Malformed scenario or robot file, or a start or joint goal outside the joint limits.
    ValueError
        A ``robot`` with other joints than the scenario's, or without a ``bound_map``; a bound map
        over other coordinates than the robot's map coordinates.
    UnreachableGoalError
        Invalid start, unreachable goal, or no valid path within the budget.
    JointLimitError
        The time-parameterized trajectory violates the drive limits.
    """
    from .mechanics import warmup

    t0 = time.perf_counter()
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if robot is not None:
        if list(robot.joint_names) != list(sc.robot.joint_names):
            raise ValueError(f"robot {robot.name!r} has joints {robot.joint_names}, the scenario's robot "
                             f"{sc.robot.joint_names}")
        if bound_map is None:
            raise ValueError(f"robot {robot.name!r} is given without its bound map: maps on disk are keyed by the "
                             "robot file's bytes; give bound_map (e.g. ctrplan.boundmap.compute_field)")
        sc = dataclasses.replace(sc, robot=robot, calibration=RobotCalibration())
    if calibration is not None:
        sc = dataclasses.replace(sc, calibration=calibration)
    warmup.start()   # the final check's contact kernels compile beside planning on a cold start
    setup = setup_plan(sc, out_dir)
    if bound_map is None:
        stage = prepare_bound_map(setup, n_jobs, progress=progress)
    elif isinstance(bound_map, BoundMapStage):
        stage = bound_map
    else:
        stage = given_bound_map(setup, bound_map)
    run = run_stages(setup, stage, iterations=iterations, compare_blind=compare_blind, n_jobs=n_jobs, started=t0)
    summary = plan_summary(run)
    if setup.out_dir is not None:
        write_plan_report(run, setup.out_dir, summary=summary)
    log_summary(summary)
    return _result(run, setup.out_dir)


@deprecated_echo
def plan_scenario(scenario: Scenario | str | os.PathLike, out_dir: str | os.PathLike | None = None, *,
                  n_jobs: int = 1, iterations: int | None = None, compare_blind: bool = True,
                  echo: Callable[[str], Any] | None = None, progress: bool = False) -> PlanResult:
    """Plan, order, time-parameterize and report one scenario, as ``ctrplan plan`` does:
    :func:`plan` writing its files.

    Parameters
    ----------
    scenario : Scenario or str or path-like
        Scenario TOML file (``docs/file-formats.md``; SI units), or the loaded scenario.
    out_dir : str or path-like, optional
        Output folder; default the scenario's ``[output] dir``, else ``out/<scenario name>``.
    n_jobs : int, keyword-only
        Worker processes: for a bound map that must be computed, and, with 2 or more, the
        bound-blind plan runs beside the bound-aware one.
    iterations : int, optional, keyword-only
        Overrides the scenario's planner iterations.
    compare_blind : bool, keyword-only
        Also plan bound-blind (length only, same planner and seed) and compare in the summary.
    echo : callable, optional, keyword-only
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher (the progress lines and the summary); configure :mod:`logging` instead.
    progress : bool, keyword-only
        tqdm bars while a bound map is computed (default none; ``ctrplan plan`` shows them).

    Returns
    -------
    PlanResult
        The bound-aware plan; the files written are those of ``ctrplan plan``.

    Raises
    ------
    ModelFileError
        Malformed scenario or robot file, or a start or joint goal outside the joint limits.
    UnreachableGoalError
        Invalid start, unreachable goal, or no valid path within the budget.
    JointLimitError
        The time-parameterized trajectory violates the drive limits.
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(Path(scenario))
    return plan(sc, out_dir=out_dir if out_dir else default_out_dir(sc), n_jobs=n_jobs, iterations=iterations,
                compare_blind=compare_blind, progress=progress)


def write_plan_ros2(result: PlanResult, out: str | os.PathLike, *, storage: str = "mcap", distro: str = "jazzy",
                    frame_id: str = "ctr_base", yaml_path: str | os.PathLike | None = None) -> dict[str, Path]:
    """Write a plan for ROS 2: a rosbag2 folder for RViz, Foxglove or ``ros2 bag play``, and the
    drive trajectory as the YAML message ``ros2 topic pub`` accepts.

    The bag (:func:`ctrplan.io.ros2.write_plan_bag`) holds the trajectory as
    ``trajectory_msgs/msg/JointTrajectory`` and its samples as joint states, the waypoint tips
    as ``nav_msgs/msg/Path`` (orientation: the standard model's tip frame, z the tangent) and
    the bound as ``visualization_msgs/msg/MarkerArray`` spheres of diameter twice the bound
    given the last motion at each waypoint tip: the calibrated bound where the robot file has a
    ``[bound_calibration]``, else the exact one. Joint names are the robot file's.

    Parameters
    ----------
    result : PlanResult
        A plan with a drive trajectory (the scenario's ``[drive]`` table).
    out : str or path-like
        Bag folder to create (replaced only if it is a plan bag written by ctrplan).
    storage : BagStorage or str
        ``"mcap"`` or ``"sqlite3"``.
    distro : RosDistro or str
        ``"humble"`` or ``"jazzy"``.
        Message definitions of the bag.
    frame_id : str
        Frame of the tip path and the spheres (the robot's base frame).
    yaml_path : str or path-like, optional
        Where to write the trajectory YAML; default ``joint_trajectory.yaml`` in the plan's
        output folder, or beside the bag folder for a plan written to no folder.

    Returns
    -------
    dict of str to Path
        ``{"bag": ..., "yaml": ...}``.

    Raises
    ------
    ValueError
        The plan has no drive trajectory, or bad storage or distro.
    FileExistsError
        ``out`` exists and is not a plan bag written by ctrplan.
    """
    from .io.atomic import atomic_write_text
    from .io.ros2 import PlanBagContent, trajectory_yaml, write_plan_bag
    from .mechanics import ModelSettings, solve_standard

    traj = result.trajectory
    if traj is None:
        raise ValueError(f"scenario {result.scenario.name!r} has no [drive] table, so no drive trajectory to write "
                         f"for ROS 2")
    calibrated = np.isfinite(result.calibrated_bound_m)
    radius = np.where(calibrated, result.calibrated_bound_m, result.bound_position_m)
    rotations = np.tile(np.eye(3), (len(result.q), 1, 1))
    settings = ModelSettings(multistart=0)
    for k, q in enumerate(result.q):
        if not np.all(np.isfinite(result.tip[k])):
            continue
        alpha, beta = result.robot.configuration(q, check_limits=False)
        sol = solve_standard(result.robot, alpha, beta, settings, check_stability=False)
        rotations[k] = sol.tip_rotation
    keep = np.all(np.isfinite(result.tip), axis=1)
    content = PlanBagContent(joint_names=traj.joint_names, t=traj.t, position=traj.position, velocity=traj.velocity,
                             acceleration=traj.acceleration, tips=result.tip[keep], tip_rotations=rotations[keep],
                             bound_radius=radius[keep],
                             bound_label="calibrated_bound" if calibrated.any() else "bound", frame_id=frame_id)
    bag = write_plan_bag(out, content, storage=storage, distro=distro)
    if yaml_path is not None:
        yaml_file = Path(yaml_path)
    else:
        yaml_file = (result.output_dir if result.output_dir is not None else Path(out).parent) / "joint_trajectory.yaml"
    atomic_write_text(yaml_file, trajectory_yaml(traj.joint_names, traj.t, traj.position, traj.velocity,
                                                 traj.acceleration, frame_id=frame_id))
    return {"bag": bag, "yaml": yaml_file}
