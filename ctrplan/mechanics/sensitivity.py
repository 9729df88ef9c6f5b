"""Exact parameter derivatives of the standard model's tip (forward sensitivities).

The standard model (``standard.py``; Section II-A of Ha, Fagogenis & Dupont 2019, refs [10],
[11]) is solved by shooting: the base torsions sigma0 (n,) are found such that the tip torsions
r(sigma0, q) = sigma(L) of the discrete RK4 map vanish. At a solution, the implicit-function
theorem gives (the forward sensitivities of D. C. Rucker and R. J. Webster III, "Computing
Jacobians and compliance matrices for externally loaded continuum robots", IEEE ICRA 2011)

    d sigma0 / dq = -(dr / d sigma0)^-1 dr / dq,

with dr / d sigma0 the shooting Jacobian (the variational equations the solver integrates) and
dr / dq the parameter sensitivities of the same RK4 map: every RK4 stage is differentiated
exactly, including the forcing df / dq of the torsion ODE. The total derivatives of the node
angles and torsions then go through the construction of the centerline of ``standard._centerline``
(Hermite midpoint angles, shared bending u_xy, exponential-coordinate steps of Eq. (57) and their
Jacobians of ``discrete.py``, Sec. 3 of docs/mechanics.md) to the tip position and tangent.

Any number of tubes. The sweep, the implicit-function theorem and the chain are numba kernels
(``_sensitivity_kernels``); this module checks the input and packs the arrays. One
configuration from a solution (:func:`standard_tip_derivatives`), or many from their base
torsions in one compiled call (:func:`standard_tip_derivatives_batch`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import GRID_MERGE_TOL
from ..errors import ConvergenceError, ElasticInstabilityError
from ._sensitivity_kernels import node_mismatch, precurvature_matches, section_index, tip_derivatives, \
    tip_derivatives_batch
from ._standard_batch import configuration_arrays
from .packed import pack_robot
from .results import ModelSettings
from .standard import solve_standard

__all__ = ["StandardTipDerivatives", "StandardTipDerivativesBatch", "standard_tip_derivatives",
           "standard_tip_derivatives_batch"]

# the node angles of the sensitivity sweep must reproduce the solution's (same RK4 steps, only
# the arithmetic order differs: 4.4e-16 rad at most on 40 random configurations of the four
# shipped robot files); a larger difference means the solution was computed for another robot,
# configuration or grid [rad]
_NODE_MATCH_TOL = 1e-8


@dataclass(frozen=True)
class StandardTipDerivatives:
    """Tip of a standard-model solution and its derivatives with respect to the model inputs.

    Parametrization: the base rotations alpha_i; the precurvature components (u_x, u_y) of every
    section of every tube, laid out as ``PackedRobot.precurvature`` (tube, section, component),
    zero-padded after a tube's last section (a straight section's columns are derivatives with
    respect to giving it a precurvature; a fit that keeps it straight drops them); each tube's
    bending stiffness k_(i,xy) with k_(i,z) held fixed, and its torsional stiffness k_(i,z) with
    k_(i,xy) held fixed. Not the translations beta (they move the grid nodes). For a fit in
    (k_xy, nu) with k_z = k_xy / (1 + nu):
    d/dk_xy|nu = ``d_*_d_k_xy`` + ``d_*_d_k_z`` / (1 + nu), d/dnu = -k_xy / (1 + nu)^2 ``d_*_d_k_z``.

    Attributes
    ----------
    tip_position : ndarray, shape (3,)
        [m] (the solution's ``tip_position``).
    tip_tangent : ndarray, shape (3,)
        Unit tangent at the tip.
    base_torsion : ndarray, shape (n,)
        Base torsions sigma0 of the solution [1/m].
    d_position_d_alpha, d_tangent_d_alpha : ndarray, shape (3, n)
        [m/rad], [1/rad].
    d_position_d_precurvature, d_tangent_d_precurvature : ndarray, shape (3, n, S, 2)
        [m^2] (m per 1/m), [m]; S the largest number of sections (zero where tube i has no
        section j).
    d_position_d_k_xy, d_tangent_d_k_xy : ndarray, shape (3, n)
        [m / (N m^2)], [1 / (N m^2)].
    d_position_d_k_z, d_tangent_d_k_z : ndarray, shape (3, n)
        [m / (N m^2)], [1 / (N m^2)].
    d_base_torsion : ndarray, shape (n, P)
        d sigma0 / dq [1/m per unit of q] for the columns of :meth:`jacobian`.
    shooting_determinant : float
        det(d sigma(L) / d sigma0) at the solution (> 0: the stability test passed).
    """

    tip_position: np.ndarray
    tip_tangent: np.ndarray
    base_torsion: np.ndarray
    d_position_d_alpha: np.ndarray
    d_tangent_d_alpha: np.ndarray
    d_position_d_precurvature: np.ndarray
    d_tangent_d_precurvature: np.ndarray
    d_position_d_k_xy: np.ndarray
    d_tangent_d_k_xy: np.ndarray
    d_position_d_k_z: np.ndarray
    d_tangent_d_k_z: np.ndarray
    d_base_torsion: np.ndarray
    shooting_determinant: float

    def jacobian(self) -> tuple[np.ndarray, np.ndarray]:
        """All columns side by side: alpha (n), precurvature (n S 2, C order of (tube, section,
        component), padded entries included), k_xy (n), k_z (n).

        Returns
        -------
        d_position : ndarray, shape (3, P)
        d_tangent : ndarray, shape (3, P)
            P = n (3 + 2 S).
        """
        pos = np.concatenate([self.d_position_d_alpha, self.d_position_d_precurvature.reshape(3, -1),
                              self.d_position_d_k_xy, self.d_position_d_k_z], axis=1)
        tan = np.concatenate([self.d_tangent_d_alpha, self.d_tangent_d_precurvature.reshape(3, -1),
                              self.d_tangent_d_k_xy, self.d_tangent_d_k_z], axis=1)
        return pos, tan


@dataclass(frozen=True)
class StandardTipDerivativesBatch:
    """Tips and their derivatives at K configurations (:func:`standard_tip_derivatives_batch`).

    Columns q (P = n (3 + 2 S)) in the order of :meth:`StandardTipDerivatives.jacobian`: alpha
    (n) [rad], precurvature (n, S, 2) in C order [1/m] (padded entries included, zero), k_xy (n)
    at fixed k_z and k_z (n) at fixed k_xy [N m^2]; ``d_position[k, :, c]`` is row k's
    ``jacobian()[0][:, c]``. Rows that are not ``ok`` are NaN except ``base_torsion``,
    ``residual``, ``shooting_determinant`` and the flags.

    Attributes
    ----------
    tip_position : ndarray, shape (K, 3)
        [m], of the re-swept centerline.
    tip_tangent : ndarray, shape (K, 3)
        Unit tangent at the tip.
    base_torsion : ndarray, shape (K, n)
        The base torsions given [1/m].
    d_position : ndarray, shape (K, 3, P)
        d tip / dq [m per unit of q: m/rad, m^2, m / (N m^2)].
    d_tangent : ndarray, shape (K, 3, P)
        d tangent / dq [1 per unit of q].
    d_base_torsion : ndarray, shape (K, n, P)
        d sigma0 / dq [1/m per unit of q].
    residual : ndarray, shape (K,)
        max_i |sigma_i(L)| of the sweep from ``base_torsion`` [1/m] (NaN: configuration not
        possible).
    shooting_determinant : ndarray, shape (K,)
        det(d sigma(L) / d sigma0) there (NaN: configuration not possible).
    valid : ndarray of bool, shape (K,)
        The configuration passed ``Robot.configurations_possible``.
    ok : ndarray of bool, shape (K,)
        Valid, ``residual`` at most 100 ``shooting_tol`` (the base torsions are a solution)
        and ``shooting_determinant`` > 0 (stable): the row's derivatives are those of
        :func:`standard_tip_derivatives`.
    """

    tip_position: np.ndarray
    tip_tangent: np.ndarray
    base_torsion: np.ndarray
    d_position: np.ndarray
    d_tangent: np.ndarray
    d_base_torsion: np.ndarray
    residual: np.ndarray
    shooting_determinant: np.ndarray
    valid: np.ndarray
    ok: np.ndarray


def _vector(x, n, name):
    """``x`` as a finite float array of shape (n,); ValueError naming ``name`` otherwise."""
    a = np.asarray(x, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) for a robot of {n} tubes, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a!r}")
    return a


def _checked_solution(robot, alpha, beta, settings, solution):
    """The converged solution to differentiate (solved here when not given)."""
    if solution is None:
        solution = solve_standard(robot, alpha, beta, settings, check_stability=False)
    else:
        if solution.grid is None or solution.base_torsion is None:
            raise ValueError("solution lacks its grid or base torsions: pass a StandardSolution of solve_standard")
        if solution.alpha.shape != alpha.shape or not (np.array_equal(solution.alpha, alpha)
                                                       and np.array_equal(solution.beta, beta)):
            raise ValueError(f"solution is for alpha={solution.alpha}, beta={solution.beta}, "
                             f"not alpha={alpha}, beta={beta}")
    d = solution.diagnostics
    if not d.converged:
        raise ConvergenceError(f"standard model at alpha={np.round(alpha, 4)} rad, "
                               f"beta={np.round(beta * 1e3, 3)} mm did not converge ({d.message}): "
                               "its tip has no derivative to take")
    return solution


def standard_tip_derivatives(robot, alpha, beta, settings: ModelSettings | None = None, *,
                             solution=None) -> StandardTipDerivatives:
    """Exact derivatives of the standard model's tip position and tangent with respect to the
    base rotations, the section precurvatures and the tube stiffnesses.

    The derivative is that of the solver's discrete output (RK4 with one step per grid interval,
    Hermite midpoint angles, exponential-coordinate chain), not of the continuous model, so it
    matches central differences of :func:`solve_standard` to their own error.

    Parameters
    ----------
    robot : Robot
    alpha : array-like, shape (n,)
        Base rotations [rad].
    beta : array-like, shape (n,)
        Base translations [m]. Not differentiated: a translation moves the grid nodes (the
        tube bases, section boundaries and ends are nodes), so the discrete map is only
        piecewise smooth in beta.
    settings : ModelSettings, optional
        Passed to :func:`solve_standard` (run with ``check_stability=False``: no multistart
        search) when ``solution`` is not given: the grid and ``shooting_tol`` (the derivative is
        exact at the solution found, whose tip torsions are below ``shooting_tol``).
    solution : StandardSolution, optional
        A converged solution at (alpha, beta) of this robot (e.g. from :func:`solve_standard`),
        reused instead of solving again; its grid is used.

    Returns
    -------
    StandardTipDerivatives
        Tip position (3,) [m] and tangent (3,), derivatives with respect to alpha (3, n),
        precurvature (3, n, S, 2), k_xy (3, n) at fixed k_z and k_z (3, n) at fixed k_xy.

    Raises
    ------
    ValueError
        If ``alpha`` or ``beta`` is not of shape (n,) or not finite, or ``solution`` is not a
        solution of this robot at this configuration.
    JointLimitError
        If the configuration is impossible (from :func:`solve_standard`).
    ConvergenceError
        If the shooting did not converge.
    ElasticInstabilityError
        If the shooting Jacobian d sigma(L) / d sigma0 has a determinant that is not positive
        (past a fold: the equilibrium is unstable and the derivative is of an unstable branch,
        unbounded at the fold). Other equilibria found by a multistart search are not a reason
        to refuse: the derivative is that of the branch the solution is on.

    Notes
    -----
    Method (implicit-function theorem; Rucker & Webster, IEEE ICRA 2011, forward
    sensitivities): with r(sigma0, q) the tip torsions of the RK4 sweep (Rucker et al. 2010,
    Eq. (11), as in ``standard.py``), d sigma0 / dq = -(dr / d sigma0)^-1 dr / dq. The tangents
    d(psi, sigma) / d(sigma0, q) are carried through every RK4 stage (forcing terms included;
    alpha enters through psi(s_0) = alpha: an absent tube keeps its angle, so
    psi_i(beta_i) = alpha_i). Then the Hermite midpoint angles
    psi_mid = (psi_j + psi_(j+1)) / 2 + h (sigma_j - sigma_(j+1)) / 8, the shared bending
    u_xy = sum_i k_(i,xy) R_z(psi_mid,i) uhat_i / sum_i k_(i,xy) of the tubes present, and the
    chain of Eq. (57) of Ha, Fagogenis & Dupont 2019 with the Jacobians of docs/mechanics.md,
    Sec. 3: dp_tip / du_k = R_k d(V e_z)/dphi h_k^2 - [p_tip - p_(k+1)]x Omega_k,
    d t / du_k = -[t]x Omega_k, Omega_k = R_k V(u_k h_k) h_k.

    Compiled (``_sensitivity_kernels.tip_derivatives``): 0.2 ms per call with ``solution``
    given on the Table II robot at the default grid (136-155 nodes), about two
    ``solve_standard(..., check_stability=False)`` calls (0.09-0.12 ms); the NumPy version it
    replaced took 26 ms.
    """
    settings = settings or ModelSettings()
    n = robot.n_tubes
    alpha = _vector(alpha, n, "alpha")
    beta = _vector(beta, n, "beta")
    solution = _checked_solution(robot, alpha, beta, settings, solution)
    pk = pack_robot(robot)
    g = solution.grid
    S = pk.precurvature.shape[1]
    P = n * (3 + 2 * S)
    s, present = np.ascontiguousarray(g.s, dtype=float), np.ascontiguousarray(g.present, dtype=bool)
    uh = np.ascontiguousarray(g.precurvature, dtype=float)
    sec = section_index(s, present, np.ascontiguousarray(beta), pk.breaks, pk.n_breaks)
    if not (uh.shape == sec.shape + (2,) and precurvature_matches(sec, uh, pk.precurvature)):
        raise ValueError("solution does not belong to this robot: its grid's precurvatures are not the robot's")
    sig0 = np.ascontiguousarray(solution.base_torsion, dtype=float)
    d_sig0 = np.empty((n, P))
    d_pos = np.empty((3, P))
    d_tan = np.empty((3, P))
    psi, _, det = tip_derivatives(s, present, uh, sec, pk.k_xy, pk.k_z, pk.stiffness_ratio,
                                  np.ascontiguousarray(alpha), sig0, S, d_sig0, d_pos, d_tan, np.empty(3), np.empty(3))
    ref = np.ascontiguousarray(solution.psi, dtype=float)
    mismatch = node_mismatch(psi, ref) if ref.shape == psi.shape else np.inf
    if not mismatch < _NODE_MATCH_TOL:
        raise ValueError(f"solution does not belong to this robot and configuration: its node angles differ "
                         f"from a sweep from its base torsions by {mismatch:.3g} rad")
    if not det > 0.0:
        raise ElasticInstabilityError(
            f"standard model at alpha={np.round(alpha, 4)} rad, beta={np.round(beta * 1e3, 3)} mm: shooting "
            f"Jacobian determinant {det:.3g} <= 0 (past a fold, unstable): no derivative of a stable branch")
    a, c, k = n, n + 2 * n * S, 2 * n + 2 * n * S     # column blocks: alpha, precurvature, k_xy, k_z
    return StandardTipDerivatives(
        tip_position=solution.tip_position.copy(), tip_tangent=solution.tip_tangent.copy(),
        base_torsion=sig0.copy(),
        d_position_d_alpha=d_pos[:, :a], d_tangent_d_alpha=d_tan[:, :a],
        d_position_d_precurvature=d_pos[:, a:c].reshape(3, n, S, 2),
        d_tangent_d_precurvature=d_tan[:, a:c].reshape(3, n, S, 2),
        d_position_d_k_xy=d_pos[:, c:k], d_tangent_d_k_xy=d_tan[:, c:k],
        d_position_d_k_z=d_pos[:, k:], d_tangent_d_k_z=d_tan[:, k:],
        d_base_torsion=d_sig0, shooting_determinant=float(det))


def standard_tip_derivatives_batch(robot, alpha, beta, base_torsion,
                                   settings: ModelSettings | None = None) -> StandardTipDerivativesBatch:
    """:func:`standard_tip_derivatives` at K configurations in one compiled call, from their
    converged base torsions (no shooting).

    Each row builds its grid from its beta (as :func:`solve_standard_batch` does, with the same
    ``settings``), sweeps the torsion ODE with its tangents from the given base torsions, and
    takes the tip and its derivatives from that sweep; with the base torsions of a solution of
    :func:`solve_standard` or :func:`solve_standard_batch` at the same ``settings``, a row equals
    :func:`standard_tip_derivatives` on that solution (to rounding: the tip is the sweep's, the
    same to 1e-15 m). Rows are flagged instead of raising: ``ok`` is False where the
    configuration is impossible, the sweep's tip torsion residual exceeds 100
    ``settings.shooting_tol`` (the base torsions are not a solution at these settings), or the
    shooting determinant is not positive (unstable).

    Parameters
    ----------
    robot : Robot
    alpha, beta : array-like, shape (K, n)
        Base rotations [rad] and translations [m].
    base_torsion : array-like, shape (K, n)
        Converged base torsions [1/m] (``StandardBatch.base_torsion``,
        ``StandardSolution.base_torsion``).
    settings : ModelSettings, optional
        The grid (``ds``, ``refine_ratio``, ``refine_length``) and ``shooting_tol``.

    Returns
    -------
    StandardTipDerivativesBatch
        Stacked tips (K, 3), derivatives (K, 3, P) with P = n (3 + 2 S) and per-row flags.

    Raises
    ------
    ValueError
        If ``alpha`` and ``beta`` are not both of shape (K, n), or ``base_torsion`` is not of
        shape (K, n).
    """
    settings = settings or ModelSettings()
    n = robot.n_tubes
    alpha, beta = configuration_arrays(robot, alpha, beta)
    K = alpha.shape[0]
    sig0 = np.ascontiguousarray(base_torsion, dtype=float)
    if sig0.shape != (K, n):
        raise ValueError(f"base_torsion must have shape ({K}, {n}) like alpha, got shape {sig0.shape}")
    pk = pack_robot(robot)
    S = pk.precurvature.shape[1]
    P = n * (3 + 2 * S)
    valid = robot.configurations_possible(alpha, beta)
    tips = np.full((K, 3), np.nan)
    tans = np.full((K, 3), np.nan)
    d_sig0 = np.full((K, n, P), np.nan)
    d_pos = np.full((K, 3, P), np.nan)
    d_tan = np.full((K, 3, P), np.nan)
    residual = np.full(K, np.nan)
    det = np.full(K, np.nan)
    ok = np.zeros(K, dtype=bool)
    tip_derivatives_batch(alpha, beta, sig0, valid, pk.lengths, pk.breaks, pk.n_breaks, pk.precurvature, pk.k_xy,
                          pk.k_z, pk.stiffness_ratio, float(settings.ds), float(GRID_MERGE_TOL),
                          float(settings.refine_ratio), float(settings.refine_length),
                          100.0 * float(settings.shooting_tol), tips, tans, d_sig0, d_pos, d_tan, residual, det, ok)
    for x in (tips, tans, d_sig0, d_pos, d_tan):
        x[~ok] = np.nan
    return StandardTipDerivativesBatch(tip_position=tips, tip_tangent=tans, base_torsion=sig0.copy(),
                                       d_position=d_pos, d_tangent=d_tan, d_base_torsion=d_sig0,
                                       residual=residual, shooting_determinant=det, valid=valid, ok=ok)
