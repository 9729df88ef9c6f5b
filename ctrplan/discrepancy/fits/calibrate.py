"""Model calibration on measured tip poses (Section V-C of Ha, Fagogenis & Dupont 2019).

- a model's tip poses along the data's motion history and their errors:
  :mod:`ctrplan.discrepancy.fits.predictions`;
- :func:`calibrate`: least squares on the weighted sum of Eq. (49), ``|dp| / 1 mm + angle / 1 deg``
  per sample (1 deg of tangent error weighs as 1 mm of position error), over the chosen
  parameters (:mod:`ctrplan.discrepancy.fits.parameters`), including the rigid registration of a
  tracker frame, started from a closed-form (Kabsch) registration. Two stages: the components
  of the pose error first (a smooth least-squares problem), then Eq. (49) itself from there with
  a Gauss-Newton model that keeps the curvature of its norms, stopped when the decrease still
  predicted is negligible in BIC units (see :func:`calibrate` for why);
- the grid search of the friction coefficients: :mod:`ctrplan.discrepancy.fits.gridsearch`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ...errors import CtrplanError
from ...models import check_model
from ..measured.data import MeasuredData
from .estimates import Uncertainty, covariance
from .fitoptions import FitRun, FitStart
from .objective import ComponentJacobians, FitObjective
from .parameters import REGISTRATION, needs_solve, parameter, read_parameters
from .predictions import FAILED_RESIDUAL, kabsch_registration

__all__ = ["CalibrationResult", "Prior", "calibrate", "information_criterion", "covariance"]

#: Stopping tolerances of both least-squares stages (``scipy.optimize.least_squares``): relative
#: change of the cost (``ftol``; 1e-6 of a cost of ~1000 (mm + deg)^2 changes the BIC by ~1e-4 per
#: 100 samples) and of the parameter vector (``xtol``).
FTOL = 1e-6
XTOL = 1e-6
#: Stage 2 has converged when the decrease of the Eq. (49) cost still predicted by its
#: Gauss-Newton model (:class:`_Eq49Model`, the curvature of the norms included) would lower the
#: Bayesian information criterion ``N ln(RSS / N)`` of the fit by less than this. The workflow
#: compares fits by BIC differences of order 1 or more (a difference below 2 is "not worth more
#: than a bare mention", Kass & Raftery 1995, J. Am. Stat. Assoc. 90:773): 0.1 would already be
#: negligible; 0.01 leaves a tenfold margin for the model's estimate of the decrease (on Ha's
#: trajectory it predicted 1.1-1.4 times the decrease that followed) at a cost of about two steps.
BIC_TOLERANCE = 0.01
#: Smallest position error [mm] and tangent cross product [deg] whose norm's curvature (1 / size)
#: enters the Gauss-Newton model (a residual at the kink of the norm is not divided by zero).
NORM_FLOOR = 1e-3
#: Smallest cosine of the tangent error in the model's ``d angle / d sin(angle)`` (errors near
#: 90 deg are failures of the fit, not its working range).
COS_FLOOR = 0.1
#: Jacobians of the error components between exact ones (:class:`ComponentJacobians`): at most this many
#: rank-one (Broyden) updates of the mechanical columns follow a forward-difference Jacobian. An
#: update costs no model evaluation where a forward difference costs one per mechanical
#: parameter; a step its model predicted poorly, a change of the failed samples, and every
#: Jacobian a stopping decision or a standard error is read from get an exact one.
MAX_JACOBIAN_UPDATES = 5
#: A Jacobian is recomputed by forward differences when the step just taken achieved less than
#: this fraction of the decrease its Gauss-Newton model predicted (the trust region's own
#: threshold of a poor step, Nocedal & Wright 2006, Algorithm 4.1).
POOR_STEP_RATIO = 0.25
#: A fit that ends at an optimizer bound has the bound widened (``ParameterSpec.widened``, up to
#: the parameter's limit) and is continued, at most this many times.
MAX_WIDENINGS = 6


@dataclass
class CalibrationResult:
    """Outcome of a calibration.

    Attributes
    ----------
    model : str
        ``"standard"``, ``"clearance"`` or ``"friction"``.
    names : tuple of str
        Fitted parameters.
    values, initial : ndarray, shape (m,)
        Fitted and initial values, in the parameters' units.
    fixed : dict
        Other parameters held at given values (e.g. the baseline's while fitting friction).
    cost : float
        Sum of squared Eq. (49) residuals [(mm + deg)^2] at ``values``.
    n_samples : int
        Samples used (failed ones included with :data:`FAILED_RESIDUAL`).
    n_failed : int
    evaluations : int
        Model evaluations over the calibration set.
    seconds : float
    message : str
    converged : bool
        The optimizer met its stopping rule (:data:`BIC_TOLERANCE`) or tolerance, and no fitted
        value sits at an optimizer bound or at the edge of a grid or scan (False: it stopped at its
        evaluation budget, or at a bound or edge: ``at_bound``).
    stderr : ndarray, shape (m,), or None
        Standard errors of the fitted values, in their units, from the Gauss-Newton matrix of
        Eq. (49) (the norms' curvature included) at the solution (:func:`covariance`): clustered
        over ``n_clusters`` clusters of units, else ``s^2 (J^T J)^-1`` with ``s^2 = cost /
        (n_samples - m)``; inf where the data do not determine the parameter; NaN where undefined
        (fewer than two clusters); None when not computed.
    correlation : ndarray, shape (m, m), or None
        Their correlation matrix.
    at_bound : tuple of str
        ``"<name> (<where>)"`` for every fitted value at an optimizer bound (``upper``, or ``lower``
        where the effect does not vanish there) or at the edge of its grid or scan that could not
        be widened further (it is at the parameter's limit), or at a bound that was widened when no
        refit was left (the last widening allowed, or the evaluation budget spent).
    widened : tuple of str
        Bounds, grids or scans widened because the fit ended at them (``"<name> upper to 1.2"``).
    prior_cost : float
        The prior's part of the minimized objective (0 without a prior) [(mm + deg)^2]; ``cost``
        is the data's part alone.
    n_clusters : int or None
        G, the clusters ``stderr`` is clustered over (neighbouring units merged); None without
        clustering. ``dof`` (``G - 1``) sets an interval's t quantile
        (:func:`~ctrplan.discrepancy.fits.estimates.interval_quantile`).
    """

    model: str
    names: tuple
    values: np.ndarray
    initial: np.ndarray
    fixed: dict = field(default_factory=dict)
    cost: float = np.nan
    n_samples: int = 0
    n_failed: int = 0
    evaluations: int = 0
    seconds: float = 0.0
    message: str = ""
    converged: bool = True
    stderr: np.ndarray | None = None
    correlation: np.ndarray | None = None
    at_bound: tuple = ()
    widened: tuple = ()
    prior_cost: float = 0.0
    n_clusters: int | None = None

    @property
    def dof(self) -> int | None:
        """Degrees of freedom of the standard errors' t quantile, ``G - 1``; None without clustering."""
        return None if self.n_clusters is None else self.n_clusters - 1

    def all_parameters(self) -> tuple[tuple, np.ndarray]:
        """Fixed and fitted parameters together: ``(names, values)``."""
        return tuple(self.fixed) + tuple(self.names), np.concatenate([np.asarray(list(self.fixed.values()), float),
                                                                      self.values])

    def as_dict(self) -> dict:
        return {"model": self.model, "parameters": dict(zip(self.names, map(float, self.values))),
                "initial": dict(zip(self.names, map(float, self.initial))),
                "fixed": {k: float(v) for k, v in self.fixed.items()}, "cost": float(self.cost),
                "n_samples": int(self.n_samples), "n_failed": int(self.n_failed),
                "evaluations": int(self.evaluations), "seconds": float(self.seconds),
                "message": self.message, "converged": bool(self.converged),
                "stderr": None if self.stderr is None else dict(zip(self.names, map(float, self.stderr))),
                "correlation": None if self.correlation is None else np.asarray(self.correlation, float).tolist(),
                "at_bound": list(self.at_bound), "widened": list(self.widened), "prior_cost": float(self.prior_cost),
                "n_clusters": self.n_clusters, "dof": self.dof}

    @classmethod
    def from_dict(cls, d: dict) -> "CalibrationResult":
        """Inverse of :meth:`as_dict`."""
        names = tuple(d["parameters"])
        stderr = d.get("stderr")
        return cls(d["model"], names, np.array(list(d["parameters"].values()), float),
                   np.array(list(d["initial"].values()), float), dict(d["fixed"]), d["cost"], d["n_samples"],
                   d["n_failed"], d["evaluations"], d["seconds"], d["message"], d.get("converged", True),
                   None if stderr is None else np.array([stderr[n] for n in names], float),
                   None if d.get("correlation") is None else np.array(d["correlation"], float),
                   tuple(d.get("at_bound", ())), tuple(d.get("widened", ())), float(d.get("prior_cost", 0.0)),
                   d.get("n_clusters"))


def information_criterion(cost: float, n_samples: int, n_params: int) -> float:
    """Bayesian information criterion of a least-squares fit with Gaussian residuals,
    ``N ln(RSS / N) + k ln N`` (Schwarz 1978).

    Parameters
    ----------
    cost : float
        Residual sum of squares RSS [(mm + deg)^2 for Eq. (49) residuals].
    n_samples : int
        N, residuals in the fit.
    n_params : int
        k, fitted parameters.

    Returns
    -------
    float
        Lower is better; only differences between fits of the same data mean anything.
    """
    return float(n_samples * np.log(max(cost, 1e-300) / n_samples) + n_params * np.log(n_samples))


def bound_flags(specs, values) -> tuple:
    """``"<name> (upper bound ...)"`` / ``"(lower bound ...)"`` for values at an optimizer bound,
    saying whether that is the parameter's limit (``ParameterSpec.widened`` is None); a value at a
    lower bound where the effect vanishes (e.g. no dead band on that drive) is not flagged."""
    out = []
    for p, v in zip(specs, values):
        where = p.at_bound(float(v))
        if where == "upper" or (where == "lower" and not p.vanishes_at_lower):
            limit = ", its limit" if p.widened(where) is None else ""
            out.append(f"{p.name} ({where} bound {p.upper if where == 'upper' else p.lower:g} {p.unit}{limit})")
    return tuple(out)


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on fitted parameters as least-squares rows ``(x_j - center_j) / scale_j``.

    Attributes
    ----------
    index : ndarray of int, shape (P,)
        Positions of the parameters in the fitted vector.
    center : ndarray, shape (P,)
        Prior means (e.g. the robot file's values), in the parameters' units.
    scale : ndarray, shape (P,)
        A deviation of ``scale`` costs as much as one squared Eq. (49) residual of 1 (mm + deg);
        in the parameters' units, > 0.
    """

    index: np.ndarray
    center: np.ndarray
    scale: np.ndarray

    @classmethod
    def of(cls, names, prior: dict | None) -> "Prior | None":
        """The rows for the parameters ``names`` that ``prior`` (``{name: (center, scale)}``) covers;
        None when it covers none."""
        idx = [j for j, n in enumerate(names) if n in prior and np.isfinite(prior[n][1])] if prior else []
        if not idx:
            return None
        return cls(np.array(idx), np.array([prior[names[j]][0] for j in idx], float),
                   np.array([prior[names[j]][1] for j in idx], float))

    def rows(self, x) -> np.ndarray:
        """Residual rows, shape (P,)."""
        return (np.asarray(x, float)[self.index] - self.center) / self.scale

    def jacobian(self, m: int) -> np.ndarray:
        """Their Jacobian, shape (P, m)."""
        J = np.zeros((self.index.size, m))
        J[np.arange(self.index.size), self.index] = 1.0 / self.scale
        return J


def _poor_step(f_old, rows_old, x_old, f_new, x_new) -> bool:
    """The step ``x_old -> x_new`` achieved less than :data:`POOR_STEP_RATIO` of the decrease of
    ``|f|^2`` that the linear model ``f_old + rows_old dx`` predicted (or the model predicted none)."""
    dx = np.asarray(x_new, float) - np.asarray(x_old, float)
    before = float(f_old @ f_old)
    predicted = before - float(np.sum((f_old + rows_old @ dx) ** 2))
    actual = before - float(f_new @ f_new)
    return not (predicted > 0.0 and actual >= POOR_STEP_RATIO * predicted)


class _Eq49Model:
    """Eq. (49) as a least-squares problem whose Gauss-Newton model keeps the curvature of its norms.

    Per sample the residual ``h = |dp| + angle`` [mm + deg] of Eq. (49) is a function of the
    error components ``c = (dp, t)`` (:meth:`FitObjective.pose_components`). Its plain
    Gauss-Newton model ``(h + grad h . J_c s)^2`` drops ``h`` times the curvature of the norms,
    which for ``h^2`` is as large as the part it keeps: ``Hess(h^2) / 2 = grad h grad h^T + h
    Hess h``, with ``Hess |dp| = (I - u u^T) / |dp|`` (u the direction of dp) and likewise for
    the angle. The rows returned here carry both parts (a generalized Gauss-Newton model, the
    curvature of the components themselves neglected as in stage 1):

    - row 0: value ``h``, Jacobian ``u^T J_dp + v^T J_t / cos(angle)``;
    - rows 1-3: value 0, Jacobian ``sqrt(h / |dp|) (I - u u^T) J_dp``;
    - rows 4-6 (with tangents): value 0, Jacobian ``sqrt(h / (|t| cos(angle))) (I - v v^T) J_t``.

    Their sum of squares is the Eq. (49) cost, their ``J^T f`` its half gradient and their
    ``J^T J`` half the Hessian of the cost up to the components' own curvature. ``J_c`` is exact
    (derivatives where the model has them, else forward differences:
    :meth:`ComponentJacobians.exact`), or with ``scale`` given a rank-one update of the last one
    after a step its model predicted well (:class:`ComponentJacobians`); a Jacobian whose model
    says the fit may stop (:meth:`bic_left` below :data:`BIC_TOLERANCE`) is always exact, so the
    stopping rule is read from an exact one. A failed
    sample has value :data:`FAILED_RESIDUAL` and zero rows. A :class:`Prior` appends its rows
    after the samples'.
    """

    def __init__(self, obj: FitObjective, lower, upper, prior: "Prior | None" = None, scale=None):
        self.obj, self.lower, self.upper = obj, np.asarray(lower, float), np.asarray(upper, float)
        self.width = 4 if obj.data.tangent is None else 7
        self.prior = prior
        self.jacobians = ComponentJacobians(obj, lower, upper, np.ones(self.lower.size) if scale is None else scale,
                                            0 if scale is None else MAX_JACOBIAN_UPDATES)
        self.n_samples = obj.data.n_samples
        self._last = None   # (f, rows, x) of the last Jacobian
        #: Decrease of the cost to the minimum of the model at the last Jacobian [(mm + deg)^2],
        #: and the cost there.
        self.remaining, self.cost = np.inf, np.nan

    def bic_left(self, n_samples: int) -> float:
        """BIC change ``N ln(cost / (cost - remaining))`` the model still predicts at the last
        Jacobian (0 at a zero cost, inf before the first Jacobian)."""
        if not np.isfinite(self.remaining):
            return np.inf
        if self.cost <= 0.0:
            return 0.0
        return float(n_samples * np.log(self.cost / max(self.cost - self.remaining, 1e-300 * self.cost)))

    def fun(self, x):
        h = self.obj.residuals(x)
        rows = np.zeros((h.size, self.width))
        rows[:, 0] = h
        return rows.ravel() if self.prior is None else np.concatenate([rows.ravel(), self.prior.rows(x)])

    def jac(self, x):
        x = np.asarray(x, float)
        jacobians = self.jacobians
        f_new = self.fun(x) if jacobians.max_updates and self._last is not None else None
        if f_new is not None and not _poor_step(*self._last, f_new, x) and not self._small_step(self._last[0], f_new):
            rows = self._rows(x, *jacobians.updated(x))
            if jacobians.is_exact or self.bic_left(self.n_samples) >= BIC_TOLERANCE:
                self._last = (self._f, rows, x.copy())
                return rows
        rows = self._rows(x, *jacobians.exact(x))
        self._last = (self._f, rows, x.copy())
        return rows

    def _small_step(self, f_old, f_new) -> bool:
        """The step lowered the BIC by less than :data:`BIC_TOLERANCE`: the fit is at the scale
        of its stopping rule, where the next Jacobian is to be exact."""
        before, after = float(f_old @ f_old), float(f_new @ f_new)
        return not (after > 0.0 and self.n_samples * np.log(before / after) >= BIC_TOLERANCE)

    def exact_rows(self, x):
        """The rows at ``x`` from an exact Jacobian (:meth:`jac` without updates)."""
        x = np.asarray(x, float)
        rows = self._rows(x, *self.jacobians.exact(x))
        self._last = (self._f, rows, x.copy())
        return rows

    def _rows(self, x, c0, cos0, ok0, jc):
        """Rows of the generalized Gauss-Newton model at ``x`` from the components ``c0``, their
        cosines, ok flags and Jacobian ``jc``; sets :attr:`remaining`, :attr:`cost`."""
        k, m = c0.shape[0], x.size
        h = self.obj.residuals(x)
        dp, jdp = c0[:, :3], jc[:, :3]
        size_p = np.maximum(np.linalg.norm(dp, axis=1), NORM_FLOOR)
        u = dp / size_p[:, None]
        radial_p = np.einsum("ki,kij->kj", u, jdp)
        blocks = [radial_p[:, None, :],
                  np.sqrt(h / size_p)[:, None, None] * (jdp - u[:, :, None] * radial_p[:, None, :])]
        if self.width == 7:
            t, jt = c0[:, 3:], jc[:, 3:]
            size_t = np.maximum(np.linalg.norm(t, axis=1), NORM_FLOOR)
            v = t / size_t[:, None]
            inv_cos = 1.0 / np.maximum(cos0, COS_FLOOR)
            radial_t = np.einsum("ki,kij->kj", v, jt)
            blocks[0] = (radial_p + inv_cos[:, None] * radial_t)[:, None, :]
            blocks.append(np.sqrt(h * inv_cos / size_t)[:, None, None]
                          * (jt - v[:, :, None] * radial_t[:, None, :]))
        rows = np.concatenate(blocks, axis=1)
        rows[~ok0] = 0.0
        rows = rows.reshape(k * self.width, m)
        f = np.zeros((k, self.width))
        f[:, 0] = h
        f = f.ravel()
        if self.prior is not None:
            rows = np.concatenate([rows, self.prior.jacobian(m)])
            f = np.concatenate([f, self.prior.rows(x)])
        # the model's minimum (no bounds: an active bound only makes this larger, i.e. safer)
        col = np.linalg.norm(rows, axis=0)
        col[col == 0] = 1.0
        s, *_ = np.linalg.lstsq(rows / col, -f, rcond=None)
        self.cost = float(f @ f)
        self.remaining = self.cost - float(np.sum((f + (rows / col) @ s) ** 2))
        self._f = f
        return rows


def calibrate(robot, data: MeasuredData, model: str, names, *, fixed: dict | None = None, prior: dict | None = None,
              start: FitStart = FitStart(), max_evaluations: int = 40, run: FitRun = FitRun()) -> CalibrationResult:
    """Fit parameters by least squares on the Eq. (49) residuals (Section V-C, Eq. (49) of
    Ha, Fagogenis & Dupont 2019).

    Parameters
    ----------
    robot : Robot
        Starting point of every mechanical parameter not in ``fixed``.
    data : MeasuredData
        The calibration samples.
    model : {"standard", "clearance", "friction"}
    names : sequence of str
        Parameters to fit.
    fixed : dict, optional
        ``{name: value}`` held fixed (applied before the fitted ones).
    prior : dict, optional
        ``{name: (center, scale)}``: a Gaussian prior on fitted parameters (:class:`Prior`), e.g.
        toward the robot file's tube parameters; names not fitted are ignored.
    start : FitStart
        Starting values, a closed-form registration, a warm start.
    max_evaluations : int
        Budget of model evaluations over the calibration set (Jacobian columns included), shared
        by the two stages: a safety net, not the usual stop (stage 1 gets at most half).
    run : FitRun
        Solver settings, worker processes, whether to compute standard errors and over which
        clusters.

    Returns
    -------
    CalibrationResult
        ``converged`` is True when the second stage stopped by the rule of
        :data:`BIC_TOLERANCE` or met :data:`FTOL`, :data:`XTOL` (or the gradient tolerance)
        before the budget and no value ended at a bound it could not widen; False otherwise.
        A value that ends at an optimizer bound has the bound widened (``ParameterSpec.widened``,
        up to the parameter's limit, at most :data:`MAX_WIDENINGS` times) and stage 2 continues
        (``widened``); a bound widened when no refit is left (the last widening allowed, or the
        budget spent) leaves the value on the old bound, which is reported in ``at_bound``. The
        message gives both stages' steps and, for stage 2, the further decrease its model still
        predicts.

    Notes
    -----
    The Eq. (49) residual of a sample is a sum of two vector norms, ``h = |dp| + angle``.
    Plain Gauss-Newton steps (the trust-region reflective method of
    ``scipy.optimize.least_squares`` on ``h``) ignore the curvature of a residual, and for a
    norm the ignored part ``h Hess h`` is as large as the kept one: the model sees only the
    error's change along ``dp``, not across it, over-predicts every step's decrease, and the
    trust region collapses. On Ha's measured trajectory (300 samples, baseline of 11
    parameters) stage 2 then fell by about 0.1 (mm + deg)^2 a step out of 25 800 (a BIC change of
    0.001 a step) and stopped at its budget after 53 steps; on a synthetic lagged trajectory it
    even met ``ftol`` with tiny steps 0.34 BIC units above the minimum. Stage 1 fits the
    components of the errors (:meth:`FitObjective.component_residuals`, smooth: a handful of
    steps); stage 2 minimises Eq. (49) from there with the generalized Gauss-Newton rows of
    :class:`_Eq49Model`, whose model includes the norms' curvature (on Ha's trajectory: 3-4
    accepted steps, the predicted decrease falling about 3.5-fold a step, and a lower minimum
    than 87 plain steps reached). It stops when the decrease that model still predicts would
    change the BIC by less than :data:`BIC_TOLERANCE`.

    Raises
    ------
    CtrplanError
        Fewer samples than fitted parameters, or every sample failing at the start.
    ValueError
        An unknown model.
    """
    t0 = time.perf_counter()
    check_model(model)
    initial, register, warm = start.values, start.register, start.warm
    settings, n_jobs, uncertainty, clusters = run.settings, run.n_jobs, run.uncertainty, run.clusters
    names = tuple(names)
    fixed = dict(fixed or {})
    k = data.n_samples
    if k <= len(names):
        raise CtrplanError(f"{data.file}: {k} calibration samples for {len(names)} parameters "
                           f"({', '.join(names)}); a calibration needs more samples than parameters")
    # fitted registration parameters start at zero (then Kabsch when ``register``)
    x0 = read_parameters(robot, names) if initial is None else np.asarray(initial, float).copy()
    obj = FitObjective(robot, data, model, names, fixed, settings, n_jobs)
    if register and initial is None and any(nm in REGISTRATION for nm in names):
        pred = obj.prediction(x0)
        if not pred.ok.any():
            raise CtrplanError(f"{data.file}: the {model} model failed at every calibration sample "
                               f"(first message: {pred.message[0]})")
        rv, tr = kabsch_registration(pred.tip_base, data.tip)
        for j, nm in enumerate(names):
            if nm in REGISTRATION:
                x0[j] = np.concatenate([rv, tr])[REGISTRATION.index(nm)]
    specs = [parameter(robot, nm) for nm in names]
    lower = np.array([p.lower for p in specs])
    upper = np.array([p.upper for p in specs])
    x0 = np.clip(x0, lower + 1e-12 * (upper - lower), upper - 1e-12 * (upper - lower))
    r0 = obj.residuals(x0)
    if not len(names):
        return CalibrationResult(model, names, x0, x0.copy(), fixed, float(r0 @ r0), k,
                                 int((r0 == FAILED_RESIDUAL).sum()), obj.evaluations,
                                 time.perf_counter() - t0, "nothing to fit: evaluated only")
    pr = Prior.of(names, prior)
    scale = np.array([p.scale for p in specs])
    # registration columns of the finite-difference Jacobian re-use the cached mechanics
    n_mech = sum(1 for nm in names if needs_solve(robot, nm))
    per_step = n_mech + 1

    def objective(x):
        r = obj.residuals(x)
        return float(r @ r) + (0.0 if pr is None else float(np.sum(pr.rows(x) ** 2)))

    # stage 1: error components (smooth), at most half the budget; skipped from a warm start
    if warm and initial is not None:
        x1, stage1 = x0, "skipped (warm start)"
    else:
        comp = obj.component_residuals if pr is None else (
            lambda x: np.concatenate([obj.component_residuals(x), pr.rows(x)]))
        first_jacobians = ComponentJacobians(obj, lower, upper, scale, MAX_JACOBIAN_UPDATES)
        last = []

        def comp_jac(x):
            """Jacobian of the components (with the prior's rows): a rank-one update after a step
            its model predicted well, else forward differences (:class:`ComponentJacobians`)."""
            x = np.asarray(x, float)
            f = comp(x)
            poor = not last or _poor_step(*last[-1], f, x)
            jc = (first_jacobians.exact(x) if poor else first_jacobians.updated(x))[3]
            rows = jc.reshape(-1, x.size)
            if pr is not None:
                rows = np.concatenate([rows, pr.jacobian(x.size)])
            last[:] = [(f, rows, x.copy())]
            return rows

        half = max(2 * per_step, max_evaluations // 2)

        def spent(intermediate_result):
            """Stop (``StopIteration``: status -2) when stage 1 has used half the budget."""
            if obj.evaluations >= half:
                raise StopIteration

        first = least_squares(comp, x0, jac=comp_jac, max_nfev=half, callback=spent,
                              bounds=(lower, upper), x_scale=scale, method="trf", xtol=XTOL, ftol=FTOL)
        x1 = first.x if np.isfinite(first.cost) else x0
        stage1 = (f"{first.nfev} steps ({'converged' if first.status > 0 else 'budget'}; "
                  f"{first_jacobians.note()})")
        if not objective(x1) <= objective(x0):
            x1 = x0   # the component fit's optimum is worse for Eq. (49): start stage 2 where we began
    # stage 2: Eq. (49) itself, with the rest of the budget, its Gauss-Newton model keeping the
    # curvature of the norms; stopped when the decrease the model still predicts is negligible.
    # A value that ends at an optimizer bound has the bound widened and stage 2 goes on from there.
    widened, steps, passes = [], 0, []
    for _ in range(MAX_WIDENINGS + 1):
        eq49 = _Eq49Model(obj, lower, upper, pr, scale=scale)
        passes.append(eq49.jacobians)

        budget_stop = []

        def settled(intermediate_result, eq49=eq49):
            """Stop (``StopIteration``: status -2) when the predicted further decrease is negligible,
            or when the evaluation budget is spent."""
            if eq49.bic_left(k) < BIC_TOLERANCE:
                raise StopIteration
            if obj.evaluations >= max_evaluations:
                budget_stop.append(True)
                raise StopIteration

        left = max(2, max_evaluations - obj.evaluations)
        sol = least_squares(eq49.fun, np.clip(x1, lower, upper), jac=eq49.jac, max_nfev=left, callback=settled,
                            bounds=(lower, upper), x_scale=scale, method="trf", xtol=XTOL, ftol=FTOL)
        steps += sol.nfev
        x1 = sol.x
        grown = []   # "<name> (...)" of the values whose bound was widened on this pass
        for j, nm in enumerate(names):
            side = specs[j].at_bound(float(sol.x[j]))
            if side == "upper" or (side == "lower" and not specs[j].vanishes_at_lower):
                wider = specs[j].widened(side)
                if wider is not None:
                    old, new = (specs[j].upper, wider.upper) if side == "upper" else (specs[j].lower, wider.lower)
                    specs[j] = wider
                    lower[j], upper[j] = wider.lower, wider.upper
                    widened.append(f"{nm} {side} bound to {new:.4g} {wider.unit}")
                    grown.append(f"{nm} ({side} bound {old:g} {wider.unit}, widened to {new:.4g} {wider.unit} but "
                                 f"not refitted")
        if not grown or obj.evaluations >= max_evaluations:
            break
    # a bound widened on the last pass was not fitted beyond: the value still sits on the old bound
    why = ("the evaluation budget is spent" if obj.evaluations >= max_evaluations
           else f"{MAX_WIDENINGS} widenings, the most allowed")
    unrefitted = tuple(f"{g}: {why})" for g in grown)
    if uncertainty and not (eq49.jacobians.is_exact and np.array_equal(eq49.jacobians.x, sol.x)):
        # stopped on an updated Jacobian (by a tolerance or the budget): the standard errors and
        # the decrease still predicted are read from an exact one
        sol.jac = eq49.exact_rows(sol.x)
    r = obj.residuals(sol.x)
    converged = bool(sol.status > 0 or (sol.status == -2 and not budget_stop))
    left_bic = eq49.bic_left(k)
    how = (f"the predicted further decrease {eq49.remaining:.3g} (mm + deg)^2 changes the BIC by "
           f"{left_bic:.2g} < {BIC_TOLERANCE:g}" if sol.status == -2 and not budget_stop
           else "the evaluation budget is spent" if budget_stop else sol.message)
    at_bound = bound_flags(specs, sol.x) + unrefitted
    msg = (f"least squares: error components {stage1}, "
           f"then Eq. (49): {how} ({steps} steps, {sum(j.n_exact for j in passes)} Jacobians "
           f"({sum(j.n_derivative_columns for j in passes)} mechanical columns from exact derivatives, "
           f"{sum(j.n_difference_columns for j in passes)} by forward differences), "
           f"{sum(j.n_updated for j in passes)} rank-one updates; {obj.evaluations} evaluations)"
           + ("" if not widened else f"; widened: {', '.join(widened)}")
           + ("" if converged else f"; NOT converged: stopped at the budget of {max_evaluations} evaluations "
                                   f"(predicted further decrease {eq49.remaining:.3g} (mm + deg)^2, "
                                   f"BIC {left_bic:.2g})")
           + (f"; at a bound, not converged: {', '.join(at_bound)}" if at_bound else ""))
    unc = (covariance(sol.jac, sol.fun, k, clusters=clusters, width=eq49.width, motion=data.sequence,
                      position=data.rows) if uncertainty else Uncertainty(None, None))
    if unc.note:
        msg += f"; standard errors over {unc.n_clusters} clusters: {unc.note}"
    prior_cost = 0.0 if pr is None else float(np.sum(pr.rows(sol.x) ** 2))
    return CalibrationResult(model, names, sol.x, x0, fixed, float(r @ r), k, int((r == FAILED_RESIDUAL).sum()),
                             obj.evaluations, time.perf_counter() - t0, msg, converged and not at_bound, unc.stderr,
                             unc.correlation, at_bound, tuple(widened), prior_cost, unc.n_clusters)


def _uncertainty(obj: FitObjective, specs, x, clusters=None) -> Uncertainty:
    """Standard errors and correlations (:func:`covariance`, unpacking as ``stderr, correlation``;
    ``n_clusters`` for the fit's result) at ``x`` from one Jacobian of Eq. (49), neighbouring units
    of one motion merged."""
    model = _Eq49Model(obj, [p.hard[0] for p in specs], [p.hard[1] for p in specs])
    rows = model.jac(x)
    return covariance(rows, model.fun(x), obj.data.n_samples, clusters=clusters, width=model.width,
                      motion=obj.data.sequence, position=obj.data.rows)
