"""The main job: a bound-aware plan for a scenario, ordered, time-parameterized and reported.

``run_plan(scenario)``:

1. load the scenario and its robot; load the robot's bound map (shipped in
   ``<robot dir>/boundmaps/`` as ``.npz`` or ``.zarr``, or cached) or compute it into a zarr store
   (local cores or a Dask cluster, resumable);
2. resolve each goal (task-space goals by inverse kinematics preferring the smallest bound), then
   aim task-space goals with the tip *predicted* after the final approach (``[planner]
   final_motion``: translation-last, the default, or rotation-last; Section V-B of Ha et al.
   2019) instead of the standard model's tip (:func:`ctrplan.planning.goals.compensate_goal`);
3. plan every leg twice with the same planner and seed: bound-aware (length + weight x integral
   of the bound) and bound-blind (length only);
4. order every segment into rotations then translations (Section V-B of Ha et al. 2019) and check
   both phases; the phases reaching each goal are swapped if the final motion asks for it;
5. re-run the exact model at the final waypoints and report the bound given the last motion, and
   the tip predicted for the history the ordered plan creates (one contact solve at most per
   waypoint, usually none: the bound's own solutions are reused);
6. time-parameterize with ruckig (rest-to-rest, stop between phases), check the samples;
7. write path.csv, trajectory.csv, figures and summary.json atomically.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .boundmap import MapSpec, default_spec, load_or_compute_bound_map
from .errors import JointLimitError, UnreachableGoalError
from .errors import CtrplanError
from .io.scenario import TaskGoal, load_scenario
from .mechanics import ModelSettings, evaluate_bound, pair_cases, predict_tip
from .planning import BoundCostObjective, JointStateSpace, bounds_given_last_motion, resolve_goal
from .planning.goals import compensate_goal
from .planning.history import approach_history, end_with, goal_indices, path_history
from .planning.route import DEFAULT_REWIRE_FACTOR, plan_route, route_checks

__all__ = ["run_plan", "map_spec"]

# Spacing of interpolated-bound samples along an ordered path for the bound plot and the
# max-bound comparison [m of the weighted joint metric].
PATH_SAMPLE_SPACING = 2e-3


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


def _route_report(ordered, robot, field, settings, joint_space):
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
    return {"dense_q": qd, "dense_s": sd, "dense_motion": md, "dense_friction": friction,
            "dense_translation_last": tlast, "dense_given_last": given_last, "planned": planned,
            "exact": bounds_given_last_motion(ordered, robot, evaluate_bound, settings)}


def _eta_text(eta) -> str:
    """Per-pair directions as text, e.g. ``+1;-1`` (0: no friction on that pair)."""
    return ";".join(f"{int(e):+d}" if e else "0" for e in eta)


def _predictions(ordered, robot, settings, exact) -> dict:
    """Tip predicted at every ordered waypoint for the history the ordered path creates.

    The history (:func:`ctrplan.planning.history.path_history`) gives per pair eta and whether
    a translation followed the last rotation; :func:`ctrplan.mechanics.predict_tip` reuses the
    exact bound's clearance or friction solution at the waypoint when it is the one needed, and
    solves only partial histories. Waypoints where the bound failed, or the prediction raises,
    get NaN."""
    t0 = time.perf_counter()
    hist = path_history(robot, ordered.q)
    K, m = len(ordered), robot.n_tubes - 1
    tips = np.full((K, 3), np.nan)
    offsets = np.full(K, np.nan)
    eta_used = np.zeros((K, m), dtype=int)
    cases, models, messages = [""] * K, [""] * K, [""] * K
    ok = np.zeros(K, dtype=bool)
    n_solved = 0
    for k in range(K):
        res = exact.results[k]
        eta, tl = hist.at(k)
        try:
            if res is None:
                raise CtrplanError("the exact bound failed here")
            alpha, beta = robot.configuration(ordered.q[k], check_limits=False)
            p = predict_tip(robot, alpha, beta, eta, tl, settings, bound=res)
        except (CtrplanError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
            messages[k] = f"{type(exc).__name__}: {exc}"
            eta_used[k], _, c = pair_cases(robot, eta, tl)
            cases[k] = ";".join(c)
            continue
        n_solved += not p.reused
        tips[k], offsets[k], eta_used[k] = p.tip_position, p.offset, p.eta
        cases[k], models[k], ok[k] = ";".join(p.cases), p.model, p.ok
        messages[k] = p.solution.diagnostics.message
    return {"tip": tips, "offset": offsets, "eta": hist.eta, "translation_last": hist.translation_last,
            "eta_used": eta_used, "cases": cases, "model": models, "ok": ok, "message": messages,
            "n_solved": n_solved, "time_s": time.perf_counter() - t0}


def _plan_mode(job: dict) -> dict:
    """One plan of a scenario (bound-aware or bound-blind): search, ordering, final check and the
    report. Takes and returns only picklable data, so that it can run in another process."""
    robot, field = job["robot"], job["field"]
    joint_space = JointStateSpace(robot)
    checks = route_checks(robot, job["obstacles"], field, job["check_settings"], joint_space=joint_space)
    p = job["planner"]
    t0 = time.perf_counter()
    route = plan_route(robot, job["start"], job["goals"], checks,
                       BoundCostObjective.factory(field, bound_weight=job["weight"]), planner=p.name,
                       iterations=job["iterations"], seed=p.seed, time_limit=p.time_limit, range_=p.range,
                       joint_space=joint_space,
                       rewire_factor=p.rewire_factor if p.rewire_factor is not None else DEFAULT_REWIRE_FACTOR)
    ordered = route.ordered
    # the motion reaching each goal ends as the scenario asks (swap its last two phases if needed
    # and if the swapped phases pass the final check)
    idx = goal_indices(ordered, job["goals"], robot)
    final_status = []
    for gi in idx:
        ordered, status = end_with(ordered, gi, job["final_motion"], checks.final.check)
        final_status.append(status)
    plan_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    rep = _route_report(ordered, robot, field, job["settings"], joint_space)
    exact_time = time.perf_counter() - t0
    pred = _predictions(ordered, robot, job["settings"], rep["exact"])
    return dict(legs=route.legs, ordered=ordered, report=rep, plan_time=plan_time, exact_time=exact_time,
                checks=checks.counters(), max_body_step_mm=checks.final.max_body_step * 1e3,
                prediction=pred, goal_indices=idx, final_motion_status=final_status)


def _plan_modes(jobs: dict, n_jobs: int) -> tuple[dict, bool]:
    """Run the plans of ``jobs`` ({mode: job}); with ``n_jobs`` >= 2 and more than one plan, the
    bound-blind plan runs in a forked process while this one plans bound-aware (the plans are
    independent and seeded, so the result is the same as in series; a failed child process is
    replaced by the same plan here). Returns ({mode: result}, whether they ran in parallel)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    modes = list(jobs)
    parallel = n_jobs >= 2 and len(modes) > 1 and "fork" in multiprocessing.get_all_start_methods()
    if not parallel:
        return {m: _plan_mode(jobs[m]) for m in modes}, False
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


def _goal_prediction(goal_docs, compensations, plan, robot, errors) -> dict:
    """Per goal: the predicted miss of standard-model IK next to the compensated one (task-space
    goals, with the assumed approach), and the tip predicted at the goal's waypoint of the plan
    (with the history the ordered plan creates there)."""
    pred = plan["prediction"]
    out = {}
    for k, (doc, c, gi) in enumerate(zip(goal_docs, compensations, plan["goal_indices"])):
        planned_eta, _, planned_cases = pair_cases(robot, *(pred["eta"][gi], pred["translation_last"][gi]))
        entry = {"waypoint": int(gi), "final_motion_status": plan["final_motion_status"][k],
                 "planned_eta": _eta_text(planned_eta), "planned_cases": ";".join(planned_cases),
                 "predicted_offset_at_goal_mm": float(pred["offset"][gi] * 1e3)}
        if k in errors:
            entry.update({"compensation_used": False, "compensation_message": errors[k]})
        if c is not None:
            assumed_eta, _, assumed_cases = pair_cases(robot, c.eta, c.translation_last)
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
                "predicted_miss_at_planned_goal_mm": float(np.linalg.norm(pred["tip"][gi] - c.target) * 1e3),
                "tolerance_mm": float(doc.tolerance * 1e3),
            })
        out[f"goal_{k + 1}"] = entry
    return out


def run_plan(scenario_path, out_dir=None, n_jobs: int = 1, iterations: int | None = None,
             compare_blind: bool = True, echo=print) -> dict:
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
    echo : callable
        Progress messages.

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
    """
    from .plots import plot_bound_along_path, plot_joint_trajectories, plot_robot_shapes
    from .report import format_summary, write_plan_outputs
    from .trajectory import check_trajectory, time_parameterize_robot

    t_start = time.perf_counter()
    sc = load_scenario(scenario_path)
    robot = sc.robot
    settings = ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()
    spec = map_spec(sc)
    out = Path(out_dir) if out_dir else (sc.output_dir or Path("out") / sc.name)
    echo(f"scenario {sc.name}: robot {robot.name} ({', '.join(robot.joint_names)})")

    field, map_source, map_time = load_or_compute_bound_map(sc.robot_file, robot, spec, settings,
                                                             n_jobs=n_jobs, echo=echo)
    echo(f"bound map: {map_source} in {map_time:.1f} s")
    check_settings = settings.replace(multistart=0)  # the map flags multi-equilibrium regions
    joint_space = JointStateSpace(robot)
    obstacles = [o.as_dict() for o in sc.obstacles]
    validity = route_checks(robot, obstacles, field, check_settings, joint_space=joint_space).search
    if not validity(sc.start):
        raise UnreachableGoalError(f"{sc.file}: start configuration {sc.joint_dict(sc.start)} is invalid "
                                   "(collision, elastic instability or outside the bound map's valid region)")
    t0 = time.perf_counter()
    goals = [resolve_goal(g, robot, validity_fn=validity, field=field, settings=check_settings, seed=k + 1)
             for k, g in enumerate(sc.goals)]
    ik_time = time.perf_counter() - t0
    for k, g in enumerate(goals):
        echo(f"goal {k + 1}: q = {np.round(g.q, 4).tolist()}, tip error {g.tip_error * 1e3:.3f} mm, "
             f"field bound {g.bound * 1e3:.2f} mm ({len(g.candidates)} candidates)")
    # compensated targeting: aim task-space goals with the tip predicted after the final approach,
    # assumed to be one straight segment from the previous goal (or the start), ordered as
    # [planner] final_motion asks (directions of the relative rotations the short way)
    final_motion = sc.planner.final_motion
    t0 = time.perf_counter()
    compensations, goal_q, q_prev = [], [], np.asarray(sc.start, dtype=float)
    compensation_errors = {}
    for k, (doc, g) in enumerate(zip(sc.goals, goals)):
        c = None
        if isinstance(doc, TaskGoal):
            eta, tl = approach_history(robot, q_prev, g.q, final_motion)
            try:
                c = compensate_goal(doc.tip_position, robot, g.q, eta, tl, settings, tolerance=doc.tolerance,
                                    validity_fn=validity)
            except CtrplanError as exc:   # no prediction at the standard solution: plan to it, say why
                compensation_errors[k] = f"{type(exc).__name__}: {exc}"
                echo(f"goal {k + 1}: no compensation ({compensation_errors[k]}); planning to the standard-model goal")
        if c is not None:
            echo(f"goal {k + 1} ({final_motion}, {c.model} model, eta {_eta_text(c.eta)}): predicted miss of "
                 f"standard-model IK {c.predicted_miss_standard * 1e3:.3f} mm, compensated "
                 f"{c.predicted_miss * 1e3:.3f} mm ({'used' if c.accepted else 'not used: ' + c.message}); "
                 f"q = {np.round(c.q, 4).tolist()}")
        compensations.append(c)
        goal_q.append(c.q if c is not None else g.q)
        q_prev = goal_q[-1]
    compensation_time = time.perf_counter() - t0
    iters = iterations or sc.planner.iterations
    modes = [("bound_aware", sc.planner.bound_weight)] + ([("bound_blind", 0.0)] if compare_blind else [])
    jobs = {mode: dict(robot=robot, field=field, obstacles=obstacles, check_settings=check_settings, settings=settings,
                       start=sc.start, goals=goal_q, weight=weight, planner=sc.planner, iterations=iters,
                       final_motion=final_motion)
            for mode, weight in modes}
    t0 = time.perf_counter()
    routes, in_parallel = _plan_modes(jobs, n_jobs)
    plans_time = time.perf_counter() - t0
    for mode, r in routes.items():
        lm = r["report"]["exact"]
        ordered = r["ordered"]
        echo(f"{mode}: {len(ordered)} ordered waypoints, planning {r['plan_time']:.1f} s "
             f"({r['checks']['search_states_evaluated']} states checked, final check "
             f"{r['checks']['final_check_states']} states, "
             f"{ordered.n_subdivisions} bisections, {ordered.n_repairs} repairs); exact bound at waypoints: "
             f"max {np.nanmax(lm.position) * 1e3:.2f} mm, final {lm.position[-1] * 1e3:.2f} mm")

    aware = routes["bound_aware"]
    ordered = aware["ordered"]
    traj = time_parameterize_robot(robot, ordered.q, ordered.motions, **sc.drive.as_kwargs()) \
        if sc.drive is not None else None
    violations = check_trajectory(traj) if traj is not None else []
    if violations:
        raise JointLimitError(f"{sc.file}: the time-parameterized trajectory violates the drive limits: "
                              + "; ".join(str(v) for v in violations[:5]))

    lm = aware["report"]["exact"]
    planned = aware["report"]["planned"]
    pred = aware["prediction"]
    rows = []
    for k, w in enumerate(ordered.waypoints):
        res = lm.results[k]
        tip = res.standard.tip_position if res is not None else np.full(3, np.nan)
        rows.append({"motion": w.motion, "q": w.q, "tip": tip, "bound_position_m": float(lm.position[k]),
                     "planned_bound_m": float(planned[k]), "bound_angle_rad": float(lm.angle[k]),
                     "bound_kind": "translation_last" if w.motion == "translation" else "friction",
                     "predicted_tip": pred["tip"][k], "predicted_offset_m": float(pred["offset"][k]),
                     "prediction_eta": _eta_text(pred["eta_used"][k]), "prediction_cases": pred["cases"][k]})

    def route_summary(r):
        lmr = r["report"]["exact"]
        rep = r["report"]
        pr = r["prediction"]
        return {
            "cost": float(sum(leg.cost for leg in r["legs"])),
            "max_predicted_offset_at_waypoints_mm": float(np.nanmax(pr["offset"]) * 1e3)
            if np.any(np.isfinite(pr["offset"])) else None,
            "final_predicted_offset_mm": float(pr["offset"][-1] * 1e3),
            "predictions_failed": int(np.sum(~pr["ok"])),
            "prediction_contact_solves": int(pr["n_solved"]), "prediction_time_s": pr["time_s"],
            "final_motion": dict(zip((f"goal_{k + 1}" for k in range(len(r["goal_indices"]))),
                                     r["final_motion_status"])),
            "joint_path_length_m": float(rep["dense_s"][-1]),
            "n_ordered_waypoints": len(r["ordered"]),
            "max_bound_at_waypoints_mm": float(np.nanmax(lmr.position) * 1e3),
            "final_bound_mm": float(lmr.position[-1] * 1e3),
            "final_bound_angle_deg": float(np.degrees(lmr.angle[-1])),
            "max_interpolated_friction_bound_along_path_mm": float(np.nanmax(rep["dense_friction"]) * 1e3),
            "max_interpolated_bound_given_last_motion_mm": float(np.nanmax(rep["dense_given_last"]) * 1e3),
            "mean_interpolated_friction_bound_along_path_mm": float(np.nanmean(rep["dense_friction"]) * 1e3),
            "max_planned_bound_at_waypoints_mm": float(np.nanmax(rep["planned"]) * 1e3),
            "max_planned_minus_exact_bound_mm": float(np.nanmax(np.abs(rep["planned"] - lmr.position)) * 1e3),
            "planning_time_s": r["plan_time"], "exact_model_time_s": r["exact_time"],
            "checks": r["checks"],
            "final_check": {"phases_checked": r["ordered"].n_phase_checks, "bisections": r["ordered"].n_subdivisions,
                            "repairs": r["ordered"].n_repairs, "failures": list(r["ordered"].failures),
                            "max_body_step_mm": r["max_body_step_mm"]},
            "planner": [{"planner": leg.planner, "iterations": leg.iterations, "n_vertices": leg.n_vertices,
                         "solve_time_s": leg.solve_time, "simplify_time_s": leg.simplify_time,
                         "seed": leg.seed, "status": leg.status, "cost": leg.cost} for leg in r["legs"]],
        }

    summary = {
        "scenario": sc.name, "robot": robot.name, "robot_source": robot.source,
        "joints": robot.joint_names,
        "goals": [{"q": g.q.tolist(), "tip_error_mm": g.tip_error * 1e3, "field_bound_mm": g.bound * 1e3,
                   "n_candidates": int(len(g.candidates)), "q_planned": np.asarray(qp).tolist(),
                   "field_bound_planned_mm": float(field(np.asarray(qp))) * 1e3}
                  for g, qp in zip(goals, goal_q)],
        "final_motion": final_motion,
        "goal_prediction": _goal_prediction(sc.goals, compensations, aware, robot, compensation_errors),
        "bound_map": {"source": map_source, "time_s": map_time, "coordinates": field.coordinate_names,
                      "resolution": list(field.shape), "placement": spec.placement, "key": field.key,
                      "mechanics_version": field.metadata.get("mechanics_version"), "ds_m": settings.ds},
        "bound_aware": route_summary(aware),
        "duration_s": float(traj.duration) if traj is not None else None,
        "model_evaluations": {
            "validity_calls": int(sum(r["checks"]["validity_calls"] for r in routes.values()) + validity.n_calls),
            "standard_model_solves": int(sum(r["checks"]["standard_model_solves"] for r in routes.values())
                                         + validity.n_model),
            "collision_time_s": float(sum(r["checks"]["search_collision_time_s"] for r in routes.values())
                                      + validity.seconds_collision),
            "ik_model_evaluations": int(sum(g.n_model_evaluations for g in goals)),
            "exact_bound_evaluations": int(sum(len(r["ordered"]) for r in routes.values())),
        },
        "times_s": {"bound_map": map_time, "inverse_kinematics": ik_time, "compensation": compensation_time,
                    "prediction_at_waypoints": aware["prediction"]["time_s"], "plans_wall": plans_time,
                    "plans_in_parallel": in_parallel, "total": None},
        "bound_weight_per_metre": sc.planner.bound_weight,
    }
    if "bound_blind" in routes:
        blind = route_summary(routes["bound_blind"])
        summary["bound_blind"] = blind
        a = summary["bound_aware"]
        metrics = ("max_bound_at_waypoints_mm", "max_interpolated_bound_given_last_motion_mm",
                   "max_interpolated_friction_bound_along_path_mm",
                   "mean_interpolated_friction_bound_along_path_mm", "final_bound_mm", "joint_path_length_m")
        # max_bound_at_waypoints_mm is the exact bound given the last motion (friction after a
        # rotation, translation-last after a translation): the headline comparison, since the
        # friction bound at the goal itself is the same for both plans.
        summary["comparison"] = {k: {"bound_aware": a[k], "bound_blind": blind[k]} for k in metrics}

    # figures
    shapes, tips = [], []
    for res in lm.results:
        if res is None:
            continue
        shapes.append(res.standard.centerline)
        tips.append(np.array([f.tip_position for f in res.friction.values()]))
    obstacles = [o.as_dict() for o in sc.obstacles]
    plans = [routes[m] for m in routes]
    labels = [m.replace("_", "-") + " plan" for m in routes]

    def fig_shapes(path):
        plot_robot_shapes(path, shapes, obstacles, tips, title=f"{sc.name}: robot at the ordered waypoints")

    def fig_bound(path):
        plot_bound_along_path(path, [p["report"]["dense_s"] for p in plans],
                              [np.asarray(p["report"]["dense_friction"]) * 1e3 for p in plans],
                              [np.asarray(p["report"]["dense_translation_last"]) * 1e3 for p in plans],
                              [p["report"]["dense_motion"] for p in plans], labels=labels,
                              s_label="joint-space path length [m, weighted metric]",
                              title=f"{sc.name}: interpolated bound along the ordered path")

    figures = {"robot_shapes.png": fig_shapes, "bound_along_path.png": fig_bound}
    if traj is not None:
        figures["joint_trajectories.png"] = lambda path: plot_joint_trajectories(
            path, traj, robot.joint_names, [j.kind for j in robot.joints], title=f"{sc.name}: drive trajectory")
    summary["times_s"]["total"] = time.perf_counter() - t_start
    write_plan_outputs(out, rows, traj, summary, joint_names=robot.joint_names, figures=figures)
    echo(format_summary(summary))
    summary["output_dir"] = str(out)
    return summary
