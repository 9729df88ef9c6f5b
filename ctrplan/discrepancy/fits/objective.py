"""The Eq. (49) objective of a calibration and the Jacobians of its error components
(Section V-C of Ha, Fagogenis & Dupont 2019; :func:`~ctrplan.discrepancy.fits.calibrate.calibrate`).

- :class:`FitObjective`: a model's tip poses and their errors as functions of the fitted
  parameters, the mechanics cached on the mechanical ones, and the exact Jacobian columns of a
  standard-model fit (:meth:`FitObjective.standard_columns`);
- :class:`ComponentJacobians`: the Jacobians of the error components, exact (derivatives and
  forward differences) or moved by rank-one updates.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...effects import EffectSet, apply_output_effects, effect_of_parameter, robot_effects
from ...errors import CtrplanError
from ...mechanics import ModelSettings, standard_tip_derivatives_batch
from ...mechanics.packed import pack_robot
from ...models import MODEL_INFO, check_model
from .parameters import apply_parameters, needs_solve
from .predictions import ANGLE_UNIT, FAILED_RESIDUAL, POSITION_UNIT, SamplePredictions, eq49_residuals, pose_errors, predict

__all__ = ["FitObjective", "ComponentJacobians", "DIFF_STEP", "CHAIN_STEP"]

#: Relative finite-difference step of the least-squares Jacobian (solver tolerances are ~1e-9).
DIFF_STEP = 1e-4
#: Relative step of the central differences of the maps around the standard model's exact
#: derivatives (the robot's packing, the motion history, the output effects and the error
#: components, none of which solves the model; :meth:`_Objective.standard_columns`): their
#: truncation error is of order this squared, their rounding error of order 1e-16 over it.
CHAIN_STEP = 1e-6

class FitObjective:
    """Eq. (49) residuals as a function of the fitted parameters, with the mechanics cached on
    the mechanical parameters (a registration step re-uses the last solve).

    With a contact model, every evaluation starts each contact solve from the solution of the
    objective's previous evaluation at that sample (:class:`~ctrplan.discrepancy.fits.simulate.WarmStarts`),
    with the outer and complementarity tolerances tightened to
    :data:`~ctrplan.discrepancy.fits.simulate.WARM_OUTER_TOL` so that finite differences between
    evaluations stay accurate."""

    def __init__(self, robot, data, model, names, fixed, settings, n_jobs):
        from .simulate import WARM_OUTER_TOL, WarmStarts

        settings = settings or ModelSettings()
        self.warm_starts = None
        if MODEL_INFO[check_model(model)].contact:
            self.warm_starts = WarmStarts()
            settings = replace(settings, outer_tol=min(settings.outer_tol, WARM_OUTER_TOL),
                               complementarity_tol=min(settings.complementarity_tol, WARM_OUTER_TOL))
        self.robot, self.data, self.model, self.settings, self.n_jobs = robot, data, model, settings, n_jobs
        self.names = tuple(names)
        self.fixed = dict(fixed)
        self.all_names = tuple(self.fixed) + self.names
        # parameters that need a new model solve: mechanical and history ones (not registration)
        self.mech = [k for k, nm in enumerate(self.all_names) if needs_solve(robot, nm)]
        self._cache: dict = {}
        self.evaluations = 0

    def full(self, x):
        return np.concatenate([np.asarray(list(self.fixed.values()), float), np.asarray(x, float)])

    def mechanics(self, x) -> SamplePredictions:
        """The model's solve at ``x`` before the output effects (cached on the mechanical
        parameters): :func:`predict` with the mechanical and history parameters."""
        v = self.full(x)
        key = tuple(np.round(v[self.mech], 15))
        base = self._cache.get(key)
        if base is None:
            mech_names = [self.all_names[k] for k in self.mech]
            base = predict(self.robot, mech_names, v[self.mech], self.data, self.model, self.settings,
                           n_jobs=self.n_jobs, warm_starts=self.warm_starts)
            self.evaluations += 1
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = base
        return base

    def observed(self, base: SamplePredictions, x, tip_base=None, tangent_base=None) -> SamplePredictions:
        """``base`` (or the given base-frame tips and tangents, shape (K, 3)) as the measurement
        shows them with the output parameters of ``x`` (registration, ...)."""
        v = self.full(x)
        mech = set(self.mech)
        out_names = [nm for k, nm in enumerate(self.all_names) if k not in mech]
        effects, _ = EffectSet.from_parameters(self.robot, out_names, [v[self.all_names.index(nm)] for nm in out_names])
        tip_base = base.tip_base if tip_base is None else tip_base
        tangent_base = base.tangent_base if tangent_base is None else tangent_base
        tip, tangent = apply_output_effects(tip_base, tangent_base, robot_effects(self.robot).merged(effects))
        return SamplePredictions(tip=tip, tangent=tangent, tip_base=tip_base, tangent_base=tangent_base,
                                 ok=base.ok, message=base.message, seconds=base.seconds)

    def prediction(self, x) -> SamplePredictions:
        return self.observed(self.mechanics(x), x)

    def residuals(self, x):
        pos, ang, _ = pose_errors(self.prediction(x), self.data)
        return eq49_residuals(pos, ang)

    def pose_components(self, x):
        """Position and tangent errors of every sample as vectors, for the Gauss-Newton model of
        Eq. (49) (``calibrate._Eq49Model``).

        Returns
        -------
        dp : ndarray, shape (K, 3)
            ``p_measured - p_model`` [mm]; zero where the model failed.
        t : ndarray, shape (K, 3), or None
            ``t_measured x t_model`` [deg] (length sin(angle) / 1 deg); None without tangents.
        cos_angle : ndarray, shape (K,)
            ``t_measured . t_model`` (1 without tangents).
        ok : ndarray of bool, shape (K,)
        """
        return self.components_of(self.prediction(x))

    def components_of(self, pred: SamplePredictions):
        """:meth:`pose_components` of a prediction."""
        dp = np.nan_to_num((self.data.tip - pred.tip) / POSITION_UNIT, nan=0.0)
        dp[~pred.ok] = 0.0
        if self.data.tangent is None:
            return dp, None, np.ones(len(dp)), pred.ok
        tm = self.data.tangent / np.linalg.norm(self.data.tangent, axis=1, keepdims=True)
        tp = pred.tangent / np.linalg.norm(pred.tangent, axis=1, keepdims=True)
        t = np.nan_to_num(np.cross(tm, tp) / ANGLE_UNIT, nan=0.0)
        c = np.nan_to_num(np.einsum("ij,ij->i", tm, tp), nan=1.0)
        t[~pred.ok] = 0.0
        return dp, t, c, pred.ok

    def standard_columns(self, x, columns) -> dict:
        """Exact columns of the Jacobian of the error components (:meth:`pose_components`) for
        the mechanical parameters ``columns`` (positions in ``x``) of a standard-model fit,
        without solving the model again.

        The standard model's tip derivatives with respect to the base rotations, the section
        precurvatures and the bending and torsional stiffnesses
        (:func:`~ctrplan.mechanics.standard_tip_derivatives_batch`, implicit-function theorem on
        the shooting residual, from the solve's own base torsions) are chained with the
        derivatives of what the parameter changes: the robot's packed precurvatures and
        stiffnesses and the base rotations of the motion history (central differences of
        :func:`~ctrplan.discrepancy.fits.parameters.apply_parameters` and
        :meth:`MeasuredData.state`, which solve nothing, one-sided at a parameter's limit; exact
        for the maps linear in the parameter, such as a scaled precurvature or a relative
        stiffness). The tip and tangent
        derivatives then pass through the output effects and the components by a central
        difference of that cheap map along them.

        A parameter that moves a translation beta at a solved sample (a time offset on a motion
        that translates a tube), a tube length or a section break has no exact column (the
        solver's discrete map is only piecewise smooth in them); nor has any parameter when the model is not the standard one, or when a
        sample the model solved has no derivative there (an unstable or unconverged row).

        Parameters
        ----------
        x : array-like, shape (m,)
        columns : iterable of int
            Positions in ``x`` of mechanical parameters.

        Returns
        -------
        dict
            ``{column: ndarray (K, w)}``, d components / d parameter [mm or deg per unit of the
            parameter], zero at failed samples; only for the columns that have one.
        """
        columns = list(columns)
        if self.model != "standard" or not columns:
            return {}
        x = np.asarray(x, float)
        base = self.mechanics(x)
        ok = np.asarray(base.ok, bool)
        if base.base_torsion is None or not ok.any():
            return {}
        v = self.full(x)
        mech_names = [self.all_names[k] for k in self.mech]

        def packed_and_state(values, motion):
            """The packed robot and (when the parameter acts on the motion) the history state."""
            robot_p = apply_parameters(self.robot, mech_names, values)
            if not motion:
                return pack_robot(robot_p), None, robot_p
            effects, _ = EffectSet.from_parameters(self.robot, mech_names, values)
            return pack_robot(robot_p), self.data.state(robot_p, effects), robot_p

        pk0, _, robot_p = packed_and_state(v[self.mech], False)
        deriv = standard_tip_derivatives_batch(robot_p, base.alpha[ok], base.beta[ok], base.base_torsion[ok],
                                               self.settings)
        if not deriv.ok.all():
            return {}
        n_fixed = len(self.fixed)
        out = {}
        for j in columns:
            pos = self.mech.index(n_fixed + j)
            effect = effect_of_parameter(self.robot, self.all_names[n_fixed + j])
            motion = effect is not None and (effect.operator is not None or effect.friction_angle is not None)
            h = CHAIN_STEP * max(1.0, abs(v[n_fixed + j]))
            sides = {}
            for sign in (1.0, -1.0):
                vs = v[self.mech].copy()
                vs[pos] += sign * h
                try:
                    sides[sign] = packed_and_state(vs, motion)[:2]
                except (ValueError, CtrplanError):   # a step past a limit: one-sided from x
                    continue
            if not sides:
                continue
            if len(sides) == 1:   # at a limit: one-sided difference of these maps
                sign = next(iter(sides))
                sides[-sign] = packed_and_state(v[self.mech], motion)[:2]
                width = h
            else:
                width = 2 * h
            (pp, sp), (pm, sm) = sides[1.0], sides[-1.0]
            if not all(np.array_equal(getattr(pp, f), getattr(pk0, f)) and np.array_equal(getattr(pm, f), getattr(pk0, f))
                       for f in ("lengths", "breaks", "n_breaks")):
                continue
            if motion and not (np.array_equal(sp.beta[ok], base.beta[ok]) and np.array_equal(sm.beta[ok], base.beta[ok])):
                continue
            # columns of the derivatives: alpha (n), precurvature (n, S, 2), k_xy (n), k_z (n)
            robot_columns = np.concatenate([((pp.precurvature - pm.precurvature) / width).ravel(),
                                            (pp.k_xy - pm.k_xy) / width, (pp.k_z - pm.k_z) / width])
            d_alpha = (sp.alpha[ok] - sm.alpha[ok]) / width if motion else np.zeros((int(ok.sum()), robot_p.n_tubes))
            dq = np.concatenate([d_alpha, np.broadcast_to(robot_columns, (d_alpha.shape[0], robot_columns.size))],
                                axis=1)
            d_tip = np.zeros_like(base.tip_base)
            d_tan = np.zeros_like(base.tangent_base)
            d_tip[ok] = np.einsum("kcp,kp->kc", deriv.d_position, dq)
            d_tan[ok] = np.einsum("kcp,kp->kc", deriv.d_tangent, dq)
            # through the output effects and the components: central difference of that map
            e = CHAIN_STEP
            cp = self._stacked(self.observed(base, x, base.tip_base + e * d_tip, base.tangent_base + e * d_tan))
            cm = self._stacked(self.observed(base, x, base.tip_base - e * d_tip, base.tangent_base - e * d_tan))
            out[j] = np.where(ok[:, None], (cp - cm) / (2 * e), 0.0)
        return out

    def _stacked(self, pred):
        dp, t, _, _ = self.components_of(pred)
        return dp if t is None else np.concatenate([dp, t], axis=1)

    def component_residuals(self, x):
        """Smooth companion of :meth:`residuals`, shape (6 K,) or (3 K,) without tangents: per
        sample the position error components [mm] and the components of ``t_measured x
        t_model`` (length sin(angle)) [deg]. Its sum of squares is ``sum |dp|^2 + angle^2``
        where Eq. (49) squares the sum; a failed sample gets :data:`FAILED_RESIDUAL` spread over
        its components."""
        pred = self.prediction(x)
        parts = [(self.data.tip - pred.tip) / POSITION_UNIT]
        if self.data.tangent is not None:
            tm = self.data.tangent / np.linalg.norm(self.data.tangent, axis=1, keepdims=True)
            tp = pred.tangent / np.linalg.norm(pred.tangent, axis=1, keepdims=True)
            parts.append(np.cross(tm, tp) / ANGLE_UNIT)
        comp = np.nan_to_num(np.concatenate(parts, axis=1), nan=0.0)
        comp[~pred.ok] = FAILED_RESIDUAL / np.sqrt(comp.shape[1])
        return comp.ravel()


class ComponentJacobians:
    """Jacobians ``J_c`` of the error components of :meth:`FitObjective.pose_components`, shape
    (K, w, m) (w = 3 position components [mm], and 3 tangent ones [deg] with tangents), exact or
    updated.

    :meth:`exact` takes each mechanical column from the model's exact derivatives where it has
    them (:meth:`FitObjective.standard_columns`: a standard-model fit, no model solve) and the
    others by forward differences (:data:`DIFF_STEP`, the step of
    ``scipy.optimize.least_squares``'s ``"2-point"`` scheme): one model evaluation per such
    column. :meth:`updated` moves the last Jacobian to a new point by Broyden's rank-one update
    of its mechanical columns in the parameters' scaled units (the secant condition
    ``J_new dx = c(x_new) - c(x_old)`` along the step; Broyden 1965, Dennis & Schnabel 1996,
    Sec. 8.1), which costs no model evaluation (on the standard model an exact Jacobian costs
    about two evaluations of the model, the derivatives and the maps around them); the
    registration columns, which re-use the cached mechanics, are always forward differences.
    It falls back to :meth:`exact` after ``max_updates`` updates (the calibration's
    :data:`~ctrplan.discrepancy.fits.calibrate.MAX_JACOBIAN_UPDATES`), when the set of
    failed samples changed, or when the step moved no mechanical parameter.
    """

    def __init__(self, obj: FitObjective, lower, upper, scale, max_updates: int = 0):
        self.obj, self.lower, self.upper = obj, np.asarray(lower, float), np.asarray(upper, float)
        self.scale = np.asarray(scale, float)
        m = self.lower.size
        n_fixed = len(obj.fixed)
        self.mech = np.array([n_fixed + j in set(obj.mech) for j in range(m)], dtype=bool)
        self.max_updates = int(max_updates)
        self.x = self.c = self.cos = self.ok = self.jc = None
        self.is_exact = False
        self.updates = 0
        self.n_exact = self.n_updated = 0
        self.n_derivative_columns = self.n_difference_columns = 0

    def components(self, x):
        """``(c, cos_angle, ok)`` at ``x``: components (K, w), cosines (K,), ok flags (K,)."""
        dp, t, c, ok = self.obj.pose_components(x)
        return (dp if t is None else np.concatenate([dp, t], axis=1)), c, ok

    def _differences(self, x, c0, columns, jc) -> None:
        for j in columns:
            step = DIFF_STEP * max(1.0, abs(x[j])) * (1.0 if x[j] >= 0 else -1.0)
            if not self.lower[j] <= x[j] + step <= self.upper[j]:
                step = -step
            xs = x.copy()
            xs[j] += step
            cj, _, okj = self.components(xs)
            jc[:, :, j] = np.where(okj[:, None], (cj - c0) / step, 0.0)
            self.n_difference_columns += bool(self.mech[j])

    def _derivatives(self, x, jc) -> np.ndarray:
        """Fill the mechanical columns that have exact derivatives; returns their mask, shape (m,)."""
        exact = self.obj.standard_columns(x, np.flatnonzero(self.mech))
        mask = np.zeros(x.size, dtype=bool)
        for j, col in exact.items():
            jc[:, :, j] = col
            mask[j] = True
        self.n_derivative_columns += len(exact)
        return mask

    def _store(self, x, c, cos, ok, jc, exact: bool):
        jc[~ok] = 0.0
        self.x, self.c, self.cos, self.ok, self.jc, self.is_exact = x.copy(), c, cos, ok, jc, exact
        return c, cos, ok, jc

    def exact(self, x):
        """Jacobian at ``x`` from exact derivatives and forward differences; returns
        ``(c, cos, ok, J_c)``."""
        x = np.asarray(x, float)
        c0, cos0, ok0 = self.components(x)
        jc = np.zeros((c0.shape[0], c0.shape[1], x.size))
        derived = self._derivatives(x, jc)
        self._differences(x, c0, np.flatnonzero(~derived), jc)
        self.updates = 0
        self.n_exact += 1
        return self._store(x, c0, cos0, ok0, jc, True)

    def updated(self, x):
        """The last Jacobian moved to ``x`` by a rank-one update of its mechanical columns (or
        :meth:`exact` where it must be); returns ``(c, cos, ok, J_c)``."""
        x = np.asarray(x, float)
        if self.jc is None or self.updates >= self.max_updates:
            return self.exact(x)
        c1, cos1, ok1 = self.components(x)
        dx = x - self.x
        s = np.where(self.mech, dx / self.scale, 0.0)
        ss = float(s @ s)
        if not np.array_equal(ok1, self.ok) or ss == 0.0:
            return self.exact(x)
        jc = self.jc.copy()
        y = c1 - self.c - jc @ dx
        jc[:, :, self.mech] += y[:, :, None] * (s[self.mech] / self.scale[self.mech])[None, None, :] / ss
        self._differences(x, c1, np.flatnonzero(~self.mech), jc)
        self.updates += 1
        self.n_updated += 1
        return self._store(x, c1, cos1, ok1, jc, False)

    def note(self) -> str:
        """``"<n> Jacobians (<a> mechanical columns from exact derivatives, <b> by forward
        differences), <m> rank-one updates"``."""
        return (f"{self.n_exact} Jacobians ({self.n_derivative_columns} mechanical columns from exact derivatives, "
                f"{self.n_difference_columns} by forward differences), {self.n_updated} rank-one updates")
