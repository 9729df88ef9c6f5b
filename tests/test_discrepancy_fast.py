"""Hidden-effect cases of the default run: the whole discrepancy workflow on a synthetic continuous
trajectory (500 samples at 10 Hz, 0.5 mm / 0.3 deg noise) of the Table I tube pair, with one
effect hidden in the data and the base file without it: drive backlash, a tracker time offset,
torsional friction, and noise only. Each asserts the verdict (named, or "ambiguous" with the
truth first or second) and the fitted size against the truth.

The candidate set of each case is the hidden effect and its closest rivals (the effects that also
lower a hysteretic or lagging error); the full sweep over every effect is
``benchmarks/bench_discrepancy_sweep.py``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.discrepancy import Noise, synthesize, write_synth
from ctrplan.discrepancy.data import load_measured_data
from ctrplan.discrepancy.decision import estimate_noise
from ctrplan.discrepancy.report import write_report
from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy
from ctrplan.io.robot_file import load_robot, robot_to_toml
from ctrplan.mechanics import ModelSettings

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT / "model" / "ha2019-table1-tube-pair.toml"
COARSE = ModelSettings(ds=6e-3)
NOISE = Noise(position_rms=0.5e-3, angle_rms=float(np.deg2rad(0.3)))
SAMPLES = 500


def _case(tmp_path, effects, seed, candidates):
    """Synthesize with ``effects`` hidden, run the workflow from the base file (friction off, no
    effect) with ``candidates``."""
    base = load_robot(PAIR).replace(friction_coefficients=(0.0,))
    model = tmp_path / "pair.toml"
    model.write_text(robot_to_toml(base, header="Table I tube pair, friction off"))
    data = tmp_path / "d.csv"
    write_synth(data, synthesize(base, effects, protocol="trajectory", samples=SAMPLES, noise=NOISE, seed=seed,
                                 settings=COARSE))
    opts = DiscrepancyOptions(effects=candidates, ds=6e-3, n_permutations=199, max_evaluations=200,
                              max_calibration_samples=200, friction_search_samples=48, bound_samples=60, n_jobs=1)
    res = run_discrepancy(model, data, tmp_path / "out", opts, echo=lambda s: None, progress=False)
    return res, data


def _verdict_has(res, effect):
    """The truth is named, or first or second of an ambiguous pair."""
    return (res["verdict"] == "named" and res["named_effect"] == effect) or (
        res["verdict"] == "ambiguous" and effect in (res["named_effect"], res["ambiguous_with"]))


def _fitted(res, effect):
    return res["candidates"][effect]["parameters"]


def _shrinks_on_the_test_split(res):
    """The untouched test split: the named model's mean error falls, with an interval above 0."""
    shrink = res["test_split"]["figures"]["shrink"]["mean"]
    return shrink["value"] > 0.3 and shrink["ci"][0] > 0.0


def test_hidden_backlash_is_named_with_its_size(tmp_path):
    """A 3.7 deg dead band in tube 2's rotation drive; rivals: time offset, friction. Backlash is
    named (or ambiguous with it first or second) with the band within 15 %; the test split's mean
    error falls; the written robot file stores the band under [effects.backlash]. Catches a
    broken play operator, a rule that names a rival, and an updated file that loses the effect."""
    res, _ = _case(tmp_path, {"backlash": {"backlash_2": 0.065}}, 3101, ("backlash", "time_offset", "friction"))
    assert _verdict_has(res, "backlash"), res["decision"]
    assert _fitted(res, "backlash")["backlash_2"] == pytest.approx(0.065, rel=0.15)
    assert not res["candidates"]["backlash"]["at_bound"]
    assert _shrinks_on_the_test_split(res), res["test_split"]["figures"]
    assert res["noise"]["consistent"] is False
    assert res["reproduced"]
    if res["verdict"] == "named":
        written = load_robot(res["updated_model_file"])
        assert dict(written.effects)["backlash"][0][1] == pytest.approx(_fitted(res, "backlash")["backlash_2"])


def test_hidden_time_offset_is_named_with_its_size(tmp_path):
    """A tracker lag of 0.08 s; rivals: backlash, friction. The time offset is named (or ambiguous
    with it) within 0.015 s. Catches a time shift of the wrong sign or scale."""
    res, _ = _case(tmp_path, {"time_offset": {"time_offset": 0.08}}, 3102, ("time_offset", "backlash", "friction"))
    assert _verdict_has(res, "time_offset"), res["decision"]
    assert _fitted(res, "time_offset")["time_offset"] == pytest.approx(0.08, abs=0.015)
    assert _shrinks_on_the_test_split(res), res["test_split"]["figures"]
    assert res["reproduced"]


def test_hidden_friction_is_named_with_its_coefficient(tmp_path):
    """Torsional friction mu = 0.25 in the data, none in the base file; rivals: backlash, time
    offset. Friction is named (or ambiguous with it) with mu within 0.05 (the grid's refined step
    is 0.025). Catches friction directions taken from the wrong history and a grid search that
    cannot find an interior minimum."""
    res, _ = _case(tmp_path, {"friction": {"mu_1": 0.25}}, 3103, ("friction", "backlash", "time_offset"))
    assert _verdict_has(res, "friction"), res["decision"]
    assert _fitted(res, "friction")["mu_1"] == pytest.approx(0.25, abs=0.05)
    assert _shrinks_on_the_test_split(res), res["test_split"]["figures"]


def test_noise_only_names_nothing_and_says_it_is_noise(tmp_path):
    """No effect hidden: nothing is named, and the F test calls the out-of-fold residual consistent
    with the noise estimated from the data's rests (within 15 % of the 0.5 mm truth). Catches
    naming on noise, a noise test that forgets the fitted parameters, and a noise estimate that
    is off."""
    res, data = _case(tmp_path, {}, 3104, ("backlash", "time_offset", "friction"))
    assert res["verdict"] == "none" and res["named_effect"] is None, res["decision"]
    assert res["decision"]["no_effect_case"] == "noise"
    noise = res["noise"]["noise"]
    assert noise["source"] == "rests" and noise["position_rms_m"] == pytest.approx(0.5e-3, rel=0.15)
    assert estimate_noise(load_measured_data(data, load_robot(PAIR)))["source"] == "rests"
    text = Path(write_report(res, tmp_path / "out")["markdown"]).read_text()
    assert "is consistent with the sensor noise" in text
