"""The source digest that ties a results file to the code that made it: blind to docstrings,
comments and layout, moved by any change of what runs, over the packages and modules it names."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from ctrplan.discrepancy import provenance
from ctrplan.discrepancy.provenance import code_digest, source_digest

MODULE = '''"""Module docstring."""
import math


class Tube:
    """Class docstring."""

    def bend(self, k):
        """Method docstring."""
        # a comment
        return math.sin(k)


def twist(x):
    return 2 * x
'''


def test_docstrings_comments_and_layout_do_not_move_the_code_digest():
    """Catches a digest over the bytes (a corrected docstring would stale every results file)."""
    edited = (MODULE.replace("Module docstring.", "Corrected module docstring, two sentences. More.")
              .replace("Method docstring.", "Bending [1/m].").replace("# a comment", "# another comment")
              .replace("return 2 * x", "return 2 * x  # doubled\n\n"))
    assert code_digest(edited) == code_digest(MODULE)
    no_docstrings = MODULE.replace('    """Class docstring."""\n', "").replace('        """Method docstring."""\n', "")
    assert code_digest(no_docstrings) == code_digest(MODULE)


@pytest.mark.parametrize("change", [("2 * x", "3 * x"), ("math.sin(k)", "math.cos(k)"), ("def twist(x)", "def twist(y)"),
                                    ('"""Module docstring."""\n', '"""Module docstring."""\nSCALE = 1.0\n'),
                                    ("return math.sin(k)", "return 'Method docstring.'")])
def test_any_change_of_what_runs_moves_the_code_digest(change):
    """Catches a digest that drops more than docstrings (a string that is not the first statement,
    a constant, a name)."""
    assert code_digest(MODULE.replace(*change)) != code_digest(MODULE)


def test_a_body_that_is_only_a_docstring_differs_from_an_empty_module():
    """A function whose body is only its docstring still counts as a function."""
    assert code_digest('def f():\n    """Only a docstring."""\n') != code_digest("")


def _tree(tmp_path: Path) -> Path:
    root = Path(provenance.__file__).resolve().parents[1]
    copy = tmp_path / "ctrplan"
    for pkg in provenance.SOURCE_PACKAGES:
        shutil.copytree(root / pkg, copy / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    for mod in provenance.SOURCE_MODULES:
        (copy / mod).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(root / mod, copy / mod)
    return copy


def test_source_digest_covers_the_packages_and_modules(tmp_path, monkeypatch):
    """Catches a file of the named packages or modules left out of the digest, and a digest
    that moves with a docstring there."""
    copy = _tree(tmp_path)
    monkeypatch.setattr(provenance, "_root", lambda: copy)
    before = source_digest()
    assert before == source_digest()
    target = copy / "mechanics" / "bound.py"
    text = target.read_text()
    target.write_text(text.replace('"""', '"""Edited. ', 1))
    assert source_digest() == before
    target.write_text(text + "\nEXTRA = 1\n")
    assert source_digest() != before
    target.write_text(text)
    constants = copy / "constants.py"
    constants.write_text(constants.read_text() + "\nEXTRA = 1\n")
    assert source_digest() != before


@pytest.mark.parametrize("module", ["choices.py", "models.py", "io/robot_file.py"])
def test_source_digest_covers_the_records_the_models_and_the_robot_file(tmp_path, monkeypatch, module):
    """The choices a run's records hold, the registry of mechanics models and the robot file the
    workflow reads and writes can move a result: a code change there changes the digest. Catches
    these modules left out of the digest (a results file then passes its check after such a change)."""
    copy = _tree(tmp_path)
    monkeypatch.setattr(provenance, "_root", lambda: copy)
    before = source_digest()
    target = copy / module
    target.write_text(target.read_text() + "\nEXTRA = 1\n")
    assert source_digest() != before


def test_the_report_formatting_is_left_out_and_the_outputs_computing_figures_are_not(tmp_path, monkeypatch):
    """``report.md`` is formatted from ``results.json`` alone and its plots are images, so a change
    of their code leaves the digest as it is; the modules beside it that compute the test split's figures and the updated
    model (``outputs/output.py``) and the results' record (``outputs/results.py``) still move it.
    Catches an exclusion that reaches past the formatting (a results file would then pass its check
    after a change of what it quotes)."""
    copy = _tree(tmp_path)
    monkeypatch.setattr(provenance, "_root", lambda: copy)
    before = source_digest()
    for name in ("report.py", "report_plots.py"):
        target = copy / "discrepancy" / "outputs" / name
        target.write_text(target.read_text() + "\nEXTRA = 1\n")
        assert source_digest() == before, name
    for name in ("output.py", "results.py"):
        target = copy / "discrepancy" / "outputs" / name
        text = target.read_text()
        target.write_text(text + "\nEXTRA = 1\n")
        assert source_digest() != before, name
        target.write_text(text)


def test_modules_left_out_as_not_imported_are_named_by_no_module_of_the_digest():
    """A module of ``NOT_IMPORTED`` cannot move a figure only while nothing of the digest imports
    it (statically or by name, as the lazy imports of ``ctrplan.mechanics``). Catches a module
    of the digest that starts to use one: it must then leave the list, so that its changes move
    the digest."""
    stems = [Path(m).stem for m in provenance.NOT_IMPORTED]
    for path in provenance.source_files():
        if path.resolve() == Path(provenance.__file__).resolve():
            continue    # the list itself
        text = path.read_text()
        for stem in stems:
            assert stem not in text, f"{path} names {stem}: remove it from provenance.NOT_IMPORTED"
    root = Path(provenance.__file__).resolve().parents[1]
    for m in provenance.NOT_IMPORTED:
        assert (root / m).is_file(), f"NOT_IMPORTED lists {m}, which does not exist"
