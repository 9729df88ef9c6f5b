"""A model's tip poses at the data's samples and their errors (Section V-C of Ha, Fagogenis &
Dupont 2019).

- :func:`predict`: a model's tip poses along the data's motion history, in the data's frame;
- :func:`pose_errors`: tip position and tangent errors;
- :func:`eq49_residuals`: the per-sample residual of Eq. (49), ``|dp| / 1 mm + angle / 1 deg``;
- :func:`kabsch_registration`: the closed-form rigid registration of model tips onto measured ones.

The calibration on them is :mod:`ctrplan.discrepancy.fits.calibrate`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ...effects import EffectSet, apply_output_effects, robot_effects
from ...mechanics import ModelSettings
from ...models import MODEL_INFO, check_model
from ..measured.data import MeasuredData
from .parameters import apply_parameters

__all__ = ["SamplePredictions", "predict", "pose_errors", "eq49_residuals", "kabsch_registration",
           "POSITION_UNIT", "ANGLE_UNIT", "FAILED_RESIDUAL"]


#: Eq. (49) residual given to a sample whose model solve failed (50 mm + 0 deg); keeps the
#: least-squares problem defined without letting failures dominate.
FAILED_RESIDUAL = 50.0
#: Eq. (49) weighting: this many metres of position error weigh as ...
POSITION_UNIT = 1e-3
#: ... this many radians of tangent error (1 mm : 1 deg).
ANGLE_UNIT = np.pi / 180.0


@dataclass(frozen=True, eq=False)
class SamplePredictions:
    """Model tip poses at the data's samples.

    Attributes
    ----------
    tip : ndarray, shape (K, 3)
        [m], in the data's frame (registration applied).
    tangent : ndarray, shape (K, 3)
        Unit tangents, in the data's frame.
    tip_base : ndarray, shape (K, 3)
        [m], in the robot base frame.
    tangent_base : ndarray, shape (K, 3)
        Unit tangents in the robot base frame.
    ok : ndarray of bool, shape (K,)
    message : list of str
    seconds : float
        Wall time of the model evaluation.
    alpha, beta : ndarray, shape (K, n), or None
        Base rotations [rad] and translations [m] the tubes reached (history effects applied).
    base_torsion : ndarray, shape (K, n), or None
        Standard-model base torsions of the branch followed [1/m] (NaN where it failed).
    """

    tip: np.ndarray
    tangent: np.ndarray
    tip_base: np.ndarray
    tangent_base: np.ndarray
    ok: np.ndarray
    message: list
    seconds: float
    alpha: np.ndarray | None = None
    beta: np.ndarray | None = None
    base_torsion: np.ndarray | None = None


def predict(robot, names, values, data: MeasuredData, model: str, settings: ModelSettings | None = None,
            *, n_jobs: int = 1, progress: bool = False, warm_starts=None) -> SamplePredictions:
    """Evaluate a model with the given parameters at every sample of ``data``.

    The named effects are applied where they act (:mod:`ctrplan.effects`): the mechanical ones
    to the robot, the history ones to the whole recorded motion (drive backlash, tracker time
    offset, gradual friction; :meth:`MeasuredData.state`), the output ones (registration) to the
    computed tip poses. Each sequence is followed in order (each sample solved from the previous
    one; :func:`ctrplan.discrepancy.fits.simulate.simulate`) with the friction the history state
    applies.

    Parameters
    ----------
    robot : Robot
    names : sequence of str
        Parameters to set (baseline parameters, :mod:`ctrplan.discrepancy.fits.parameters`, and effect
        parameters, :mod:`ctrplan.effects`), registration included.
    values : array-like, shape (m,)
        In the parameters' units (SI).
    data : MeasuredData
    model : {"standard", "clearance", "friction"}
    settings : ModelSettings, optional
    n_jobs : int
    progress : bool
    warm_starts : WarmStarts, optional
        Contact solutions of earlier evaluations of the same samples to start from
        (:class:`ctrplan.discrepancy.fits.simulate.WarmStarts`).

    Returns
    -------
    SamplePredictions
        Tips (K, 3) [m] in the data's frame and in the robot base frame, tangents, ok flags.

    Raises
    ------
    ParameterError, PhysicalParameterError
        Parameter values that give an impossible robot.
    ValueError
        A time offset on data without times; an unknown model.
    """
    from .simulate import simulate

    t0 = time.perf_counter()
    friction = MODEL_INFO[check_model(model)].friction
    names = tuple(names)
    values = np.asarray(values, float)
    robot_p = apply_parameters(robot, names, values)
    effects, _ = EffectSet.from_parameters(robot, names, values)
    state = data.state(robot_p, effects)
    eta, mu = state.applied(robot_p.friction_coefficients)
    sim = simulate(robot_p, state.alpha, state.beta, model=model, eta=eta if friction else None,
                   mu=mu if friction else None, sequence=data.sequence, settings=settings, n_jobs=n_jobs,
                   progress=progress, warm_starts=warm_starts)
    tip_base = np.asarray(sim.tip, float)
    tip, tangent = apply_output_effects(tip_base, sim.tangent, robot_effects(robot_p).merged(effects))
    return SamplePredictions(tip=tip, tangent=tangent, tip_base=tip_base, tangent_base=np.asarray(sim.tangent, float),
                      ok=np.asarray(sim.ok, bool), message=list(sim.message), seconds=time.perf_counter() - t0,
                      alpha=np.asarray(state.alpha, float), beta=np.asarray(state.beta, float),
                      base_torsion=np.asarray(sim.base_torsion, float))


def pose_errors(pred: SamplePredictions, data: MeasuredData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tip position and tangent errors of a prediction.

    Returns
    -------
    position : ndarray, shape (K,)
        ``|p_measured - p_model|`` [m]; NaN where the model failed.
    angle : ndarray, shape (K,)
        Angle between measured and model tangents [rad]; NaN where failed or not measured.
    vector : ndarray, shape (K, 3)
        ``p_measured - p_model`` [m] in the data's frame; NaN where failed.
    """
    vec = data.tip - pred.tip
    vec[~pred.ok] = np.nan
    pos = np.linalg.norm(vec, axis=1)
    if data.tangent is None:
        ang = np.full(pos.shape, np.nan)
    else:
        c = np.einsum("ij,ij->i", data.tangent / np.linalg.norm(data.tangent, axis=1, keepdims=True),
                      pred.tangent / np.linalg.norm(pred.tangent, axis=1, keepdims=True))
        ang = np.arccos(np.clip(c, -1.0, 1.0))
        ang[~pred.ok] = np.nan
    return pos, ang, vec


def eq49_residuals(position, angle) -> np.ndarray:
    """Per-sample residual of Eq. (49): ``|dp| / 1 mm + angle / 1 deg`` (angle term dropped where
    the tangent is not measured); :data:`FAILED_RESIDUAL` where the model failed.

    Parameters
    ----------
    position : ndarray, shape (K,) [m]
    angle : ndarray, shape (K,) [rad]

    Returns
    -------
    ndarray, shape (K,) [mm + deg]
    """
    r = position / POSITION_UNIT + np.nan_to_num(angle / ANGLE_UNIT, nan=0.0)
    return np.where(np.isfinite(position), r, FAILED_RESIDUAL)


def kabsch_registration(model_tip, measured_tip) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid registration ``measured ~ R model + t`` (Kabsch / Umeyama, no scale).

    Parameters
    ----------
    model_tip, measured_tip : ndarray, shape (K, 3) [m]
        Rows with NaN are ignored.

    Returns
    -------
    rotation_vector : ndarray, shape (3,) [rad]
    translation : ndarray, shape (3,) [m]
    """
    ok = np.all(np.isfinite(model_tip), axis=1) & np.all(np.isfinite(measured_tip), axis=1)
    a, b = measured_tip[ok], model_tip[ok]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    rot, _ = Rotation.align_vectors(a - ca, b - cb)
    return rot.as_rotvec(), ca - rot.as_matrix() @ cb
