"""Compiling the contact kernels in a second process (ctrplan.mechanics.warmup, _warmup_child)
and the first row of a parallel evaluation run in the calling process (ctrplan.batch)."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from ctrplan.batch import evaluate_table
from ctrplan.mechanics import ModelSettings, _warmup_child, solve_contact, warmup
from ctrplan.mechanics._contact_fast import _outer_loop

from _robots import table2_robot

DS = 0.004


@pytest.fixture(scope="module")
def compiled():
    """The contact kernels compiled (or loaded) in this process by a real clearance solve."""
    robot = table2_robot()
    solve_contact(robot, [0.0, 1.0, 2.0], list(robot.home_beta), ModelSettings(ds=DS))
    return robot


@pytest.fixture
def not_ready(monkeypatch):
    """This process as on a cold start: it has not yet waited for or checked the kernels."""
    monkeypatch.setattr(warmup, "_READY", [False])


def test_the_straight_state_compiles_the_specialization_the_real_solves_use(compiled):
    """A straight-tube state with other array types than a StandardSolution would make the
    child compile a specialization nobody uses, and the real solve compile its own after all."""
    before = list(_outer_loop.signatures)
    assert len(before) == 1
    _warmup_child.compile_contact_kernels()
    assert _outer_loop.signatures == before


def _hold_lock(seconds):
    """A process that holds the compile lock for ``seconds``, as a compiling child does."""
    code = ("import fcntl, os, sys, time\n"
            "fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT)\n"
            "fcntl.flock(fd, fcntl.LOCK_EX)\n"
            "print('locked', flush=True)\n"
            "time.sleep(float(sys.argv[2]))\n")
    holder = subprocess.Popen([sys.executable, "-c", code, warmup._lock_path(), str(seconds)],
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    return holder


def test_wait_returns_when_the_compiling_process_lets_go_and_start_does_not_start_a_second(compiled, not_ready,
                                                                                           monkeypatch):
    monkeypatch.setattr(warmup, "contact_kernels_cached", lambda: False)
    holder = _hold_lock(1.5)
    try:
        assert warmup.start() is False     # one compiling process per cache
        waited = warmup.wait(timeout=60.0)
    finally:
        holder.wait()
    assert 0.8 < waited < 30.0
    assert warmup.wait() == 0.0           # once waited, never again in this process


def test_the_child_compiles_without_waiting_for_its_own_lock(compiled, not_ready, monkeypatch):
    """The child holds the lock while it solves; were its own solve to wait for the lock, it would
    hang until the timeout (with the kernels cached, it needs seconds)."""
    monkeypatch.setattr(warmup, "contact_kernels_cached", lambda: False)
    assert warmup.start() is True
    t0 = time.perf_counter()
    warmup.wait(timeout=240.0)
    assert time.perf_counter() - t0 < 200.0
    fd = os.open(warmup._lock_path(), os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # raises if the child still held it
    finally:
        os.close(fd)


def test_start_does_nothing_where_the_kernels_are_cached(compiled, not_ready):
    if not warmup.contact_kernels_cached():
        pytest.skip("numba cache not writable here: the kernels were compiled but not cached")
    assert warmup.start() is False
    assert warmup.wait() == 0.0


@pytest.mark.parametrize("cold", [True, False], ids=["cold", "warm"])
def test_a_parallel_evaluation_gives_the_rows_of_a_serial_one(compiled, cold, monkeypatch):
    """On a cold start the first row runs in this process before the workers start: the rows and
    their order must not depend on it."""
    monkeypatch.setattr(warmup, "contact_kernels_cached", lambda: not cold)
    robot = compiled
    rng = np.random.default_rng(8123)
    alpha = np.column_stack([np.zeros(4), rng.uniform(-np.pi, np.pi, (4, 2))])
    beta = np.tile(np.asarray(robot.home_beta, dtype=float), (4, 1))
    settings = ModelSettings(ds=DS)
    serial = evaluate_table(robot, alpha, beta, "clearance", settings, n_jobs=1, progress=False)
    parallel = evaluate_table(robot, alpha, beta, "clearance", settings, n_jobs=2, progress=False)
    assert list(parallel["row"]) == list(serial["row"]) == [1, 2, 3, 4]
    np.testing.assert_allclose(parallel[["tip_x", "tip_y", "tip_z"]].to_numpy(),
                               serial[["tip_x", "tip_y", "tip_z"]].to_numpy(), rtol=0, atol=1e-12)


@pytest.fixture
def threaded_not_ready(monkeypatch):
    """This process as on a cold start for the threaded batch kernel."""
    monkeypatch.setattr(warmup, "_THREADED_READY", [False])


def _batch_input(robot, k, seed):
    rng = np.random.default_rng(seed)
    alpha = np.column_stack([np.zeros(k), rng.uniform(-np.pi, np.pi, (k, 2))])
    beta = np.tile(np.asarray(robot.home_beta, dtype=float), (k, 1))
    return alpha, beta


def test_an_uncompiled_threaded_batch_runs_serially_and_compiles_in_the_background(threaded_not_ready,
                                                                                   monkeypatch):
    """Cold, a threaded batch call must not compile the threaded kernel (about a minute) in the
    caller: it runs the serial kernel, gets the serial results, and starts one child for the
    threaded kernel under the threaded kernel's own lock file."""
    from ctrplan.mechanics import _standard_batch, solve_standard_batch

    class NotCompiled:
        signatures = []

        def __call__(self, *args):
            raise AssertionError("the threaded kernel ran on a cold start")

    spawned = []
    monkeypatch.setattr(warmup, "_cached", lambda kernel: False)
    monkeypatch.setattr(_standard_batch, "_batch_parallel", NotCompiled())
    monkeypatch.setattr(warmup, "_lock_path", lambda kernel=None, name=warmup._LOCK_NAME: name)
    monkeypatch.setattr(warmup, "_spawn_holding_lock", lambda path, call: spawned.append((path, call)) or True)
    robot = table2_robot()
    alpha, beta = _batch_input(robot, 6, 4417)
    settings = ModelSettings(ds=DS)
    serial = solve_standard_batch(robot, alpha, beta, settings, check_stability=True, follow=True)
    cold = solve_standard_batch(robot, alpha, beta, settings, check_stability=True, follow=True, n_threads=2)
    np.testing.assert_array_equal(cold.tip_position, serial.tip_position)
    assert spawned == [(warmup._THREADED_LOCK_NAME,
                        "from ctrplan.mechanics._warmup_child import main_threaded_batch; main_threaded_batch()")]


def test_the_threaded_batch_child_compiles_the_specialization_the_command_line_uses(threaded_not_ready):
    """The child must compile the threaded kernel with the argument types of a real call (the
    evaluate command's stability check and following), or later calls compile their own."""
    from ctrplan.mechanics._standard_batch import _batch_parallel, solve_standard_batch

    robot = table2_robot()
    alpha, beta = _batch_input(robot, 4, 9031)
    solve_standard_batch(robot, alpha, beta, ModelSettings(ds=DS), check_stability=True, follow=True,
                         n_threads=2, compile_threads=True)
    before = list(_batch_parallel.signatures)
    assert len(before) == 1
    _warmup_child.compile_threaded_batch()
    assert _batch_parallel.signatures == before


def test_a_compiled_threaded_kernel_is_used_without_a_child(threaded_not_ready, monkeypatch):
    """Once the threaded kernel is compiled in this process, threaded calls use it and start no
    child."""
    from ctrplan.mechanics._standard_batch import _batch_parallel, solve_standard_batch

    robot = table2_robot()
    alpha, beta = _batch_input(robot, 3, 5120)
    solve_standard_batch(robot, alpha, beta, ModelSettings(ds=DS), n_threads=2, compile_threads=True)
    assert _batch_parallel.signatures
    monkeypatch.setattr(warmup, "_THREADED_READY", [False])
    monkeypatch.setattr(warmup, "_spawn_holding_lock",
                        lambda path, call: pytest.fail("a child was started for a compiled kernel"))
    assert warmup.threaded_batch_usable(_batch_parallel) is True
