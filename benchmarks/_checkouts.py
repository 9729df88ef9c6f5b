"""Another commit of this repository beside the current checkout, for side-by-side benchmarks
(bench_contact_fit.py): a temporary git worktree, and the environment that
makes a child process import ``ctrplan`` from a given checkout with its own numba cache."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# ``python -c`` program that runs the ``ctrplan`` command line of the checkout given as its first
# argument, and refuses to run one imported from anywhere else (a comparison would time or
# compare one code twice)
_CLI = ("import sys, ctrplan\n"
        "root = sys.argv.pop(1)\n"
        "if not ctrplan.__file__.startswith(root):\n"
        "    raise RuntimeError(f'ctrplan imported from {ctrplan.__file__}, not from {root}')\n"
        "from ctrplan.cli import main\n"
        "sys.argv[0] = 'ctrplan'\n"
        "main()\n")


def cli_command(code, *args):
    """Command (list of str) that runs ``ctrplan *args`` from the checkout ``code``; run it with
    ``env=child_env(code, cache)`` and ``cwd=code``."""
    return [sys.executable, "-c", _CLI, str(code), *map(str, args)]


@contextlib.contextmanager
def worktree(revision, path):
    """Check out ``revision`` (a git revision of this repository) at ``path`` (detached) for the
    duration of the ``with`` block; removed afterwards, also after an error.

    Raises
    ------
    subprocess.CalledProcessError
        If git cannot check the revision out (unknown revision, ``path`` in use)."""
    path = Path(path)
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), revision],
                   check=True, capture_output=True)
    try:
        yield path
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(path)], check=False)


def child_env(code, cache):
    """Environment of a child process that imports ``ctrplan`` from the checkout ``code``, with
    one BLAS thread and the numba cache in ``cache`` (so two checkouts never share kernels)."""
    return dict(os.environ, PYTHONPATH=str(code), OPENBLAS_NUM_THREADS="1", NUMBA_CACHE_DIR=str(cache))
