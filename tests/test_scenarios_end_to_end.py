"""The shipped task-target and sequence scenarios, end to end, in the default run.

``ctrplan.plan_scenario`` on copies of ``scenarios/task-target.toml`` and
``scenarios/sequence.toml`` as shipped (their own planner, iterations, seed and shipped bound map),
into ``tmp_path``. Checked here, beyond the shared output invariants of ``test_pipeline``
(``_check_outputs``: pure rotation / translation phases, start, rest-to-rest trajectory within the
drive limits, figures):

- the summary agrees with the files (its bound maxima are those of path.csv's rows), and the
  typed result with both (the goals' waypoints);
- every goal is reached, in the scenario's order: a joint goal exactly (modulo 2 pi on the
  periodic joints), a task goal with the tip of the model it was aimed with within its tolerance
  at the goal's waypoint (the standard-model tip when the summary says the standard model was
  aimed with, as for the shipped robot files, which have no [prediction_validation]; the tip
  predicted after the planned motion when the goal was compensated);
- every phase passed the final check (no failures, one check per phase);
- task-target: the bound-aware plan's largest exact bound at the waypoints is below the
  bound-blind plan's.

``test_pipeline_prediction`` covers the prediction columns and the compensation on task-target
(bound-aware only, 60 iterations); these tests run the scenarios as a user would.
Measured run times on the shared 2-core machine (others' jobs running): task-target with the
bound-blind comparison 11-17 s, sequence bound-aware only, its roadmap built once and read once,
about 15 s alone; well under a minute each, so both stay in the default run.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import ctrplan
from ctrplan.io.robot_file import load_robot
from ctrplan.io.scenario import TaskGoal, load_scenario

from ctrplan.testing import (assert_bound_below, assert_collision_free, assert_rotations_before_translations,
                             assert_trajectory_within_limits)
from test_pipeline import _check_outputs, _shipped_scenario

REPO = Path(__file__).resolve().parents[1]


def _run(tmp_path, monkeypatch, name, compare_blind):
    monkeypatch.chdir(tmp_path)      # a computed map would be cached under ./.cache
    sc = _shipped_scenario(tmp_path, name)
    out = tmp_path / "out"
    result = ctrplan.plan_scenario(sc, out, n_jobs=1, compare_blind=compare_blind)
    assert result.run.bound_map.source == "shipped"   # no map computed in the default run
    with open(out / "path.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    on_disk = json.loads((out / "summary.json").read_text())
    return sc, out, result, on_disk, rows


def _goal_waypoints(robot, scenario, rows, summary):
    """Index in path.csv of the waypoint where each goal is reached, in order: the first
    waypoint at or after the previous goal's that equals the goal's joint vector (the scenario's
    for a joint goal, the planned one from the summary for a task goal) modulo 2 pi on periodic
    joints."""
    names = robot.joint_names
    periodic = np.array([j.periodic for j in robot.joints])
    q = np.array([[float(r[n]) for n in names] for r in rows])
    found, start = [], 0
    for k, goal in enumerate(scenario.goals):
        if isinstance(goal, TaskGoal):
            doc = summary["goals"][k]
            target_q = np.asarray(doc.get("q_planned", doc["q"]), dtype=float)
        else:
            target_q = np.asarray(goal.q, dtype=float)
        d = q[start:] - target_q
        d[:, periodic] = (d[:, periodic] + np.pi) % (2 * np.pi) - np.pi
        hits = np.flatnonzero(np.max(np.abs(d), axis=1) < 1e-9)
        assert hits.size, f"goal {k + 1} ({type(goal).__name__}) is not on the path"
        found.append(start + int(hits[0]))
        start = found[-1]
    return found


def _check_goals_and_summary(robot, sc_path, result, on_disk, rows, plans):
    scenario = load_scenario(sc_path)
    summary = result.summary
    # the file says what the function returned, and its bound maxima are those of path.csv
    assert on_disk["bound_aware"] == json.loads(json.dumps(summary["bound_aware"]))
    exact = np.array([float(r["bound_position_m"]) for r in rows])
    planned = np.array([float(r["planned_bound_m"]) for r in rows])
    aware = on_disk["bound_aware"]
    assert aware["max_bound_at_waypoints_mm"] == pytest.approx(exact.max() * 1e3, rel=1e-12)
    assert aware["max_planned_bound_at_waypoints_mm"] == pytest.approx(planned.max() * 1e3, rel=1e-12)
    assert aware["n_ordered_waypoints"] == len(rows)
    # the user-facing assertions on the output folder: the bound at the waypoints within the
    # summary's maximum, phases in order, obstacles clear, drive limits and waypoints met
    out = sc_path.parent / "out"
    assert_bound_below(out, aware["max_bound_at_waypoints_mm"] * 1e-3 * (1 + 1e-9), between=False)
    assert_rotations_before_translations(out)
    assert_collision_free(out, between=False)
    assert_trajectory_within_limits(out)
    # every phase passed the final check
    for plan in plans:
        fc = on_disk[plan]["final_check"]
        assert fc["failures"] == [], (plan, fc)
        assert fc["phases_checked"] >= on_disk[plan]["n_ordered_waypoints"] - 1, (plan, fc)
    # every goal reached, in order; the last waypoint is the last goal
    idx = _goal_waypoints(robot, scenario, rows, on_disk)
    assert idx == sorted(idx) and idx[-1] == len(rows) - 1
    assert tuple(idx) == result.goal_waypoints == tuple(g.waypoint for g in result.run.goals)
    for k, (goal, i) in enumerate(zip(scenario.goals, idx)):
        if not isinstance(goal, TaskGoal):
            continue
        entry = on_disk["goal_prediction"][f"goal_{k + 1}"]
        prefix = "predicted_tip_" if entry.get("compensation_used") else "tip_"
        assert entry["aimed_with"] == ("history-aware prediction" if prefix == "predicted_tip_" else "standard model")
        tip = np.array([float(rows[i][f"{prefix}{c}"]) for c in "xyz"])
        miss = np.linalg.norm(tip - goal.tip_position)
        assert miss <= goal.tolerance, (k, prefix, miss, goal.tolerance)
    return scenario


def test_task_target_scenario_end_to_end(tmp_path, monkeypatch):
    """Shipped task-target (300 RRT* iterations, seed 1) with the bound-blind comparison: files,
    goal within its 1 mm tolerance, final check, and the bound-aware plan's largest exact bound at
    the waypoints below the bound-blind one's (measured 3.80 against 8.51 mm). Catches a run that
    no longer reaches the task target, a summary that disagrees with path.csv, a phase that
    skipped the final check, and a bound cost that no longer steers the planner."""
    sc, out, result, on_disk, rows = _run(tmp_path, monkeypatch, "task-target", compare_blind=True)
    robot = load_robot(REPO / "model" / "ha2019-table7-calibrated.toml")
    _check_outputs(out, robot, sc)
    _check_goals_and_summary(robot, sc, result, on_disk, rows, ("bound_aware", "bound_blind"))
    comp = on_disk["comparison"]["max_bound_at_waypoints_mm"]
    assert comp["bound_aware"] < comp["bound_blind"], comp
    # both plans end at the same goal, so their final bounds are equal
    final = on_disk["comparison"]["final_bound_mm"]
    assert final["bound_aware"] == pytest.approx(final["bound_blind"], rel=1e-12)


def test_sequence_scenario_end_to_end(tmp_path, monkeypatch):
    """Shipped sequence (joint goal, task goal, joint goal back to the start), bound-aware only:
    files, every goal reached in order (the joint goals exactly, the task goal within 1 mm), every
    phase checked, and the path returns to the start configuration. With three goals and the
    shipped map, the legs go through the roadmap, built on the first run and read from the cache
    on the second, which plans the same path. Catches a leg dropped or planned out of order, a
    task goal reached only approximately beyond its tolerance, a route whose legs do not join, and
    a roadmap not stored or not found again."""
    sc, out, result, on_disk, rows = _run(tmp_path, monkeypatch, "sequence", compare_blind=False)
    robot = load_robot(REPO / "model" / "ha2019-table7-calibrated.toml")
    _check_outputs(out, robot, sc)
    scenario = _check_goals_and_summary(robot, sc, result, on_disk, rows, ("bound_aware",))
    assert len(scenario.goals) == 3 and "bound_blind" not in on_disk
    last = np.array([float(rows[-1][n]) for n in robot.joint_names])
    d = last - scenario.start
    d[:2] = (d[:2] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(d, 0.0, atol=1e-9)
    assert on_disk["roadmap"]["source"] == "built" and on_disk["roadmap"]["states"] == 1500
    assert [leg["planner"] for leg in on_disk["bound_aware"]["planner"]] == ["roadmap"] * 3
    again = ctrplan.plan_scenario(sc, tmp_path / "again", n_jobs=1, compare_blind=False)
    assert again.run.plans.roadmap["source"] == "cache"
    np.testing.assert_array_equal(again.run.plans.aware.ordered.q, result.run.plans.aware.ordered.q)
