"""One call that plans a scenario and returns its results as arrays: :func:`plan_scenario`.

A thin layer over :func:`ctrplan.pipeline.plan_stages` (the same stages and output files as
``ctrplan plan``); the result is a frozen :class:`PlanResult` in SI units (m, rad, s), for scripts
and for the assertions of :mod:`ctrplan.testing`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = ["PlanResult", "plan_scenario", "write_plan_ros2"]


@dataclass(frozen=True, eq=False)
class PlanResult:
    """The bound-aware plan of a scenario, ordered and time-parameterized.

    K is the number of ordered waypoints (the rows of ``path.csv``).

    Attributes
    ----------
    scenario : Scenario
        The loaded scenario (:func:`ctrplan.io.scenario.load_scenario`).
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
        (``[bound_calibration]``, :func:`ctrplan.pipeline.calibrated_bound`); NaN without one.
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
    summary : dict
        The content of ``summary.json`` (report units: keys ending ``_mm`` in mm, ``_deg`` in
        degrees, ``_s`` in s), plus ``output_dir``.
    output_dir : pathlib.Path
        Folder of ``path.csv``, ``trajectory.csv``, ``summary.json`` and the figures.
    timings_s : dict of str to float
        Stage times [s] (``summary["times_s"]``: ``bound_map``, ``inverse_kinematics``, ...,
        ``total``).
    """

    scenario: Any
    robot: Any
    joint_names: tuple
    q: np.ndarray
    motion: np.ndarray
    tip: np.ndarray
    bound_position_m: np.ndarray
    calibrated_bound_m: np.ndarray
    bound_kind: np.ndarray
    predicted_tip: np.ndarray
    goal_waypoints: tuple
    trajectory: Any
    summary: dict
    output_dir: Path
    timings_s: dict


def plan_scenario(scenario: str | os.PathLike, out_dir: str | os.PathLike | None = None, *, n_jobs: int = 1,
                  iterations: int | None = None, compare_blind: bool = True,
                  echo: Callable[[str], Any] = print) -> PlanResult:
    """Plan, order, time-parameterize and report one scenario, as ``ctrplan plan`` does.

    Parameters
    ----------
    scenario : str or path-like
        Scenario TOML file (``docs/file-formats.md``; SI units).
    out_dir : str or path-like, optional
        Output folder; default the scenario's ``[output] dir``, else ``out/<scenario name>``.
    n_jobs : int, keyword-only
        Worker processes: for a bound map that must be computed, and, with 2 or more, the
        bound-blind plan runs beside the bound-aware one.
    iterations : int, optional, keyword-only
        Overrides the scenario's planner iterations.
    compare_blind : bool, keyword-only
        Also plan bound-blind (length only, same planner and seed) and compare in the summary.
    echo : callable, keyword-only
        Receives progress messages and the human-readable summary (``lambda *a: None`` for
        silence).

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
    from .mechanics import warmup
    from .pipeline import plan_stages

    warmup.start()   # the final check's contact kernels compile beside planning on a cold start
    run = plan_stages(Path(scenario), out_dir, n_jobs=n_jobs, iterations=iterations,
                      compare_blind=compare_blind, echo=echo)
    aware, robot = run.plans.aware, run.setup.robot
    return PlanResult(
        scenario=run.setup.scenario, robot=robot, joint_names=tuple(robot.joint_names),
        q=np.array(aware.ordered.q, dtype=float), motion=np.array(aware.ordered.motions),
        tip=np.array([r["tip"] for r in run.rows], dtype=float).reshape(-1, 3),
        bound_position_m=np.array(aware.bounds.exact.position, dtype=float),
        calibrated_bound_m=np.array([r["calibrated_bound_m"] for r in run.rows], dtype=float),
        bound_kind=np.array([r["bound_kind"] for r in run.rows]),
        predicted_tip=np.array(aware.prediction.tip, dtype=float).reshape(-1, 3),
        goal_waypoints=tuple(int(g) for g in aware.goal_indices), trajectory=run.trajectory,
        summary=run.summary, output_dir=Path(run.setup.out_dir), timings_s=dict(run.summary["times_s"]))


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
    storage : {"mcap", "sqlite3"}
    distro : {"humble", "jazzy"}
        Message definitions of the bag.
    frame_id : str
        Frame of the tip path and the spheres (the robot's base frame).
    yaml_path : str or path-like, optional
        Where to write the trajectory YAML; default ``joint_trajectory.yaml`` in the plan's
        output folder.

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
    yaml_file = Path(yaml_path) if yaml_path is not None else result.output_dir / "joint_trajectory.yaml"
    atomic_write_text(yaml_file, trajectory_yaml(traj.joint_names, traj.t, traj.position, traj.velocity,
                                                 traj.acceleration, frame_id=frame_id))
    return {"bag": bag, "yaml": yaml_file}
