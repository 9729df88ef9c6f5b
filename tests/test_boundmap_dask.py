"""Bound maps on local worker processes and on a local Dask cluster started by the tests (2 workers x 1 thread).

The real model (:func:`ctrplan.mechanics.evaluate_bound`) on the Table I tube pair with an extra
translation joint, a coarse 8 x 3 grid and a 10 mm arc-length step: ~30 ms per node, so a whole
map takes about a second and the cluster start-up dominates.

- a map computed on the cluster, or on two local worker processes, equals the serial map node for node;
- a run stopped after k chunks (an exception from the chunk callback, as an interruption would)
  leaves exactly k chunks in the store, and the rerun computes only the other chunks;
- ``ctrplan boundmap --jobs 2`` killed with SIGKILL (client and workers) resumes from its store.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ctrplan.boundmap import (BoundMapStore, ComputeOptions, compute_bound_map, compute_bound_map_store, load_bound_map,
                              start_local_cluster)
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, evaluate_bound

REPO = Path(__file__).resolve().parents[1]
SETTINGS = ModelSettings(ds=1e-2)
RES = (8, 3)
CHUNK = 3  # chunks of (1, 3) nodes -> 8 chunks


def pair_with_translation(path: Path) -> Path:
    """The Table I tube pair file plus a beta_2 joint in [-17, -5] mm (tube 2's straight 17 mm
    section keeps its curved part in front of tube 1's base)."""
    text = (REPO / "model" / "ha2019-table1-tube-pair.toml").read_text()
    text += '\n[[joints]]\nname = "beta_2"\nlower = -0.017\nupper = -0.005\n'
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def robot_file(tmp_path_factory):
    return pair_with_translation(tmp_path_factory.mktemp("robot") / "pair.toml")


@pytest.fixture(scope="module")
def serial(robot_file):
    robot = load_robot(robot_file)
    return compute_bound_map_store(robot, evaluate_bound, RES, SETTINGS, robot_file_text=robot_file.read_text(),
                                   options=ComputeOptions(chunk_size=CHUNK))


@pytest.fixture(scope="module")
def client():
    from distributed import Client

    with start_local_cluster(2) as cluster:
        with Client(cluster) as c:
            yield c


def _run(robot_file, store, client, **kw):
    robot = load_robot(robot_file)
    return compute_bound_map_store(robot, evaluate_bound, RES, SETTINGS, store, robot_file_text=robot_file.read_text(),
                                   options=ComputeOptions(scheduler=client, chunk_size=CHUNK, **kw))


def test_serial_reference_is_a_real_map(serial):
    f = serial.field
    assert serial.executor == "serial" and serial.n_chunks == 8 and serial.n_computed == 8
    assert f.valid.all()
    # no bound with the pair's curved sections aligned and coincident (alpha_2 = 0, node 4 of
    # -pi + 2 pi k / 8; beta_2 = -17 mm, node 0), a larger one when they are opposed (alpha_2 = -pi)
    pos = f.values[..., 0]
    assert f.axes[0][4] == pytest.approx(0.0, abs=1e-12) and f.axes[1][0] == -0.017
    assert pos[4, 0] < 1e-6 and np.all(pos[0] > pos[4]) and pos[0, 0] > 1e-3


def test_cluster_map_equals_serial_map(robot_file, serial, client, tmp_path):
    store = tmp_path / "pair.zarr"
    run = _run(robot_file, store, client)
    assert run.executor.startswith("dask client") and run.n_computed == 8 and run.n_reused == 0
    np.testing.assert_array_equal(run.field.values, serial.field.values)
    np.testing.assert_array_equal(run.field.valid, serial.field.valid)
    assert run.field.key == serial.field.key
    loaded = load_bound_map(store, key=serial.field.key)
    np.testing.assert_array_equal(loaded.values, serial.field.values)
    assert loaded.metadata["robot_hash_of"] == "robot file"


def test_local_processes_map_equals_serial_map(robot_file, serial, tmp_path):
    """Catches chunks written to the wrong nodes when they come back out of order from workers."""
    robot = load_robot(robot_file)
    run = compute_bound_map_store(robot, evaluate_bound, RES, SETTINGS, tmp_path / "local.zarr",
                                  robot_file_text=robot_file.read_text(),
                                  options=ComputeOptions(n_jobs=2, chunk_size=CHUNK))
    assert run.executor == "2 local processes" and run.n_computed == 8
    np.testing.assert_array_equal(run.field.values, serial.field.values)
    np.testing.assert_array_equal(run.field.valid, serial.field.valid)


class Interrupted(Exception):
    pass


def test_interrupted_cluster_run_resumes_only_missing_chunks(robot_file, serial, client, tmp_path):
    store = tmp_path / "pair.zarr"
    k = 3

    def stop_after_k(n_written, chunk):
        if n_written == k:
            raise Interrupted

    with pytest.raises(Interrupted):
        _run(robot_file, store, client, on_chunk=stop_after_k)
    st = BoundMapStore.open(store)
    first = np.flatnonzero(st.done())
    assert first.size == k
    with pytest.raises(Exception, match="incomplete"):
        load_bound_map(store)
    seen = []
    run = _run(robot_file, store, client, on_chunk=lambda n, c: seen.append(c))
    assert run.n_reused == k and run.n_computed == 8 - k
    assert sorted(seen) == sorted(set(range(8)) - set(first.tolist()))
    runs = run.store.chunk_run()
    assert np.all(runs[first] == 1) and np.sum(runs == 2) == 8 - k
    np.testing.assert_array_equal(run.field.values, serial.field.values)
    # the cluster is still usable after the interruption, and a finished store computes nothing
    again = _run(robot_file, store, client)
    assert again.n_computed == 0 and again.n_reused == 8


def test_cli_killed_run_resumes(tmp_path):
    """SIGKILL of `ctrplan boundmap --jobs 2` (client and workers) mid-run, then resume."""
    import psutil

    robot_file = pair_with_translation(tmp_path / "pair.toml")
    store = tmp_path / "pair.zarr"
    res = (24, 4)  # 24 chunks of 4 nodes: a few seconds on 2 workers
    cmd = [sys.executable, "-c", "from ctrplan.cli import run; run()", "boundmap", "--robot", str(robot_file),
           "--resolution", "24,4", "--ds", "0.01", "--chunk-size", "4", "--jobs", "2", "--out", str(store),
           "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
                            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 90.0
        n_done = 0
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                n_done = int(BoundMapStore.open(store).done().sum())
            except Exception:  # store not created yet (or being created)
                n_done = 0
            if n_done >= 3:
                break
            time.sleep(0.05)
        assert proc.poll() is None, f"boundmap ended before it could be killed:\n{proc.stdout.read().decode()}"
        assert n_done >= 3, "fewer than 3 chunks finished within 90 s"
        procs = [psutil.Process(proc.pid)] + psutil.Process(proc.pid).children(recursive=True)
        for p in procs:
            try:
                p.send_signal(signal.SIGKILL)
            except psutil.NoSuchProcess:
                pass
        proc.wait(timeout=30)
        psutil.wait_procs(procs, timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    st = BoundMapStore.open(store)
    done_before = np.flatnonzero(st.done())
    assert 3 <= done_before.size < st.n_chunks == 24
    run, path = compute_bound_map(robot_file, res, SETTINGS, out_path=store, options=ComputeOptions(n_jobs=1))
    assert path == store
    assert run.n_reused == done_before.size and run.n_computed == 24 - done_before.size
    runs = run.store.chunk_run()
    assert np.all(runs[done_before] == 1) and np.all(np.delete(runs, done_before) == 2)
    assert run.field.valid.all()


def test_cli_with_scheduler_address(robot_file, serial, client, tmp_path):
    """`ctrplan boundmap --scheduler ADDRESS` connects to a running cluster (the test's)."""
    from click.testing import CliRunner

    from ctrplan import cli

    address = client.scheduler.address
    out = tmp_path / "pair.zarr"
    res = CliRunner().invoke(cli.main, ["boundmap", "--robot", str(robot_file), "--resolution", "8,3", "--ds", "0.01",
                                        "--chunk-size", str(CHUNK), "--scheduler", address, "--out", str(out),
                                        "--no-progress"])
    assert res.exit_code == 0, res.output
    assert f"dask scheduler {address}: 8 chunks computed, 0 reused of 8" in res.output
    np.testing.assert_array_equal(load_bound_map(out, key=serial.field.key).values, serial.field.values)
