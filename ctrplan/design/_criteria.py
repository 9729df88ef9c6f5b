"""Design criteria: how well a motion separates hypotheses, and how well it determines parameters.

Both criteria are sums over the measured samples of a motion, so a motion's value is the sum of
its parts' (:class:`Information`), and the recorded trajectory, a repetition of it and a designed
addition combine by addition.

- **Separation of two hypotheses** (T-optimality, Atkinson & Fedorov, Biometrika 62(1) 1975): with
  hypothesis A true, the noise-weighted sum of squares between A's predicted tip positions and
  those of hypothesis B refitted to them over every parameter B's own fit moved,

  .. math:: T_{AB} = \\min_\\delta \\lVert W^{1/2} (y_A - y_B - J_B \\delta) \\rVert^2
                   = c - b^T G^{+} b,

  linearized about B's fitted values (``c = r^T W r``, ``b = J_B^T W r``, ``G = J_B^T W J_B``,
  ``r = y_A - y_B``). T is the non-centrality of the likelihood-ratio test of B against A: the
  expected evidence for A. A design for several hypotheses maximizes the smallest T over the
  ordered pairs, so it separates them whichever is true.
- **Parameters** (Ds-optimality, Atkinson, Donev & Tobias, Optimum Experimental Designs, 2007,
  ch. 10): the predicted covariance of the parameters of interest with every other free parameter
  as a nuisance, ``(J^T W J + P)^{-1}``, where ``P`` is a weak prior of one typical-range
  half-width per parameter so that parameters the recorded data leave undetermined get a finite
  (prior-limited) variance; the criterion is ``-log det`` of its block of interest.

``W`` is the sensor's position noise, ``1 / (s^2 f)`` per coordinate, with ``f`` the long-run
variance factor of the discrepancy workflow's own noise model
(:meth:`ctrplan.discrepancy.measured.noise.NoiseEstimate.long_run_factor`): ``f = 1 + 2 c phi /
(1 - phi)`` for a white part of share ``1 - c`` beside an exponentially correlated part with
lag-one correlation ``phi``, the factor by which the variance of a mean of many consecutive
samples exceeds the white one; ``(1 + phi) / (1 - phi)`` when the noise is all AR(1)
(``c = 1``). Correlated noise carries less evidence per sample.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..discrepancy.fits.parameters import apply_parameters, needs_solve, parameter
from ..discrepancy.fits.predictions import predict
from ..discrepancy.fits.simulate import WarmStarts
from ..effects import EffectSet, apply_output_effects, robot_effects
from ..mechanics import ModelSettings
from ..models import MODEL_INFO

#: Forward-difference step of a sensitivity, as a fraction of the parameter's scale
#: (``ParameterSpec.scale``) [-].
SENSITIVITY_STEP = 1e-3
#: Outer and complementarity tolerance of the contact solves a sensitivity differences [-]. A
#: solve stops with an error of about its tolerance, and a column divides that error by the step:
#: at the solver's default (1e-6) the friction-coefficient columns are off by 5-10 %, at 1e-11
#: (each column's solves started from the base solution at the same sample) by 0.01-0.04 %, at
#: 0.6-0.85 times the CPU time (``benchmarks/friction_columns_accuracy.py``).
SENSITIVITY_TOL = 1e-11
#: Relative cut-off of small singular values in ``G^+`` [-].
PINV_RCOND = 1e-10


@dataclass(frozen=True, eq=False)
class Sensitivities:
    """A hypothesis's predicted tip positions along samples and their derivatives.

    Attributes
    ----------
    tip : ndarray, shape (K, 3)
        Predicted tip positions in the data's frame [m].
    jacobian : ndarray, shape (K, 3, p)
        d tip / d parameter for the hypothesis's free parameters [m per parameter unit].
    ok : ndarray of bool, shape (K,)
        Every evaluation converged at the sample.
    evaluations : int
        Model evaluations over the K samples.
    """

    tip: np.ndarray
    jacobian: np.ndarray
    ok: np.ndarray
    evaluations: int


def sensitivities(robot, hyp, data, settings=None, *, n_jobs: int = 1) -> Sensitivities:
    """Predicted tips of hypothesis ``hyp`` at ``data``'s samples and their forward-difference
    derivatives with respect to its free parameters (backward at a parameter's upper limit).

    Parameters that act only on the measurement (registration) are differentiated on the computed
    tips without solving the model again. A contact model (clearance, friction; Sections II-III of
    Ha, Fagogenis & Dupont 2019) is solved at the outer and complementarity tolerance
    :data:`SENSITIVITY_TOL`, each column's solves started from the base solution at the same sample.

    Parameters
    ----------
    robot : Robot
        The robot file the hypotheses were fitted to.
    hyp : Hypothesis
    data : MeasuredData
        Samples with their motion history (:func:`ctrplan.design.motion_data` for a planned motion).
    settings : ModelSettings, optional
    n_jobs : int

    Returns
    -------
    Sensitivities
        Tips (K, 3) [m] and their derivatives (K, 3, p) [m per parameter unit] at the K samples.

    Raises
    ------
    ParameterError, PhysicalParameterError
        A hypothesis whose values give an impossible robot.
    """
    names, values = hyp.names, hyp.values
    store = None
    if MODEL_INFO[hyp.model].contact:
        # a contact solve stops when its curvatures move less than its tolerance; a difference
        # over a step of SENSITIVITY_STEP needs that error far below the step's effect, and each
        # column starts from the base solution at the same sample (fewer outer iterations)
        store = WarmStarts()
        s0 = settings or ModelSettings()
        settings = replace(s0, outer_tol=min(s0.outer_tol, SENSITIVITY_TOL),
                           complementarity_tol=min(s0.complementarity_tol, SENSITIVITY_TOL))
    base = predict(robot, names, values, data, hyp.model, settings, n_jobs=n_jobs, warm_starts=store)
    K = base.tip.shape[0]
    J = np.zeros((K, 3, len(hyp.free)))
    ok = base.ok.copy()
    evaluations = 1
    for j, name in enumerate(hyp.free):
        i = names.index(name)
        spec = parameter(robot, name)
        h = SENSITIVITY_STEP * spec.scale
        if not spec.within_limit(values[i] + h):
            h = -h              # a value at its upper limit: a backward difference
        v = values.copy()
        v[i] += h
        if needs_solve(robot, name):
            p = predict(robot, names, v, data, hyp.model, settings, n_jobs=n_jobs, warm_starts=store)
            tip, ok = p.tip, ok & p.ok
            evaluations += 1
        else:
            robot_v = apply_parameters(robot, names, v)
            effects, _ = EffectSet.from_parameters(robot, names, v)
            tip, _ = apply_output_effects(base.tip_base, base.tangent_base, robot_effects(robot_v).merged(effects))
        J[:, :, j] = (np.asarray(tip) - base.tip) / h
    # a sample whose tip or derivative is not finite counts as not converged
    ok &= np.all(np.isfinite(base.tip), axis=1) & np.all(np.isfinite(J), axis=(1, 2))
    tip = np.where(ok[:, None], base.tip, np.nan)
    J[~ok] = np.nan
    return Sensitivities(tip=tip, jacobian=J, ok=ok, evaluations=evaluations)


@dataclass(frozen=True, eq=False)
class Information:
    """Sums over samples that give both criteria; additive over motions.

    Attributes
    ----------
    pairs : dict of (int, int) to tuple (c, b, G)
        For the ordered pair (a, b) of hypotheses: ``c = r^T W r`` [-], ``b = J_b^T W r`` shape
        (p_b,), ``G = J_b^T W J_b`` shape (p_b, p_b), with ``r = y_a - y_b``.
    fisher : tuple of ndarray
        Per hypothesis, ``J^T W J``, shape (p, p) [1 / parameter units^2].
    n_samples : int
        Samples summed (those where every hypothesis converged).
    """

    pairs: dict
    fisher: tuple
    n_samples: int

    def __add__(self, other: "Information") -> "Information":
        pairs = {k: tuple(x + y for x, y in zip(v, other.pairs[k])) for k, v in self.pairs.items()}
        return Information(pairs, tuple(a + b for a, b in zip(self.fisher, other.fisher)),
                           self.n_samples + other.n_samples)

    def scaled(self, factor: float) -> "Information":
        """Every sum times ``factor`` (e.g. a recording repeated, or a subsample standing for all)."""
        return Information({k: tuple(factor * x for x in v) for k, v in self.pairs.items()},
                           tuple(factor * f for f in self.fisher), int(round(factor * self.n_samples)))

    def separation(self) -> dict:
        """``T`` per ordered pair ``(a, b)``: the evidence for hypothesis a against b refitted [-]."""
        out = {}
        for k, (c, b, G) in self.pairs.items():
            t = float(c - b @ np.linalg.pinv(G, rcond=PINV_RCOND, hermitian=True) @ b) if b.size else float(c)
            out[k] = max(t, 0.0)
        return out

    def covariance(self, h: int, prior: np.ndarray) -> np.ndarray:
        """Predicted covariance of hypothesis ``h``'s free parameters, ``(J^T W J + diag(prior))^-1``
        [parameter units^2]."""
        return np.linalg.inv(self.fisher[h] + np.diag(prior))


def information(sens, weight: float) -> Information:
    """:class:`Information` of samples from the hypotheses' :class:`Sensitivities` (same samples).

    Parameters
    ----------
    sens : sequence of Sensitivities
        One per hypothesis.
    weight : float
        ``W``: inverse noise variance per coordinate [1/m^2].

    Returns
    -------
    Information
        Over the samples where every hypothesis converged.
    """
    ok = np.logical_and.reduce([s.ok for s in sens])
    pairs = {}
    for a, sa in enumerate(sens):
        for b, sb in enumerate(sens):
            if a == b:
                continue
            r = (sa.tip[ok] - sb.tip[ok]).reshape(-1)
            J = sb.jacobian[ok].reshape(-1, sb.jacobian.shape[2])
            pairs[(a, b)] = (weight * float(r @ r), weight * (J.T @ r), weight * (J.T @ J))
    fisher = []
    for s in sens:
        J = s.jacobian[ok].reshape(-1, s.jacobian.shape[2])
        fisher.append(weight * (J.T @ J))
    return Information(pairs, tuple(fisher), int(ok.sum()))


def long_run_factor(lag1: float | None = None, correlated_share: float = 1.0) -> float:
    """The long-run variance factor ``1 + 2 c phi / (1 - phi)`` of noise whose correlated part
    (share ``c`` of the variance) has lag-one correlation ``phi`` and whose rest is white: the
    factor by which the variance of a mean of many consecutive samples exceeds that of white
    noise (the discrepancy workflow's
    :meth:`~ctrplan.discrepancy.measured.noise.NoiseEstimate.long_run_factor`).

    Parameters
    ----------
    lag1 : float, optional
        ``phi``, the correlated part's lag-one correlation [-], clipped to [0, 0.99]; None, NaN
        or negative: white (factor 1).
    correlated_share : float
        ``c`` in [0, 1] [-] (1: all AR(1), factor ``(1 + phi) / (1 - phi)``).

    Returns
    -------
    float
        [-], >= 1.

    Raises
    ------
    ValueError
        ``correlated_share`` outside [0, 1].
    """
    if not 0.0 <= correlated_share <= 1.0:
        raise ValueError(f"correlated share must be in [0, 1], got {correlated_share!r}")
    phi = 0.0 if lag1 is None or not np.isfinite(lag1) else float(np.clip(lag1, 0.0, 0.99))
    return 1.0 + 2.0 * correlated_share * phi / (1.0 - phi)


def noise_weight(position_rms: float, lag1: float | None = None, *,
                 correlated_share: float = 1.0) -> tuple[float, float]:
    """``W`` and the long-run variance factor ``f`` it includes (:func:`long_run_factor`).

    Parameters
    ----------
    position_rms : float
        Sensor noise per tip coordinate [m], > 0.
    lag1 : float, optional
        Lag-one correlation of the correlated part of the noise in [0, 1); None or negative:
        white.
    correlated_share : float, keyword-only
        Share of the variance in the correlated part, [0, 1] (1: all AR(1)).

    Returns
    -------
    weight : float
        [1/m^2]
    inflation : float
        [-], >= 1.

    Raises
    ------
    ValueError
        ``position_rms`` not > 0, or ``correlated_share`` outside [0, 1].
    """
    if not (position_rms > 0 and np.isfinite(position_rms)):
        raise ValueError(f"position noise must be > 0 m, got {position_rms!r}")
    inflation = long_run_factor(lag1, correlated_share)
    return 1.0 / (position_rms ** 2 * inflation), inflation


def prior_precision(robot, names) -> np.ndarray:
    """Weak prior precision per parameter: one over the square of half its typical range (else of its
    scale) [1 / parameter units^2], shape (len(names),)."""
    out = []
    for n in names:
        spec = parameter(robot, n)
        half = 0.5 * abs(spec.typical[1] - spec.typical[0]) if spec.typical is not None else spec.scale
        out.append(1.0 / max(half, 1e-12) ** 2)
    return np.array(out)


def ds_criterion(info: Information, h: int, interest, prior: np.ndarray) -> float:
    """``log det`` of the predicted covariance of the parameters of interest (lower is better) [-].

    Parameters
    ----------
    info : Information
    h : int
        The hypothesis.
    interest : array-like of int
        Indices of its free parameters of interest.
    prior : ndarray, shape (p,)
        :func:`prior_precision` of its free parameters.
    """
    cov = info.covariance(h, prior)
    idx = np.asarray(interest, int)
    sign, logdet = np.linalg.slogdet(cov[np.ix_(idx, idx)])
    return float(logdet) if sign > 0 else float("inf")
