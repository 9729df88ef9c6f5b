"""A model's errors on given samples: out of fold on the development data, or on the test split."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import logging

import numpy as np

from ..._log import progress_level
from ...effects import EffectSet, registration_transform
from .predictions import pose_errors, predict

logger = logging.getLogger(__name__)

__all__ = ["Errors", "ErrorFigures", "evaluate_rows", "out_of_fold"]


@dataclass(frozen=True, eq=False)
class Errors:
    """A model's errors at K samples (the Eq. (49) terms).

    Attributes
    ----------
    rows : ndarray of int, shape (K,)
        The samples (indices into the run's data), in order.
    position : ndarray, shape (K,)
        Tip position error [m]; NaN where the model failed.
    angle : ndarray, shape (K,)
        Tip tangent error [rad]; NaN where it failed or the tangent is not measured.
    residual_base : ndarray, shape (K, 3)
        Measured minus predicted tip, rotated into the robot's base frame [m].
    tip_base : ndarray, shape (K, 3)
        Predicted tip in the robot's base frame [m].
    seconds : float
        Evaluation time [s].
    """

    rows: np.ndarray
    position: np.ndarray
    angle: np.ndarray
    residual_base: np.ndarray
    tip_base: np.ndarray
    seconds: float

    def as_dict(self) -> dict:
        """The stage file's content (arrays as arrays; SI units)."""
        return {"rows": self.rows, "position": self.position, "angle": self.angle,
                "residual_base": self.residual_base, "tip_base": self.tip_base, "seconds": self.seconds}

    @classmethod
    def from_dict(cls, d: dict) -> "Errors":
        return cls(rows=np.asarray(d["rows"], int), position=np.array(d["position"], float),
                   angle=np.array(d["angle"], float), residual_base=np.array(d["residual_base"], float).reshape(-1, 3),
                   tip_base=np.array(d["tip_base"], float).reshape(-1, 3), seconds=float(d["seconds"]))


@dataclass(frozen=True)
class ErrorFigures:
    """A model's errors at K samples summarized as a row of Table VIII of Ha et al. 2019.

    Attributes
    ----------
    position_mean, position_std, position_p95, position_max : float or None
        Of the finite tip position errors [m]; None when none is finite.
    tangent_mean, tangent_max : float or None
        Of the finite tip tangent errors [rad]; None when none is finite.
    seconds_per_sample : float
        Evaluation time per sample [s].
    n_samples : int
        Samples evaluated.
    n_failed : int
        Samples where the model failed (no finite position error).
    """

    position_mean: float | None
    position_std: float | None
    position_p95: float | None
    position_max: float | None
    tangent_mean: float | None
    tangent_max: float | None
    seconds_per_sample: float
    n_samples: int
    n_failed: int

    @classmethod
    def of(cls, errors: Errors) -> "ErrorFigures":
        """The figures of :class:`Errors` (its ``rows`` are the samples evaluated)."""
        pos, ang, n = errors.position, errors.angle, int(errors.rows.size)
        p = pos[np.isfinite(pos)]
        a = ang[np.isfinite(ang)]
        return cls(position_mean=float(p.mean()) if p.size else None,
                   position_std=float(p.std()) if p.size else None,
                   position_p95=float(np.percentile(p, 95)) if p.size else None,
                   position_max=float(p.max()) if p.size else None,
                   tangent_mean=float(a.mean()) if a.size else None, tangent_max=float(a.max()) if a.size else None,
                   seconds_per_sample=errors.seconds / max(n, 1), n_samples=n,
                   n_failed=int(np.count_nonzero(~np.isfinite(pos))))


def _errors(setup, rows: np.ndarray, model: str, params: Mapping, *, n_jobs: int, progress: bool) -> Errors:
    sub = setup.data.take(rows)
    pred = predict(setup.robot, tuple(params), tuple(params.values()), sub, model, setup.settings, n_jobs=n_jobs,
                   progress=progress)
    pos, ang, vec = pose_errors(pred, sub)
    effects, _ = EffectSet.from_parameters(setup.robot, tuple(params), tuple(params.values()))
    R, _ = registration_transform(effects["registration"] if "registration" in effects else {})
    return Errors(rows=np.asarray(rows, int), position=pos, angle=ang, residual_base=vec @ R, tip_base=pred.tip_base,
                  seconds=pred.seconds)


def evaluate_rows(setup, rows, stage: str, model: str, params: Mapping, *, n_jobs: int = 1,
                  progress: bool = False) -> Errors:
    """A model's errors at the samples ``rows``, read from the stage ``stage`` if an earlier run
    finished it, else evaluated (along the whole recorded history) and stored there.

    Parameters
    ----------
    setup : DiscrepancySetup
    rows : ndarray of bool, shape (N,), or of int
        The samples.
    stage : str
    model : {"standard", "clearance", "friction"}
    params : mapping of str to float
        Parameters applied (baseline and effect parameters, registration included) [SI].
    n_jobs : int
    progress : bool

    Returns
    -------
    Errors
    """
    cached = setup.stages.load(stage)
    if cached is not None:
        return Errors.from_dict(cached)
    rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, int)
    logger.log(progress_level(), f"  evaluating {stage} ({model} model) on {rows.size} samples ...")
    res = _errors(setup, rows, model, params, n_jobs=n_jobs, progress=progress)
    setup.stages.save(stage, res.as_dict())
    return res


def out_of_fold(setup, split, name: str, model: str, fold_params, *, n_jobs: int = 1,
                progress: bool = False) -> Errors:
    """Out-of-fold errors on the development samples: each fold evaluated with the parameters
    fitted without it (blocked cross-validation), read from the stage ``oof-<name>`` if an
    earlier run finished it.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    name : str
        Model name for the stage (``"baseline"``, an effect, ``"pair-a+b"``).
    model : {"standard", "clearance", "friction"}
    fold_params : sequence of mappings, length ``split.n_folds``
        The parameters fitted without each fold [SI].
    n_jobs : int
    progress : bool

    Returns
    -------
    Errors
        At the development samples in data order.
    """
    stage = f"oof-{name}"
    cached = setup.stages.load(stage)
    if cached is not None:
        return Errors.from_dict(cached)
    dev = np.flatnonzero(split.dev_rows)
    logger.log(progress_level(), f"  cross-validating {name} ({model} model): {split.n_folds} folds, {dev.size} "
                                 f"samples ...")
    pos = np.full(dev.size, np.nan)
    ang = np.full(dev.size, np.nan)
    res = np.full((dev.size, 3), np.nan)
    tip = np.full((dev.size, 3), np.nan)
    seconds = 0.0
    where = {r: i for i, r in enumerate(dev)}
    for k in range(split.n_folds):
        rows = np.flatnonzero(split.validation_rows(k))
        e = _errors(setup, rows, model, fold_params[k], n_jobs=n_jobs, progress=progress)
        at = np.array([where[r] for r in rows])
        pos[at], ang[at], res[at], tip[at] = e.position, e.angle, e.residual_base, e.tip_base
        seconds += e.seconds
    out = Errors(rows=dev, position=pos, angle=ang, residual_base=res, tip_base=tip, seconds=seconds)
    setup.stages.save(stage, out.as_dict())
    return out
