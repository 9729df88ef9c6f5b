"""Keys of everything ctrplan stores to reuse: one rule for checkpoints, stages, outputs and maps.

A stored result is reused only under the key of what it was computed from. Every key is a
SHA-256 over canonical JSON (:func:`content_key`: sorted keys, values that are not JSON by their
``repr``) of a payload that names

- the input files by the SHA-256 of their bytes (:func:`file_hash`; a folder, such as a ROS 2
  bag, by its files' names and bytes),
- the options that change the result (and none that do not, such as the number of workers),
- the version of the mechanics (:data:`ctrplan.constants.MECHANICS_VERSION`), so that a result of
  older mechanics is computed again rather than reused, and any other version or method that can
  move the figures (the discrepancy fits' ``FIT_VERSION`` and their code's digest; the noise estimate's method, which
  depends on the installed scipy).

Every key is the full digest (64 hex digits); file names that show a key may show its first 12.
Users of the rule: :func:`ctrplan.batch.job_key` (checkpoints of ``ctrplan evaluate``),
:func:`ctrplan.studies.input_key` (a study's finished scenarios),
:func:`ctrplan.boundmap.field_key` (bound maps), :func:`ctrplan.discrepancy.stages.stage_key`
(finished stages of a discrepancy run).

What is stored to be reused across runs (bound maps computed for a robot file, roadmaps) goes to
one folder, :func:`cache_dir`: the environment variable ``CTRPLAN_CACHE_DIR`` when set, else the
user's cache folder (``platformdirs.user_cache_path("ctrplan")``, e.g. ``~/.cache/ctrplan`` on
Linux), not a folder that follows the working directory unless the variable asks for one.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any, Mapping

__all__ = ["content_key", "file_hash", "mechanics_version", "cache_dir", "CACHE_ENV"]

#: The environment variable that names the cache folder (:func:`cache_dir`).
CACHE_ENV = "CTRPLAN_CACHE_DIR"


def cache_dir(kind: str | None = None) -> Path:
    """The folder where ctrplan keeps what it reuses across runs, read at call time.

    Parameters
    ----------
    kind : str, optional
        A subfolder: ``"boundmaps"``, ``"roadmaps"``.

    Returns
    -------
    pathlib.Path
        ``$CTRPLAN_CACHE_DIR`` when the variable is set and not empty (a relative value is
        relative to the working directory at the time of the call: ``CTRPLAN_CACHE_DIR=.cache``
        keeps a cache per working folder, as the test suite does), else the user's cache folder
        for ctrplan (``platformdirs.user_cache_path("ctrplan")``); joined with ``kind``. Not
        created here: writers create it.
    """
    given = os.environ.get(CACHE_ENV, "").strip()
    if given:
        root = Path(given).expanduser().absolute()
    else:
        import platformdirs

        root = platformdirs.user_cache_path("ctrplan")
    return root / kind if kind else root


def mechanics_version() -> str:
    """The running code's :data:`ctrplan.constants.MECHANICS_VERSION` (read at call time)."""
    from . import constants

    return str(constants.MECHANICS_VERSION)


def content_key(payload: Mapping[str, Any] | list) -> str:
    """SHA-256 of ``payload`` as canonical JSON (keys sorted, non-JSON values by ``repr``).

    Parameters
    ----------
    payload : mapping or list
        What the stored result depends on (file hashes, options, versions).

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=repr).encode()).hexdigest()


def file_hash(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, as 64 hex digits (to record which model or data a result used).
    For a folder (a ROS 2 bag), of the names and bytes of the files in it, in sorted order.

    Raises
    ------
    FileNotFoundError
    """
    p = Path(path)
    if not p.is_dir():
        return hashlib.sha256(p.read_bytes()).hexdigest()
    h = hashlib.sha256()
    for f in sorted(x for x in p.rglob("*") if x.is_file()):
        h.update(f.relative_to(p).as_posix().encode() + b"\0")
        with open(f, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        h.update(b"\0")
    return h.hexdigest()
