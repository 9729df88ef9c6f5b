"""Compiling kernels in a second process on a cold start.

On a fresh checkout numba compiles every kernel on its first call and caches it on disk
(``__pycache__``, or ``NUMBA_CACHE_DIR``). A command that needs both model families (``ctrplan
plan``'s final check, ``ctrplan evaluate --model clearance|friction``) would compile them one
after the other: the standard-model kernels (Newton shooting, the robot bodies) and then the
contact-model kernels (the outer loop of :func:`ctrplan.mechanics.solve_contact` with its
complementarity solver), about as long again. The two families share no large kernel, so
:func:`start` compiles the contact kernels in a child process on another core while the caller
compiles the standard ones (or plans), and :func:`wait`, called by ``solve_contact`` before its
first compiled call, waits for the child; the caller then loads the contact kernels from the
cache instead of compiling them. A lock file beside the cache files keeps other processes
sharing the cache (bound-map workers, parallel test runs) from compiling them a third time.

The child (``_warmup_child``) needs a linearization point for the contact solver but must not
compile the standard-model kernels itself (that is the caller's work): it gives the solver a
straight-tube state (psi = alpha, no bending, no torsion) on the common grid of a small
three-tube robot. Kernel types depend on array ranks and dtypes only, not on the robot or the
values, so this compiles exactly the specializations the real solves use. Nothing depends on
the child for correctness: if it fails or is not started, the caller compiles the kernels
itself.

The threaded standard-model batch kernel (``_standard_batch._batch_parallel``, numba ``prange``)
takes about a minute to compile on top of the serial one and pays that back only after millions
of rows. :func:`threaded_batch_usable` lets ``solve_standard_batch`` use it when it is compiled
or cached; otherwise the call runs the serial kernel (same results) and
:func:`start_threaded_batch` compiles the threaded one in a child process for later calls, under
its own lock file.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import tempfile
import time

__all__ = ["contact_kernels_cached", "start", "wait", "threaded_batch_usable", "start_threaded_batch"]

# Set once this process knows the contact kernels need no waiting: they were cached, it has
# waited for a compiling process, or it is that process.
_READY = [False]
_LOCK_NAME = "ctrplan-contact-compile.lock"
# The same for the threaded standard-model batch kernel.
_THREADED_READY = [False]
_THREADED_LOCK_NAME = "ctrplan-threaded-batch-compile.lock"


def _outer_loop():
    from ._contact_fast import _outer_loop as kernel
    return kernel


def _cached(kernel) -> bool:
    """Whether ``kernel`` (a numba dispatcher) is in numba's on-disk cache for the present source
    (so a first call loads it instead of compiling). True also when it cannot be told (a numba
    without the cache layout read here), so that no second process is started on a guess."""
    try:
        index = kernel._cache._cache_file._load_index()
    except Exception:   # pragma: no cover - numba internals of another version
        return True
    return bool(index)


def contact_kernels_cached() -> bool:
    """Whether the contact solver's compiled outer loop is in numba's on-disk cache for the
    present source (so a first call loads it instead of compiling).

    Returns True also when it cannot be told (a numba without the cache layout read here), so
    that no second process is started on a guess.
    """
    return _cached(_outer_loop())


def _lock_path(kernel=None, name: str = _LOCK_NAME) -> str:
    """The lock file held by the compiling process: beside numba's cache files of ``kernel``
    (default the contact solver's outer loop), so that every process sharing that cache sees it."""
    try:
        folder = (kernel or _outer_loop())._cache._cache_path
    except Exception:   # pragma: no cover - numba internals of another version
        folder = tempfile.gettempdir()
    return os.path.join(folder, name)


def _spawn_holding_lock(lock_path: str, call: str) -> bool:
    """Start ``python -c call`` holding an exclusive lock on ``lock_path`` (taken here and
    passed on as an inherited descriptor). Returns False when another process holds the lock
    or the file cannot be opened (no child started)."""
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:   # a read-only cache folder: numba cannot cache there either
        return False
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:   # another process is compiling
            return False
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
        subprocess.Popen([sys.executable, "-c", call], env=env, stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, pass_fds=(fd,))
        return True
    finally:
        os.close(fd)   # the child's copy keeps the lock until it exits


def _wait_for_lock(lock_path: str, timeout: float) -> float:
    """Wait until no process holds the lock on ``lock_path``; returns the seconds waited (at most
    about ``timeout``; no lock file: 0)."""
    t0 = time.perf_counter()
    try:
        fd = os.open(lock_path, os.O_RDWR)
    except OSError:   # no lock file: nobody started compiling
        return 0.0
    try:
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(fd, fcntl.LOCK_UN)
                break
            except OSError:
                if time.perf_counter() - t0 > timeout:   # pragma: no cover - a stuck compiler
                    break
                time.sleep(0.1)
    finally:
        os.close(fd)
    return time.perf_counter() - t0


def start() -> bool:
    """Start compiling the contact kernels in a child process unless they are cached or
    another process is compiling them.

    The child holds an exclusive lock on a file beside numba's cache files while it runs
    (taken here and passed on, so there is no moment without it); :func:`wait` in this or any
    other process sharing the cache waits for that lock. Returns whether a child was started.
    """
    if _READY[0] or os.environ.get("NUMBA_DISABLE_JIT") == "1":
        return False
    if contact_kernels_cached():
        _READY[0] = True
        return False
    # not started: another process is compiling them (wait() waits for it), or the cache folder
    # is read-only (nothing to wait for; wait() finds no lock file)
    return _spawn_holding_lock(_lock_path(), "from ctrplan.mechanics._warmup_child import main; main()")


def wait(timeout: float = 600.0) -> float:
    """Wait until no process is compiling the contact kernels (:func:`start`); returns the
    seconds waited. After ``timeout`` [s] it returns and the caller compiles what it needs."""
    if _READY[0]:
        return 0.0
    waited = _wait_for_lock(_lock_path(), timeout)
    _READY[0] = True
    return waited


def start_threaded_batch(kernel) -> bool:
    """Start compiling the threaded standard-model batch kernel ``kernel``
    (``_standard_batch._batch_parallel``) in a child process, unless it is cached or another
    process is compiling it. Returns whether a child was started."""
    if _THREADED_READY[0] or os.environ.get("NUMBA_DISABLE_JIT") == "1" or _cached(kernel):
        return False
    return _spawn_holding_lock(_lock_path(kernel, _THREADED_LOCK_NAME),
                               "from ctrplan.mechanics._warmup_child import main_threaded_batch; "
                               "main_threaded_batch()")


def threaded_batch_usable(kernel, compile_now: bool = False, timeout: float = 600.0) -> bool:
    """Whether a batch call should run the threaded kernel ``kernel``
    (``_standard_batch._batch_parallel``): True once it is compiled in this process or cached on
    disk. Otherwise, with ``compile_now`` False, it starts the background compile
    (:func:`start_threaded_batch`) and returns False (run serially: the results are the same);
    with ``compile_now`` True it waits for a compiling process (at most ``timeout`` [s]) and
    returns True (the caller loads the kernel, or compiles it)."""
    if _THREADED_READY[0] or os.environ.get("NUMBA_DISABLE_JIT") == "1":
        return True
    if kernel.signatures or _cached(kernel):
        _THREADED_READY[0] = True
        return True
    if compile_now:
        _wait_for_lock(_lock_path(kernel, _THREADED_LOCK_NAME), timeout)
        _THREADED_READY[0] = True
        return True
    start_threaded_batch(kernel)
    return False
