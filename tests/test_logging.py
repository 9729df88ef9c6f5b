"""The library's messages go through :mod:`logging` and print nothing unless the caller asks.

The ``ctrplan`` logger has only a NullHandler; progress bars are off by default; the deprecated
``echo`` arguments still receive the messages of their call. The command line's printing of the
same messages (default, ``--quiet``, ``--verbose``) and a whole library plan are checked in
``test_pipeline.py``.
"""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_planning_helpers import fake_bound, fake_robot

from ctrplan import planning
from ctrplan._log import details

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "scenarios" / "task-target.toml"


def test_library_without_logging_configuration_prints_nothing():
    """In a fresh interpreter that configures no logging, a warning and an info record of a
    ctrplan logger print nothing. Catches a missing NullHandler: Python's last-resort handler
    would print the warning to stderr."""
    code = ("import logging, ctrplan\n"
            "assert [type(h).__name__ for h in logging.getLogger('ctrplan').handlers] == ['NullHandler']\n"
            "logging.getLogger('ctrplan.planning').warning('a caution')\n"
            "logging.getLogger('ctrplan.planning').info('a progress line')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "" and out.stderr == ""


def test_stage_logs_info_record_and_prints_nothing(capsys, caplog):
    """``load_setup`` logs its line at INFO under ``ctrplan.planning`` and prints nothing."""
    caplog.set_level(logging.INFO, logger="ctrplan")
    setup = planning.load_setup(SCENARIO, "out-not-written")
    assert capsys.readouterr() == ("", "")
    assert [(r.name, r.levelno, r.getMessage()) for r in caplog.records] == [
        ("ctrplan.planning", logging.INFO,
         f"scenario task-target: robot {setup.robot.name} ({', '.join(setup.robot.joint_names)})")]


def test_progress_lines_are_debug_inside_details(caplog):
    """A study lowers each scenario's progress lines to DEBUG (``ctrplan._log.details``), and only
    inside the block."""
    caplog.set_level(logging.DEBUG, logger="ctrplan")
    with details():
        planning.load_setup(SCENARIO, "out-not-written")
    planning.load_setup(SCENARIO, "out-not-written")
    assert [r.levelno for r in caplog.records] == [logging.DEBUG, logging.INFO]


def test_deprecated_echo_receives_the_messages_of_its_call():
    """A callable passed as ``echo`` (keyword or position) warns and receives the call's INFO
    messages; afterwards the logger is as before (no handler left, level restored), so a later
    call sends it nothing. Catches a broken old call and a handler that outlives its call."""
    package = logging.getLogger("ctrplan")
    handlers, level = list(package.handlers), package.level
    got = []
    with pytest.warns(DeprecationWarning, match="echo"):
        setup = planning.load_setup(SCENARIO, "out-not-written", echo=got.append)
    with pytest.warns(DeprecationWarning, match="echo"):
        planning.load_setup(SCENARIO, "out-not-written", got.append)
    line = f"scenario task-target: robot {setup.robot.name} ({', '.join(setup.robot.joint_names)})"
    assert got == [line, line]
    assert package.handlers == handlers and package.level == level
    planning.load_setup(SCENARIO, "out-not-written")
    assert got == [line, line]


def test_progress_bars_are_off_by_default(capsys):
    """Library calls show no tqdm bar unless asked: a bound map computed with the default, then
    with ``progress=True`` (the bar goes to stderr)."""
    from ctrplan.boundmap import ComputeOptions, compute_field

    compute_field(fake_robot(), fake_bound, (4, 4, 3))
    assert capsys.readouterr() == ("", "")
    compute_field(fake_robot(), fake_bound, (4, 4, 3), options=ComputeOptions(progress=True))
    assert "bound map" in capsys.readouterr().err


def test_evaluate_table_shows_no_bar_by_default(capsys):
    from ctrplan.batch import evaluate_table
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(REPO / "model" / "ha2019-table7-calibrated.toml")
    alpha, beta = robot.configuration(np.array([0.3, -0.2, -0.07]))
    frame = evaluate_table(robot, alpha[None], beta[None], "standard")
    assert list(frame["status"]) == ["ok"]
    assert capsys.readouterr() == ("", "")


def test_no_library_function_prints_or_takes_print_as_its_echo():
    """No function of the package defaults a parameter to ``print`` and no module calls
    ``print(...)`` outside the command line: read from the syntax trees, so that a module the
    other tests never import is checked too. Catches a stage that would write to stdout in a
    caller's program whatever its logging configuration."""
    import ast

    offenders = []
    for path in sorted((REPO / "ctrplan").rglob("*.py")):
        if path.name == "cli.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                defaults = node.args.defaults + [d for d in node.args.kw_defaults if d is not None]
                if any(isinstance(d, ast.Name) and d.id == "print" for d in defaults):
                    offenders.append(f"{path.relative_to(REPO)}:{node.lineno} {node.name} defaults to print")
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                offenders.append(f"{path.relative_to(REPO)}:{node.lineno} calls print")
    assert not offenders, offenders
