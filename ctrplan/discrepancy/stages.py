"""The store of finished workflow stages, so that an interrupted run resumes without redoing them."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..effects import REGISTRY
from ..io.atomic import atomic_write_text
from ..io.robot_file import file_hash
from .calibrate import CalibrationResult
from .options import FIT_VERSION, DiscrepancyOptions

__all__ = ["StageStore", "stage_key"]


class StageStore:
    """Finished stages on disk (JSON files ``<folder>/.stages/<key>-<name>.json``).

    Parameters
    ----------
    folder : path
        The report folder.
    key : str
        :func:`stage_key` of the run.
    """

    def __init__(self, folder, key: str):
        self.folder = Path(folder) / ".stages"
        self.key = key

    def path(self, name: str) -> Path:
        return self.folder / f"{self.key}-{name}.json"

    def load(self, name: str):
        """The stored value of stage ``name``, or None."""
        p = self.path(name)
        return json.loads(p.read_text()) if p.exists() else None

    def save(self, name: str, value) -> None:
        """Store a stage's value (numpy arrays as lists), atomically."""
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.path(name), json.dumps(value, default=_jsonable))


def _jsonable(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    raise TypeError(type(x))


def stage_key(robot_path, data_path, options: DiscrepancyOptions) -> str:
    """The key under which a run's finished stages are stored.

    The stages depend on the inputs, on the options that change a fit and on the effects tried,
    not on the number of workers, the tests' permutations and level (the tests are not stored),
    the stated noise, the envelope or the reference friction; :data:`FIT_VERSION` enters it so
    that stages of an earlier fitting procedure are not reused.

    Parameters
    ----------
    robot_path, data_path : path
        The input files (their bytes enter the key; a bag folder's files with their names).
    options : DiscrepancyOptions

    Returns
    -------
    str
        12 hexadecimal digits of a SHA-256.
    """
    keyed = {k: v for k, v in asdict(options).items()
             if k not in ("n_jobs", "n_permutations", "significance", "noise_position", "envelope_samples",
                          "reference_friction", "effects", "bound_target", "bound_samples")}
    keyed["fit_version"] = FIT_VERSION
    keyed["effects"] = sorted(options.effects if options.effects is not None else REGISTRY)
    return hashlib.sha256(Path(robot_path).read_bytes() + file_hash(data_path).encode()
                          + json.dumps(keyed, sort_keys=True, default=str).encode()).hexdigest()[:12]
