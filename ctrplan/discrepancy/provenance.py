"""What a discrepancy result was made with: a digest of the code that can move its figures and of
its options, so that a results file can be tied to the code that made it.

The code is every Python source file of the packages whose behaviour the figures depend on
(:data:`SOURCE_PACKAGES`: the discrepancy workflow, the effects, the motion history and the
mechanics); the digest is a SHA-256 over their paths (relative to the ``ctrplan`` package) and
bytes, in sorted order, so it changes when any of them changes and nowhere else. A results file
that records it can be checked against the code at hand (``tests/test_docs_results.py`` does so
for the files the docs quote).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, is_dataclass
from pathlib import Path

__all__ = ["SOURCE_PACKAGES", "source_digest", "options_digest", "provenance"]

#: Subpackages of ``ctrplan`` whose code can move a discrepancy result's figures.
SOURCE_PACKAGES = ("discrepancy", "effects", "history", "mechanics")


def _root() -> Path:
    return Path(__file__).resolve().parents[1]


def source_digest(packages=SOURCE_PACKAGES) -> str:
    """SHA-256 (hex) of the Python sources of ``packages`` (paths and bytes, sorted).

    Parameters
    ----------
    packages : sequence of str
        Subpackages of ``ctrplan``.

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    root = _root()
    h = hashlib.sha256()
    for pkg in sorted(packages):
        for path in sorted((root / pkg).rglob("*.py")):
            h.update(path.relative_to(root).as_posix().encode() + b"\0")
            h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


def options_digest(options) -> str:
    """SHA-256 (hex) of options (a dataclass or a mapping) as sorted JSON."""
    value = asdict(options) if is_dataclass(options) else dict(options)
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()


def provenance(options=None) -> dict:
    """``{"source_sha256", "source_packages", "options_sha256"}`` for a results file."""
    out = {"source_sha256": source_digest(), "source_packages": [f"ctrplan/{p}" for p in SOURCE_PACKAGES]}
    if options is not None:
        out["options_sha256"] = options_digest(options)
    return out
