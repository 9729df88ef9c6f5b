"""The one registry type (:mod:`ctrplan.registry`) and the registries built on it: mechanics
models, planners (with declared parameters) and obstacle types.

A planner registered at run time is planned with through :func:`ctrplan.planning.plan_leg` and
through :func:`ctrplan.plan` from a scenario file, in this process and in a worker process; a
parameter it does not declare is refused, in a scenario file with the file and the key.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ompl import geometric as og

import ctrplan
from _maps import constant_field
from _scenarios import write_scenario
from ctrplan.errors import ModelFileError
from ctrplan.io.robot_file import load_robot
from ctrplan.io.scenario import load_scenario
from ctrplan.models import MODEL_REGISTRY, ModelInfo, check_model, contact_solution, standard_solution
from ctrplan.obstacles import OBSTACLE_REGISTRY, OBSTACLE_TYPES, Sphere
from ctrplan.planner_info import (PLANNER_REGISTRY, PlannerInfo, PlannerParameter, check_planner_options,
                                  register_planner)
from ctrplan.planning import PLANNERS, BoundCostObjective, ValidityChecker, plan_leg
from ctrplan.registry import Registry, UnknownNameError
from test_planning_helpers import fake_robot

REPO = Path(__file__).resolve().parents[1]
TABLE7 = REPO / "model" / "ha2019-table7-calibrated.toml"


# ------------------------------------------------------------------------------ the type
def test_register_look_up_and_unregister():
    """Order is registration order; the same entry again is a no-op, another one under a taken
    name an error unless replaced (which keeps its place); an unknown name is one line naming the
    registry and the registered names, caught as KeyError and as ValueError."""
    reg = Registry("colour")
    red, blue = (1, 0, 0), (0, 0, 1)
    assert reg.register("red", red) is red and reg.register("blue", blue) is blue
    assert reg.register("red", red) is red                      # the same entry: no-op
    assert reg.names() == ("red", "blue") and list(reg) == ["red", "blue"] and len(reg) == 2
    with pytest.raises(ValueError, match="colour 'red' is already registered"):
        reg.register("red", (0.9, 0, 0))
    reg.register("red", (0.9, 0, 0), replace=True)
    assert reg.names() == ("red", "blue") and reg["red"] == (0.9, 0, 0)
    for catch in (KeyError, ValueError):
        with pytest.raises(catch) as info:
            reg["green"]
        assert str(info.value) == "unknown colour 'green'; registered: red, blue"
    assert reg.unregister("blue") is blue and reg.names() == ("red",)
    with pytest.raises(UnknownNameError, match="unknown colour 'blue'; registered: red"):
        reg.unregister("blue")
    with pytest.raises(TypeError, match="non-empty str"):
        reg.register("", red)


def test_registered_restores_what_was_there_and_the_view_is_live_and_read_only():
    """The context manager removes a new entry and puts a replaced one back at its place, also
    when the block raises (catches a registry left changed by a failing test); the view follows
    the registry and cannot be written."""
    reg = Registry("colour")
    reg.register("red", 1)
    reg.register("blue", 2)
    view = reg.view
    with reg.registered("green", 3):
        assert view["green"] == 3 and reg.names() == ("red", "blue", "green")
    assert "green" not in reg and "green" not in view
    with pytest.raises(RuntimeError):
        with reg.registered("red", 10, replace=True):
            assert reg["red"] == 10 and reg.names() == ("red", "blue")
            raise RuntimeError("inside")
    assert reg.items() == (("red", 1), ("blue", 2))
    with pytest.raises(TypeError):
        view["red"] = 5


def test_the_check_refuses_an_entry_before_it_is_added():
    def positive(name, value):
        if value <= 0:
            raise ValueError(f"{name} must be positive")

    reg = Registry("gain", check=positive)
    with pytest.raises(ValueError, match="kp must be positive"):
        reg.register("kp", -1.0)
    assert "kp" not in reg


# ------------------------------------------------------------------------------ the three registries
def test_the_packages_registries_share_the_type_and_refuse_malformed_entries():
    """Models, planners and obstacle types are Registry instances whose views are the mappings
    the package reads (catches a second copy that registration does not reach)."""
    for reg, view in ((MODEL_REGISTRY, ctrplan.models.MODEL_INFO), (PLANNER_REGISTRY, ctrplan.planner_info.PLANNER_INFO),
                      (OBSTACLE_REGISTRY, OBSTACLE_TYPES)):
        assert isinstance(reg, Registry) and reg.view is view
    assert MODEL_REGISTRY.names() == ("standard", "clearance", "friction")
    assert PLANNER_REGISTRY.names()[:4] == ("RRTstar", "InformedRRTstar", "SORRTstar", "BITstar")
    assert OBSTACLE_REGISTRY.names()[:5] == ("sphere", "capsule", "box", "mesh", "triangles")
    with pytest.raises(ValueError, match="unknown mechanics model 'magic'; registered: standard, clearance, friction"):
        check_model("magic")
    with pytest.raises(ValueError, match="friction needs the contact solve"):
        MODEL_REGISTRY.register("sticky", ModelInfo("sticky", "x", "y", contact_solution, contact=False, friction=True))
    with pytest.raises(TypeError, match="solve must be a function, got 'solve_friction'"):
        MODEL_REGISTRY.register("named", ModelInfo("named", "x", "y", "solve_friction", contact=True, friction=True))
    with pytest.raises(TypeError, match="ModelInfo named 'other'"):
        MODEL_REGISTRY.register("other", ModelInfo("standard", "x", "y", standard_solution, False, False))
    with pytest.raises(ValueError, match="exactly one of ompl_class"):
        register_planner(PlannerInfo("Nothing", "makes nothing"))
    with pytest.raises(ValueError, match="is named 'sphere' by its type field, not 'ball'"):
        OBSTACLE_REGISTRY.register("ball", Sphere)
    assert "sticky" not in MODEL_REGISTRY and "named" not in MODEL_REGISTRY and "Nothing" not in PLANNER_REGISTRY and "ball" not in OBSTACLE_REGISTRY


# ------------------------------------------------------------------------------ planner parameters
def test_planner_options_are_checked_against_what_the_planner_declares():
    """BITstar has no range (OMPL's BITstar has no setRange: before declared parameters a range
    given to it was silently ignored); values of the wrong type or outside the limits are
    refused naming the parameter; ints are accepted for floats and None counts as not given."""
    assert check_planner_options("RRTstar", {"range": 1, "goal_bias": None}) == {"range": 1.0}
    assert isinstance(check_planner_options("RRTstar", {"range": 1})["range"], float)
    with pytest.raises(ValueError, match=r"planner BITstar does not declare a parameter 'range' \(its parameters: "
                                         r"rewire_factor\)"):
        check_planner_options("BITstar", {"range": 0.1})
    with pytest.raises(ValueError, match=r"goal_bias must be in \[0, 1\], got 1.5"):
        check_planner_options("RRTstar", {"goal_bias": 1.5})
    with pytest.raises(ValueError, match="range must be a float, got 'far'"):
        check_planner_options("RRTstar", {"range": "far"})
    with pytest.raises(ValueError, match="range must be a float, got True"):
        check_planner_options("RRTstar", {"range": True})
    with pytest.raises(ValueError, match="unknown planner 'PRM'"):
        check_planner_options("PRM", {})


def _radius_rrt_star(si):
    planner = og.RRTstar(si)
    planner.setKNearest(False)
    return planner


def _counting_info(applied: list) -> PlannerInfo:
    """RRT* with radius neighbourhoods, declaring a range (by a callable setter that records its
    value and sets it) and a rewire factor."""
    def set_range(planner, value):
        applied.append(value)
        planner.setRange(value)

    return PlannerInfo("RadiusRRTstar", "RRT* connecting within a radius instead of to the k nearest",
                       make=_radius_rrt_star,
                       parameters={"range": PlannerParameter("range", float, "motion length [m]", set_range, low=0.0),
                                   "rewire_factor": PlannerParameter("rewire_factor", float, "rewire factor",
                                                                     "setRewireFactor", low=0.0, default=0.5)})


def test_a_registered_planner_plans_with_its_declared_parameters():
    """plan_leg() makes the planner through its entry and applies the declared parameters (catches
    a plan that falls back to a built-in class or drops the options); an option it does not
    declare is an error, not ignored. Unregistered after the block, the name is unknown again."""
    robot = fake_robot()
    valid = ValidityChecker(robot, check_stability=False)
    objective = BoundCostObjective.factory(None, bound_weight=0.0)
    applied = []
    start, goal = np.array([-1.2, 0.0, -0.07]), np.array([1.2, 0.0, -0.07])
    with PLANNER_REGISTRY.registered("RadiusRRTstar", _counting_info(applied)):
        assert PLANNERS["RadiusRRTstar"] is _radius_rrt_star
        res = plan_leg(robot, start, goal, valid, objective, planner="RadiusRRTstar", iterations=200, seed=2, range_=0.3)
        assert res.planner == "RadiusRRTstar" and res.solved and applied == [0.3]
        with pytest.raises(ValueError, match="planner RadiusRRTstar does not declare a parameter 'goal_bias'"):
            plan_leg(robot, start, goal, valid, objective, planner="RadiusRRTstar", iterations=10, goal_bias=0.1)
    with pytest.raises(ValueError, match="unknown planner 'RadiusRRTstar'"):
        plan_leg(robot, start, goal, valid, objective, planner="RadiusRRTstar", iterations=10)


def _scenario(tmp_path, planner_table: str) -> Path:
    return write_scenario(tmp_path, "{alpha_2 = 0.6, alpha_3 = -0.4, beta_3 = -0.06}", planner=planner_table)


@pytest.mark.parametrize("table, key, text", [
    ('name = "BITstar"\nrange = 0.1', "planner.range",
     "planner BITstar does not declare a parameter 'range' (its parameters: rewire_factor); got 0.1"),
    ('name = "RRTstar"\niteration = 10', "planner.iteration",
     "not a key of [planner] (name, iterations, "),
    ('name = "RRTstar"\ngoal_bias = 1.5', "planner.goal_bias", "goal_bias must be in [0, 1], got 1.5"),
    ('name = "RRTstar"\ngoal_bias = "often"', "planner.goal_bias", "goal_bias must be a float, got 'often'"),
    ('name = "PRM"', "planner.name", "unknown planner 'PRM'; registered: RRTstar"),
])
def test_a_scenario_key_the_planner_does_not_declare_names_the_file_and_the_key(tmp_path, table, key, text):
    path = _scenario(tmp_path, table)
    with pytest.raises(ModelFileError) as info:
        load_scenario(path)
    assert (info.value.file, info.value.key) == (str(path), key), str(info.value)
    assert text in str(info.value) and "\n" not in str(info.value)


def test_a_declared_parameter_from_a_scenario_reaches_the_planner(tmp_path):
    """``goal_bias`` is a key of [planner] because the RRT* family declares it."""
    sc = load_scenario(_scenario(tmp_path, 'name = "RRTstar"\ngoal_bias = 0.2'))
    assert dict(sc.planner.parameters) == {"goal_bias": 0.2}


def test_a_registered_planner_plans_a_scenario_in_series_and_in_a_worker(tmp_path, monkeypatch):
    """ctrplan.plan with a scenario naming the run-time planner and giving its parameter: the
    bound-aware and bound-blind plans in this process and in a forked worker process give the
    same paths, every leg planned by it (catches a worker that does not know the planner, or a
    leg planned with another)."""
    monkeypatch.chdir(tmp_path)
    field = constant_field(load_robot(TABLE7))
    paths = {}
    with PLANNER_REGISTRY.registered("RadiusRRTstar", _counting_info([])):
        sc = _scenario(tmp_path, 'name = "RadiusRRTstar"\niterations = 30\nseed = 1\nrange = 0.5')
        for jobs in (1, 2):
            out = tmp_path / f"out{jobs}"
            run = ctrplan.plan(sc, bound_map=field, out_dir=out, n_jobs=jobs, compare_blind=True).run
            assert run.plans.in_parallel == (jobs == 2)
            assert {leg.planner for p in run.plans.routes.values() for leg in p.legs} == {"RadiusRRTstar"}
            paths[jobs] = (out / "path.csv").read_text()
    assert paths[1] == paths[2]


def test_the_planner_table_of_the_docs_is_the_registry_s():
    """docs/planning.md lists the planners and their parameters as planner_table() writes them
    (catches a planner or parameter added to the registry and not to the docs, or the reverse)."""
    from ctrplan.planner_info import planner_table

    text = (REPO / "docs" / "planning.md").read_text()
    block = text.split("<!-- planner_table() -->\n", 1)[1].split("<!-- /planner_table() -->", 1)[0]
    assert block == planner_table()
