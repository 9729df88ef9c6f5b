"""The one rule of keys of stored results (ctrplan.cache): content, options and the mechanics
version in; the number of workers and the order of a payload's keys out."""

from __future__ import annotations

from pathlib import Path

import pytest

from ctrplan import constants
from ctrplan.batch import job_key
from ctrplan.boundmap import map_paths
from ctrplan.boundmap.identity import map_identity
from ctrplan.cache import content_key, file_hash
from ctrplan.mechanics import ModelSettings, evaluate_bound
from ctrplan.studies import input_key

REPO = Path(__file__).resolve().parents[1]


def test_content_key_is_canonical_and_sees_every_value():
    """Catches a key that depends on the order a payload was built in, or misses a nested value."""
    a = {"robot": "abc", "options": {"ds": 0.003, "mu": [0.2, 0.3]}}
    b = {"options": {"mu": [0.2, 0.3], "ds": 0.003}, "robot": "abc"}
    assert content_key(a) == content_key(b)
    assert content_key(a) != content_key({"robot": "abc", "options": {"ds": 0.003, "mu": [0.2, 0.31]}})
    assert len(content_key(a)) == 64


def test_file_hash_of_a_folder_sees_names_and_bytes(tmp_path):
    """Catches a bag folder hashed by its bytes alone (two files swapped) or by its names alone."""
    d = tmp_path / "bag"
    d.mkdir()
    (d / "a.db3").write_bytes(b"one")
    (d / "b.yaml").write_bytes(b"two")
    first = file_hash(d)
    (d / "a.db3").write_bytes(b"two")
    (d / "b.yaml").write_bytes(b"one")
    assert file_hash(d) != first
    (d / "b.yaml").write_bytes(b"onf")
    assert file_hash(d) != first


def test_checkpoint_and_study_keys_change_with_the_mechanics_version(monkeypatch, tmp_path):
    """Catches a checkpoint or a study's outputs reused after the mechanics changed."""
    robot = (REPO / "model" / "ha2019-table2-nominal.toml").read_text()
    scenario = REPO / "scenarios" / "sequence.toml"
    args = (robot, "alpha_1,beta_1\n0,0\n", "friction", ModelSettings())
    before = job_key(*args), input_key(scenario, None, True)
    monkeypatch.setattr(constants, "MECHANICS_VERSION", "a later version")
    after = job_key(*args), input_key(scenario, None, True)
    assert before[0] != after[0] and before[1] != after[1]


@pytest.mark.parametrize("scenario", ["six-joint.toml", "sequence.toml"])
def test_the_shipped_maps_are_found_under_their_scenarios_keys(scenario, tmp_path):
    """Catches a change of the key rule that would orphan the shipped bound maps (every plan
    would then wait for a map computed again)."""
    from ctrplan.pipeline.setup import load_setup

    setup = load_setup(REPO / "scenarios" / scenario, tmp_path)
    path = setup.scenario.robot_file
    ident = map_identity(setup.robot, setup.settings, setup.spec, evaluate_bound, Path(path).read_text())
    shipped, _ = map_paths(path, ident.key)
    assert shipped.with_suffix(".npz").exists(), f"{shipped.with_suffix('.npz')} (key {ident.key[:12]})"
