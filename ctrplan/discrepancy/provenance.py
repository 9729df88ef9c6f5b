"""What a discrepancy result was made with: a digest of the code that can move its figures and of
its options, so that a results file can be tied to the code that made it.

The code is every Python source file of the packages whose behaviour the figures depend on
(:data:`SOURCE_PACKAGES`: the discrepancy workflow, the effects, the motion history and the
mechanics) and the modules they take numbers and the robot from (:data:`SOURCE_MODULES`), less the
modules that only present figures already computed (:data:`FORMAT_ONLY`: ``report.md`` is written
from ``results.json`` alone and the plots beside it are images, so neither can move a figure) and
those no module of the digest imports (:data:`NOT_IMPORTED`). The
digest is a SHA-256 over their paths (relative to the ``ctrplan`` package) and their **code**: the
syntax tree of each file with its docstrings left out (comments and layout never reach it), in
sorted order. It changes with any change that can change what runs, and not with a corrected
docstring, comment or line break. A results file that records it can be checked against the
code at hand (``tests/test_docs_results.py`` does so for the files the docs quote).
"""

from __future__ import annotations

import ast
import hashlib
import json
from dataclasses import asdict, is_dataclass
from pathlib import Path

__all__ = ["SOURCE_PACKAGES", "SOURCE_MODULES", "FORMAT_ONLY", "NOT_IMPORTED", "source_digest", "source_files", "code_digest", "options_digest", "provenance"]

#: Subpackages of ``ctrplan`` whose code can move a discrepancy result's figures.
SOURCE_PACKAGES = ("discrepancy", "effects", "history", "mechanics")
#: Modules of ``ctrplan`` outside them whose code can too: the solvers' constants, the robot, the
#: choices the workflow's records hold, the registry of mechanics models, and the robot file that
#: the workflow reads and writes.
SOURCE_MODULES = ("constants.py", "robot.py", "choices.py", "models.py", "io/robot_file.py")
#: Modules inside :data:`SOURCE_PACKAGES` left out: they format ``results.json`` into ``report.md``
#: (:func:`ctrplan.discrepancy.outputs.report.report_markdown`) and draw its plots
#: (:func:`ctrplan.discrepancy.outputs.report_plots.write_plots`), and compute nothing a results file holds.
FORMAT_ONLY = ("discrepancy/outputs/report.py", "discrepancy/outputs/report_plots.py")
#: Modules inside :data:`SOURCE_PACKAGES` that no module of the digest imports or names (the
#: implicit-function derivatives of the contact models, for benchmarks and users' code): they
#: cannot move a figure. ``tests/test_discrepancy_provenance.py`` checks that no module of the
#: digest names them; one that starts to use them must leave this list.
NOT_IMPORTED = ("mechanics/contact_sensitivity.py", "mechanics/_contact_sensitivity_kernels.py")


def _root() -> Path:
    return Path(__file__).resolve().parents[1]


def code_digest(source: str, filename: str = "<source>") -> str:
    """SHA-256 (hex) of a Python module's code: its syntax tree without docstrings.

    A docstring is a string constant that is the first statement of a module, class or function
    body; it is left out (a body that is only a docstring keeps an empty body). Comments and
    layout are not part of the tree.

    Parameters
    ----------
    source : str
        The module's text.
    filename : str
        Named in the error.

    Returns
    -------
    str
        64 hexadecimal digits.

    Raises
    ------
    SyntaxError
        ``source`` is not valid Python.
    """
    tree = ast.parse(source, filename=filename)
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                node.body = body[1:]
    return hashlib.sha256(ast.dump(tree, annotate_fields=False).encode()).hexdigest()


def source_files(packages=SOURCE_PACKAGES, modules=SOURCE_MODULES, excluded=FORMAT_ONLY + NOT_IMPORTED) -> list:
    """The files of the digest (:func:`source_digest`), sorted by their path relative to the
    ``ctrplan`` package.

    Returns
    -------
    list of pathlib.Path
    """
    root = _root()
    paths = [p for pkg in packages for p in (root / pkg).rglob("*.py")
             if p.relative_to(root).as_posix() not in excluded] + [root / m for m in modules]
    return sorted(paths, key=lambda p: p.relative_to(root).as_posix())


def source_digest(packages=SOURCE_PACKAGES, modules=SOURCE_MODULES, excluded=FORMAT_ONLY + NOT_IMPORTED) -> str:
    """SHA-256 (hex) of the code of ``packages`` and ``modules`` less ``excluded``: their paths and
    :func:`code_digest`, sorted by path.

    Parameters
    ----------
    packages : sequence of str
        Subpackages of ``ctrplan``.
    modules : sequence of str
        Module files of ``ctrplan`` (paths relative to the package).
    excluded : sequence of str
        Module files inside ``packages`` left out (paths relative to the package).

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    root = _root()
    h = hashlib.sha256()
    for path in source_files(packages, modules, excluded):
        rel = path.relative_to(root).as_posix()
        h.update(rel.encode() + b"\0" + code_digest(path.read_text(), rel).encode() + b"\0")
    return h.hexdigest()


def options_digest(options) -> str:
    """SHA-256 (hex) of options (a dataclass or a mapping) as sorted JSON."""
    value = asdict(options) if is_dataclass(options) else dict(options)
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()


def provenance(options=None) -> dict:
    """``{"source_sha256", "source_packages", "options_sha256"}`` for a results file."""
    out = {"source_sha256": source_digest(),
           "source_packages": [f"ctrplan/{p}" for p in SOURCE_PACKAGES] + [f"ctrplan/{m}" for m in SOURCE_MODULES],
           "source_excluded": [f"ctrplan/{m}" for m in FORMAT_ONLY + NOT_IMPORTED]}
    if options is not None:
        out["options_sha256"] = options_digest(options)
    return out
