"""A model's errors on given samples: out of fold on the development data, or on the test split."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..effects import EffectSet, registration_transform
from .calibrate import pose_errors, predict

__all__ = ["Errors", "evaluate_rows", "out_of_fold", "error_summary", "stats_mm"]


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


def _errors(setup, rows: np.ndarray, model: str, params: Mapping, *, n_jobs: int, progress: bool) -> Errors:
    sub = setup.data.take(rows)
    pred = predict(setup.robot, tuple(params), tuple(params.values()), sub, model, setup.settings, n_jobs=n_jobs,
                   progress=progress)
    pos, ang, vec = pose_errors(pred, sub)
    effects, _ = EffectSet.from_parameters(setup.robot, tuple(params), tuple(params.values()))
    R, _ = registration_transform(effects["registration"] if "registration" in effects else {})
    return Errors(rows=np.asarray(rows, int), position=pos, angle=ang, residual_base=vec @ R, tip_base=pred.tip_base,
                  seconds=pred.seconds)


def evaluate_rows(setup, rows, stage: str, model: str, params: Mapping, *, n_jobs: int = 1, progress: bool = False,
                  echo=print) -> Errors:
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
    echo : callable

    Returns
    -------
    Errors
    """
    cached = setup.stages.load(stage)
    if cached is not None:
        return Errors.from_dict(cached)
    rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, int)
    echo(f"  evaluating {stage} ({model} model) on {rows.size} samples ...")
    res = _errors(setup, rows, model, params, n_jobs=n_jobs, progress=progress)
    setup.stages.save(stage, res.as_dict())
    return res


def out_of_fold(setup, split, name: str, model: str, fold_params, *, n_jobs: int = 1, progress: bool = False,
                echo=print) -> Errors:
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
    echo : callable

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
    echo(f"  cross-validating {name} ({model} model): {split.n_folds} folds, {dev.size} samples ...")
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


def error_summary(pos, ang, seconds, n) -> dict:
    """Table VIII row: tip position error mean, std, p95, max [mm]; tangent mean, max [deg].

    Parameters
    ----------
    pos : ndarray, shape (K,) [m]
    ang : ndarray, shape (K,) [rad]
    seconds : float
        Evaluation time [s].
    n : int
        Samples evaluated.
    """
    pos_mm = pos[np.isfinite(pos)] * 1e3
    ang_deg = np.rad2deg(ang[np.isfinite(ang)])
    return {"position_mean_mm": float(pos_mm.mean()) if pos_mm.size else None,
            "position_std_mm": float(pos_mm.std()) if pos_mm.size else None,
            "position_p95_mm": float(np.percentile(pos_mm, 95)) if pos_mm.size else None,
            "position_max_mm": float(pos_mm.max()) if pos_mm.size else None,
            "tangent_mean_deg": float(ang_deg.mean()) if ang_deg.size else None,
            "tangent_max_deg": float(ang_deg.max()) if ang_deg.size else None,
            "evaluation_ms_per_sample": 1e3 * seconds / max(n, 1),
            "n_samples": int(n), "n_failed": int(np.count_nonzero(~np.isfinite(pos)))}


def stats_mm(pos) -> dict:
    """Mean, p95 and max of position errors (K,) [m], in mm."""
    p = pos[np.isfinite(pos)] * 1e3
    if not p.size:
        return {"n": 0, "mean_mm": None, "p95_mm": None, "max_mm": None}
    return {"n": int(p.size), "mean_mm": float(p.mean()), "p95_mm": float(np.percentile(p, 95)),
            "max_mm": float(p.max())}
