"""The store of finished workflow stages, so that an interrupted run resumes without redoing them."""

from __future__ import annotations

import json
import time
from dataclasses import fields
from pathlib import Path

import numpy as np

from ..cache import content_key, file_hash, mechanics_version
from ..effects import REGISTRY
from ..io.atomic import atomic_write_text
from .measured.noise import CORRELATION_LENGTH_METHOD
from .options import FIT_VERSION, DiscrepancyOptions
from .provenance import source_digest

__all__ = ["StageStore", "stage_key"]


class StageStore:
    """Finished stages on disk (JSON files ``<folder>/.stages/<key>-<name>.json``).

    Parameters
    ----------
    folder : path
        The report folder.
    key : str
        :func:`stage_key` of the run.

    Attributes
    ----------
    events : list of (str, str, float)
        ``(name, kind, time.perf_counter())`` of every stored value this store read (a load that
        found one) or wrote, in order; ``kind`` is ``"read"`` for a value an earlier run stored,
        ``"read back"`` for one this store wrote, ``"written"``. The workflow reads from it which
        of its stages came from an earlier run and where each candidate's stages ended
        (:func:`ctrplan.discrepancy.workflow.run_discrepancy`). A copy sent to a worker process
        records there, not here.
    """

    def __init__(self, folder, key: str):
        self.folder = Path(folder) / ".stages"
        self.key = key
        self.events = []
        self._written = set()

    def path(self, name: str) -> Path:
        return self.folder / f"{self.key}-{name}.json"

    def load(self, name: str):
        """The stored value of stage ``name``, or None."""
        p = self.path(name)
        if not p.exists():
            return None
        value = json.loads(p.read_text())
        self.events.append((name, "read back" if name in self._written else "read", time.perf_counter()))
        return value

    def save(self, name: str, value) -> None:
        """Store a stage's value (numpy arrays as lists), atomically."""
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.path(name), json.dumps(value, default=_jsonable))
        self._written.add(name)
        self.events.append((name, "written", time.perf_counter()))


def _jsonable(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    raise TypeError(type(x))


def stage_key(robot_path, data_path, options: DiscrepancyOptions) -> str:
    """The key under which a run's finished stages are stored (the key rule of :mod:`ctrplan.cache`).

    The stages depend on the inputs (by the SHA-256 of their bytes), on the options that change a
    fit and on the effects tried, not on the options marked
    :data:`~ctrplan.discrepancy.options.NOT_IN_STAGE_KEY` (the number of workers, the tests'
    permutations and level, the stated noise, the envelope, the reference friction, the bound's
    samples and target); :data:`~ctrplan.discrepancy.options.FIT_VERSION` and
    :data:`ctrplan.constants.MECHANICS_VERSION` enter it so that stages of an earlier fitting
    procedure or of other mechanics are not reused, and so do the digest of the code that can move
    the figures (:func:`~ctrplan.discrepancy.provenance.source_digest`: a change of that code
    that leaves ``FIT_VERSION`` as it was does not reuse stages of the earlier code) and the
    method the installed scipy gives the noise estimate
    (:data:`~ctrplan.discrepancy.measured.noise.CORRELATION_LENGTH_METHOD`).

    Parameters
    ----------
    robot_path, data_path : path
        The input files (their bytes enter the key; a bag folder's files with their names).
    options : DiscrepancyOptions

    Returns
    -------
    str
        A SHA-256, 64 hexadecimal digits (:func:`ctrplan.cache.content_key`).
    """
    keyed = {f.name: getattr(options, f.name) for f in fields(options) if f.metadata.get("stage_key", True)}
    keyed["effects"] = sorted(options.effects if options.effects is not None else REGISTRY)
    return content_key({"robot_sha256": file_hash(robot_path), "data_sha256": file_hash(data_path), "options": keyed,
                        "fit_version": FIT_VERSION, "mechanics_version": mechanics_version(),
                        "code_sha256": source_digest(),
                        "correlation_length_method": CORRELATION_LENGTH_METHOD})
