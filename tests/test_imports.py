"""The package's import structure: what a standard-model-only command loads."""

import subprocess
import sys

import pytest


def test_standard_model_command_path_does_not_load_the_contact_stack():
    """`ctrplan evaluate --model standard` imports ctrplan.batch and runs the standard batch; the
    contact kernels are not needed there and must stay unimported (scipy.linalg too, at import
    time: numba loads it later, with the compiled kernels). Fails if an eager import of a contact-model name comes back (in
    ctrplan.mechanics or ctrplan.batch). Run in a fresh interpreter: this test process has
    long imported everything."""
    code = ("import sys, numpy as np\n"
            "import ctrplan.batch\n"
            "from ctrplan.mechanics import ModelSettings, solve_standard, solve_standard_batch\n"
            "print(','.join(m for m in ('ctrplan.mechanics.contact', 'ctrplan.mechanics._contact_kernels',\n"
            "                           'ctrplan.mechanics._lapack', 'scipy.linalg') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_contact_model_names_resolve_on_first_use():
    """The lazily imported names are the real functions, are listed by dir(), and an unknown
    name still raises AttributeError."""
    import ctrplan.mechanics as mechanics
    from ctrplan.mechanics import evaluate_bound, predict_tip, solve_friction
    from ctrplan.mechanics.bound import evaluate_bound as direct_bound
    from ctrplan.mechanics.contact import solve_friction as direct_friction
    from ctrplan.mechanics.prediction import predict_tip as direct_predict

    assert evaluate_bound is direct_bound
    assert solve_friction is direct_friction
    assert predict_tip is direct_predict
    assert {"evaluate_bound", "solve_clearance", "PAIR_CASES"} <= set(dir(mechanics))
    assert set(mechanics.__all__) <= set(dir(mechanics))
    with pytest.raises(AttributeError, match="no_such_solver"):
        mechanics.no_such_solver  # noqa: B018


def test_the_frozen_reference_is_not_a_package_of_the_distribution():
    """The packages the build puts into ctrplan's distribution (pyproject's
    ``[tool.setuptools.packages.find]``, found as setuptools finds them) are ``ctrplan`` and its
    subpackages only: the frozen reference of ``tests/ctrplan_reference`` is for the tests and the
    benchmarks, which put ``tests/`` on their import path, not a top-level package of every
    user's environment."""
    import tomllib
    from pathlib import Path

    from setuptools import find_packages

    root = Path(__file__).resolve().parents[1]
    spec = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]
    found = [pkg for where in spec["where"] for pkg in find_packages(str(root / where), include=spec["include"])]
    assert "ctrplan" in found and "ctrplan.mechanics" in found
    assert all(pkg == "ctrplan" or pkg.startswith("ctrplan.") for pkg in found), found
