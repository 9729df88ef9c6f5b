"""The main job ``ctrplan plan`` / :func:`ctrplan.pipeline.run_plan`.

Default run: planning failures (goal outside the joint limits, goal in collision, no path within
the budget) stop with exit code 2, an ``error:`` message, and no output folder. These use a
synthetic constant bound field in place of the robot's map (the failures happen before or
without using its values), so they take seconds.

Slow (``-m slow``): a full bound-aware versus bound-blind plan on a shipped scenario with the
shipped bound map, checking the output files' invariants and that the bound-aware path has the
lower maximum interpolated friction bound.
"""

from __future__ import annotations

import csv
import json
import logging
import sys
from pathlib import Path

import numpy as np
import pytest

from ctrplan import cli, pipeline
from ctrplan.errors import UnreachableGoalError
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, solve_standard
from ctrplan.boundmap import BoundField, map_coordinates, uniform_axis

REPO = Path(__file__).resolve().parents[1]
TABLE7 = REPO / "model" / "ha2019-table7-calibrated.toml"
SCENARIOS = REPO / "scenarios"

DRIVE = """
[drive]
control_rate_hz = 250.0
max_velocity = {alpha_2 = 1.0, alpha_3 = 1.0, beta_3 = 0.01}
max_acceleration = {alpha_2 = 4.0, alpha_3 = 4.0, beta_3 = 0.04}
max_jerk = {alpha_2 = 40.0, alpha_3 = 40.0, beta_3 = 0.4}
"""


def _scenario(tmp_path: Path, goal_q: str, obstacles: str = "", name: str = "probe") -> Path:
    text = f"""
name = "{name}"
robot = "{TABLE7.as_posix()}"

[start]
q = {{alpha_2 = 0.0, alpha_3 = 0.0, beta_3 = -0.07}}

[[goals]]
type = "joint"
q = {goal_q}
{obstacles}
[planner]
name = "RRTstar"
iterations = 5
seed = 1
bound_weight = 500.0

[bound_field]
resolution = [4, 4, 3]
ds_m = 0.004
{DRIVE}"""
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


@pytest.fixture
def synthetic_map(monkeypatch):
    """Replace the bound map by a constant, everywhere-valid field (1 mm, 0.1 rad) and count
    the calls: no map is computed or read."""
    calls = []

    def fake(robot_path, robot, spec, settings, n_jobs=1, **kwargs):
        calls.append(spec.resolution)
        coords = map_coordinates(robot)
        axes = [uniform_axis(lo, hi, n, per) for lo, hi, n, per in zip(coords.lower, coords.upper, spec.resolution,
                                                                         coords.periodic)]
        shape = tuple(len(a) for a in axes)
        values = np.broadcast_to(np.array([1e-3, 0.1, 5e-4, 0.05]), shape + (4,)).copy()
        field = BoundField(axes, coords.periodic, values, np.ones(shape, bool), key="synthetic",
                           coordinates=coords)
        return field, "synthetic", 0.0

    monkeypatch.setattr(pipeline.bound_map, "load_or_compute_bound_map", fake)
    return calls


def _run_entry(monkeypatch, capsys, args):
    """The console entry ``ctrplan.cli.run`` in-process: (exit code, stdout, stderr)."""
    monkeypatch.setattr(sys, "argv", ["ctrplan", *args])
    with pytest.raises(SystemExit) as info:
        cli.run()
    out = capsys.readouterr()
    return (0 if info.value.code is None else info.value.code), out.out, out.err


def test_goal_outside_joint_limits_fails_without_outputs(tmp_path, monkeypatch, capsys, synthetic_map):
    sc = _scenario(tmp_path, "{alpha_2 = 1.0, alpha_3 = 0.0, beta_3 = -0.2}")
    out = tmp_path / "out"
    code, _, err = _run_entry(monkeypatch, capsys, ["plan", str(sc), "--out", str(out), "--jobs", "1"])
    assert code == 2
    assert err.startswith("error: ")
    assert "goals[1].q.beta_3" in err and "joint limits" in err, err
    assert not out.exists()
    assert synthetic_map == []  # rejected while reading the scenario


def test_goal_in_collision_fails_without_outputs(tmp_path, monkeypatch, capsys, synthetic_map):
    goal = (1.0, 0.5, -0.05)
    robot = load_robot(TABLE7)
    alpha, beta = robot.configuration(np.array(goal))
    tip = solve_standard(robot, alpha, beta, ModelSettings(ds=0.004)).tip_position
    sphere = f"""
[[obstacles]]
type = "sphere"
center_m = [{float(tip[0])!r}, {float(tip[1])!r}, {float(tip[2])!r}]
radius_m = 0.004
"""
    q = f"{{alpha_2 = {goal[0]}, alpha_3 = {goal[1]}, beta_3 = {goal[2]}}}"
    out = tmp_path / "out"
    code, _, err = _run_entry(monkeypatch, capsys, ["plan", str(_scenario(tmp_path, q, sphere)), "--out", str(out),
                                                    "--jobs", "1"])
    assert code == 2
    assert err.startswith("error: ") and "goal" in err and "invalid" in err, err
    assert not out.exists()
    assert len(synthetic_map) == 1
    # control: without the sphere the same goal is valid and the run gets to planning (stopped
    # here by a failing planner so that the test stays fast)
    def no_plan(*args, **kwargs):
        raise UnreachableGoalError("planner stopped by the test")

    monkeypatch.setattr(pipeline.routes, "plan_route", no_plan)
    code, _, err = _run_entry(monkeypatch, capsys, ["plan", str(_scenario(tmp_path, q, "", name="free")),
                                                    "--out", str(out), "--jobs", "1"])
    assert code == 2 and "planner stopped by the test" in err, err
    assert not out.exists()


def test_no_path_within_budget_fails_without_outputs(tmp_path, monkeypatch, capsys, synthetic_map):
    calls = []

    def no_plan(robot, start_q, goal_q, *args, **kwargs):
        calls.append(kwargs.get("iterations"))
        raise UnreachableGoalError(f"RRTstar found no exact path in {kwargs.get('iterations')} iterations")

    monkeypatch.setattr(pipeline.routes, "plan_route", no_plan)
    sc = _scenario(tmp_path, "{alpha_2 = 2.0, alpha_3 = 2.0, beta_3 = -0.06}")
    out = tmp_path / "out"
    code, _, err = _run_entry(monkeypatch, capsys, ["plan", str(sc), "--out", str(out), "--jobs", "1",
                                                    "--iterations", "7"])
    assert code == 2
    assert "found no exact path in 7 iterations" in err, err
    assert calls == [7]  # the --iterations override reaches the planner
    assert not out.exists()


# --------------------------------------------------------------------------- messages
MOVE = "{alpha_2 = 0.6, alpha_3 = -0.4, beta_3 = -0.06}"


def test_library_plan_prints_nothing_and_logs_its_lines(tmp_path, monkeypatch, capsys, caplog, synthetic_map):
    """``ctrplan.plan_scenario`` prints nothing (no stray print, no progress bar), even with INFO
    enabled, and its progress lines and summary arrive as INFO records of loggers under
    ``ctrplan``, first the scenario line, last the summary. Catches a message printed around
    logging, logged under a logger outside ``ctrplan`` or at the wrong level."""
    import ctrplan

    monkeypatch.chdir(tmp_path)
    caplog.set_level(logging.INFO, logger="ctrplan")
    ctrplan.plan_scenario(_scenario(tmp_path, MOVE), tmp_path / "out", iterations=20, compare_blind=False)
    assert capsys.readouterr() == ("", "")
    assert caplog.records and all(r.name.startswith("ctrplan.") for r in caplog.records)
    info = [r.getMessage() for r in caplog.records if r.levelno == logging.INFO]
    assert info[0] == "scenario probe: robot ha2019-table7-calibrated (alpha_2, alpha_3, beta_3)"
    assert "bound map: synthetic in 0.0 s" in info
    assert info[-1].startswith("scenario: probe\n")   # the summary, one record


def test_plan_command_prints_its_lines_and_quiet_silences_them(tmp_path, monkeypatch, synthetic_map):
    """``ctrplan plan``: by default the stages' lines, the summary and ``outputs in`` are plain
    lines on stdout (no logger prefix), each once although the command runs twice in this
    process; ``--quiet`` prints none of them, ``--verbose`` adds details; afterwards the
    ``ctrplan`` logger is as before. Catches a handler left behind (lines doubled), a format with
    prefixes, a line printed around logging, and options that do not reach the level."""
    from click.testing import CliRunner

    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    args = ["plan", str(_scenario(tmp_path, MOVE)), "--out", str(out), "--jobs", "1", "--iterations", "20",
            "--no-blind"]
    package = logging.getLogger("ctrplan")
    before = (list(package.handlers), package.level)
    runner = CliRunner()
    for _ in range(2):
        r = runner.invoke(cli.main, args)
        assert r.exit_code == 0, (r.output, r.exception)
        lines = r.stdout.splitlines()
        assert lines[:2] == ["scenario probe: robot ha2019-table7-calibrated (alpha_2, alpha_3, beta_3)",
                             "bound map: synthetic in 0.0 s"]
        assert lines[2].startswith("goal 1: q = [0.6, -0.4, -0.06], tip error ")
        assert lines[3].startswith("bound_aware: ") and " ordered waypoints, planning " in lines[3]
        assert lines[4] == "scenario: probe"            # the summary's first line
        assert lines[-1] == f"outputs in {out}"
        assert sum(line.startswith("scenario probe:") for line in lines) == 1
        assert r.stderr == ""
    quiet = runner.invoke(cli.main, ["--quiet", *args])
    assert quiet.exit_code == 0 and quiet.output == ""
    assert (out / "summary.json").exists()
    verbose = runner.invoke(cli.main, ["-v", *args])
    assert verbose.exit_code == 0
    assert "wrote path.csv, " in verbose.stdout and verbose.stdout.endswith(f"outputs in {out}\n")
    assert (list(package.handlers), package.level) == before
    both = runner.invoke(cli.main, ["-q", "-v", *args])
    assert both.exit_code == 2 and "exclude each other" in both.output


# --------------------------------------------------------------------------- full run (slow)
def _shipped_scenario(tmp_path, name):
    """A copy of a shipped scenario with absolute paths (its map is the shipped one)."""
    text = (SCENARIOS / f"{name}.toml").read_text()
    text = text.replace('robot = "../model/', f'robot = "{(REPO / "model").as_posix()}/')
    text = text.replace('file = "meshes/', f'file = "{(SCENARIOS / "meshes").as_posix()}/')
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_shipped_scenario_bound_aware_beats_bound_blind(tmp_path, monkeypatch):
    """Scenario ``obstacles`` (shipped, its own 600 RRT* iterations, seed 1) with the shipped
    (16, 16, 6), ds 3 mm map of the Table VII robot: the bound-aware plan has a lower max bound
    along the path than the bound-blind plan (same planner and seed, length only).

    The bound compared is the one that applies given the last motion (friction bound after a
    rotation, translation-last bound after a translation, Section V-B): the friction bound at
    the goal itself is the same for both plans, so the max of the friction bound alone is pinned
    at the goal's value (5.29 mm) for any path.

    Measured (2026-11-21): exact bound at the ordered waypoints, max 3.17 mm (bound-aware) versus
    4.92 mm (bound-blind); interpolated along the path 3.24 versus 4.96 mm; mean friction bound
    along the path 2.93 versus 3.70 mm.
    """
    monkeypatch.chdir(tmp_path)  # a computed map would be cached under ./.cache
    sc = _shipped_scenario(tmp_path, "obstacles")
    out = tmp_path / "out"
    summary = pipeline.run_plan(sc, out_dir=out, n_jobs=1, compare_blind=True)
    assert summary["bound_map"]["source"] == "shipped"

    comp = summary["comparison"]
    for key in ("max_bound_at_waypoints_mm", "max_interpolated_bound_given_last_motion_mm",
                "max_interpolated_friction_bound_along_path_mm", "final_bound_mm", "joint_path_length_m"):
        assert set(comp[key]) == {"bound_aware", "bound_blind"}, key
    for key in ("max_bound_at_waypoints_mm", "max_interpolated_bound_given_last_motion_mm"):
        assert comp[key]["bound_aware"] < comp[key]["bound_blind"] - 0.5, (key, comp[key])
    assert comp["mean_interpolated_friction_bound_along_path_mm"]["bound_aware"] < \
        comp["mean_interpolated_friction_bound_along_path_mm"]["bound_blind"]
    # the file says the same as the returned summary
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["comparison"] == json.loads(json.dumps(comp))

    _check_outputs(out, load_robot(TABLE7), sc)




@pytest.mark.slow
def test_six_joint_scenario_plans_bound_aware_below_bound_blind(tmp_path, monkeypatch):
    """The shipped six-joint scenario (4-D shipped map, task-space goal past the STL lesion): the
    whole run with both plans; the bound-aware plan's exact bound at the waypoints is below the
    bound-blind plan's (measured 8.81 against 17.00 mm), every phase passed the final check, and
    the map's values at the waypoints are within 2 mm of the exact ones. About a minute."""
    monkeypatch.chdir(tmp_path)
    sc = _shipped_scenario(tmp_path, "six-joint")
    out = tmp_path / "out"
    summary = pipeline.run_plan(sc, out_dir=out, n_jobs=1, compare_blind=True)
    assert summary["bound_map"]["source"] == "shipped" and len(summary["bound_map"]["coordinates"]) == 4
    comp = summary["comparison"]["max_bound_at_waypoints_mm"]
    assert comp["bound_aware"] < comp["bound_blind"], comp
    assert summary["goals"][0]["tip_error_mm"] <= 1.0
    rows = _check_outputs(out, load_robot(REPO / "model" / "ha2019-table2-six-joint.toml"), sc)
    diff = [abs(float(r["planned_bound_m"]) - float(r["bound_position_m"])) for r in rows]
    assert max(diff) < 2e-3, diff


def _check_outputs(out: Path, robot, scenario_path: Path):
    from ctrplan.io.scenario import load_scenario

    sc = load_scenario(scenario_path)
    names = robot.joint_names
    kinds = np.array([j.kind for j in robot.joints])
    # path.csv: rotate, then translate; in a segment only its joint group changes
    with open(out / "path.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert rows[0]["motion"] == "start"
    q = np.array([[float(r[n]) for n in names] for r in rows])
    motions = [r["motion"] for r in rows]
    for k in range(1, len(rows)):
        assert motions[k] in ("rotation", "translation")
        changed = np.abs(q[k] - q[k - 1]) > 1e-9
        assert changed.any(), f"waypoint {k} repeats waypoint {k - 1}"
        assert np.all(kinds[changed] == motions[k]), (k, motions[k], q[k - 1], q[k])
    np.testing.assert_allclose(q[0], sc.start, atol=1e-12)
    # the bound the planner used next to the exact one, the same quantity (given the last motion)
    exact = np.array([float(r["bound_position_m"]) for r in rows])
    planned = np.array([float(r["planned_bound_m"]) for r in rows])
    assert np.all(np.isfinite(exact)) and np.all(np.isfinite(planned))
    assert [r["bound_kind"] for r in rows] == ["translation_last" if m == "translation" else "friction"
                                              for m in motions]
    # the goals change both joint groups, so both phases occur (the checks above are not vacuous)
    assert {"rotation", "translation"} <= set(motions[1:])
    # every rotation phase of a planner segment comes before its translation: the last phase
    # reaching the final goal (which changes beta_3) is a translation
    assert motions[-1] == "translation"

    # trajectory.csv: starts and ends at rest, within the drive limits
    traj = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    for i, n in enumerate(names):
        v, a = traj[f"{n}_vel"], traj[f"{n}_acc"]
        for arr in (v, a):
            assert abs(arr[0]) < 1e-9 and abs(arr[-1]) < 1e-9
        assert np.max(np.abs(v)) <= sc.drive.max_velocity[i] * (1 + 1e-6)
        assert np.max(np.abs(a)) <= sc.drive.max_acceleration[i] * (1 + 1e-6)
        assert abs(traj[n][0] - q[0, i]) < 1e-9
        assert abs(traj[n][-1] - q[-1, i]) < 1e-9
    assert np.all(np.diff(traj["t"]) > 0)

    # figures: PNGs whose pixel size is the figure's (one bound panel per plan, one row of panels
    # per joint; figure sizes [in] of ctrplan.plots at its DPI) and that show something (dark
    # pixels of lines and text: none in a blank figure, most of it in a filled one)
    import matplotlib.image as mpimg

    from ctrplan import plots

    n_plans = 2 if "bound_blind" in json.loads((out / "summary.json").read_text()) else 1
    inches = {"robot_shapes.png": (7.5, 6.5), "bound_along_path.png": (5.5 * n_plans, 4.0),
              "joint_trajectories.png": (12.0, 2.2 * len(names) + 0.8)}
    for png, (w_in, h_in) in inches.items():
        p = out / png
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", png
        img = mpimg.imread(p)
        assert img.shape[:2] == (round(h_in * plots.DPI), round(w_in * plots.DPI)), (png, img.shape)
        ink = np.mean(np.any(img[..., :3] < 0.5, axis=-1))
        assert 0.002 < ink < 0.5, (png, ink)
    return rows


def test_short_plan_outputs_are_ordered_at_rest_and_complete(tmp_path, monkeypatch, synthetic_map):
    """A short joint-space move (no obstacles, constant synthetic bound field, RRTstar 20
    iterations): path.csv alternates pure rotation / pure translation phases, trajectory.csv is
    rest-to-rest within the drive limits, summary.json has the comparison, the PNGs exist."""
    monkeypatch.chdir(tmp_path)
    sc = _scenario(tmp_path, "{alpha_2 = 0.6, alpha_3 = -0.4, beta_3 = -0.06}")
    out = tmp_path / "out"
    summary = pipeline.run_plan(sc, out_dir=out, n_jobs=1, iterations=20, compare_blind=True)
    on_disk = json.loads((out / "summary.json").read_text())
    for key in ("max_bound_at_waypoints_mm", "max_interpolated_friction_bound_along_path_mm", "final_bound_mm",
                "joint_path_length_m"):
        assert set(on_disk["comparison"][key]) == {"bound_aware", "bound_blind"}, key
    assert on_disk["bound_map"]["source"] == "synthetic"
    assert summary["output_dir"] == str(out)
    rows = _check_outputs(out, load_robot(TABLE7), sc)
    # the synthetic map is 1 mm (friction) and 0.5 mm (translation-last) everywhere: the planned
    # bound of each waypoint is the one of its motion
    planned = [float(r["planned_bound_m"]) for r in rows]
    np.testing.assert_allclose(planned, [5e-4 if r["motion"] == "translation" else 1e-3 for r in rows], rtol=1e-12)


def test_plans_in_parallel_equal_plans_in_series(tmp_path, monkeypatch, synthetic_map):
    """With --jobs 2 the bound-blind plan runs in a forked process beside the bound-aware one: the
    outputs equal those of the serial run (seeded planners, iteration-count termination)."""
    monkeypatch.chdir(tmp_path)
    sc = _scenario(tmp_path, "{alpha_2 = 0.6, alpha_3 = -0.4, beta_3 = -0.06}")
    runs = {}
    for jobs in (1, 2):
        out = tmp_path / f"out{jobs}"
        s = pipeline.run_plan(sc, out_dir=out, n_jobs=jobs, iterations=30, compare_blind=True)
        assert s["times_s"]["plans_in_parallel"] == (jobs == 2)
        runs[jobs] = ((out / "path.csv").read_text(), s["bound_blind"]["joint_path_length_m"],
                      s["bound_blind"]["max_bound_at_waypoints_mm"], s["bound_aware"]["cost"])
    assert runs[1] == runs[2]
