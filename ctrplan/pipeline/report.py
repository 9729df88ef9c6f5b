"""The report stage: ``path.csv`` rows, the figures, ``plan.html`` and ``summary.json`` of a run
(millimetres and degrees only here and in :mod:`~ctrplan.pipeline.summary`)."""

from __future__ import annotations

import logging

import numpy as np

from .._log import deprecated_echo, progress_level
from .goals import _eta_text
from .routes import Plans, RoutePlan
from .setup import PlanSetup

__all__ = ["calibrated_bound", "path_rows", "write_report"]

logger = logging.getLogger(__package__)


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
    from ..plots import plot_bound_along_path, plot_joint_trajectories, plot_robot_shapes
    from ..report import format_summary, write_plan_outputs
    from ..view import PLAN_VIEW_FILE, write_plan_view

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
