"""What ``ctrplan plan`` reports, pinned: the printed lines, ``summary.json`` and ``path.csv`` of two
cheap runs compared with the reference recorded from the code before the pipeline's stages passed
typed results (``tests/data/plan_characterization.json``).

Each run plans a task-space goal and then a joint goal on the Table VII robot (60 RRT* iterations,
seed 1, no roadmap, bound-aware and bound-blind, with a drive) against a constant synthetic bound map (1 mm
and 0.1 rad friction, 0.5 mm and 0.05 rad translation-last), placed in the map cache of the working
folder under the key of its robot file, so that the run reads it as it reads any cached map. The
second run's robot file carries a ``[bound_calibration]`` and a ``[prediction_validation]`` that
says the history-aware prediction beat the standard model, so its task goal is compensated and
its paths ranked by the calibrated bound. The same keys in the same order, the same strings and
the same numbers (to :data:`REL_TOL`, see there; the plans are seeded and stop on an iteration
count) are expected; times are not compared. Catches a summary key lost, renamed or moved, a
value converted twice or not at all, and a printed line that changed.

``CTRPLAN_RECORD_CHARACTERIZATION=1`` writes the reference again from the code under test.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from _maps import cache_constant_field

REPO = Path(__file__).resolve().parents[1]
TABLE7 = REPO / "model" / "ha2019-table7-calibrated.toml"
REFERENCE = Path(__file__).resolve().parent / "data" / "plan_characterization.json"

CALIBRATION = """
[bound_calibration]
method = "split-conformal"
target_coverage = 0.9
factor = 1.5
noise_margin_m = 0.0003
test_coverage = 0.88
test_coverage_low = 0.8
test_coverage_high = 0.95
failing = false
status = "met"
data_file = "measured.csv"

[prediction_validation]
standard_mean_m = 0.004
standard_max_m = 0.012
history_mean_m = 0.003
history_max_m = 0.009
history_beats_standard = true
difference_mean_m = -0.001
difference_low_m = -0.0015
difference_high_m = -0.0005
test_units = 10
test_samples = 250
data_file = "measured.csv"
"""


def _scenario(folder: Path, robot_file: Path) -> Path:
    """A task goal (the standard-model tip at q = (1.0, 0.5, -0.05)) then a joint goal."""
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import ModelSettings, solve_standard

    robot = load_robot(robot_file)
    alpha, beta = robot.configuration(np.array([1.0, 0.5, -0.05]))
    tip = solve_standard(robot, alpha, beta, ModelSettings(ds=0.004, multistart=0)).tip_position
    text = f"""
name = "character"
robot = "{robot_file.as_posix()}"

[start]
q = {{alpha_2 = 0.0, alpha_3 = 0.0, beta_3 = -0.07}}

[[goals]]
type = "task"
tip_position_m = [{float(tip[0])!r}, {float(tip[1])!r}, {float(tip[2])!r}]
tolerance_m = 1.0e-3

[[goals]]
type = "joint"
q = {{alpha_2 = -0.6, alpha_3 = 0.4, beta_3 = -0.06}}

[planner]
name = "RRTstar"
iterations = 60
seed = 1
bound_weight = 500.0
roadmap = false

[bound_field]
resolution = [4, 4, 3]
ds_m = 0.004

[drive]
control_rate_hz = 250.0
max_velocity = {{alpha_2 = 1.0, alpha_3 = 1.0, beta_3 = 0.01}}
max_acceleration = {{alpha_2 = 4.0, alpha_3 = 4.0, beta_3 = 0.04}}
max_jerk = {{alpha_2 = 40.0, alpha_3 = 40.0, beta_3 = 0.4}}
"""
    path = folder / "character.toml"
    path.write_text(text)
    return path


_TIME = re.compile(r"\b\d+(\.\d+)?(e[-+]?\d+)? s\b")
_TIME_ITEM = re.compile(r"'(\w*time_s)': [-+0-9.e]+")


#: Numbers (in the summary, in CSV cells and inside printed lines, integers included) agree with
#: the recorded ones to this relative tolerance or :data:`ABS_TOL`. The task goal's inverse
#: kinematics stops at its least-squares tolerance, and where it stops follows the last bits of
#: the compiled standard model, which differ between CPUs: on two x86-64 machines the goal's q
#: differed by about 1e-6 rad, its tip residual by 2e-5 mm, the IK's model evaluations by 1.5 %
#: (1104 and 1121), and the seeded plans from that goal by 0.1 % of their checked states. A value
#: converted twice or not at all (a factor of 1000, or 57.3 between radians and degrees) is
#: still far outside it.
REL_TOL = 0.02
ABS_TOL = 1e-4
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d*)?(?:e[-+]?\d+)?")


def _close(got: float, want: float) -> bool:
    return math.isclose(got, want, rel_tol=REL_TOL, abs_tol=ABS_TOL)


def _lines_times_out(lines: list[str]) -> list[str]:
    """Printed lines with times replaced: numbers followed by "s", ``'..._time_s': x`` items, and
    the values of the summary's ``times_s:`` block."""
    out, block = [], None
    for line in lines:
        indent = len(line) - len(line.lstrip())
        if block is not None and indent <= block:
            block = None
        if block is not None:
            label, _, value = line.partition(": ")
            line = label + ": " + (value if value in ("True", "False", "None") else "<time>")
        elif line.strip() == "times_s:":
            block = indent
        out.append(_TIME_ITEM.sub(r"'\1': <time>", _TIME.sub("<t> s", line)))
    return out


def _times_out(value, key: str = ""):
    """The summary with every time [s] replaced by the string "<time>" (durations of the trajectory
    are kept: they are computed, not measured)."""
    if isinstance(value, dict):
        return {k: ("<time>" if key == "times_s" and k != "plans_in_parallel" and value[k] is not None
                    else _times_out(v, k)) for k, v in value.items()}
    if isinstance(value, list):
        return [_times_out(v, key) for v in value]
    if key.endswith("time_s") and isinstance(value, (int, float)):
        return "<time>"
    return value


def _run(tmp_path: Path, monkeypatch, calibrated: bool) -> dict:
    from click.testing import CliRunner

    from ctrplan.cli import main

    folder = tmp_path / ("calibrated" if calibrated else "plain")
    folder.mkdir()
    monkeypatch.chdir(folder)
    robot_file = folder / "robot.toml"
    robot_file.write_text(TABLE7.read_text() + (CALIBRATION if calibrated else ""))
    cache_constant_field(robot_file)   # the same map (4 x 4 x 3, ds 0.004 m, uniform) as when recorded
    scenario = _scenario(folder, robot_file)
    out = folder / "out"
    r = CliRunner().invoke(main, ["plan", str(scenario), "--out", str(out), "--jobs", "1"])
    assert r.exit_code == 0, (r.output, r.exception)
    lines = _lines_times_out([line.replace(str(folder), "<tmp>") for line in r.stdout.splitlines()])
    summary = json.loads((out / "summary.json").read_text())
    summary["scenario_file"] = summary["scenario_file"].replace(str(folder), "<tmp>")
    with open(out / "path.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    files = sorted(p.name for p in out.iterdir())
    return {"lines": lines, "summary": _times_out(summary), "path_csv": rows, "files": files}


def _same(got, want, where="") -> list[str]:
    """Differences between two JSON values: keys (and their order), strings and numbers (to
    :data:`REL_TOL` or :data:`ABS_TOL`; numbers inside strings and CSV cells too)."""
    if isinstance(want, dict):
        if not isinstance(got, dict) or list(got) != list(want):
            return [f"{where}: keys {list(got) if isinstance(got, dict) else got!r} != {list(want)}"]
        return [d for k in want for d in _same(got[k], want[k], f"{where}.{k}")]
    if isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            return [f"{where}: {got!r} != {want!r}"]
        return [d for k, (g, w) in enumerate(zip(got, want)) for d in _same(g, w, f"{where}[{k}]")]
    if isinstance(want, bool) or want is None or isinstance(got, bool) or got is None:
        return [] if got == want else [f"{where}: {got!r} != {want!r}"]
    if isinstance(want, (int, float)):
        ok = isinstance(got, (int, float)) and _close(got, want)
        return [] if ok else [f"{where}: {got!r} != {want!r}"]
    if isinstance(want, str) and isinstance(got, str):
        if _NUMBER.sub("#", got) != _NUMBER.sub("#", want):
            return [f"{where}: {got!r} != {want!r}"]
        for g, w in zip(_NUMBER.findall(got), _NUMBER.findall(want)):
            if not _close(float(g), float(w)) and g != w:
                return [f"{where}: {got!r} != {want!r}"]
        return []
    return [] if got == want else [f"{where}: {got!r} != {want!r}"]


@pytest.mark.parametrize("calibrated", [False, True], ids=["plain", "calibrated"])
def test_printed_lines_summary_and_path_are_as_recorded(tmp_path, monkeypatch, calibrated):
    got = _run(tmp_path, monkeypatch, calibrated)
    name = "calibrated" if calibrated else "plain"
    if os.environ.get("CTRPLAN_RECORD_CHARACTERIZATION") == "1":
        recorded = json.loads(REFERENCE.read_text()) if REFERENCE.exists() else {}
        recorded[name] = got
        REFERENCE.write_text(json.dumps(recorded, indent=1, sort_keys=False) + "\n")
    want = json.loads(REFERENCE.read_text())[name]
    diffs = _same(got, want)
    assert not diffs, "\n".join(diffs[:20])
