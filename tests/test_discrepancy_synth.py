"""ctrplan.discrepancy.measured.synth and ``ctrplan synth``: measured-like data with hidden effects.

Checks the protocols (the paper's grid with 2^(n-1) approach directions and its calibration
subset, Section V-C of Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906; a continuous
trajectory with reversals), the noise statistics (EM sensor 1.4 mm / 0.5 deg rms), that effects
and registration reach the tips, seeded reproducibility, and the command line. Robot: Table II
nominal robot at a coarse ds for speed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from ctrplan import cli
from ctrplan.effects import EffectSet
from ctrplan.history import MotionRecord, motion_state
from ctrplan.discrepancy.measured.synth import (Noise, SynthProtocol, add_noise, approach_path, paper_protocol, synthesize,
                                       trajectory_protocol, truth_model, truth_path, _reversals)
from ctrplan.errors import PhysicalParameterError
from ctrplan.io.robot_file import load_robot
from ctrplan.io.tables import read_measurements
from ctrplan.mechanics import ModelSettings, solve_standard

REPO = Path(__file__).resolve().parents[1]
TABLE2 = REPO / "model" / "ha2019-table2-nominal.toml"
SETTINGS = ModelSettings(ds=0.004)
TIP = ["tip_x", "tip_y", "tip_z"]
TANGENT = ["tangent_x", "tangent_y", "tangent_z"]
ALPHA = ["alpha_1", "alpha_2", "alpha_3"]
BETA = ["beta_1", "beta_2", "beta_3"]
NO_NOISE = Noise(0.0, 0.0)


@pytest.fixture(scope="module")
def robot():
    return load_robot(TABLE2)


# --------------------------------------------------------------------------- protocols
def test_paper_protocol_structure(robot):
    f = paper_protocol(robot, grid=4)
    assert len(f) == 4 ** 3 * 4 and f["sequence"].is_unique
    assert (f.groupby("config_id").size() == 4).all()
    calib = f[f["subset"] == "calibration"]
    assert calib["config_id"].nunique() == 2 ** 3           # every other node: 2 x 2 x 2
    # periodic rotations: -pi once, never pi; translation grid includes both limits
    assert np.isclose(f["alpha_2"].min(), -np.pi) and f["alpha_2"].max() < np.pi - 0.1
    np.testing.assert_allclose(sorted(f["beta_3"].unique()), np.linspace(-0.104, -0.034, 4))
    # the four approaches of each configuration, in the paper's order
    first = f[f["config_id"] == 5][["eta_1", "eta_2"]].to_numpy()
    assert first.tolist() == [[1, 1], [1, -1], [-1, 1], [-1, -1]]
    assert (f[f["config_id"] == 5][ALPHA + BETA].nunique() == 1).all()
    with pytest.raises(PhysicalParameterError, match="grid"):
        paper_protocol(robot, grid=1)


def test_paper_protocol_eta_columns_match_the_realised_approach(robot):
    f = paper_protocol(robot, grid=2)
    for _, row in f.iterrows():
        eta = row[["eta_1", "eta_2"]].to_numpy(int)
        path = approach_path(row[ALPHA].to_numpy(float), eta, steps=6)
        np.testing.assert_allclose(path[-1], row[ALPHA].to_numpy(float))
        rel = np.diff(path, axis=1)
        np.testing.assert_allclose(rel[-1] - rel[0], eta * np.pi / 2)      # 90 deg per pair
        beta = np.repeat(row[BETA].to_numpy(float)[None], len(path), axis=0)
        h = motion_state(MotionRecord(path, beta))
        assert h.eta[-1].tolist() == eta.tolist() and not h.released[-1].any()
        assert path[0, 0] == path[-1, 0]                                   # tube 1 does not move


def test_trajectory_protocol_has_reversals_and_translation_last(robot):
    f = trajectory_protocol(robot, np.random.default_rng(3))
    assert len(f) == 1200 and (f["sequence"] == 0).all()
    np.testing.assert_allclose(np.diff(f["time"]), 0.1)
    for j in ("alpha_2", "alpha_3", "beta_3"):
        assert _reversals(f[j]) >= 2, j
    alpha, beta = f[ALPHA].to_numpy(), f[BETA].to_numpy()
    h = motion_state(MotionRecord(alpha, beta, sequence=f["sequence"].to_numpy()))
    assert 0.05 < h.released.any(axis=1).mean() < 0.8
    assert (h.eta[1:] != 0).mean() > 0.5
    for k in range(0, 1200, 97):
        robot.check_configuration(alpha[k], beta[k])
        assert -0.104 - 1e-12 <= beta[k, 2] <= -0.034 + 1e-12


# --------------------------------------------------------------------------- noise
def test_noise_statistics():
    rng = np.random.default_rng(1)
    K = 20000
    tip = rng.normal(size=(K, 3)) * 0.05
    t = rng.normal(size=(K, 3))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    noise = Noise()
    tip_n, t_n = add_noise(tip, t, noise, rng)
    rms = np.sqrt(np.mean(np.sum((tip_n - tip) ** 2, axis=1)))
    assert rms == pytest.approx(1.4e-3, rel=0.02)
    np.testing.assert_allclose(np.linalg.norm(t_n, axis=1), 1.0, atol=1e-12)
    ang = np.arccos(np.clip(np.sum(t_n * t, axis=1), -1, 1))
    assert np.sqrt(np.mean(ang ** 2)) == pytest.approx(np.deg2rad(0.5), rel=0.02)
    # no bias: the mean error is near zero, components are independent with equal spread
    assert np.all(np.abs(np.mean(tip_n - tip, axis=0)) < 4 * 1.4e-3 / np.sqrt(3 * K))
    np.testing.assert_allclose(np.std(tip_n - tip, axis=0), 1.4e-3 / np.sqrt(3), rtol=0.03)
    with pytest.raises(PhysicalParameterError, match="position_rms"):
        Noise(position_rms=-1.0)


# --------------------------------------------------------------------------- synthesize
@pytest.fixture(scope="module")
def clean(robot):
    """Grid-3 paper protocol, no effects, no noise (standard truth)."""
    return synthesize(robot, {}, protocol=SynthProtocol.paper(3), noise=NO_NOISE, settings=SETTINGS)


def test_standard_truth_is_the_standard_model_and_noise_rms_on_the_grid(robot, clean):
    f = clean.frame
    assert clean.truth["truth_model"] == "standard" and len(f) == 27 * 4
    for k in (0, 50):
        std = solve_standard(robot, f.loc[k, ALPHA].to_numpy(float), f.loc[k, BETA].to_numpy(float), SETTINGS)
        np.testing.assert_allclose(f.loc[k, TIP].to_numpy(float), std.tip_position, atol=1e-12)
    # the approach does not matter without friction: four equal rows per configuration
    assert (f.groupby("config_id")[TIP].nunique() == 1).all().all()
    noisy = synthesize(robot, {}, protocol=SynthProtocol.paper(3), settings=SETTINGS, seed=4)
    err = noisy.frame[TIP].to_numpy() - f[TIP].to_numpy()
    assert np.sqrt(np.mean(np.sum(err ** 2, axis=1))) == pytest.approx(1.4e-3, rel=0.2)
    assert (noisy.frame.groupby("config_id")[TIP].nunique() == 4).all().all()   # independent noise


def test_seeded_reproducibility(robot):
    a = synthesize(robot, {}, protocol=SynthProtocol.paper(2), settings=SETTINGS, seed=7)
    b = synthesize(robot, {}, protocol=SynthProtocol.paper(2), settings=SETTINGS, seed=7)
    c = synthesize(robot, {}, protocol=SynthProtocol.paper(2), settings=SETTINGS, seed=8)
    pd.testing.assert_frame_equal(a.frame, b.frame)
    assert not np.allclose(a.frame[TIP], c.frame[TIP])


def test_effects_change_the_tips_and_friction_separates_the_approaches(robot, clean):
    ref = clean.frame[clean.frame["config_id"] < 8]
    off = synthesize(robot, {"offplane": {"precurvature_x_3": 2.0}}, protocol=SynthProtocol.paper(3), noise=NO_NOISE,
                     settings=SETTINGS)
    d = np.linalg.norm(off.frame[TIP].to_numpy() - clean.frame[TIP].to_numpy(), axis=1)
    assert np.median(d) > 1e-4
    fr = synthesize(robot, {"friction": {"mu_1": 0.3, "mu_2": 0.3}}, protocol=SynthProtocol.paper(2), noise=NO_NOISE,
                    settings=SETTINGS)
    assert fr.truth["truth_model"] == "friction"
    # alpha_3 - alpha_2 = pi at alpha_2 = 0 is past the bifurcation (unstable): dropped, listed
    dropped = fr.truth["dropped"]
    assert len(fr.frame) + len(dropped) == 32 and len(dropped) in (0, 4)
    assert all("unstable" in d["message"] for d in dropped)
    spread = fr.frame.groupby("config_id")[TIP].agg(lambda x: x.max() - x.min()).to_numpy().max(axis=1)
    assert np.max(spread) > 5e-4            # the four approaches end at different tips
    assert truth_model(EffectSet.from_values(robot, {"clearance": (1e-4, 1e-4)})) == "clearance"
    assert truth_model(EffectSet.from_values(robot, {"friction": (0.0, 0.0)})) == "standard"
    assert len(ref) == 32


def test_the_protocol_record_refuses_what_the_protocols_cannot_make():
    """A kind alone takes the default grid and samples; an unknown kind, a grid of one node and
    a single sample are refused with the value named (each would fail later inside the protocol,
    or silently make a grid without relative rotations)."""
    assert SynthProtocol.of("trajectory") == SynthProtocol.trajectory()
    assert SynthProtocol.of("paper").grid == 8 and SynthProtocol().kind == "paper"
    with pytest.raises(PhysicalParameterError, match="paper, trajectory, got 'helix'"):
        SynthProtocol("helix")
    with pytest.raises(PhysicalParameterError, match="grid must be an integer >= 2, got 1"):
        SynthProtocol.paper(1)
    with pytest.raises(PhysicalParameterError, match="samples must be an integer >= 2, got 1.5"):
        SynthProtocol.trajectory(1.5)


def test_registration_is_applied(robot, clean):
    reg = (0.1, -0.2, 0.3, 0.01, -0.02, 0.03)
    moved = synthesize(robot, EffectSet.from_values(robot, {"registration": reg}), protocol=SynthProtocol.paper(3),
                       noise=NO_NOISE, settings=SETTINGS)
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(reg[:3]).as_matrix()
    np.testing.assert_allclose(moved.frame[TIP].to_numpy(), clean.frame[TIP].to_numpy() @ R.T + reg[3:],
                               atol=1e-12)
    np.testing.assert_allclose(moved.frame[TANGENT].to_numpy(), clean.frame[TANGENT].to_numpy() @ R.T,
                               atol=1e-12)


def test_trajectory_synth_friction_uses_the_history(robot):
    res = synthesize(robot, {"friction": {"mu_1": 0.3, "mu_2": 0.3}}, protocol=SynthProtocol.trajectory(30),
                     noise=NO_NOISE, settings=SETTINGS, seed=2)
    f = res.frame
    assert res.truth["truth_model"] == "friction" and len(f) + res.truth["counts"]["dropped"] == 30
    h = motion_state(MotionRecord(f[ALPHA].to_numpy(), f[BETA].to_numpy(), sequence=f["sequence"].to_numpy()))
    np.testing.assert_array_equal(f[["eta_1", "eta_2"]].to_numpy(), h.eta)


# --------------------------------------------------------------------------- command line
def test_cli_synth_smoke_and_bad_options(tmp_path):
    out = tmp_path / "synth.csv"
    args = ["synth", "--robot", str(TABLE2), "--out", str(out), "--grid", "2", "--mu", "0.2,0.1",
            "--registration", "0,0,0.1,0.001,0,0", "--ds", "0.004", "--jobs", "1", "--no-progress"]
    res = CliRunner().invoke(cli.main, args)
    assert res.exit_code == 0, (res.output, res.exception)
    m = read_measurements(out, 3)
    truth = json.loads(Path(truth_path(out)).read_text())
    assert m.tip.shape == (truth["counts"]["rows"], 3) and m.eta is not None and m.tangent is not None
    assert truth["effects"] == {"friction": {"mu_1": 0.2, "mu_2": 0.1},
                                "registration": dict(zip([f"registration_{a}" for a in ("rx", "ry", "rz", "tx", "ty", "tz")],
                                                         [0, 0, 0.1, 0.001, 0, 0]))}
    assert truth["truth_model"] == "friction" and truth["counts"]["rows"] + truth["counts"]["dropped"] == 32
    assert len(truth["robot_file_hash"]) == 64
    for bad, needle in ((["--mu", "0.2"], "--mu '0.2'"), (["--poisson", "0.3,0.7,0.3"], "--poisson"),
                        (["--registration", "1,2,x"], "--registration"), (["--grid", "1"], "--grid 1"),
                        (["--noise-angle-deg", "-1"], "--noise-angle-deg")):
        r = CliRunner().invoke(cli.main, args[:5] + bad + ["--ds", "0.004", "--jobs", "1", "--no-progress"])
        assert r.exit_code != 0 and isinstance(r.exception, PhysicalParameterError), bad
        assert needle in str(r.exception)
