"""Shared test set-up: single-threaded BLAS (small dense solves are faster that way on the
project's 2-core machines, and parallel tests do not oversubscribe), and a fixture that runs a
test in a child process."""

import os
import subprocess
import sys

import pytest

_CHILD_VARIABLE = "CTRPLAN_TEST_IN_CHILD"

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
# Stored maps and roadmaps go to .cache of the working folder (ctrplan.cache.cache_dir reads a
# relative value at each call): a test that works in tmp_path starts with an empty cache, and
# no test reads or writes the user's cache folder.
os.environ["CTRPLAN_CACHE_DIR"] = ".cache"

try:  # also applies when numpy was imported before this file
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
except ImportError:  # pragma: no cover
    pass


SLOW_TEST_TIMEOUT_S = 4 * 3600   # the slowest (Ha's trajectory end to end) takes about 40 min


def pytest_collection_modifyitems(config, items):
    """Tests marked slow get :data:`SLOW_TEST_TIMEOUT_S` unless they set their own timeout."""
    for item in items:
        if item.get_closest_marker("slow") and not item.get_closest_marker("timeout"):
            item.add_marker(pytest.mark.timeout(SLOW_TEST_TIMEOUT_S))


@pytest.fixture
def in_child_process(request):
    """Run the requesting test again in a child pytest process; returns True in the parent.

    For tests of OMPL planners whose C++ side keeps Python-bound objects alive past interpreter
    exit (BITstar keeps its ``SpaceInformation``): nanobind then prints a leak report at exit,
    which belongs in the child's captured output, not after the parent's summary line. Call it
    first: ``if in_child_process(): return``. The child's output is shown when it fails.
    """
    def run() -> bool:
        if os.environ.get(_CHILD_VARIABLE) == request.node.nodeid:
            return False
        env = dict(os.environ, **{_CHILD_VARIABLE: request.node.nodeid})
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                               request.node.nodeid], cwd=request.config.rootpath, env=env,
                              capture_output=True, text=True)
        assert proc.returncode == 0, f"child process failed:\n{proc.stdout}\n{proc.stderr}"
        assert "1 passed" in proc.stdout, proc.stdout
        return True

    return run
