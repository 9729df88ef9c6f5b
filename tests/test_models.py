"""The model registry (ctrplan.models) is the one list every reader of a model name uses."""

from pathlib import Path

import pytest

from ctrplan import mechanics
from ctrplan.errors import ModelFileError
from ctrplan.io.robot_file import robot_from_toml_text
from ctrplan.models import MODEL_INFO, MODELS, check_model

TABLE7 = Path(__file__).resolve().parents[1] / "model" / "ha2019-table7-calibrated.toml"


def test_every_registered_model_names_a_solver_and_a_paper_section():
    assert MODELS == ("standard", "clearance", "friction")
    for name in MODELS:
        info = MODEL_INFO[name]
        assert info.name == name
        assert callable(getattr(mechanics, info.solver)), info.solver
        assert info.source.startswith("Section") and info.description


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

    simulate = importlib.import_module("ctrplan.discrepancy.simulate")

    assert robot_file.MODELS is MODELS
    assert batch.MODELS is MODELS and simulate.MODELS is MODELS


def test_registry_says_what_each_model_needs():
    # the contact models need the clearances and contact solve; only friction takes eta and mu
    assert [MODEL_INFO[m].contact for m in MODELS] == [False, True, True]
    assert [MODEL_INFO[m].friction for m in MODELS] == [False, False, True]
    # a friction solver's signature takes eta; the others do not
    import inspect

    for m in MODELS:
        params = inspect.signature(getattr(mechanics, MODEL_INFO[m].solver)).parameters
        assert ("eta" in params) == MODEL_INFO[m].friction, m


def test_batch_rejects_an_unregistered_model_before_solving():
    from ctrplan import batch
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(TABLE7)
    with pytest.raises(ValueError, match="unknown mechanics model 'magic'; registered: standard, clearance, friction"):
        batch.evaluate_configuration(robot, [0.0] * robot.n_tubes, [0.0] * robot.n_tubes, "magic")
