"""The one executor (ctrplan.parallel): where tasks run, what comes back, what a failure does."""

from __future__ import annotations

import os

import pytest

from ctrplan import parallel
from ctrplan.parallel import Executor, SchedulerUnreachableError


def _pid_and_square(x):
    return os.getpid(), x * x


def _square(x):
    return x * x


def _fail_on(x, bad):
    if x == bad:
        raise ValueError(f"task {x} failed")
    return x


@pytest.mark.parametrize("n_jobs, fork", [(1, False), (2, False), (2, True)])
def test_every_task_comes_back_once_with_its_tag(n_jobs, fork):
    """Catches a lost or duplicated task, or a result paired with another task's tag."""
    with Executor(n_jobs, fork=fork) as ex:
        out = list(ex.run(_pid_and_square, [(f"t{k}", (k,)) for k in range(7)]))
    assert sorted(tag for tag, _ in out) == sorted(f"t{k}" for k in range(7))
    assert all(value == int(tag[1:]) ** 2 for tag, (_, value) in out)
    pids = {pid for _, (pid, _) in out}
    if n_jobs == 1:
        assert pids == {os.getpid()} and [t for t, _ in out] == [f"t{k}" for k in range(7)]   # in order, here
    else:
        assert os.getpid() not in pids                         # on workers, not here


@pytest.mark.parametrize("fork", [False, True])
def test_first_here_runs_the_first_task_in_this_process_and_the_rest_on_workers(fork):
    """Catches a ``first_here`` that sends every task away (this process idle) or keeps all here."""
    with Executor(2, fork=fork) as ex:
        out = list(ex.run(_pid_and_square, [(k, (k,)) for k in range(3)], first_here=True))
    assert out[0] == (0, (os.getpid(), 0))
    assert {tag for tag, _ in out[1:]} == {1, 2}
    assert all(pid != os.getpid() for _, (pid, _) in out[1:])


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_a_failed_task_raises_where_the_results_are_read(n_jobs):
    """Catches a failure swallowed (a missing result with no error)."""
    with Executor(n_jobs) as ex:
        with pytest.raises(ValueError, match="task 3 failed"):
            list(ex.run(_fail_on, [(k, (k, 3)) for k in range(6)]))


def test_bad_arguments_and_an_unreachable_scheduler_are_clear_errors(monkeypatch):
    with pytest.raises(ValueError, match="n_jobs must be at least 1, got 0"):
        Executor(0)
    monkeypatch.setattr(parallel, "SCHEDULER_TIMEOUT_S", 1.0)
    ex = Executor(scheduler="tcp://127.0.0.1:9")               # nothing listens on the discard port
    assert ex.kind == "dask" and ex.description == "dask scheduler tcp://127.0.0.1:9"
    with pytest.raises(SchedulerUnreachableError, match="tcp://127.0.0.1:9"):
        list(ex.run(_pid_and_square, [(0, (1,))]))


def test_descriptions_name_where_the_tasks_run():
    assert Executor().description == "serial"
    assert Executor(3).description == "3 local processes" and Executor(3).kind == "processes"


def test_local_workers_and_joblib_share_one_process():
    """Other code of the same process uses joblib.Parallel (the discrepancy simulation, user
    code): its pool must keep working after the executor's local workers ran, and the executor's
    after joblib's. Catches the executor taking loky's reusable pool, which joblib then finds
    without its own attributes (AttributeError '_temp_folder_manager')."""
    from joblib import Parallel, delayed

    for _ in range(2):
        with Executor(2) as ex:
            assert sorted(ex.run(_square, [(k, (k,)) for k in range(4)])) == [(k, k * k) for k in range(4)]
        assert Parallel(n_jobs=2)(delayed(_square)(k) for k in range(4)) == [0, 1, 4, 9]
