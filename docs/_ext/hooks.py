"""MkDocs hooks: links from a docs page to a file of the repository outside ``docs/``.

The docs are read in the repository as much as on the site, and link to its files (scripts,
results, robot files: ``../benchmarks/...``, ``../model/...``). MkDocs validates each relative
link against the documentation files only, and reports one to a file outside ``docs/`` with the
same warning as a broken link between pages, which fails ``mkdocs build --strict``.

This hook lowers that warning to INFO when the link leaves ``docs/`` and its target exists in the
repository (the folder of ``mkdocs.yml``). Every other broken link, a link outside ``docs/`` to a
file that does not exist, and every missing anchor stay warnings (``validation`` in
``mkdocs.yml``). If MkDocs words the warning differently one day, nothing is lowered and such
links fail the strict build again.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from urllib.parse import unquote, urlsplit

# MkDocs' warnings for a relative link with no documentation file behind it (mkdocs 1.6,
# mkdocs/structure/pages.py): "not found" (a path with a suffix) and "unrecognized" (without).
_LINK_WARNING = re.compile(r"^Doc file '(?P<page>[^']+)' contains (?:a|an unrecognized relative) link "
                           r"'(?P<url>[^']+)'")


class RepositoryLinks(logging.Filter):
    """Lowers MkDocs' warning for a link to an existing repository file outside ``docs/`` to INFO."""

    def __init__(self, docs_dir: Path, root: Path):
        super().__init__()
        self.docs_dir = docs_dir.resolve()
        self.root = root.resolve()

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno == logging.WARNING:
            match = _LINK_WARNING.match(record.getMessage())
            if match and self.in_repository(match["page"], match["url"]):
                record.levelno, record.levelname = logging.INFO, logging.getLevelName(logging.INFO)
        return True

    def in_repository(self, page: str, url: str) -> bool:
        """Whether ``url``, linked from the docs page ``page``, is an existing file or folder of
        the repository outside ``docs/``."""
        path = unquote(urlsplit(url).path)
        if not path or path.startswith("/"):
            return False
        target = ((self.docs_dir / page).parent / path).resolve()
        return (target.is_relative_to(self.root) and not target.is_relative_to(self.docs_dir)
                and target.exists())


def on_config(config):
    logger = logging.getLogger("mkdocs.structure.pages")
    for old in [f for f in logger.filters if type(f).__name__ == RepositoryLinks.__name__]:
        logger.removeFilter(old)  # `mkdocs serve` loads the config again on every rebuild
    logger.addFilter(RepositoryLinks(Path(config.docs_dir), Path(config.config_file_path).parent))
    return config
