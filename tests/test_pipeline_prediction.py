"""``ctrplan plan`` with prediction and compensated targeting (issue 13, sections 1 and 2).

The shipped task-target scenario with its shipped bound map, planned bound-aware only with 60
RRT* iterations (the goal and its compensation do not depend on the plan's length; each run
takes about 10 s).
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest

from ctrplan import pipeline
from ctrplan.errors import ModelFileError
from ctrplan.io.scenario import load_scenario

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "scenarios"


def _task_target(tmp_path, extra_planner_line: str = "") -> Path:
    """A copy of the shipped task-target scenario with absolute paths, without its ``final_motion``
    line (the default), optionally with one more line in ``[planner]``."""
    text = (SCENARIOS / "task-target.toml").read_text()
    text = text.replace('robot = "../model/', f'robot = "{(REPO / "model").as_posix()}/')
    text = re.sub(r"(?m)^final_motion = .*$", "", text)     # the shipped file spells out the default
    if extra_planner_line:
        text = text.replace("[planner]\n", f"[planner]\n{extra_planner_line}\n")
    path = tmp_path / "task-target.toml"
    path.write_text(text)
    return path


def _rows(out: Path) -> list[dict]:
    with open(out / "path.csv") as fh:
        return list(csv.DictReader(fh))


def _run(tmp_path, monkeypatch, sc):
    monkeypatch.chdir(tmp_path)      # a computed map would be cached under ./.cache
    out = tmp_path / "out"
    summary = pipeline.run_plan(sc, out_dir=out, n_jobs=1, iterations=60, compare_blind=False, echo=lambda *a: None)
    assert summary["bound_map"]["source"] == "shipped"
    return summary, _rows(out)


def _check_prediction_columns(rows):
    """predicted_offset_m is the distance between the predicted and the standard tip; the start
    has no history."""
    for r in rows:
        pred = np.array([float(r[f"predicted_tip_{c}"]) for c in "xyz"])
        tip = np.array([float(r[f"tip_{c}"]) for c in "xyz"])
        assert float(r["predicted_offset_m"]) == pytest.approx(np.linalg.norm(pred - tip), abs=1e-12)
    assert rows[0]["prediction_cases"] == "no_history;no_history" and rows[0]["prediction_eta"] == "0;0"


def test_task_target_compensated_miss_is_within_tolerance(tmp_path, monkeypatch):
    """Shipped task-target scenario, default final motion (translation-last): the tip predicted
    after the planned motion misses the target by more than the 1 mm tolerance when the goal is
    the standard-model IK solution (measured 2.85 mm), and by less than the tolerance with the
    compensated goal (measured 0.002 mm); the plan ends with a translation, so the prediction at
    the goal is the clearance solution and equals the one the compensation assumed. Catches a
    compensation that is not applied to the planned goal, and a path.csv prediction that is not
    the one at the goal."""
    sc = _task_target(tmp_path)
    summary, rows = _run(tmp_path, monkeypatch, sc)
    tol = load_scenario(sc).goals[0].tolerance
    target = load_scenario(sc).goals[0].tip_position
    g = summary["goal_prediction"]["goal_1"]
    assert summary["final_motion"] == "translation-last"
    assert g["compensation_used"] and g["prediction_model"] == "clearance"
    assert g["predicted_miss_compensated_mm"] <= tol * 1e3
    assert g["predicted_miss_standard_ik_mm"] > tol * 1e3
    assert g["predicted_miss_standard_ik_mm"] > 10 * g["predicted_miss_compensated_mm"]
    assert g["planned_history_as_assumed"] and g["planned_cases"] == "translation_last;translation_last"
    # the last waypoint of path.csv is the goal: its predicted tip is on the target, its standard
    # tip is not (the compensation aims the standard model off by the predicted offset)
    last = rows[-1]
    assert last["motion"] == "translation"
    pred = np.array([float(last[f"predicted_tip_{c}"]) for c in "xyz"])
    tip = np.array([float(last[f"tip_{c}"]) for c in "xyz"])
    assert np.linalg.norm(pred - target) == pytest.approx(g["predicted_miss_at_planned_goal_mm"] * 1e-3, abs=1e-9)
    assert np.linalg.norm(pred - target) <= tol
    assert np.linalg.norm(tip - target) > tol
    np.testing.assert_allclose(summary["goals"][0]["q_planned"], [float(last[n]) for n in ("alpha_2", "alpha_3",
                                                                                          "beta_3")], atol=1e-9)
    _check_prediction_columns(rows)


def test_task_target_rotation_last(tmp_path, monkeypatch):
    """``final_motion = "rotation-last"``: the phases reaching the goal are swapped (the path ends
    with a rotation), the prediction at the goal is the friction solution with the directions of
    that last rotation, and the compensated predicted miss is within tolerance (measured 0.004
    mm against 2.78 mm uncompensated). Catches the option being read but not applied to the
    ordering, and an approach direction that does not match the plan's."""
    sc = _task_target(tmp_path, 'final_motion = "rotation-last"')
    summary, rows = _run(tmp_path, monkeypatch, sc)
    tol_mm = load_scenario(sc).goals[0].tolerance * 1e3
    g = summary["goal_prediction"]["goal_1"]
    assert summary["final_motion"] == "rotation-last"
    assert rows[-1]["motion"] == "rotation" and g["final_motion_status"] in ("reordered", "already")
    assert g["prediction_model"] == "friction" and rows[-1]["prediction_cases"] == "friction;friction"
    assert rows[-1]["prediction_eta"] == g["planned_eta"] and g["planned_history_as_assumed"]
    assert g["predicted_miss_compensated_mm"] <= tol_mm < g["predicted_miss_standard_ik_mm"]
    assert g["predicted_miss_at_planned_goal_mm"] <= tol_mm
    _check_prediction_columns(rows)


def test_bad_final_motion_names_file_key_and_value(tmp_path):
    """An unknown final motion is a ModelFileError naming the file, the key and the value."""
    sc = _task_target(tmp_path, 'final_motion = "rotation_last"')
    with pytest.raises(ModelFileError, match=r"task-target\.toml.*planner\.final_motion.*'rotation_last'"):
        load_scenario(sc)
