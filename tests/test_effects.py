"""ctrplan.effects: the registry of effects, their values, and the robot file's ``[effects]`` table.

Each built-in entry changes what it says it changes (robot, motion or measurement) and nothing
else; a robot file carries history effects with their source and refuses atypical or unknown
ones naming the file, the key and the value; and a new effect is added in one place: a toy
effect registered here, hidden in synthetic data, is named by the unchanged workflow.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.effects import (REGISTRY, EffectSet, ParameterSpec, apply_output_effects, apply_robot_effects,
                             history_state, model_of, robot_effects)
from ctrplan.errors import ModelFileError, PhysicalParameterError
from ctrplan.history import MotionRecord, play
from ctrplan.io.robot_file import load_robot, robot_from_toml_text, robot_to_toml

from _robots import table2_robot

ROOT = Path(__file__).resolve().parents[1]
TABLE7 = ROOT / "model" / "ha2019-table7-calibrated.toml"
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"


# --------------------------------------------------------------------------- entries
def test_every_entry_is_complete_and_its_typical_range_lies_inside_its_bounds():
    """Every registered effect has a label, a model, parameters with units and typical ranges
    strictly inside the optimizer bounds (a lower end only where the effect vanishes), a
    signature test, a synth option and a word on planning. Catches an entry added half-way, and
    a typical range equal to the bounds (a fit at the bound would then count as typical)."""
    robot = load_robot(TABLE7)
    for e in REGISTRY.values():
        assert e.label and e.model in ("standard", "clearance", "friction") and e.plan, e.name
        assert e.signature is not None and e.synth_option and e.synth_option.startswith("--"), e.name
        for p in e.parameters(robot):
            assert p.unit in ("rad", "s", "m", "1/m", "-"), p
            assert p.typical is not None, p
            lo, hi = p.typical
            assert p.lower <= lo < hi < p.upper, p
            assert lo > p.lower or p.vanishes_at_lower, p
    with pytest.raises(ValueError, match="strictly inside"):
        ParameterSpec("x_1", "x", 0, "-", -1.0, 1.0, 0.1, (-1.0, 0.5))
    import dataclasses

    from ctrplan.effects import register

    with pytest.raises(ValueError, match="effect 'backlash' is already registered"):
        register(dataclasses.replace(REGISTRY["backlash"], label="another backlash"))
    with pytest.raises(TypeError, match="fit must be a FitStrategy"):
        dataclasses.replace(REGISTRY["backlash"], fit="nested")


def test_robot_effects_change_the_robot_and_nothing_else():
    """Friction, clearance, off-plane precurvature and Poisson ratio change the robot's tables;
    the history effects do not (they act on the motion). Catches a straight collar that gains a
    precurvature, an effect applied to the wrong tube, or a history effect leaking into the robot."""
    r = table2_robot(mu=0.2)
    es = EffectSet.from_values(r, {"friction": (0.1, 0.3), "clearance": (1e-4, 2e-4),
                                   "offplane": (0.5, -1.0, 2.0), "poisson": (0.3, 0.35, -0.15)})
    m = apply_robot_effects(r, es)
    assert m.friction_coefficients == (0.1, 0.3)
    np.testing.assert_allclose(m.clearances, [1e-4, 2e-4])
    assert m.tubes[2].poisson_ratio == -0.15
    assert m.tubes[1].sections[0].precurvature == (0.0, 0.0)          # straight collar stays straight
    assert m.tubes[1].sections[1].precurvature[0] == -1.0
    assert m.tubes[2].sections[1].precurvature[1] == r.tubes[2].sections[1].precurvature[1]
    hist = EffectSet.from_values(r, {"backlash": (0.0, 0.05, 0.05), "time_offset": (0.1,)})
    assert apply_robot_effects(r, hist) == r
    assert model_of(es) == "friction" and model_of(hist) == "standard"
    assert model_of(EffectSet.from_values(r, {"friction": (0.0, 0.0)})) == "standard"
    with pytest.raises(PhysicalParameterError, match="needs 3 values"):
        EffectSet.from_values(r, {"offplane": (1.0, 2.0)})
    with pytest.raises(PhysicalParameterError, match="outside"):
        EffectSet.from_values(r, {"clearance": (0.0, 1e-4)})
    with pytest.raises(PhysicalParameterError, match="outside"):
        EffectSet.from_values(r, {"poisson": (0.3, 0.6, 0.3)})
    with pytest.raises(PhysicalParameterError, match="unknown effect 'mu'"):
        EffectSet({"mu": {"mu_1": 0.1}})
    with pytest.raises(PhysicalParameterError, match="needs the effect 'friction'"):
        EffectSet.from_values(r.replace(friction_coefficients=(0.0, 0.0)), {"gradual_friction": (0.1,)})


def test_registration_maps_the_robot_frame_to_the_tracker_frame():
    """p' = R p + t with R a quarter turn about z: (1, 0, 0) -> (t_x, 1, 0); tangents rotate only."""
    r = table2_robot()
    es = EffectSet.from_values(r, {"registration": (0.0, 0.0, np.pi / 2, 0.01, 0.0, 0.0)})
    tip, tan = apply_output_effects(np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), es)
    np.testing.assert_allclose(tip, [[0.01, 1.0, 0.0]], atol=1e-15)
    np.testing.assert_allclose(tan, [[-1.0, 0.0, 0.0]], atol=1e-15)


def test_the_robot_files_history_effects_act_on_the_motion():
    """A robot whose file has a dead band on tube 2's drive: history_state moves the tubes
    through the play (as ctrplan.history.play does), and a time offset acts only with the tracker."""
    robot = table2_robot().replace(effects=(("backlash", (("backlash_2", 0.2),)), ("time_offset", (("time_offset", 0.1),))))
    t = np.arange(6) * 0.1
    alpha = np.column_stack([np.zeros(6), np.linspace(0, 1, 6), np.zeros(6)])
    rec = MotionRecord(alpha, np.tile(robot.home_beta, (6, 1)), t)
    s = history_state(robot, rec, tracker=False)
    np.testing.assert_allclose(s.alpha, play(rec, [0.0, 0.2, 0.0]).alpha)
    assert not np.allclose(history_state(robot, rec).alpha, s.alpha)
    assert set(robot_effects(robot)) == {"backlash", "time_offset"}


# --------------------------------------------------------------------------- robot files
def _with_effects(text: str) -> str:
    return text + "\n[effects.backlash]\nbacklash_2_rad = 0.05\n[effects.time_offset]\ntime_offset_s = 0.04\n"


def test_robot_file_effects_round_trip_with_their_source(tmp_path):
    robot = load_robot(TABLE7)
    r2 = robot.replace(effects=(("backlash", (("backlash_2", 0.05),)), ("gradual_friction", (("friction_angle", 0.2),))))
    text = robot_to_toml(r2, effects_source={"method": "ctrplan discrepancy", "data_file": "d.csv",
                                            "held_out_position_mean_m": 0.0031})
    back = robot_from_toml_text(text, "f.toml")
    assert back.effects == r2.effects and back == r2
    assert back.metadata["effects_source"]["data_file"] == "d.csv"
    assert back.metadata["effects_source"]["held_out_position_mean_m"] == 0.0031


@pytest.mark.parametrize("edit, key, match", [
    (lambda t: t.replace("backlash_2_rad = 0.05", "backlash_2_rad = 4.0"), "effects.backlash.backlash_2_rad",
     r"4.0 \(229.2 deg\) is outside the values this parameter can take, 0..180 deg"),
    (lambda t: t.replace("backlash_2_rad", "backlash_9_rad"), "effects.backlash.backlash_9_rad", "unknown key"),
    (lambda t: t.replace("[effects.time_offset]", "[effects.lag]"), "effects.lag", "unknown effect"),
    (lambda t: t + "[effects.friction]\nmu_1 = 0.2\n", "effects.friction", r"belongs in \[\[tubes\]\] and \[\[pairs\]\]"),
    (lambda t: t.replace("time_offset_s = 0.04", 'time_offset_s = "fast"'), "effects.time_offset.time_offset_s",
     "expected a finite number"),
])
def test_a_bad_effects_table_names_the_file_the_key_and_the_value(edit, key, match):
    text = _with_effects(TABLE7.read_text())
    robot_from_toml_text(text, "f.toml")          # the unedited table loads
    with pytest.raises(ModelFileError, match=match) as err:
        robot_from_toml_text(edit(text), "f.toml")
    assert err.value.file == "f.toml" and err.value.key == key


def test_an_atypical_effect_loads_with_the_cautions_that_explain_it():
    """A dead band of 11.5 deg (beyond a geared stage's 0-5 deg, within what a drive can have)
    is written by the discrepancy workflow when the data show it, with a caution in
    [effects_source]; the file loads and keeps both. Catches a loader that refuses what the
    workflow writes, or drops the caution."""
    text = _with_effects(TABLE7.read_text()).replace("backlash_2_rad = 0.05", "backlash_2_rad = 0.2")
    text += '\n[effects_source]\ncautions = ["drive backlash 11.46 deg: check the couplings"]\n'
    robot = robot_from_toml_text(text, "f.toml")
    assert dict(robot.effects)["backlash"] == (("backlash_2", 0.2),)
    assert robot.metadata["effects_source"]["cautions"] == ["drive backlash 11.46 deg: check the couplings"]


def test_an_effects_source_without_effects_is_refused():
    with pytest.raises(ModelFileError, match="effects_source"):
        robot_from_toml_text(TABLE7.read_text() + '\n[effects_source]\ndata_file = "d.csv"\n', "f.toml")


def test_synth_options_come_from_the_registry():
    from click.testing import CliRunner

    from ctrplan.cli import main

    out = CliRunner().invoke(main, ["synth", "--help"]).output
    for e in REGISTRY.values():
        assert e.synth_option in out, e.name
