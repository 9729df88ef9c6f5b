"""The worked examples of ``docs/architecture.md`` run as written: the planner and the obstacle
type it registers are used by a scenario file that plans with both, the refusals the page
quotes happen, the mechanics model it registers is solved by name by the batch evaluator, the
discrepancy simulator and a robot file, with the physics the page states, and the effect it
registers is hidden in synthetic data and named by the discrepancy workflow.

Each example registers into the package's registries; the tests remove what they registered
(so that other tests see the built-in entries only).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import ctrplan
from _maps import constant_field
from _scenarios import write_scenario
from ctrplan.errors import ModelFileError
from ctrplan.io.scenario import load_scenario
from ctrplan.obstacles import OBSTACLE_REGISTRY
from ctrplan.planner_info import PLANNER_REGISTRY
from ctrplan.planning import JointStateSpace
from ctrplan.planning.route import route_checks
from ctrplan.mechanics import ModelSettings

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "architecture.md"
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
# the post of the page's example sits across the tip's path from START to GOAL
START = {"alpha_2": 0.0, "alpha_3": 0.0, "beta_3": -0.05}
GOAL = {"alpha_2": 0.8, "alpha_3": 0.0, "beta_3": -0.05}


def _section(title: str) -> str:
    text = PAGE.read_text()
    start = text.index(f"### {title}\n")
    end = text.find("\n## ", start)
    nxt = text.find("\n### ", start + 1)
    return text[start:min(x for x in (end, nxt, len(text)) if x > 0)]


def _blocks(title: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", _section(title), flags=re.S)


@pytest.fixture
def examples():
    """The page's planner and obstacle type, registered by running its code blocks; removed after."""
    names = {}
    try:
        for title, registry, name in (("A planner", PLANNER_REGISTRY, "RadiusRRTstar"),
                                      ("An obstacle type", OBSTACLE_REGISTRY, "post")):
            (code,) = _blocks(title, "python")
            namespace = {}
            exec(compile(code, str(PAGE), "exec", dont_inherit=True), namespace)
            assert name in registry
            names[name] = namespace
        yield names
    finally:
        for registry, name in ((PLANNER_REGISTRY, "RadiusRRTstar"), (OBSTACLE_REGISTRY, "post")):
            if name in registry:
                registry.unregister(name)


def _q(q: dict) -> str:
    return "{" + ", ".join(f"{k} = {v}" for k, v in q.items()) + "}"


def _scenario(tmp_path: Path, planner_table: str) -> Path:
    """The page's obstacle and ``[planner]`` table (its header dropped) in a scenario from START to GOAL."""
    (obstacle,) = _blocks("An obstacle type", "toml")
    body = planner_table.removeprefix("[planner]\n")
    return write_scenario(tmp_path, _q(GOAL), name="architecture", start_q=_q(START), obstacles=obstacle,
                          planner=body + "iterations = 300\nseed = 2")


def test_the_page_s_planner_and_obstacle_plan_a_scenario(tmp_path, monkeypatch, examples):
    """The scenario of the page's two TOML snippets loads the post as the page's class and plans
    every leg with the page's planner, around the post: its straight motion is refused by the
    collision check (so the route is not the straight one by accident), and the plan's final
    check passed every phase."""
    monkeypatch.chdir(tmp_path)
    (planner_table,) = _blocks("A planner", "toml")
    sc = load_scenario(_scenario(tmp_path, planner_table))
    post = sc.obstacles[0]
    assert type(post) is examples["post"]["Post"] and sc.planner.name == "RadiusRRTstar"
    js = JointStateSpace(sc.robot)
    checks = route_checks(sc.robot, list(sc.obstacles), None, ModelSettings(ds=3e-3), joint_space=js)
    q0, q1 = np.array(list(START.values())), np.array(list(GOAL.values()))
    assert not checks.search.check_motion(q0, q1)
    run = ctrplan.plan(sc, bound_map=constant_field(sc.robot), compare_blind=False).run
    aware = run.plans.aware
    assert {leg.planner for leg in aware.legs} == {"RadiusRRTstar"}
    np.testing.assert_allclose(js.difference(aware.ordered.q[-1], q1), 0.0, atol=1e-9)
    for a, b in zip(aware.ordered.q[:-1], aware.ordered.q[1:]):
        assert checks.final.check(a, b), (a, b)


@pytest.mark.parametrize("line, key, text", [
    ("goal_bias = 0.1", "planner.goal_bias",
     "nor a parameter that planner RadiusRRTstar declares (range)"),
    ("range = -1.0", "planner.range", "greater than 0; got -1.0"),
])
def test_the_refusals_the_page_quotes(tmp_path, examples, line, key, text):
    (planner_table,) = _blocks("A planner", "toml")
    table = re.sub(r"range = .*", line, planner_table) if line.startswith("range") else planner_table + line + "\n"
    path = _scenario(tmp_path, table)
    with pytest.raises(ModelFileError) as info:
        load_scenario(path)
    assert (info.value.file, info.value.key) == (str(path), key) and text in str(info.value)


def test_the_page_s_mechanics_model_is_solved_by_name_with_the_physics_it_states():
    """The page's torsionally rigid model, registered by its code block: with the Table I pair's
    precurvatures aligned or opposed no twist arises, so its tip is the standard model's; a
    quarter turn apart the standard model twists by several rad at the base and the rigid one
    does not (catches a solve that is not called, or called with the wrong robot). The batch
    evaluator, the simulator along a motion and a robot file's ``model`` key take it by name."""
    from ctrplan.batch import evaluate_configuration
    from ctrplan.discrepancy.fits.simulate import simulate
    from ctrplan.io.robot_file import load_robot, robot_from_toml_text
    from ctrplan.mechanics import solve_standard
    from ctrplan.models import MODEL_REGISTRY

    (code,) = _blocks("A mechanics model", "python")
    try:
        namespace = {}
        exec(compile(code, str(PAGE), "exec", dont_inherit=True), namespace)
        robot = load_robot(PAIR)
        settings = ModelSettings()
        tips = {}
        for rel in (0.0, np.pi / 2, np.pi):
            alpha, beta = robot.configuration([rel])
            (row,) = evaluate_configuration(robot, alpha, beta, "rigid-torsion", settings)
            assert row["status"] == "ok" and row["model"] == "rigid-torsion"
            std = solve_standard(robot, alpha, beta, settings)
            rigid = namespace["torsionally_rigid"](robot, alpha, beta, settings, standard=std)
            tip = np.array([row["tip_x"], row["tip_y"], row["tip_z"]])   # [m]
            np.testing.assert_array_equal(tip, rigid.tip_position)
            tips[rel] = (tip, std)
        for rel in (0.0, np.pi):
            np.testing.assert_allclose(tips[rel][0], tips[rel][1].tip_position, atol=1e-9)
        tip, std = tips[np.pi / 2]
        alpha, beta = robot.configuration([np.pi / 2])
        rigid = namespace["torsionally_rigid"](robot, alpha, beta, settings, standard=std)
        assert np.abs(std.base_torsion).max() > 1.0 and np.abs(rigid.base_torsion).max() < 1e-5
        assert 5e-3 < np.linalg.norm(tip - std.tip_position) < 12e-3
        # along a motion, followed sample to sample, as the discrepancy workflow evaluates it
        rel = np.linspace(0.0, np.pi / 2, 5)
        alpha = np.column_stack([np.zeros(5), rel])
        beta = np.tile(robot.configuration([0.0])[1], (5, 1))
        sim = simulate(robot, alpha, beta, model="rigid-torsion", sequence=np.zeros(5, int), settings=settings)
        assert sim.ok.all()
        np.testing.assert_allclose(sim.tip[-1], tip, atol=1e-9)
        text = PAIR.read_text()
        assert robot_from_toml_text('model = "rigid-torsion"\n' + text, file="t.toml").metadata["model"] == "rigid-torsion"
    finally:
        if "rigid-torsion" in MODEL_REGISTRY:
            MODEL_REGISTRY.unregister("rigid-torsion")


def test_the_page_s_effect_is_hidden_by_synthesize_and_named_by_the_workflow(tmp_path):
    """The page's effect, registered by its code block and nowhere else: a constant offset of the
    measured tip along z (3 mm) hidden in a 500-sample trajectory of the Table I tube pair by
    synthesize, competing with the built-in backlash and time offset. The workflow tests its
    signature, fits it, names it with its size within 0.5 mm, writes it into the updated robot
    file's [effects] table and reproduces the errors from that file. Catches any place that still
    lists the effects by name instead of iterating the registry."""
    from ctrplan.discrepancy import Noise, SynthProtocol, synthesize, write_synth
    from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy
    from ctrplan.effects import REGISTRY, unregister
    from ctrplan.io.robot_file import load_robot, robot_to_toml

    (code,) = _blocks("An effect", "python")
    try:
        exec(compile(code, str(PAGE), "exec", dont_inherit=True), {})
        assert "tip_offset_z" in REGISTRY
        robot = load_robot(PAIR).replace(friction_coefficients=(0.0,))
        model = tmp_path / "pair.toml"
        model.write_text(robot_to_toml(robot))
        data = tmp_path / "toy.csv"
        write_synth(data, synthesize(robot, {"tip_offset_z": {"tip_offset_z": 0.003}},
                                     protocol=SynthProtocol.trajectory(500),
                                     noise=Noise(position_rms=0.5e-3, angle_rms=0.005), seed=37,
                                     settings=ModelSettings(ds=6e-3)))
        opts = DiscrepancyOptions(effects=("backlash", "time_offset", "tip_offset_z"), ds=6e-3, n_permutations=199,
                                  max_evaluations=200, n_folds=5, prior_strengths=(0.03, float("inf")), n_jobs=1)
        res = run_discrepancy(model, data, tmp_path / "out", opts, progress=False).to_dict()
        assert res["named_effect"] == "tip_offset_z", res["decision"]
        assert res["candidates"]["tip_offset_z"]["parameters"]["tip_offset_z"] == pytest.approx(0.003, abs=5e-4)
        assert res["signature_tests"]["tip_offset_z"]["p_value"] < 0.01
        written = load_robot(res["updated_model_file"])
        assert dict(written.effects)["tip_offset_z"][0][0] == "tip_offset_z"
        assert res["reproduced"]
    finally:
        if "tip_offset_z" in REGISTRY:
            unregister("tip_offset_z")


def test_an_effect_fitted_by_a_strategy_of_its_own(tmp_path):
    """A fit strategy written outside the package from the FitContext's solvers alone: the page's
    tip offset fitted by a scan in 1 mm steps with the baseline held. The workflow calls it for
    the development fit and every fold's, and the fitted offset is exactly a scan value (3 mm),
    which the default least-squares strategy would not give. Catches a workflow that fits an
    effect by anything other than its entry's strategy."""
    import dataclasses

    from ctrplan.discrepancy import Noise, SynthProtocol, synthesize, write_synth
    from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy
    from ctrplan.effects import REGISTRY, FitStrategy, register, unregister
    from ctrplan.io.robot_file import load_robot, robot_to_toml

    steps = tuple(np.round(np.arange(-0.006, 0.0065, 0.001), 6))
    folds = []

    def scan_in_millimetres(ctx):
        folds.append(ctx.k)
        held = dict(zip(*ctx.base.all_parameters()))
        return ctx.scan(ctx.entry.model, held, ctx.extra, steps, uncertainty=ctx.k is None)

    (code,) = _blocks("An effect", "python")
    try:
        exec(compile(code, str(PAGE), "exec", dont_inherit=True), {})
        register(dataclasses.replace(REGISTRY["tip_offset_z"], fit=FitStrategy("millimetre scan", scan_in_millimetres)),
                 replace=True)
        robot = load_robot(PAIR).replace(friction_coefficients=(0.0,))
        model = tmp_path / "pair.toml"
        model.write_text(robot_to_toml(robot))
        data = tmp_path / "toy.csv"
        write_synth(data, synthesize(robot, {"tip_offset_z": {"tip_offset_z": 0.0031}},
                                     protocol=SynthProtocol.trajectory(300),
                                     noise=Noise(position_rms=0.5e-3, angle_rms=0.005), seed=41,
                                     settings=ModelSettings(ds=6e-3)))
        opts = DiscrepancyOptions(effects=("tip_offset_z",), ds=6e-3, n_permutations=99, max_evaluations=200,
                                  n_folds=4, prior_strengths=(0.03,), n_jobs=1)
        res = run_discrepancy(model, data, tmp_path / "out", opts, progress=False).to_dict()
        assert sorted(folds, key=lambda k: -1 if k is None else k) == [None, 0, 1, 2, 3]
        assert res["candidates"]["tip_offset_z"]["parameters"]["tip_offset_z"] == 0.003
    finally:
        if "tip_offset_z" in REGISTRY:
            unregister("tip_offset_z")
