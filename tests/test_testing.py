"""The assertions of ``ctrplan.testing`` on a real plan and on broken copies of its outputs.

One plan per module: the shipped task-target scenario (its goal, planner, seed and drive
limits) with 60 RRT* iterations, bound-aware only, through :func:`ctrplan.plan`. It is handed a
constant synthetic bound field (``tests/_maps.py``) instead of the robot's map: the assertions
read the plan and the exact model, not the map, and the module does not depend on a shipped
map matching the robot file. Each assertion passes on the plan (as a ``PlanResult`` and as its
output folder) and fails, naming the waypoint, the quantity, its value and the limit, on an
input broken on purpose.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

import ctrplan
from _maps import constant_field
from ctrplan.io.scenario import load_scenario
from ctrplan.testing import _between, _plan
from ctrplan.testing import (assert_bound_below, assert_collision_free, assert_rotations_before_translations,
                             assert_trajectory_within_limits)

REPO = Path(__file__).resolve().parents[1]

# Few, coarse points between waypoints (each costs an exact-bound evaluation).
COARSE = (math.radians(30.0), 0.01)


def _task_target(folder: Path, obstacle: str = "") -> Path:
    """A copy of the shipped task-target scenario with an absolute robot path and optionally one
    more ``[[obstacles]]`` table."""
    text = (REPO / "scenarios" / "task-target.toml").read_text()
    text = text.replace('robot = "../model/', f'robot = "{(REPO / "model").as_posix()}/')
    if obstacle:
        text = text.replace("[planner]\n", f"{obstacle}\n[planner]\n")
    path = folder / "task-target.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def plan(tmp_path_factory):
    """(PlanResult, output folder) of the task-target plan."""
    tmp = tmp_path_factory.mktemp("plan")
    sc = load_scenario(_task_target(tmp))
    field = constant_field(sc.robot, sc.bound_field.resolution)
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(tmp)
        result = ctrplan.plan(sc, bound_map=field, out_dir=tmp / "out", iterations=60, compare_blind=False)
    return result, tmp / "out"


def _copy(out: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "broken"
    shutil.copytree(out, dst)
    return dst


def _rows(folder: Path) -> list[dict]:
    with open(folder / "path.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _write_rows(folder: Path, rows: list[dict]) -> None:
    with open(folder / "path.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def test_plan_result_matches_its_files(plan):
    """The PlanResult is what path.csv and summary.json say (catches a result built from another
    stage's objects than the files)."""
    result, out = plan
    rows = _rows(out)
    assert result.q.shape == (len(rows), len(result.joint_names))
    np.testing.assert_array_equal(result.q, [[float(r[n]) for n in result.joint_names] for r in rows])
    assert list(result.motion) == [r["motion"] for r in rows]
    np.testing.assert_array_equal(result.bound_position_m, [float(r["bound_position_m"]) for r in rows])
    # the shipped robot file has no [bound_calibration]: no calibrated bound, empty cells
    assert np.all(np.isnan(result.calibrated_bound_m)) and all(r["calibrated_bound_m"] == "" for r in rows)
    on_disk = json.loads((out / "summary.json").read_text())
    assert result.goal_waypoints == (on_disk["goal_prediction"]["goal_1"]["waypoint"],) == (len(rows) - 1,)
    assert Path(on_disk["scenario_file"]) == result.scenario.file
    assert result.output_dir == out and result.timings_s["total"] > 0


@pytest.mark.parametrize("form", ["result", "folder"])
def test_every_assertion_passes_on_the_plan(plan, form):
    result, out = plan
    subject = result if form == "result" else out
    top = float(np.max(result.bound_position_m))
    assert_bound_below(subject, top * 1.001, between=False)
    assert_rotations_before_translations(subject)
    assert_collision_free(subject, clearance_m=1e-3, resolution=COARSE)
    assert_trajectory_within_limits(subject)


def test_bound_between_waypoints_is_evaluated(plan):
    """A generous limit passes between waypoints too; a limit below the largest waypoint bound
    fails naming that waypoint with its bound and the limit in mm."""
    result, _ = plan
    assert len(list(_between(_plan(result), COARSE))) >= 2       # the check between is not vacuous
    assert_bound_below(result, 0.05, resolution=COARSE)
    top = float(np.max(result.bound_position_m))
    k = int(np.argmax(result.bound_position_m))
    with pytest.raises(AssertionError) as info:
        assert_bound_below(result, 0.9 * top, between=False)
    msg = str(info.value)
    assert f"waypoint {k} ({result.motion[k]}" in msg
    assert f"{top * 1e3:.3f} mm, not below the limit {0.9 * top * 1e3:.3f} mm" in msg


def test_a_rotation_after_a_translation_before_the_goal_fails(plan, tmp_path):
    """path.csv edited so that the goal is reached by the same joint changes in the other order
    (translation, then rotation)."""
    _, out = plan
    broken = _copy(out, tmp_path)
    rows = _rows(broken)
    assert [r["motion"] for r in rows[-3:]] == ["translation", "rotation", "translation"]
    names = json.loads((broken / "summary.json").read_text())["joints"]
    swapped = dict(rows[-2])
    for n in names:           # rotations as before the last rotation, translations as at the goal
        swapped[n] = rows[-3][n] if n.startswith("alpha") else rows[-1][n]
    swapped["motion"], rows[-1]["motion"] = "translation", "rotation"
    rows[-2] = swapped
    _write_rows(broken, rows)
    goal = len(rows) - 1
    with pytest.raises(AssertionError, match=rf"goal 1 \(waypoint {goal}\) is reached by a rotation \(alpha_2 "
                                             rf"-?[0-9.]+ deg.*after the translation to waypoint {goal - 1}"):
        assert_rotations_before_translations(broken)
    # a phase that changes the other joint group is named with the joint and its change
    rows[-1]["motion"] = "translation"
    _write_rows(broken, rows)
    with pytest.raises(AssertionError, match=rf"waypoint {goal} is reached by a translation phase that also "
                                             r"changes the rotation joint alpha_2 by"):
        assert_rotations_before_translations(broken)


def test_an_obstacle_on_a_waypoint_tip_fails(plan, tmp_path):
    """A 2 mm sphere on the tip of waypoint 3; summary.json pointed at that scenario."""
    result, out = plan
    broken = _copy(out, tmp_path)
    centre = ", ".join(repr(float(x)) for x in result.tip[3])
    sc = _task_target(broken, f'[[obstacles]]\ntype = "sphere"\ncenter_m = [{centre}]\nradius_m = 0.002\n')
    summary = json.loads((broken / "summary.json").read_text())
    summary["scenario_file"] = str(sc)
    (broken / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(AssertionError, match=r"robot body at waypoint [0-3] \(\w+\): distance to the nearest "
                                             r"obstacle 0\.000 mm, below the clearance 0\.000 mm"):
        assert_collision_free(broken, between=False)


def test_a_velocity_beyond_the_drive_limit_fails(plan, tmp_path):
    """trajectory.csv with beta_3's velocity scaled to twice its limit's worth."""
    result, out = plan
    broken = _copy(out, tmp_path)
    text = (broken / "trajectory.csv").read_text().splitlines()
    header = text[0].split(",")
    col = header.index("beta_3_vel")
    table = [line.split(",") for line in text[1:]]
    vmax = result.scenario.drive.max_velocity[result.joint_names.index("beta_3")]
    peak = max(abs(float(r[col])) for r in table)
    for r in table:
        r[col] = repr(float(r[col]) * 2 * float(vmax) / peak)
    (broken / "trajectory.csv").write_text("\n".join([text[0], *(",".join(r) for r in table)]) + "\n")
    with pytest.raises(AssertionError, match=r"trajectory at t = [0-9.]+ s \(between waypoints \d+ and \d+\): "
                                             r"beta_3 velocity -?20 mm/s, above the drive limit 10 mm/s"):
        assert_trajectory_within_limits(broken)


def test_a_waypoint_missing_from_the_trajectory_fails(plan, tmp_path):
    """path.csv's goal moved by 1 mm in beta_3: no trajectory sample reaches it."""
    _, out = plan
    broken = _copy(out, tmp_path)
    rows = _rows(broken)
    rows[-1]["beta_3"] = repr(float(rows[-1]["beta_3"]) + 1e-3)
    _write_rows(broken, rows)
    with pytest.raises(AssertionError, match=rf"waypoint {len(rows) - 1} \(translation\) is not on the trajectory "
                                             r".* differs in beta_3 by 1 mm"):
        assert_trajectory_within_limits(broken)
