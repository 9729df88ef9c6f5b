"""The files of a run (:func:`write_plan_report`: ``path.csv``, ``trajectory.csv``, the figures,
``plan.html`` and ``summary.json``) and its printed summary (:func:`log_summary`).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from ..._log import progress_level
from ..aiming import _eta_text
from ..waypoints import WaypointTable
from .summary import plan_summary

__all__ = ["path_rows", "write_plan_report", "log_summary"]

logger = logging.getLogger(__package__)


def path_rows(table: WaypointTable) -> list[dict]:
    """Rows of ``path.csv``, one per ordered waypoint (SI units, as the file stores them).

    Parameters
    ----------
    table : WaypointTable
        The plan's waypoints (``PlanRun.waypoints``).

    Returns
    -------
    list of dict
        Keys ``motion``, ``q`` (shape (n_joints,) [rad or m]), ``tip`` (standard model, shape (3,)
        [m]; NaN where the exact bound failed), ``bound_position_m`` and ``planned_bound_m`` [m],
        ``calibrated_bound_m`` [m] (NaN without a calibration in the robot file),
        ``bound_angle_rad`` [rad], ``bound_kind``, ``predicted_tip`` (shape (3,) [m]),
        ``predicted_offset_m`` [m], ``prediction_eta`` and ``prediction_cases``
        (:func:`~ctrplan.planning.outputs.folder.write_plan_outputs`).
    """
    t = table
    return [{"motion": str(t.motion[k]), "q": t.q[k], "tip": t.tip[k], "bound_position_m": float(t.bound_position_m[k]),
             "calibrated_bound_m": float(t.calibrated_bound_m[k]), "planned_bound_m": float(t.planned_bound_m[k]),
             "bound_angle_rad": float(t.bound_angle_rad[k]), "bound_kind": str(t.bound_kind[k]),
             "predicted_tip": t.predicted_tip[k], "predicted_offset_m": float(t.predicted_offset_m[k]),
             "prediction_eta": _eta_text(t.prediction_eta[k]), "prediction_cases": t.prediction_cases[k]}
            for k in range(len(t))]


def log_summary(summary: dict) -> None:
    """Log the run's summary as ``ctrplan plan`` prints it: one record, one ``label: value unit``
    line per key (:func:`~ctrplan.planning.outputs.folder.format_summary`), at the progress level (INFO, DEBUG in a
    study).

    Parameters
    ----------
    summary : dict
        :func:`~ctrplan.planning.outputs.summary.plan_summary`.
    """
    from .folder import format_summary

    logger.log(progress_level(), format_summary(summary))


def write_plan_report(run, out_dir: str | os.PathLike | None = None, *, summary: dict | None = None) -> dict:
    """Write path.csv, trajectory.csv, the figures, the interactive view ``plan.html`` and
    summary.json (last) of a run.

    Every file is written atomically (:func:`~ctrplan.planning.outputs.folder.write_plan_outputs`); the figures
    plot bounds in mm. ``plan.html`` (:func:`~ctrplan.planning.outputs.view.write_plan_view`) shows the bound-aware
    plan at every ordered waypoint (standard, predicted and friction-solution shapes), the
    obstacles and the goal tips (task-space targets; the standard-model tip at a joint goal's
    waypoint), with no further model solves.

    Parameters
    ----------
    run : PlanRun
        Every stage's result (:func:`~ctrplan.planning.run.run_stages`).
    out_dir : str or path-like, optional
        Output folder (created if missing); default ``run.setup.out_dir``.
    summary : dict, optional, keyword-only
        :func:`~ctrplan.planning.outputs.summary.plan_summary` of the run, if already made.

    Returns
    -------
    dict of str to Path
        Written files by name.

    Raises
    ------
    ValueError
        No output folder: neither ``out_dir`` nor ``run.setup.out_dir``.
    """
    from .figures import BoundProfile, plot_bound_along_path, plot_joint_trajectories, plot_robot_shapes
    from .folder import write_plan_outputs
    from .view import PLAN_VIEW_FILE, WaypointFrames, write_plan_view

    out = Path(out_dir) if out_dir is not None else run.setup.out_dir
    if out is None:
        raise ValueError("no output folder: give out_dir (the run was set up without one)")
    summary = plan_summary(run) if summary is None else summary
    sc, robot, plans, traj = run.setup.scenario, run.setup.robot, run.plans, run.trajectory
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
        profiles = [BoundProfile(b.dense_s, b.dense_friction, b.dense_translation_last, b.dense_motion,
                                 given_last=b.dense_given_last, label=label) for b, label in zip(bounds, labels)]
        plot_bound_along_path(path, profiles, s_label="joint-space path length [m, weighted metric]",
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
        frames = WaypointFrames(
            [None if r is None else r.standard.centerline for r in results],
            friction_tips=[None if r is None else [f.tip_position for f in r.friction.values()]
                           for r in results],
            friction_shapes=[None if r is None else [f.centerlines[-1] for f in r.friction.values()]
                             for r in results],
            predicted_tips=pred.tip, predicted_shapes=pred.shape or None,
            labels=[str(k) for k in range(len(results))],
            notes=[f"{m}, bound {1e3 * b:.2f} mm, predicted offset {1e3 * o:.2f} mm"
                   for m, b, o in zip(aware.ordered.motions, exact.position, pred.offset)])
        write_plan_view(path, frames, obstacles=obstacles, targets=np.array(targets).reshape(-1, 3),
                        title=f"{sc.name} (bound-aware plan)")

    figures = {"robot_shapes.png": fig_shapes, "bound_along_path.png": fig_bound, PLAN_VIEW_FILE: view}
    if traj is not None:
        figures["joint_trajectories.png"] = lambda path: plot_joint_trajectories(
            path, traj, robot.joint_names, [j.kind for j in robot.joints], title=f"{sc.name}: drive trajectory")
    written = write_plan_outputs(out, path_rows(run.waypoints), traj, summary, joint_names=robot.joint_names,
                                 figures=figures)
    logger.debug(f"wrote {', '.join(written)} into {out}")
    return written
