"""The model registry (ctrplan.models) is the one list every reader of a model name uses."""

from pathlib import Path

import pytest

from ctrplan import mechanics
from ctrplan.errors import ModelFileError
from ctrplan.io.robot_file import robot_from_toml_text
from ctrplan.models import MODEL_INFO, MODELS, check_model

TABLE7 = Path(__file__).resolve().parents[1] / "model" / "ha2019-table7-calibrated.toml"


def test_every_registered_model_holds_its_solver_and_a_paper_section():
    assert MODELS == ("standard", "clearance", "friction")
    for name in MODELS:
        info = MODEL_INFO[name]
        assert info.name == name
        assert callable(info.solve)
        assert info.source.startswith("Section") and info.description


def test_the_entries_solve_as_the_mechanics_functions_they_stand_for():
    """Each built-in entry's ``solve`` gives what the mechanics function of its section gives, bit
    for bit (catches an entry wired to the wrong solver or dropping eta)."""
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(TABLE7)
    alpha, beta = robot.configuration([1.2, -2.0, -0.07])   # alpha_2, alpha_3 [rad], beta_3 [m]
    settings = mechanics.ModelSettings()
    std = mechanics.solve_standard(robot, alpha, beta, settings)
    assert MODEL_INFO["standard"].solve(robot, alpha, beta, settings, standard=std) is std
    cl = mechanics.solve_clearance(robot, alpha, beta, settings, standard=std)
    got = MODEL_INFO["clearance"].solve(robot, alpha, beta, settings, standard=std)
    assert (got.tip_position == cl.tip_position).all() and (got.tip_tangent == cl.tip_tangent).all()
    eta = [1, -1]
    fr = mechanics.solve_friction(robot, alpha, beta, eta, settings, standard=std, warm_start=cl)
    got = MODEL_INFO["friction"].solve(robot, alpha, beta, settings, standard=std, eta=eta, warm_start=cl)
    assert (got.tip_position == fr.tip_position).all()
    assert abs(got.tip_position - cl.tip_position).max() > 1e-6, "eta did not reach the friction solve"


@pytest.mark.parametrize("name", MODELS)
def test_robot_file_accepts_each_registered_model(name):
    robot = robot_from_toml_text(f'model = "{name}"\n' + TABLE7.read_text(), file="t.toml")
    assert robot.metadata["model"] == name


def test_robot_file_rejects_an_unregistered_model_naming_the_key():
    with pytest.raises(ModelFileError, match="key 'model'.*'standard', 'clearance' or 'friction'.*magic"):
        robot_from_toml_text('model = "magic"\n' + TABLE7.read_text(), file="t.toml")


def test_check_model_lists_the_registry():
    assert check_model("friction") == "friction"
    with pytest.raises(ValueError, match="unknown mechanics model 'magic'; registered: standard, clearance, friction"):
        check_model("magic")


def test_command_line_model_choices_are_the_registry():
    from ctrplan.cli import evaluate

    option = next(p for p in evaluate.params if p.name == "model")
    assert tuple(option.type.choices) == MODELS


def test_other_modules_use_the_same_model_names():
    import importlib

    from ctrplan import batch
    from ctrplan.io import robot_file

    simulate = importlib.import_module("ctrplan.discrepancy.fits.simulate")

    assert robot_file.MODELS is MODELS
    assert batch.MODELS is MODELS and simulate.MODELS is MODELS


def test_registry_says_what_each_model_needs():
    # the contact models need the clearances and contact solve; only friction takes eta and mu
    assert [MODEL_INFO[m].contact for m in MODELS] == [False, True, True]
    assert [MODEL_INFO[m].friction for m in MODELS] == [False, False, True]
    # only the standard model's solution is the standard solve (the batched standard solver's rows)
    assert [MODEL_INFO[m].standard_only for m in MODELS] == [True, False, False]


def test_batch_rejects_an_unregistered_model_before_solving():
    from ctrplan import batch
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(TABLE7)
    with pytest.raises(ValueError, match="unknown mechanics model 'magic'; registered: standard, clearance, friction"):
        batch.evaluate_configuration(robot, [0.0] * robot.n_tubes, [0.0] * robot.n_tubes, "magic")
