"""Bound-map stores: chunk layout, identity checks (maps are never mixed), formats the planner
reads, and the ``ctrplan boundmap`` command. Serial and fast (fake bound or a coarse real map)."""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_planning_helpers import fake_bound, fake_robot

from ctrplan import cli
from ctrplan.boundmap import (BoundMapMismatchError, BoundMapStore, ComputeOptions, IncompleteBoundMapError,
                              chunk_shape_for, compute_bound_map, compute_bound_map_store, compute_field, field_key,
                              load_bound_map, load_or_compute_bound_map)
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import MECHANICS_VERSION, ModelSettings, evaluate_bound

REPO = Path(__file__).resolve().parents[1]
SETTINGS = ModelSettings(ds=2e-2)


def pair_file(tmp_path: Path, mu: float = 0.2) -> Path:
    """Table I tube pair plus a beta_2 joint, with friction coefficient ``mu``."""
    text = (REPO / "model" / "ha2019-table1-tube-pair.toml").read_text()
    text = text.replace("friction_coefficient = 0.2 ", f"friction_coefficient = {mu} ")
    text += '\n[[joints]]\nname = "beta_2"\nlower = -0.017\nupper = -0.005\n'
    path = tmp_path / "pair.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("res, size, want", [((16, 16, 6), 64, (1, 8, 6)), ((4, 4, 4, 2, 2, 2), 8, (1, 1, 1, 2, 2, 2)),
                                             ((5, 7), 3, (1, 3)), ((3,), 100, (3,)), ((8, 3), 4, (1, 3)),
                                             ((16, 16, 16, 6, 6, 6), 64, (1, 1, 1, 1, 6, 6))])
def test_chunk_shape(res, size, want):
    c = chunk_shape_for(res, size)
    assert c == want
    assert int(np.prod(c)) <= size and all(1 <= cj <= nj for cj, nj in zip(c, res))
    with pytest.raises(ValueError, match="chunk_size"):
        chunk_shape_for(res, 0)


def test_fake_map_chunks_cover_the_grid_once(tmp_path):
    robot = fake_robot()
    run = compute_bound_map_store(robot, fake_bound, (5, 7, 3), store=tmp_path / "m.zarr",
                                  options=ComputeOptions(chunk_size=10))
    st = run.store
    assert st.chunks == chunk_shape_for((5, 7, 3), 10)
    assert st.chunk_sizes().sum() == 5 * 7 * 3
    covered = np.zeros((5, 7, 3), dtype=int)
    for c in range(st.n_chunks):
        covered[st.chunk_slices(c)] += 1
        np.testing.assert_array_equal(st.chunk_nodes(c), run.field.nodes().reshape(5, 7, 3, 3)[st.chunk_slices(c)]
                                      .reshape(-1, 3))
    assert np.all(covered == 1)
    ref = compute_field(robot, fake_bound, (5, 7, 3))
    np.testing.assert_array_equal(run.field.values, ref.values)
    assert np.all(np.isfinite(st.chunk_seconds())) and st.chunk_cold().sum() <= 1


def test_store_records_robot_file_hash_and_settings(tmp_path):
    robot_file = pair_file(tmp_path)
    run, path = compute_bound_map(robot_file, (4, 3), SETTINGS, out_path=tmp_path / "m.zarr")
    attrs = BoundMapStore.open(path).attrs
    assert attrs["robot_sha256"] == hashlib.sha256(robot_file.read_bytes()).hexdigest()
    assert attrs["robot_hash_of"] == "robot file"
    assert attrs["settings"] == SETTINGS.as_dict() and attrs["spec"] == {"resolution": [4, 3], "placement": "uniform"}
    assert attrs["coordinate_names"] == ["alpha_2-alpha_1", "beta_2-beta_1"]
    assert attrs["mechanics_version"] == MECHANICS_VERSION
    assert attrs["evaluator"].endswith("evaluate_bound")
    assert attrs["key"] == run.field.key == field_key(load_robot(robot_file), SETTINGS, (4, 3), evaluate_bound,
                                                       robot_file.read_text())
    assert run.field.metadata["robot_file"] == "pair.toml"


def test_resuming_into_another_map_is_refused(tmp_path):
    robot_file = pair_file(tmp_path)
    store = tmp_path / "m.zarr"
    compute_bound_map(robot_file, (4, 3), SETTINGS, out_path=store, options=ComputeOptions(max_chunks=1))
    old_sha = hashlib.sha256(robot_file.read_bytes()).hexdigest()
    cases = [
        (dict(resolution=(4, 4)), "spec", {"resolution": [4, 3], "placement": "uniform"},
         {"resolution": [4, 4], "placement": "uniform"}),
        (dict(settings=ModelSettings(ds=1e-2)), "settings.ds", 0.02, 0.01),
    ]
    for change, key, stored, requested in cases:
        kw = dict(resolution=(4, 3), settings=SETTINGS) | change
        with pytest.raises(BoundMapMismatchError) as err:
            compute_bound_map(robot_file, kw["resolution"], kw["settings"], out_path=store)
        e = err.value
        assert (e.key, e.stored, e.requested) == (key, stored, requested)
        assert str(store) in str(e) and key in str(e)
    # the same name, another robot file content (friction coefficient 0.2 -> 0.3)
    robot_file = pair_file(tmp_path, mu=0.3)
    new_sha = hashlib.sha256(robot_file.read_bytes()).hexdigest()
    with pytest.raises(BoundMapMismatchError) as err:
        compute_bound_map(robot_file, (4, 3), SETTINGS, out_path=store)
    assert (err.value.key, err.value.stored, err.value.requested) == ("robot_sha256", old_sha, new_sha)
    assert old_sha in str(err.value) and new_sha in str(err.value)
    # nothing of the refused runs was written
    assert BoundMapStore.open(store).done().sum() == 1


def test_incomplete_store_is_not_a_map(tmp_path):
    robot = fake_robot()
    store = tmp_path / "m.zarr"
    run = compute_bound_map_store(robot, fake_bound, (4, 4, 3), store=store,
                                  options=ComputeOptions(chunk_size=12, max_chunks=2))
    assert run.field is None and run.n_computed == 2
    with pytest.raises(IncompleteBoundMapError, match=r"m\.zarr.*2 of 4 chunks not computed"):
        load_bound_map(store)
    with pytest.raises(FileNotFoundError):
        load_bound_map(tmp_path / "missing.zarr")


def test_npz_output_and_planner_lookup(tmp_path, monkeypatch, caplog):
    """An .npz output goes through its store; the planner finds cached stores and resumes them."""
    robot_file = pair_file(tmp_path)
    robot = load_robot(robot_file)
    run, path = compute_bound_map(robot_file, (4, 3), SETTINGS, out_path=tmp_path / "m.npz")
    assert path == tmp_path / "m.npz" and (tmp_path / "m.zarr").is_dir()
    np.testing.assert_array_equal(load_bound_map(path, key=run.field.key).values,
                                  load_bound_map(tmp_path / "m.zarr", key=run.field.key).values)
    # planner lookup: an interrupted cache store is resumed, then found
    monkeypatch.chdir(tmp_path)
    key = run.field.key
    cache = Path(".cache") / "boundmaps" / f"pair-{key[:12]}.zarr"
    compute_bound_map(robot_file, (4, 3), SETTINGS, out_path=cache, options=ComputeOptions(max_chunks=1, chunk_size=3))
    caplog.set_level(logging.INFO, logger="ctrplan")
    field, source, _ = load_or_compute_bound_map(robot_file, robot, (4, 3), SETTINGS)
    assert source == "computed" and ".cache/boundmaps" in caplog.messages[-1]
    st = BoundMapStore.open(cache)  # resumed with its own chunks (4 of 3 nodes), not restarted
    assert st.n_chunks == 4 and list(st.chunk_run()) == [1, 2, 2, 2]
    np.testing.assert_array_equal(field.values, run.field.values)
    field, source, _ = load_or_compute_bound_map(robot_file, robot, (4, 3), SETTINGS)
    assert source == "cache"


def test_a_dot_in_the_robot_file_name_keeps_each_map_in_its_own_store(tmp_path, monkeypatch):
    """Catches the key dropped from a cached map's name by ``Path.with_suffix`` when the robot
    file's name holds a dot (``pair-x1.1.toml``): two grids of that robot then shared one store, and
    the second stopped with a mismatch (a preview map and its full map, the first plan of a new robot)."""
    robot_file = pair_file(tmp_path).rename(tmp_path / "pair-x1.1.toml")
    robot = load_robot(robot_file)
    monkeypatch.chdir(tmp_path)
    coarse, _, _ = load_or_compute_bound_map(robot_file, robot, (3, 3), SETTINGS)
    fine, source, _ = load_or_compute_bound_map(robot_file, robot, (4, 3), SETTINGS)
    assert source == "computed" and fine.shape == (4, 3) and coarse.shape == (3, 3)
    stores = sorted(p.name for p in (tmp_path / ".cache" / "boundmaps").glob("*.zarr"))
    assert stores == sorted(f"pair-x1.1-{f.key[:12]}.zarr" for f in (coarse, fine))
    again, source, _ = load_or_compute_bound_map(robot_file, robot, (3, 3), SETTINGS)
    assert source == "cache" and again.key == coarse.key


@pytest.mark.parametrize("scenario", sorted((REPO / "scenarios").glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scenarios_find_their_map_without_computing(scenario, caplog):
    """Every shipped scenario's bound map is shipped: the main job computes no map (and says
    nothing about stale maps)."""
    from ctrplan.io.scenario import load_scenario
    from ctrplan.planning import map_spec

    sc = load_scenario(scenario)
    settings = ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()
    caplog.set_level(logging.INFO, logger="ctrplan")
    field, source, _ = load_or_compute_bound_map(sc.robot_file, sc.robot, map_spec(sc), settings)
    assert source == "shipped" and field.shape == tuple(sc.bound_field.resolution)
    assert not caplog.records, caplog.messages


def test_cli_boundmap(tmp_path):
    robot_file = pair_file(tmp_path)
    runner = CliRunner()
    out = tmp_path / "cli.zarr"
    args = ["boundmap", "--robot", str(robot_file), "--resolution", "4,3", "--ds", "0.02", "--jobs", "1",
            "--chunk-size", "4", "--out", str(out), "--no-progress"]
    res = runner.invoke(cli.main, args)
    assert res.exit_code == 0, res.output
    assert "serial: 4 chunks computed, 0 reused of 4" in res.output and f"wrote {out}" in res.output
    res = runner.invoke(cli.main, args)
    assert "0 chunks computed, 4 reused of 4" in res.output
    # another resolution into the same store: a clear error (exit 2 through ctrplan's entry point)
    res = runner.invoke(cli.main, args[:4] + ["4,4"] + args[5:])
    assert isinstance(res.exception, BoundMapMismatchError) and "'spec'" in str(res.exception)
    # one number: the same resolution for every map coordinate
    res = runner.invoke(cli.main, args[:4] + ["3"] + args[5:-3] + ["--out", str(tmp_path / "r3.zarr"),
                                                                   "--no-progress"])
    assert res.exit_code == 0, res.output
    assert BoundMapStore.open(tmp_path / "r3.zarr").resolution == (3, 3)
    for bad, hint in ((["--resolution", "4,x"], "--resolution"), (["--resolution", "4,3,2"], "--resolution"),
                      (["--out", str(tmp_path / "m.h5")], "--out")):
        res = runner.invoke(cli.main, ["boundmap", "--robot", str(robot_file), "--jobs", "1"] + bad)
        assert res.exit_code == 2 and hint in res.output


def test_six_joint_model_joint_box_is_feasible():
    """Every point of the six-joint robot's joint box is a possible configuration with each inner
    tube protruding from its outer neighbour (constraints are linear in beta: corners suffice)."""
    import itertools

    robot = load_robot(REPO / "model" / "ha2019-table2-six-joint.toml")
    assert robot.joint_names == ["alpha_1", "alpha_2", "alpha_3", "beta_1", "beta_2", "beta_3"]
    assert "Table II" in robot.source and not robot.links
    for corner in itertools.product(*[(j.lower, j.upper) for j in robot.joints]):
        alpha, beta = robot.configuration(corner)
        robot.check_configuration(alpha, beta)
        ends = robot.tube_ends(beta)
        assert ends[1] >= ends[0] - 1e-12 and ends[2] > ends[1] + 9e-3


def test_unreachable_scheduler_is_a_clear_error(tmp_path, monkeypatch):
    from ctrplan import parallel
    from ctrplan.boundmap import compute as bound_store

    monkeypatch.setattr(parallel, "SCHEDULER_TIMEOUT_S", 1.0)   # the executor's connection timeout
    robot_file = pair_file(tmp_path)
    res = CliRunner().invoke(cli.main, ["boundmap", "--robot", str(robot_file), "--resolution", "4,3",
                                        "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path / "m.zarr")])
    assert isinstance(res.exception, bound_store.SchedulerUnreachableError)
    assert "tcp://127.0.0.1:9" in str(res.exception) and "within 1 s" in str(res.exception)


def test_maps_of_other_mechanics_are_stale_and_named(tmp_path, monkeypatch, caplog):
    """The key holds the mechanics version: a map computed by other mechanics is not used, and
    the planner's lookup says which map it skipped and why."""
    from ctrplan import constants

    robot = fake_robot()
    key_now = field_key(robot, None, (4, 4, 3), fake_bound)
    assert field_key(robot, None, (4, 4, 3), fake_bound, mechanics_version="1999.01.01") != key_now
    # a map computed by "older" mechanics, shipped next to a robot file
    robot_file = pair_file(tmp_path)
    monkeypatch.setattr(constants, "MECHANICS_VERSION", "1999.01.01")
    old_run, old_path = compute_bound_map(robot_file, (4, 3), SETTINGS, fake_pair_bound,
                                          out_path=tmp_path / "boundmaps" / "placeholder.npz")
    old_path.rename(tmp_path / "boundmaps" / f"pair-{old_run.field.key[:12]}.npz")
    store = tmp_path / "boundmaps" / "placeholder.zarr"
    monkeypatch.undo()
    # resuming the old store with today's mechanics is refused, naming the version
    with pytest.raises(BoundMapMismatchError) as err:
        compute_bound_map(robot_file, (4, 3), SETTINGS, fake_pair_bound, out_path=store)
    assert (err.value.key, err.value.stored, err.value.requested) == ("mechanics_version", "1999.01.01",
                                                                       MECHANICS_VERSION)
    # the lookup skips the old shipped map, says why, and computes a new one
    monkeypatch.chdir(tmp_path)
    caplog.set_level(logging.INFO, logger="ctrplan")
    field, source, _ = load_or_compute_bound_map(robot_file, load_robot(robot_file), (4, 3), SETTINGS,
                                                 evaluator=fake_pair_bound)
    assert source == "computed" and field.key != old_run.field.key
    stale = [r for r in caplog.records if "mechanics_version" in r.getMessage() and "1999.01.01" in r.getMessage()
             and f"pair-{old_run.field.key[:12]}" in r.getMessage()]
    assert stale and all(r.levelno == logging.WARNING for r in stale), caplog.messages


def fake_pair_bound(robot, alpha, beta, settings=None):
    """Fast stand-in for evaluate_bound on the tube pair: smooth in the relative coordinates."""
    from types import SimpleNamespace

    p = 1e-3 * (2.0 + np.cos(alpha[1] - alpha[0])) * (1.0 + 10.0 * (beta[1] - beta[0]))
    return SimpleNamespace(position=p, angle=p, translation_last_position=0.5 * p, translation_last_angle=0.5 * p,
                           diagnostics=SimpleNamespace(converged=True, unstable=False))


fake_pair_bound.name = "fake-pair-bound"
