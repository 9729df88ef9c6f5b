"""``ctrplan plan`` with prediction and compensated targeting.

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

import ctrplan
from ctrplan import planning
from ctrplan.errors import ModelFileError
from ctrplan.io.scenario import load_scenario

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "scenarios"


def _task_target(tmp_path, extra_planner_line: str = "", aim_with: str | None = "history") -> Path:
    """A copy of the shipped task-target scenario with absolute paths, without its ``final_motion``
    line (the default), with ``aim_with`` (default "history": the compensation is what these
    tests check; None keeps the default "auto") and optionally one more line in ``[planner]``."""
    text = (SCENARIOS / "task-target.toml").read_text()
    text = text.replace('robot = "../model/', f'robot = "{(REPO / "model").as_posix()}/')
    text = re.sub(r"(?m)^final_motion = .*$", "", text)     # the shipped file spells out the default
    if aim_with is not None:
        extra_planner_line = "\n".join(x for x in (extra_planner_line, f'aim_with = "{aim_with}"') if x)
    if extra_planner_line:
        text = text.replace("[planner]\n", f"[planner]\n{extra_planner_line}\n")
    path = tmp_path / "task-target.toml"
    path.write_text(text)
    return path


def _rows(out: Path) -> list[dict]:
    with open(out / "path.csv") as fh:
        return list(csv.DictReader(fh))


def _run(tmp_path, monkeypatch, sc, calibration=None):
    """Plan (bound-aware only, 60 iterations) with the shipped map into ``tmp_path/out``: the
    summary and path.csv's rows."""
    monkeypatch.chdir(tmp_path)      # a computed map would be cached under ./.cache
    out = tmp_path / "out"
    result = ctrplan.plan(sc, calibration=calibration, out_dir=out, n_jobs=1, iterations=60, compare_blind=False)
    assert result.run.bound_map.source == "shipped"
    return result.summary, _rows(out)


def _hand_eta(robot, rows) -> np.ndarray:
    """eta of each pair at the last waypoint, from path.csv's joints by hand: the sign of the last
    change of the relative angle alpha_(k+1) - alpha_k (Eq. (38) of Ha et al. 2019)."""
    alpha = np.array([robot.configuration([float(r[n]) for n in robot.joint_names], check_limits=False)[0]
                      for r in rows])
    rel = np.diff(alpha, axis=1)                           # (K, n - 1)
    eta = np.zeros(rel.shape[1], int)
    for k in range(rel.shape[1]):
        steps = np.diff(rel[:, k])
        moved = steps[np.abs(steps) > 1e-9]
        eta[k] = int(np.sign(moved[-1])) if moved.size else 0
    return eta


def _check_goal_prediction(robot, sc, rows, final_motion):
    """The predicted tip at the goal (last waypoint) against the mechanics called directly with a
    history built by hand from path.csv: after a final translation every pair is released (the
    clearance solution); after a final rotation, the friction solution with the directions of the
    last relative rotations. Catches a prediction column computed with the wrong history (a
    missing release, a flipped direction) or at another waypoint."""
    from ctrplan.mechanics import solve_contact

    last = rows[-1]
    q = [float(last[n]) for n in robot.joint_names]
    alpha, beta = robot.configuration(q)
    settings = planning.load_setup(sc, sc.parent / "setup-check").settings
    if final_motion == "translation-last":
        sol = solve_contact(robot, alpha, beta, settings)
    else:
        sol = solve_contact(robot, alpha, beta, settings, eta=tuple(_hand_eta(robot, rows)))
    pred = np.array([float(last[f"predicted_tip_{c}"]) for c in "xyz"])
    assert np.linalg.norm(pred - sol.tip_position) < 1e-6, (final_motion, pred, sol.tip_position)


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
    assert np.linalg.norm(pred - target) <= tol
    assert np.linalg.norm(tip - target) > tol
    np.testing.assert_allclose(summary["goals"][0]["q_planned"], [float(last[n]) for n in ("alpha_2", "alpha_3",
                                                                                          "beta_3")], atol=1e-9)
    _check_goal_prediction(load_scenario(sc).robot, sc, rows, "translation-last")


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
    _check_goal_prediction(load_scenario(sc).robot, sc, rows, "rotation-last")
    assert rows[-1]["prediction_eta"] == ";".join(f"{e:+d}" for e in _hand_eta(load_scenario(sc).robot, rows))


def test_bad_final_motion_names_file_key_and_value(tmp_path):
    """An unknown final motion is a ModelFileError naming the file, the key and the value."""
    sc = _task_target(tmp_path, 'final_motion = "rotation_last"')
    with pytest.raises(ModelFileError, match=r"task-target\.toml.*planner\.final_motion.*'rotation_last'"):
        load_scenario(sc)


def _calibration(prediction_validation=None, bound_calibration=None):
    """Robot-file tables as the typed records a plan is handed (the robot file's text, and so its
    shipped bound map, stay the same)."""
    from ctrplan.calibration import CalibratedBound, PredictionValidation, RobotCalibration

    return RobotCalibration(
        bound=None if bound_calibration is None else CalibratedBound(**bound_calibration),
        prediction=None if prediction_validation is None else PredictionValidation(**prediction_validation))


def test_auto_aims_with_the_standard_model_when_the_prediction_is_not_validated(tmp_path, monkeypatch):
    """Default ``aim_with = "auto"`` with the shipped robot file (no [prediction_validation]): the
    goal is the standard-model IK solution, the summary says the standard model was aimed with
    and why, that its real error is not measured, and that the bound is the model's, not
    validated; path.csv's calibrated_bound_m is empty. Catches a planner that compensates with an
    unvalidated prediction and reports 0.002 mm as the expected miss."""
    sc = _task_target(tmp_path, aim_with=None)
    summary, rows = _run(tmp_path, monkeypatch, sc)
    g = summary["goal_prediction"]["goal_1"]
    assert summary["aiming"]["model"] == "standard model" and not summary["aiming"]["use_history"]
    assert "[prediction_validation]" in summary["aiming"]["reason"] and summary["aiming"]["why"] == "not_validated"
    assert g["aimed_with"] == "standard model" and "compensation_used" not in g
    assert g["measured_error_of_aiming_model_mean_mm"] is None and "not measured" in g["expected_real_miss_note"]
    np.testing.assert_allclose(summary["goals"][0]["q_planned"], summary["goals"][0]["q"], atol=0)
    assert summary["bound_calibration"]["calibrated"] is False
    assert "not validated on measurements" in summary["bound_calibration"]["note"]
    assert all(r["calibrated_bound_m"] == "" for r in rows)


def test_auto_aims_with_a_validated_prediction_and_ranks_by_the_calibrated_bound(tmp_path, monkeypatch):
    """The robot file records that the history-aware prediction beat the standard model on
    measurements and a calibrated bound 1.5 x (bound + 0.3 mm): the goal is compensated, the
    summary gives the measured error of the prediction next to the predicted miss, path.csv's
    calibrated_bound_m is 1.5 x (bound_position_m + 0.3 mm) at every waypoint, and the planner's
    bound weight is the one that ranks paths by the calibrated bound. Catches a calibration that
    is read but not applied, and a column computed from another bound."""
    pv = {"standard_mean_m": 4.0e-3, "standard_max_m": 12.0e-3, "history_mean_m": 3.0e-3, "history_max_m": 9.0e-3,
          "history_beats_standard": True, "test_samples": 250, "data_file": "measured.csv"}
    bc = {"factor": 1.5, "noise_margin_m": 0.3e-3, "target_coverage": 0.9, "test_coverage": 0.88,
          "test_coverage_low": 0.8, "test_coverage_high": 0.95, "failing": False, "data_file": "measured.csv"}
    sc = _task_target(tmp_path, aim_with=None)
    summary, rows = _run(tmp_path, monkeypatch, sc, _calibration(prediction_validation=pv, bound_calibration=bc))
    g = summary["goal_prediction"]["goal_1"]
    assert summary["aiming"]["use_history"] and g["aimed_with"] == "history-aware prediction"
    assert g["compensation_used"] and g["measured_error_of_aiming_model_mean_mm"] == pytest.approx(3.0)
    assert g["measured_error_of_aiming_model_max_mm"] == pytest.approx(9.0)
    for r in rows:
        assert float(r["calibrated_bound_m"]) == pytest.approx(1.5 * (float(r["bound_position_m"]) + 0.3e-3), rel=1e-12)
    w = summary["bound_weight_per_metre"]
    cal = summary["bound_calibration"]
    assert cal["calibrated"] and cal["effective_bound_weight_per_metre"] == pytest.approx(w * 1.5 / (1 + w * 1.5 * 0.3e-3))
    assert "88 %" in cal["note"]


def test_the_effective_bound_weight_ranks_paths_as_the_calibrated_bound_does():
    """For any paths (length L, bound integral I), L + w' I is (1 + w c m)^-1 times the cost with the
    calibrated bound, (1 + w c m) L + w c I: the same order. Catches a wrong effective weight."""
    from ctrplan.calibration import CalibratedBound

    cal = CalibratedBound(factor=1.7, target_coverage=0.9, noise_margin_m=0.4e-3)
    w, c, m = 1000.0, 1.7, 0.4e-3
    w_eff = planning.effective_bound_weight(cal, w)
    rng = np.random.default_rng(2718)
    L, I = rng.uniform(0.1, 2.0, 50), rng.uniform(0.0, 5e-3, 50)
    np.testing.assert_allclose((1 + w * c * m) * L + w * c * I, (1 + w * c * m) * (L + w_eff * I), rtol=1e-12)
    assert planning.effective_bound_weight(cal, 0.0) == 0.0
    assert planning.effective_bound_weight(None, w) == w


def test_the_aim_decision_is_an_enum_and_numbers_worded_by_the_report_layer():
    """Each way of choosing the aiming model gives its AimReason and the measured errors of the
    model chosen; the sentence comes from ctrplan.planning.aiming with those numbers in mm
    (catches a decision that carries only prose, or a sentence that names the wrong model's
    figures)."""
    from ctrplan.calibration import PredictionValidation
    from ctrplan.planning import AimReason, aim_decision
    from ctrplan.planning.aiming import aim_reason

    better = PredictionValidation(standard_mean_m=1.52e-3, standard_max_m=3.4e-3, history_mean_m=0.91e-3,
                                  history_max_m=2.1e-3, history_beats_standard=True, difference_mean_m=-0.61e-3,
                                  difference_low_m=-0.8e-3, difference_high_m=-0.42e-3, test_samples=200,
                                  data_file="run.csv")
    worse = better.model_copy(update={"history_beats_standard": False})
    cases = [(None, "auto", AimReason.NOT_VALIDATED, False), (better, "auto", AimReason.BEATS_STANDARD, True),
             (worse, "auto", AimReason.DOES_NOT_BEAT_STANDARD, False), (None, "history", AimReason.ASKED_HISTORY, True),
             (better, "standard", AimReason.ASKED_STANDARD, False)]
    for pv, aim_with, why, use in cases:
        d = aim_decision(pv, aim_with)
        assert (d.why, d.use_history) == (why, use), (aim_with, pv is None)
        if pv is not None:
            assert d.measured_mean_m == (pv.history_mean_m if use else pv.standard_mean_m)
    text = aim_reason(aim_decision(better))
    assert "mean 0.91 / max 2.10 mm against the standard model's 1.52 / 3.40 mm" in text
    assert "95 % interval -0.80..-0.42 mm" in text and "run.csv, 200 test samples" in text
    assert aim_reason(aim_decision(worse)).endswith("it does not beat the standard model")
    assert aim_reason(aim_decision(None, "history")).endswith("not validated on measurements")
    with pytest.raises(ValueError, match="aim_with must be"):
        aim_decision(None, "maybe")
