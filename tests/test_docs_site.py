"""The documentation site (mkdocs.yml, docs/) builds in strict mode, and its API reference has an
entry for every public name.

- The strict build fails on a broken link between pages, a link to a missing anchor, a page
  missing from the nav, a ``:::`` entry naming a module or object that no longer exists, and a
  docstring that griffe reports (a documented parameter the signature does not have, a section
  it cannot read).
- The strict build alone passes when a public name has no entry: mkdocstrings leaves out, without
  a word, a name without a docstring, a name griffe cannot see (one a package imports on first
  use, or one shadowed by a submodule of the same name) and a module no page names. The checks
  on ``__all__`` catch those.
- Links from the docs to repository files outside ``docs/`` pass the strict build only when the
  file exists (``docs/_ext/hooks.py``).

mkdocs and mkdocstrings are test dependencies (pyproject.toml): without them these tests fail.
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
API_PAGES = ROOT / "docs" / "api"
# The first `::: name` of an API page is the module the page documents.
DIRECTIVE = re.compile(r"^::: *(\S+)", re.MULTILINE)


def _mkdocs_build(config: Path, site: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(config),
                           "--site-dir", str(site)], cwd=ROOT, capture_output=True, text=True, env=env)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built from the repository's mkdocs.yml in strict mode (once for this module)."""
    out = tmp_path_factory.mktemp("site")
    run = _mkdocs_build(ROOT / "mkdocs.yml", out)
    assert run.returncode == 0, f"mkdocs build --strict failed:\n{run.stdout}\n{run.stderr}"
    return out


def _documented_modules() -> dict[str, Path]:
    """Module documented by each API page -> the page."""
    modules = {}
    for page in sorted(API_PAGES.glob("*.md")):
        found = DIRECTIVE.findall(page.read_text())
        assert found, f"{page.relative_to(ROOT)} has no ::: entry"
        modules[found[0]] = page
    return modules


def _source(module: str) -> Path:
    path = ROOT.joinpath(*module.split("."))
    return path / "__init__.py" if path.is_dir() else path.with_suffix(".py")


def _all(module: str) -> list[str] | None:
    """The literal ``__all__`` of ``module``, read from its source (without importing it)."""
    for node in ast.parse(_source(module).read_text()).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return list(ast.literal_eval(node.value))
    return None


def test_site_builds_strict(site):
    """`mkdocs build --strict` succeeds (the fixture fails otherwise, with mkdocs' output)."""
    assert (site / "index.html").exists()
    assert (site / "api" / "mechanics" / "index.html").exists()


@pytest.mark.parametrize("module", sorted(_documented_modules()))
def test_api_page_has_every_public_name(site, module):
    """Each name in the module's ``__all__`` has an entry (a heading whose id is its path) in the
    built page: ``module.name``, or ``module.name.name`` for a function a package imports over its
    submodule of the same name, entered by that submodule's path."""
    names = _all(module)
    assert names, f"{module} has no literal __all__ to document"
    page = _documented_modules()[module]
    html = (site / page.relative_to(ROOT / "docs").with_suffix("") / "index.html").read_text()
    ids = set(re.findall(r'\bid="([^"]+)"', html))
    missing = [n for n in names if f"{module}.{n}" not in ids and f"{module}.{n}.{n}" not in ids]
    assert not missing, (f"{page.relative_to(ROOT)}: no entry for {missing} of {module}.__all__ (a name "
                         f"without a docstring is left out; see mkdocs.yml and docs/_ext/griffe_ctrplan.py)")


def test_every_public_module_has_an_api_page():
    """Each module of the package's top level and each subpackage that declares ``__all__`` is the
    subject of a page in docs/api/ and in the nav."""
    public = sorted(
        {f"ctrplan.{p.stem}" for p in (ROOT / "ctrplan").glob("*.py") if not p.name.startswith("_")}
        | {f"ctrplan.{p.parent.name}" for p in (ROOT / "ctrplan").glob("*/__init__.py")
           if not p.parent.name.startswith("_")})
    public = [m for m in public if _all(m) is not None]
    documented = _documented_modules()
    assert not [m for m in public if m not in documented], "public modules without a page in docs/api/"
    nav = (ROOT / "mkdocs.yml").read_text()
    assert not [p for p in documented.values() if f"api/{p.name}" not in nav], "API pages not in the nav"


def _tiny_site(tmp_path: Path, index: str) -> subprocess.CompletedProcess:
    """Build a two-page site with the repository's hooks and link validation."""
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    (tmp_path / "docs").mkdir(parents=True)
    (tmp_path / "docs" / "index.md").write_text(index)
    (tmp_path / "docs" / "other.md").write_text("# Other\n\n## A section\n")
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "table.csv").write_text("a,b\n")
    tiny = {"site_name": "links", "docs_dir": "docs", "nav": ["index.md", "other.md"],
            "hooks": [str(ROOT / h) for h in config["hooks"]], "validation": config["validation"]}
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(tiny))
    return _mkdocs_build(tmp_path / "mkdocs.yml", tmp_path / "site")


def test_links_to_repository_files_pass_and_broken_links_fail(tmp_path):
    """A link from a page to an existing file or folder outside docs/ passes the strict build;
    a link to a missing page, to a missing anchor or to a missing file outside docs/ fails it."""
    good = "# Home\n\n[table](../data/table.csv), [folder](../data/), [section](other.md#a-section)\n"
    run = _tiny_site(tmp_path / "good", good)
    assert run.returncode == 0, f"{run.stdout}\n{run.stderr}"

    bad = ("missing.md", "other.md#no-such-section", "../data/missing.csv", "../data/missing/")
    run = _tiny_site(tmp_path / "bad", "# Home\n\n" + ", ".join(f"[x]({link})" for link in bad) + "\n")
    assert run.returncode != 0, f"broken links passed the strict build:\n{run.stderr}"
    warnings = [line for line in run.stderr.splitlines() if line.startswith("WARNING")]
    assert not [link for link in bad if not any(f"'{link}'" in w for w in warnings)], "\n".join(warnings)
