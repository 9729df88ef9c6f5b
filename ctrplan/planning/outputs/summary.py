"""The report of a run as a dict in report units, as ``summary.json`` stores it and ``ctrplan plan``
prints it (:func:`plan_summary`), and back (:func:`read_plan_record`).

Keys ending ``_mm`` are in mm, ``_deg`` in degrees, ``_m`` in m and ``_s`` in s.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from ...calibration import CalibratedBound
from ...effects import REGISTRY, robot_effects
from ...io.scenario import TaskGoal
from ..aiming import AimDecision, _eta_text, aim_reason
from ..comparison import PlanComparison, RouteMetrics
from ..plans import RoutePlan, effective_bound_weight

__all__ = ["COMPARED", "plan_summary", "PlanRecord", "read_plan_record"]

#: The metrics of ``summary.json["comparison"]``, bound-aware against bound-blind: keys of the
#: plans' summaries. ``max_bound_at_waypoints_mm`` (the exact bound given the last motion:
#: friction after a rotation, translation-last after a translation) is the headline comparison,
#: since the friction bound at the goal itself is the same for both plans.
COMPARED = ("max_bound_at_waypoints_mm", "max_interpolated_bound_given_last_motion_mm",
            "max_interpolated_friction_bound_along_path_mm", "mean_interpolated_friction_bound_along_path_mm",
            "final_bound_mm", "joint_path_length_m")


def _mm(x: float | None) -> float | None:
    """Metres to millimetres (None stays None)."""
    return None if x is None else x * 1e3


def _route_summary(r: RoutePlan, m: RouteMetrics) -> dict:
    """The summary of one plan (report units: mm, degrees)."""
    pr = r.prediction
    return {
        "cost": m.cost,
        "max_predicted_offset_at_waypoints_mm": None if math.isnan(m.max_predicted_offset_m)
        else m.max_predicted_offset_m * 1e3,
        "final_predicted_offset_mm": m.final_predicted_offset_m * 1e3,
        "predictions_failed": m.predictions_failed,
        "prediction_contact_solves": int(pr.n_solved), "prediction_time_s": pr.time_s,
        "final_motion": dict(zip((f"goal_{k + 1}" for k in range(len(r.goal_indices))),
                                 r.final_motion_status)),
        "joint_path_length_m": m.joint_path_length_m,
        "n_ordered_waypoints": m.n_ordered_waypoints,
        "max_bound_at_waypoints_mm": m.max_bound_at_waypoints_m * 1e3,
        "final_bound_mm": m.final_bound_m * 1e3,
        "final_bound_angle_deg": float(np.degrees(m.final_bound_angle_rad)),
        "max_interpolated_friction_bound_along_path_mm": m.max_interpolated_friction_bound_m * 1e3,
        "max_interpolated_bound_given_last_motion_mm": m.max_interpolated_bound_given_last_motion_m * 1e3,
        "mean_interpolated_friction_bound_along_path_mm": m.mean_interpolated_friction_bound_m * 1e3,
        "max_planned_bound_at_waypoints_mm": m.max_planned_bound_at_waypoints_m * 1e3,
        "max_planned_minus_exact_bound_mm": m.max_planned_minus_exact_bound_m * 1e3,
        "planning_time_s": r.plan_time_s, "exact_model_time_s": r.exact_time_s,
        "checks": r.checks,
        "final_check": {"phases_checked": r.ordered.n_phase_checks, "bisections": r.ordered.n_subdivisions,
                        "repairs": m.repairs, "failures": list(m.failures),
                        "max_body_step_mm": r.max_body_step_m * 1e3},
        "planner": [{"planner": leg.planner, "iterations": leg.iterations, "n_vertices": leg.n_vertices,
                     "solve_time_s": leg.solve_time, "simplify_time_s": leg.simplify_time,
                     "seed": leg.seed, "status": leg.status, "cost": leg.cost} for leg in r.legs],
    }


def _aiming(aim: AimDecision) -> dict:
    """``summary.json["aiming"]``: the model goals are aimed with, why, and its measured error."""
    return {"model": aim.model, "use_history": aim.use_history, "why": aim.why.value, "reason": aim_reason(aim),
            "measured_mean_mm": _mm(aim.measured_mean_m), "measured_max_mm": _mm(aim.measured_max_m)}


def _goal_prediction(run) -> dict:
    """Per goal: the model it was aimed with and that model's measured tip error (from the robot
    file; None when not measured), the predicted miss of standard-model IK next to the
    compensated one (task-space goals, with the assumed approach), and the tip predicted at the
    goal's waypoint of the plan (with the history the ordered plan creates there)."""
    aimed, aim = run.aimed, run.aimed.aim
    out = {}
    for k, (doc, c, g) in enumerate(zip(run.setup.scenario.goals, aimed.compensations, run.goals)):
        entry = {"waypoint": g.waypoint, "final_motion_status": g.final_motion_status,
                 "planned_eta": _eta_text(g.planned_eta), "planned_cases": ";".join(g.planned_cases),
                 "predicted_offset_at_goal_mm": g.predicted_offset_m * 1e3}
        if isinstance(doc, TaskGoal):
            entry.update({"aimed_with": aim.model, "aim_reason": aim_reason(aim),
                          "measured_error_of_aiming_model_mean_mm": _mm(aim.measured_mean_m),
                          "measured_error_of_aiming_model_max_mm": _mm(aim.measured_max_m),
                          "expected_real_miss_note": (
                              "the predicted miss is the model's own; the real tip lands about the measured error "
                              "of the model aimed with away" if aim.measured_mean_m is not None else
                              "the predicted miss is the model's own; its real error is not measured")})
        if k in aimed.errors:
            entry.update({"compensation_used": False, "compensation_message": aimed.errors[k]})
        if c is not None:
            entry.update({
                "assumed_eta": _eta_text(g.assumed_eta), "assumed_cases": ";".join(g.assumed_cases),
                "planned_history_as_assumed": g.planned_history_as_assumed,
                "prediction_model": c.model,
                "predicted_miss_standard_ik_mm": c.predicted_miss_standard * 1e3,
                "predicted_miss_compensated_mm": c.predicted_miss * 1e3,
                "standard_tip_error_compensated_mm": c.standard_tip_error * 1e3,
                "compensation_used": c.accepted, "compensation_iterations": c.iterations,
                "compensation_message": c.message,
                "predicted_miss_at_planned_goal_mm": g.predicted_miss_m * 1e3,
                "tolerance_mm": float(doc.tolerance * 1e3),
            })
        out[f"goal_{k + 1}"] = entry
    return out


def _robot_effects(robot) -> dict:
    """The robot file's history and measurement effects (its ``[effects]``) and what planning
    does with each (``Effect.plan``); values under keys with their unit suffix."""
    from ...effects import file_key

    out = {}
    effects = robot_effects(robot)
    for name in effects:
        entry = REGISTRY[name]
        specs = {p.name: p for p in entry.parameters(robot)}
        out[name] = {"label": entry.label, **{file_key(specs[p]): v for p, v in effects[name].items()},
                     "planning": entry.plan}
    return out


def _bound_calibration(cal: CalibratedBound | None, weight: float) -> dict:
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
                        "; conservative on the test split" if (cal.conservative or cal.status == "conservative")
                        else "; its coverage is not shown on the test split (its interval reaches below the "
                             "target)" if cal.status == "not shown" else ""))}


def plan_summary(run) -> dict:
    """The run's summary as ``summary.json`` stores it (report units: keys ending ``_mm`` in mm,
    ``_deg`` in degrees, ``_m`` in m, ``_s`` in s).

    Parameters
    ----------
    run : PlanRun
        Every stage's result (:func:`~ctrplan.planning.run.run_stages`).

    Returns
    -------
    dict
        Scenario (its name and ``scenario_file``, the resolved path it was read from) and robot,
        the goals (resolved and planned, with the map's bound there), the goal predictions, the
        bound map, the bound-aware plan (and the bound-blind one with a ``comparison`` of the
        headline metrics :data:`COMPARED`), the trajectory's duration, model-evaluation counts,
        stage times (``times_s``, with the run's ``total``) and the roadmap the legs went through
        (``roadmap``: states, motions, source, file, time [s]; None without).
    """
    setup, field, plans = run.setup, run.bound_map.field, run.plans
    ref = run.refinement
    sc, robot = setup.scenario, setup.robot
    routes = plans.routes
    summary = {
        "scenario": sc.name, "scenario_file": str(sc.file), "robot": robot.name, "robot_source": robot.source,
        "joints": robot.joint_names,
        "goals": [{"q": g.q.tolist(), "tip_error_mm": g.tip_error * 1e3, "field_bound_mm": g.bound * 1e3,
                   "n_candidates": int(len(g.candidates)), "q_planned": np.asarray(qp).tolist(),
                   "field_bound_planned_mm": outcome.planned_field_bound_m * 1e3}
                  for g, qp, outcome in zip(run.resolved.goals, run.aimed.q, run.goals)],
        "final_motion": run.aimed.final_motion,
        "robot_effects": _robot_effects(robot),
        "aiming": _aiming(run.aimed.aim),
        "bound_calibration": _bound_calibration(setup.calibration.bound, sc.planner.bound_weight),
        "goal_prediction": _goal_prediction(run),
        "bound_map": {"source": run.bound_map.source, "time_s": run.bound_map.time_s,
                      "coordinates": field.coordinate_names, "resolution": list(field.shape),
                      "placement": setup.spec.placement, "key": field.key,
                      "mechanics_version": field.metadata.get("mechanics_version"), "ds_m": setup.settings.ds,
                      "preview": run.bound_map.preview,
                      "refinement": None if ref is None else {
                          "plans": len(ref.rounds), "converged": ref.converged,
                          "tolerance_mm": ref.tolerance * 1e3, "exact_samples": ref.samples.n,
                          "exact_nodes": ref.n_nodes, "node_evaluations": ref.node_evaluations,
                          "node_time_s": ref.node_time_s, "resolution": list(ref.field.shape), "time_s": ref.time_s,
                          "max_map_minus_exact_at_waypoints_mm": [r.max_error * 1e3 for r in ref.rounds],
                          "median_map_minus_exact_at_waypoints_mm": [r.median_error * 1e3 for r in ref.rounds]}},
        "bound_aware": _route_summary(plans.aware, run.comparison.aware),
        "duration_s": float(run.trajectory.duration) if run.trajectory is not None else None,
        "model_evaluations": {
            "validity_calls": int(sum(r.checks["validity_calls"] for r in routes.values()) + run.goal_checks.n_calls),
            "standard_model_solves": int(sum(r.checks["standard_model_solves"] for r in routes.values())
                                         + run.goal_checks.n_model),
            "collision_time_s": float(sum(r.checks["search_collision_time_s"] for r in routes.values())
                                      + run.goal_checks.collision_time_s),
            "ik_model_evaluations": int(sum(g.n_model_evaluations for g in run.resolved.goals)),
            "exact_bound_evaluations": int(sum(len(r.ordered) for r in routes.values())),
        },
        "times_s": run.timings_s,
        "bound_weight_per_metre": sc.planner.bound_weight,
        "roadmap": plans.roadmap,
    }
    if run.comparison.blind is not None:
        blind = _route_summary(routes["bound_blind"], run.comparison.blind)
        summary["bound_blind"] = blind
        aware = summary["bound_aware"]
        summary["comparison"] = {k: {"bound_aware": aware[k], "bound_blind": blind[k]} for k in COMPARED}
    return summary


# --------------------------------------------------------------------------- back from summary.json
@dataclass(frozen=True)
class PlanRecord:
    """What a finished run's ``summary.json`` says of its plans, back in SI units
    (:func:`read_plan_record`).

    Attributes
    ----------
    comparison : PlanComparison
        The headline numbers of the bound-aware plan and, if planned, the bound-blind one.
    time_s : float or None
        The run's total time [s].
    """

    comparison: PlanComparison
    time_s: float | None


def _metrics(entry: Mapping) -> RouteMetrics:
    """A plan's summary (report units) as :class:`RouteMetrics` (SI)."""
    offset = entry["max_predicted_offset_at_waypoints_mm"]
    nan = math.nan

    def m(key):
        value = entry[key]
        return nan if value is None else value / 1e3

    return RouteMetrics(
        cost=entry["cost"], joint_path_length_m=entry["joint_path_length_m"],
        n_ordered_waypoints=entry["n_ordered_waypoints"], max_bound_at_waypoints_m=m("max_bound_at_waypoints_mm"),
        final_bound_m=m("final_bound_mm"), final_bound_angle_rad=math.radians(entry["final_bound_angle_deg"]),
        max_interpolated_friction_bound_m=m("max_interpolated_friction_bound_along_path_mm"),
        mean_interpolated_friction_bound_m=m("mean_interpolated_friction_bound_along_path_mm"),
        max_interpolated_bound_given_last_motion_m=m("max_interpolated_bound_given_last_motion_mm"),
        max_planned_bound_at_waypoints_m=m("max_planned_bound_at_waypoints_mm"),
        max_planned_minus_exact_bound_m=m("max_planned_minus_exact_bound_mm"),
        max_predicted_offset_m=nan if offset is None else offset / 1e3,
        final_predicted_offset_m=m("final_predicted_offset_mm"), predictions_failed=entry["predictions_failed"],
        repairs=entry["final_check"]["repairs"], failures=tuple(entry["final_check"]["failures"]))


def read_plan_record(path: str | os.PathLike) -> PlanRecord:
    """Read what a finished run's ``summary.json`` says of its plans.

    Parameters
    ----------
    path : str or path-like
        A ``summary.json`` written by :func:`ctrplan.plan` / ``ctrplan plan``.

    Returns
    -------
    PlanRecord

    Raises
    ------
    FileNotFoundError
    ValueError
        Not JSON, or not the summary of a plan (a key missing, e.g. one written by an older
        version).
    """
    data = json.loads(Path(path).read_text())
    try:
        blind = data.get("bound_blind")
        comparison = PlanComparison(aware=_metrics(data["bound_aware"]),
                                    blind=None if blind is None else _metrics(blind))
        return PlanRecord(comparison=comparison, time_s=data["times_s"]["total"])
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not the summary of a plan ({type(exc).__name__}: {exc})") from None
