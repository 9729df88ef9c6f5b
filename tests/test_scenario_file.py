"""Scenario files: good scenarios load into arrays in joint order; bad ones name file and key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.errors import ModelFileError
from ctrplan.io.scenario import (Box, Capsule, JointGoal, Mesh, Sphere, TaskGoal, load_scenario)

TABLE2 = Path(__file__).resolve().parents[1] / "model" / "ha2019-table2-nominal.toml"

STL = """solid t
facet normal 0 0 1
outer loop
vertex 0 0 0
vertex 10 0 0
vertex 0 10 0
endloop
endfacet
endsolid t
"""

GOOD = f"""
name = "demo"
robot = "{TABLE2.as_posix()}"

[start]
q = {{alpha_2 = 0.0, alpha_3 = 0.5, beta_3 = -0.05}}

[[goals]]
type = "joint"
q = {{beta_3 = -0.04, alpha_3 = -0.5, alpha_2 = 1.0}}

[[goals]]
type = "task"
tip_position_m = [0.02, 0.01, 0.18]
tolerance_m = 1e-3

[[obstacles]]
type = "sphere"
center_m = [0.03, 0.0, 0.15]
radius_m = 0.01

[[obstacles]]
type = "capsule"
a_m = [0.0, 0.0, 0.2]
b_m = [0.0, 0.05, 0.2]
radius_m = 0.002

[[obstacles]]
type = "box"
center_m = [0.0, 0.05, 0.15]
size_m = [0.1, 0.01, 0.1]
rpy_rad = [0.0, 0.0, 0.3]

[[obstacles]]
type = "mesh"
file = "meshes/tri.stl"
scale = 0.001

[planner]
iterations = 500
time_limit_s = 10.0
bound_weight = 2.5

[bound_field]
resolution = [9, 9, 5]
ds_m = 0.002

[drive]
control_rate_hz = 100.0
max_velocity = {{alpha_2 = 1.0, alpha_3 = 2.0, beta_3 = 0.01}}
max_acceleration = {{alpha_2 = 5.0, alpha_3 = 5.0, beta_3 = 0.05}}
max_jerk = {{alpha_2 = 50.0, alpha_3 = 50.0, beta_3 = 0.5}}

[output]
dir = "out"
"""


def _write(tmp_path, text, name="scenario.toml"):
    (tmp_path / "meshes").mkdir(exist_ok=True)
    (tmp_path / "meshes" / "tri.stl").write_text(STL)
    p = tmp_path / name
    p.write_text(text)
    return p


def _error(tmp_path, text):
    p = _write(tmp_path, text)
    with pytest.raises(ModelFileError) as info:
        load_scenario(p)
    assert info.value.file == str(p)
    return info.value


def test_good_scenario(tmp_path):
    s = load_scenario(_write(tmp_path, GOOD))
    assert s.name == "demo" and s.robot.name == "ha2019-table2-nominal"
    assert s.robot_file == TABLE2
    np.testing.assert_array_equal(s.start, [0.0, 0.5, -0.05])
    assert isinstance(s.goals[0], JointGoal) and isinstance(s.goals[1], TaskGoal)
    np.testing.assert_array_equal(s.goals[0].q, [1.0, -0.5, -0.04])    # reordered to joint order
    assert s.goals[1].tolerance == 1e-3
    kinds = [type(o) for o in s.obstacles]
    assert kinds == [Sphere, Capsule, Box, Mesh]
    assert s.obstacles[3].file == (tmp_path / "meshes" / "tri.stl").resolve()
    assert s.obstacles[3].scale == 0.001
    np.testing.assert_array_equal(s.obstacles[2].rpy_rad, [0.0, 0.0, 0.3])
    assert s.planner.name == "RRTstar" and s.planner.iterations == 500 and s.planner.seed == 1
    assert s.planner.time_limit == 10.0 and s.planner.bound_weight == 2.5 and s.planner.range is None
    assert s.bound_field.resolution == (9, 9, 5) and s.bound_field.ds == 0.002
    np.testing.assert_array_equal(s.drive.max_velocity, [1.0, 2.0, 0.01])
    assert s.output_dir == (tmp_path / "out").resolve()
    with pytest.raises(ValueError):
        s.start[0] = 1.0                                                    # read-only


def test_relative_robot_path_and_defaults(tmp_path):
    text = """
name = "minimal"
robot = "model.toml"
[start]
q = {alpha_2 = 0.0, alpha_3 = 0.0, beta_3 = -0.034}
[[goals]]
type = "joint"
q = {alpha_2 = 0.0, alpha_3 = 1.0, beta_3 = -0.034}
"""
    (tmp_path / "model.toml").write_text(TABLE2.read_text())
    s = load_scenario(_write(tmp_path, text))
    assert s.robot_file == (tmp_path / "model.toml").resolve()
    assert s.obstacles == () and s.drive is None and s.output_dir is None
    assert s.planner.iterations == 3000 and s.planner.name == "RRTstar"
    assert s.bound_field.resolution is None
    assert s.bound_field.first_plan == "preview" and s.bound_field.refine_rounds is None
    assert s.bound_field.refine_tolerance == 0.25e-3
    # the robot file records no measurements; with them, the scenario carries them typed
    assert s.calibration.bound is None and s.calibration.prediction is None
    (tmp_path / "model.toml").write_text(TABLE2.read_text() + "\n[bound_calibration]\ntarget_coverage = 0.9\n"
                                         "factor = 1.25\nnoise_margin_m = 0.0002\n")
    cal = load_scenario(tmp_path / "scenario.toml").calibration
    assert (cal.bound.factor, cal.bound.noise_margin_m, cal.bound.target_coverage) == (1.25, 2e-4, 0.9)
    assert cal.prediction is None


def test_joint_array_helpers(tmp_path):
    s = load_scenario(_write(tmp_path, GOOD))
    q = s.joint_array({"beta_3": -0.06, "alpha_2": 0.1, "alpha_3": 0.2})
    np.testing.assert_array_equal(q, [0.1, 0.2, -0.06])
    assert s.joint_dict(q) == {"alpha_2": 0.1, "alpha_3": 0.2, "beta_3": -0.06}
    with pytest.raises(KeyError, match="unknown joint.*alpha_1.*missing joint.*beta_3"):
        s.joint_array({"alpha_1": 0.0, "alpha_2": 0.1, "alpha_3": 0.2})


@pytest.mark.parametrize("old,new,key", [
    ("bound_weight = 2.5", "bound_weight = 2.5\nbound_wieght = 1.0", "planner.bound_wieght"),
    ("tolerance_m = 1e-3\n", "", "goals[2].tolerance_m"),
    ("iterations = 500", 'iterations = "500"', "planner.iterations"),
    ("iterations = 500", "iterations = 5.5", "planner.iterations"),
    ("alpha_3 = 0.5, beta_3 = -0.05}", "alpha_3 = 0.5, beta_3 = -0.05, alpha_9 = 0.0}", "start.q.alpha_9"),
    ("alpha_3 = 0.5, beta_3 = -0.05}", "alpha_3 = 0.5}", "start.q.beta_3"),
    ("beta_3 = -0.04,", "beta_3 = -40.0,", "goals[1].q.beta_3"),            # outside limits (mm)
    ("tip_position_m = [0.02, 0.01, 0.18]", "tip_position_m = [20.0, 10.0, 180.0]", "goals[2].tip_position_m"),
    ("tip_position_m = [0.02, 0.01, 0.18]", "tip_position_m = [0.02, 0.01]", "goals[2].tip_position_m"),
    ("radius_m = 0.01", "radius_m = -0.01", "obstacles[1].radius_m"),
    ('type = "sphere"', 'type = "cylinder"', "obstacles[1]"),
    ('file = "meshes/tri.stl"', 'file = "meshes/missing.stl"', "obstacles[4].file"),
    ("scale = 0.001\n", "", "obstacles[4].scale"),
    ("resolution = [9, 9, 5]", "resolution = [9, 9]", "bound_field.resolution"),
    ("ds_m = 0.002", 'placement = "smart"\nds_m = 0.002', "bound_field.placement"),
    ("ds_m = 0.002", 'ds_m = 0.002\nfirst_plan = "later"', "bound_field.first_plan"),
    ("ds_m = 0.002", "ds_m = 0.002\nrefine_rounds = -1", "bound_field.refine_rounds"),
    ("ds_m = 0.002", "ds_m = 0.002\nrefine_tolerance_m = 0.0", "bound_field.refine_tolerance_m"),
    ("max_jerk = {alpha_2 = 50.0, ", "max_jerk = {", "drive.max_jerk.alpha_2"),
    ("max_velocity = {alpha_2 = 1.0,", "max_velocity = {alpha_2 = 0.0,", "drive.max_velocity.alpha_2"),
    ('dir = "out"', "dir = 3", "output.dir"),
    ('name = "demo"\n', "", "name"),
    ("iterations = 500", 'iterations = 500\nname = "RRTstr"', "planner.name"),
    ("iterations = 500", 'iterations = 500\nroadmap = "yes"', "planner.roadmap"),
])
def test_bad_scenarios(tmp_path, old, new, key):
    assert old in GOOD
    err = _error(tmp_path, GOOD.replace(old, new))
    assert err.key == key, str(err)


def test_missing_robot_file(tmp_path):
    err = _error(tmp_path, GOOD.replace(TABLE2.as_posix(), "no-such-robot.toml"))
    assert err.key == "robot" and "not found" in str(err)


def test_value_in_message(tmp_path):
    err = _error(tmp_path, GOOD.replace("radius_m = 0.01", "radius_m = -0.01"))
    assert "-0.01" in str(err) and str(tmp_path) in str(err)


def test_joint_outside_its_limits_prints_values_not_reprs(tmp_path):
    """A joint value outside its limits is named with its value, limits and unit as numbers
    (catches "np.float64(-40.0) m")."""
    msg = str(_error(tmp_path, GOOD.replace("beta_3 = -0.04,", "beta_3 = -40.0,")))
    assert "-40 m is outside the joint limits [" in msg, msg
    assert "np.float64" not in msg and "float64" not in msg


def test_unknown_planner_is_refused_when_the_scenario_loads(tmp_path):
    """A misspelt planner fails at load (before any planning) naming the value and the planners
    the package has; every registered planner loads. Catches a name checked only by the planner
    after the goals were solved, or a registry out of step with the one the planners are built from."""
    from ctrplan.planning import PLANNERS

    err = _error(tmp_path, GOOD.replace("iterations = 500", 'iterations = 500\nname = "RRTstr"'))
    assert "'RRTstr'" in str(err) and "RRTstar" in err.detail and "Value error" not in str(err)
    assert "\n" not in str(err)
    for name in PLANNERS:
        assert load_scenario(_write(tmp_path, GOOD.replace("iterations = 500", f'iterations = 500\nname = "{name}"'))).planner.name == name


def test_obstacles_and_drive_feed_the_planning_and_trajectory_modules(tmp_path):
    s = load_scenario(_write(tmp_path, GOOD))
    dicts = [o.as_dict() for o in s.obstacles]
    assert [d["type"] for d in dicts] == ["sphere", "capsule", "box", "mesh"]
    assert dicts[3]["file"] == str((tmp_path / "meshes" / "tri.stl").resolve())
    assert s.drive.joint_names == ("alpha_2", "alpha_3", "beta_3")
    assert s.drive.max_velocity.tolist() == [1.0, 2.0, 0.01] and s.drive.control_rate_hz == 100.0
    from ctrplan.obstacles import obstacle_from_dict

    built = [obstacle_from_dict(dict(d)) for d in dicts]
    assert built == list(s.obstacles)


def test_default_bound_weight_matches_the_planning_objective():
    from ctrplan.io.scenario import DEFAULT_BOUND_WEIGHT
    from ctrplan.planning.objective import DEFAULT_BOUND_WEIGHT as OBJECTIVE_DEFAULT

    assert DEFAULT_BOUND_WEIGHT == OBJECTIVE_DEFAULT


@pytest.mark.parametrize("table, key, value, member", [
    ("planner", "final_motion", "rotation-last", "FinalMotion.ROTATION_LAST"),
    ("planner", "aim_with", "history", "AimWith.HISTORY"),
    ("bound_field", "placement", "adaptive", "MapPlacement.ADAPTIVE"),
    ("bound_field", "first_plan", "full", "FirstPlan.FULL"),
])
def test_a_choice_loads_as_its_enum_member_and_a_wrong_one_lists_the_choices(tmp_path, table, key, value, member):
    """A choice key of a scenario file becomes the member of its ctrplan.choices enum, which is
    its string (files and JSON keep the string); a value that is none of the choices is a one-line
    error naming the file, the key and the choices. Catches a loader that keeps a bare string
    (no check) or one that accepts a misspelt choice."""
    import json

    from ctrplan import choices

    text = GOOD.replace(f"[{table}]\n", f'[{table}]\n{key} = "{value}"\n')
    sc = load_scenario(_write(tmp_path, text))
    got = getattr(getattr(sc, "planner" if table == "planner" else "bound_field"), key)
    enum_name, name = member.split(".")
    assert got is getattr(getattr(choices, enum_name), name)
    assert got == value and json.dumps({key: got}) == json.dumps({key: value}) and f"{got}" == value
    err = _error(tmp_path, text.replace(f'{key} = "{value}"', f'{key} = "{value}x"'))
    assert err.key == f"{table}.{key}"
    assert all(f"'{m.value}'" in str(err) for m in getattr(choices, enum_name)), str(err)
