"""A model's errors on the held-out samples, and their summaries (Table VIII's columns)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from ..effects import EffectSet, registration_transform
from .calibrate import pose_errors, predict
from .setup import DiscrepancySetup
from .split import SampleSplit

__all__ = ["HeldOut", "HeldOutFn", "evaluate_held_out", "error_summary", "stats_mm"]


@dataclass(frozen=True, eq=False)
class HeldOut:
    """A model's errors on the held-out samples (the Eq. (49) terms).

    Attributes
    ----------
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

    position: np.ndarray
    angle: np.ndarray
    residual_base: np.ndarray
    tip_base: np.ndarray
    seconds: float

    def as_dict(self) -> dict:
        """The stage file's content (arrays as arrays; SI units)."""
        return {"position": self.position, "angle": self.angle, "residual_base": self.residual_base,
                "tip_base": self.tip_base, "seconds": self.seconds}


#: ``held_out(name, model, params) -> HeldOut``: :func:`evaluate_held_out` bound to one run.
HeldOutFn = Callable[[str, str, Mapping], HeldOut]


def evaluate_held_out(setup: DiscrepancySetup, split: SampleSplit, name: str, model: str, params: Mapping,
                      *, n_jobs: int = 1, progress: bool = True, echo=print) -> HeldOut:
    """A model's errors on the held-out samples, read from the stage ``validation-<name>`` if
    an earlier run finished it, else evaluated and stored there.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : SampleSplit
    name : str
        Stage name (e.g. ``"baseline"``, an effect, ``"combination-<a>+<b>"``).
    model : str
        ``"standard"``, ``"clearance"`` or ``"friction"``.
    params : mapping of str to float
        Parameters applied (baseline and effect parameters, registration included) [SI].
    n_jobs : int
    progress : bool
        Progress bar of the evaluation.
    echo : callable

    Returns
    -------
    HeldOut
        Errors of the K held-out samples [m, rad].
    """
    cached = setup.stages.load(f"validation-{name}")
    if cached is not None:
        return HeldOut(**{k: np.array(v, float) if isinstance(v, list) else v for k, v in cached.items()})
    val = split.val
    echo(f"  evaluating {name} ({model} model) on {val.n_samples} held-out samples ...")
    pred = predict(setup.robot, tuple(params), tuple(params.values()), val, model, setup.settings,
                   n_jobs=n_jobs, progress=progress)
    pos, ang, vec = pose_errors(pred, val)
    effects, _ = EffectSet.from_parameters(setup.robot, tuple(params), tuple(params.values()))
    R, _ = registration_transform(effects["registration"] if "registration" in effects else {})
    res = HeldOut(position=pos, angle=ang, residual_base=vec @ R, tip_base=pred.tip_base, seconds=pred.seconds)
    setup.stages.save(f"validation-{name}", res.as_dict())
    return res


def error_summary(pos, ang, seconds, n) -> dict:
    """Table VIII row: tip position error mean, std, max [mm]; tangent mean, max [deg].

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
