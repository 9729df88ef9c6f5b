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
    from ctrplan.planning.setup import load_setup

    setup = load_setup(REPO / "scenarios" / scenario, tmp_path)
    path = setup.scenario.robot_file
    ident = map_identity(setup.robot, setup.settings, setup.spec, evaluate_bound, Path(path).read_text())
    shipped, _ = map_paths(path, ident.key)
    assert shipped.with_suffix(".npz").exists(), f"{shipped.with_suffix('.npz')} (key {ident.key[:12]})"


def test_the_cache_folder_is_the_variable_s_else_the_user_s(tmp_path, monkeypatch):
    """The cache folder does not follow the working directory unless CTRPLAN_CACHE_DIR asks
    for it (catches a default left at ./.cache, or a folder read once at import)."""
    import platformdirs

    from ctrplan.boundmap.files import cache_folder
    from ctrplan.cache import CACHE_ENV, cache_dir

    monkeypatch.delenv(CACHE_ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    assert cache_dir() == platformdirs.user_cache_path("ctrplan")
    assert cache_folder() == platformdirs.user_cache_path("ctrplan") / "boundmaps"
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "store"))
    assert cache_dir("roadmaps") == tmp_path / "store" / "roadmaps"
    monkeypatch.setenv(CACHE_ENV, ".cache")
    (tmp_path / "a").mkdir()
    monkeypatch.chdir(tmp_path / "a")
    assert cache_dir() == tmp_path / "a" / ".cache"          # relative: read at each call


def test_a_study_s_key_sees_the_obstacle_files_and_keeps_unexpected_errors(tmp_path, monkeypatch):
    """A scenario's stored plan is keyed by its mesh file's bytes too (catches a study that
    reuses a plan around a mesh edited since); a scenario that does not load is keyed by its
    own bytes, and an error the loader does not document is raised, not swallowed."""
    import ctrplan.io.scenario as scenario_module

    meshes = REPO / "scenarios" / "meshes"
    for f in meshes.iterdir():
        (tmp_path / f.name).write_bytes(f.read_bytes())
    text = (REPO / "scenarios" / "obstacles.toml").read_text()
    text = text.replace('robot = "../model/', f'robot = "{(REPO / "model").as_posix()}/')
    text = text.replace('file = "meshes/', 'file = "')
    sc = tmp_path / "obstacles.toml"
    sc.write_text(text)
    first = input_key(sc, None, True)
    (mesh,) = [tmp_path / f.name for f in meshes.iterdir() if f.suffix.lower() == ".stl"]
    mesh.write_bytes(mesh.read_bytes() + b"\n")
    assert input_key(sc, None, True) != first
    broken = tmp_path / "broken.toml"
    broken.write_text("name = 3\n")
    assert len(input_key(broken, None, True)) == 64

    def explode(path):
        raise RuntimeError("a bug in the loader")

    monkeypatch.setattr(scenario_module, "load_scenario", explode)
    with pytest.raises(RuntimeError, match="a bug in the loader"):
        input_key(sc, None, True)
