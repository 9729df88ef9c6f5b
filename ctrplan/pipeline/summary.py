"""The run's summary in report units (mm, degrees), as ``summary.json`` stores it and ``ctrplan
plan`` prints it."""

from __future__ import annotations

import numpy as np

from ..effects import REGISTRY, robot_effects
from ..history import pair_friction
from ..io.scenario import TaskGoal
from .bound_map import BoundMapStage
from .goals import AimedGoals, ResolvedGoals, _eta_text, aim_decision
from .routes import Plans, RoutePlan, effective_bound_weight
from .setup import PlanSetup

__all__ = ["plan_summary"]


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
    from ..effects import file_key

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
