"""Parameter derivatives of the clearance and friction models' tip (implicit-function theorem).

A converged solution of :func:`~ctrplan.mechanics.solve_contact` (Sections II and III of Ha,
Fagogenis & Dupont 2019) is a fixed point of the outer re-linearization: with segment
curvatures u (S, 3), the multipliers lambda_a of the active contacts a (those with
lambda > 0) and the model parameters q,

    F1(u, lambda; q) = u - uhat - K^-1 (A(u)^T phi(u, lambda) + Z(u)^T lambda) = 0   (34)-(36), (41)
    F2_a(u; q)       = (|d_a(u)|^2 - c_a^2) / 2 = 0,                                 (19)-(24)

with d_a(u) = B_a(u)^T (p_(i, a)(u) - p_(i+1, a)(u)) the offset of the inner from the outer
centerline in the outer tube's cross section and phi_a = -lambda_a M_a d_a (M_a = I + eta mu J,
Eqs. (38), (40)). Held on its contact set, the solution is a smooth function of q and

    [dF/d(u, lambda)] d(u, lambda)/dq = -dF/dq.

The solver's own linearization (``_contact_fast``: A, B and the friction torques' directions
frozen at u) is that Jacobian without the derivatives of the chain's Jacobian and of the
contact frames (the geometric stiffness the outer loop converges linearly for). Here it is the
preconditioner: its Woodbury reduction onto the active contacts (Appendix A, Eqs. (50)-(56))
is one small dense factorization, and the generalized conjugate residual method on the
preconditioned system converges in about five products with the full Jacobian per column (the
columns share one memory of directions). The products of the full Jacobian with a direction are
central differences of F along that direction: F is an explicit function of (u, lambda) (one
pass of the kinematics and the generalized forces, no solve), so its directional derivative
carries only the rounding of those passes, about 1e-9 of F's scale. dF/dq is written out per
parameter (below; the base rotations, which enter F through the tubes' base frames alone, by
central differences of F). One factorization serves every parameter column; nothing is solved
again.

The derivative is that of the solution on its contact set (a contact active at q stays active,
an inactive one stays off). Where a multiplier is at zero or an inactive contact touches its
clearance, the solution is only one-sidedly differentiable and this is the side of the set the
solver found; :attr:`ContactTipDerivatives.set_margin` says how far the set is from changing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _contact_kernels as ck
from ._contact_fast import FlatProblem
from ._contact_sensitivity_kernels import equilibrium_residual, frozen_factors, gcr_solve, jacobian_rows
from ._sensitivity_kernels import section_index
from .packed import pack_robot
from .results import ModelSettings
from .standard import solve_standard
from ..errors import ConvergenceError

__all__ = ["ContactTipDerivatives", "ContactTipJacobian", "contact_tip_derivatives", "contact_tip_jacobian",
           "contact_parameter_columns", "BoundDerivatives", "bound_derivatives"]

# relative residual of the linear solve of every parameter column, and the largest number of
# products with the full Jacobian over all columns
_GCR_RTOL = 1e-10
_GCR_MAXIT = 200
# largest curvature residual |F1| of a solution to differentiate, relative to its largest curvature:
# converged solutions at the default tolerance leave up to 1.6e-3 (0.026 1/m at 16 1/m at the
# Table VII robot's grid configurations, whose tips are within 2 um of solves at 2e-9 m), a
# solution of another configuration or robot leaves O(1)
_EQUILIBRIUM_TOL = 1e-2
# step of the central differences of F in a base rotation [rad] (F is explicit in them, no solve)
_ALPHA_STEP = 1e-5
# relative step of the central differences of F along a direction (F is explicit, no solve)
_JVP_STEP = 1e-5


@dataclass(frozen=True)
class ContactTipDerivatives:
    """Tip of a clearance or friction solution and its derivatives with respect to the tube
    parameters and the base rotations, on the solution's contact set.

    Attributes
    ----------
    tip_position : ndarray, shape (3,)
        [m].
    tip_tangent : ndarray, shape (3,)
    d_position_d_precurvature, d_tangent_d_precurvature : ndarray, shape (3, n, S, 2)
        Per precurvature component (u_x, u_y) of section j of tube i [m^2], [m] (S the largest
        number of sections; zero where tube i has no section j or the section is not inserted).
    d_position_d_k_xy, d_tangent_d_k_xy : ndarray, shape (3, n)
        Bending stiffness k_(i,xy) with k_(i,z) held [m / (N m^2)], [1 / (N m^2)].
    d_position_d_k_z, d_tangent_d_k_z : ndarray, shape (3, n)
        Torsional stiffness k_(i,z) with k_(i,xy) held [m / (N m^2)], [1 / (N m^2)].
    d_position_d_clearance, d_tangent_d_clearance : ndarray, shape (3, n - 1)
        Radial clearance c_i of pair i [m/m], [1/m].
    d_position_d_mu, d_tangent_d_mu : ndarray, shape (3, n - 1)
        Friction coefficient mu_i of pair i (zero columns without friction on the pair) [m], [-].
    d_position_d_alpha, d_tangent_d_alpha : ndarray, shape (3, n)
        Base rotation alpha_i, the friction directions held [m/rad], [1/rad].
    active : int
        Number of active contacts (lambda > 0).
    set_margin : float
        How far the contact set is from changing [-]: the smaller of the smallest active
        multiplier relative to the largest and the smallest relative gap c / |d| - 1 of the
        inactive contacts. Near 0 the derivative is one-sided.
    jacobian_products : int
        Products with the full Jacobian used for all columns together.
    """

    tip_position: np.ndarray
    tip_tangent: np.ndarray
    d_position_d_precurvature: np.ndarray
    d_tangent_d_precurvature: np.ndarray
    d_position_d_k_xy: np.ndarray
    d_tangent_d_k_xy: np.ndarray
    d_position_d_k_z: np.ndarray
    d_tangent_d_k_z: np.ndarray
    d_position_d_clearance: np.ndarray
    d_tangent_d_clearance: np.ndarray
    d_position_d_mu: np.ndarray
    d_tangent_d_mu: np.ndarray
    d_position_d_alpha: np.ndarray
    d_tangent_d_alpha: np.ndarray
    active: int
    set_margin: float
    jacobian_products: int


@dataclass(frozen=True)
class ContactTipJacobian:
    """Tip of a clearance or friction solution and its derivatives along Q directions in the
    tube parameters (:func:`contact_tip_jacobian`).

    Attributes
    ----------
    tip_position : ndarray, shape (3,)
        [m].
    tip_tangent : ndarray, shape (3,)
    d_position : ndarray, shape (3, Q)
        [m per unit of the direction].
    d_tangent : ndarray, shape (3, Q)
        [1 per unit of the direction].
    active, set_margin, jacobian_products
        As in :class:`ContactTipDerivatives`.
    """

    tip_position: np.ndarray
    tip_tangent: np.ndarray
    d_position: np.ndarray
    d_tangent: np.ndarray
    active: int
    set_margin: float
    jacobian_products: int


class _Equilibrium:
    """F1, F2 of the module docstring for one FlatProblem and active set (compiled,
    ``_contact_sensitivity_kernels.equilibrium_residual``)."""

    def __init__(self, prob: FlatProblem, act: np.ndarray):
        self.prob = prob
        self.act = np.ascontiguousarray(act, dtype=np.int64)
        self.arr = prob.outer_arrays()
        self.scr = prob.outer_scratch()

    def state(self, u):
        """Kinematics, Jacobian factors, contact frames and offsets d (M, 2) at u (S, 3)."""
        arr, scr = self.arr, self.scr
        R, p = self.prob.kinematics(u)
        ck.linearize(u, arr.uhat, arr.kinv, arr.h, arr.node_off, R, p, scr.Omega, scr.base, scr.H1, scr.H2,
                     scr.F3, scr.Jpv)
        ck.contact_frames(R, p, arr.jo, arr.ji, scr.Jpv, scr.B, scr.dfree, scr.diagW, scr.H1, scr.H2, arr.pair)
        d = np.einsum("mrq,mr->mq", scr.B, p[arr.jo] - p[arr.ji])
        return R, p, d

    def residual(self, u, lam):
        """(F1 (S, 3) [1/m], F2 (m,) [m^2]) at curvatures u (S, 3) and multipliers lam (M,)."""
        F1 = np.empty_like(u)
        F2 = np.empty(self.act.size)
        equilibrium_residual(np.ascontiguousarray(u), lam, self.act, self.arr, self.scr, F1, F2)
        return F1, F2


def _vector(x, n, name):
    a = np.asarray(x, dtype=float)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite array of shape ({n},), got {a!r}")
    return a


_BLAS = []


def _one_blas_thread():
    """A context that holds BLAS to one thread: its products here are of a few hundred by a few
    tens, where OpenBLAS's threads cost more than they save (a derivative took 5.9 ms of such
    products with the default threads on two cores, 1.1 ms with one)."""
    if not _BLAS:
        from threadpoolctl import ThreadpoolController

        _BLAS.append(ThreadpoolController())
    return _BLAS[0].limit(limits=1, user_api="blas")


def contact_tip_jacobian(robot, alpha, beta, solution, settings: ModelSettings | None = None, *,
                         directions=None, standard=None) -> ContactTipJacobian:
    """Derivatives of a clearance or friction solution's tip along directions in the tube
    parameters (implicit-function theorem on the solution's contact set, module docstring).

    Parameters
    ----------
    robot : Robot
    alpha, beta : array-like, shape (n,)
        Base rotations [rad] and translations [m] of ``solution``.
    solution : ContactSolution
        Converged result of :func:`~ctrplan.mechanics.solve_contact` for ``robot`` at this
        configuration with ``settings`` (its friction directions ``eta`` and coefficients
        ``mu`` are read from it). The derivatives are as accurate as the solution: solve at a
        tight ``outer_tol`` (1e-10 m or below) for derivatives to 1e-5.
    settings : ModelSettings, optional
        Those of the solve (the grid step must match).
    directions : array-like, shape (P, Q), optional
        Columns of combinations of the tube parameters, in the order of
        :func:`contact_parameter_columns` (P of them); default all P, one by one. Only Q
        columns are solved for (a fit's parameter moves several tube parameters together).
    standard : StandardSolution, optional
        Standard solution at the configuration (its grid is used; solved when not given).

    Returns
    -------
    ContactTipJacobian

    Raises
    ------
    ValueError
        Malformed joints, or a solution that does not belong to this robot, configuration and
        grid (its curvatures or multipliers do not have the grid's shapes, or it is not an
        equilibrium of this robot: a curvature residual above 1e-2 of the largest curvature).
    ConvergenceError
        The solution is flagged as not converged or is not finite, or the linear solve of the
        derivatives did not reach a relative residual of 1e-6.

    Notes
    -----
    Equilibrium (34)-(36), (41) and constraints (19)-(24) of Ha, Fagogenis & Dupont 2019 on the
    active set; preconditioner from the Woodbury reduction of Appendix A (Eqs. (50)-(56)).
    Cost: about five products with the full Jacobian per column, 0.7-1.6 ms per column on the
    shipped robots, about what a forward difference of a warm-started solve costs
    (``benchmarks/friction_columns_accuracy.py``, docs/mechanics.md Sec. 6); the gain is
    accuracy (1e-5 where such differences are off by 0.1-30 %).
    """
    with _one_blas_thread():
        return _contact_tip_jacobian(robot, alpha, beta, solution, settings, directions, standard)


def _contact_tip_jacobian(robot, alpha, beta, solution, settings, directions, standard):
    settings = settings or ModelSettings()
    n = robot.n_tubes
    alpha = _vector(alpha, n, "alpha")
    beta = _vector(beta, n, "beta")
    if not solution.diagnostics.converged:
        raise ConvergenceError(f"contact solution at alpha={np.round(alpha, 4)} rad, beta={np.round(beta * 1e3, 3)} mm "
                               f"did not converge ({solution.diagnostics.message}): its tip has no derivative")
    if standard is None:
        standard = solve_standard(robot, alpha, beta, settings, check_stability=False)
    eta = np.asarray(solution.eta, dtype=float)
    friction = bool(np.any(eta != 0))
    mu = np.asarray(solution.mu, dtype=float)
    prob = FlatProblem(robot, standard, eta if friction else None, mu if friction else np.zeros(n - 1))
    parts = prob.split_segments(prob.u0)
    if len(solution.curvatures) != n or any(c.shape != q.shape for c, q in zip(solution.curvatures, parts)):
        raise ValueError("solution's curvatures do not have the grid's shape: it belongs to another robot, "
                         "configuration or grid step")
    if solution.multipliers is None or np.shape(solution.multipliers) != (prob.M,):
        raise ValueError(f"solution's multipliers do not match the grid's {prob.M} contacts: pass a ContactSolution "
                         "of solve_contact for this robot and configuration")
    u = np.ascontiguousarray(np.concatenate(solution.curvatures), dtype=float)
    lam = np.asarray(solution.multipliers, dtype=float)
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(lam))):
        # the outer loop's centerline test passes NaN centerlines (docs/mechanics.md, Sec. 11)
        raise ConvergenceError(f"contact solution at alpha={np.round(alpha, 4)} rad, beta={np.round(beta * 1e3, 3)} mm "
                               "is flagged converged but its curvatures or multipliers are not finite")
    act = np.nonzero(lam > 0.0)[0]
    eq = _Equilibrium(prob, act)
    F1, _ = eq.residual(u, lam)
    scale = max(float(np.max(np.abs(u))), 1e-300)
    if not np.max(np.abs(F1)) <= _EQUILIBRIUM_TOL * scale:
        raise ValueError(f"solution is not an equilibrium of this robot at this configuration (curvature residual "
                         f"{np.max(np.abs(F1)):.3g} 1/m against curvatures of {scale:.3g} 1/m)")
    R, p, d = eq.state(u)
    ends = robot.tube_ends(beta)
    tip_tube = int(max(range(n), key=lambda i: (ends[i], i)))
    tip_node = int(prob.node_off[tip_tube + 1] - 1)
    # position and rotation Jacobian rows at the active contacts' nodes and the tip
    nodes = np.concatenate([eq.arr.jo[act], eq.arr.ji[act], [tip_node]]).astype(np.int64)
    Jp, Jw = jacobian_rows(nodes, p, eq.scr.Omega, eq.scr.base, prob.node_off)
    frozen = _FrozenJacobian(eq, R, d, lam, Jp, Jw)
    rhs = _parameter_rhs(robot, prob, standard, beta, u, lam, act, d, R, Jp, Jw, friction, eta)
    rhs_cols = rhs.shape[1]
    if directions is not None:
        directions = np.asarray(directions, dtype=float)
        if directions.ndim != 2 or directions.shape[0] != rhs.shape[1]:
            raise ValueError(f"directions must have shape ({rhs.shape[1]}, Q) (contact_parameter_columns), "
                             f"got {directions.shape}")
        rhs = rhs @ directions
    sol, products, res = frozen.solve_exact(u, lam, rhs)
    if not res <= 1e-6:
        raise ConvergenceError(f"derivatives of the contact solution at alpha={np.round(alpha, 4)} rad, "
                               f"beta={np.round(beta * 1e3, 3)} mm: linear solve stopped at relative residual {res:.3g}")
    du = sol[:3 * prob.S]
    t_tip = R[tip_node][:, 2]
    # the tip tube's base rotation also turns its tip about the z axis at fixed curvatures
    direct_p = np.zeros((3, rhs_cols))
    direct_t = np.zeros((3, rhs_cols))
    tip_alpha = contact_parameter_columns(robot).index(("alpha", tip_tube))
    direct_p[:, tip_alpha] = np.cross([0.0, 0.0, 1.0], p[tip_node])
    direct_t[:, tip_alpha] = np.cross([0.0, 0.0, 1.0], t_tip)
    if directions is not None:
        direct_p, direct_t = direct_p @ directions, direct_t @ directions
    return ContactTipJacobian(
        tip_position=p[tip_node].copy(), tip_tangent=t_tip.copy(), d_position=Jp[-1] @ du + direct_p,
        d_tangent=np.cross(Jw[-1] @ du, t_tip, axis=0) + direct_t, active=int(act.size),
        set_margin=_set_margin(lam, act, d, eq.arr.c), jacobian_products=int(products))


def contact_tip_derivatives(robot, alpha, beta, solution, settings: ModelSettings | None = None, *,
                            standard=None) -> ContactTipDerivatives:
    """Derivatives of a clearance or friction solution's tip with respect to every tube parameter,
    one by one (:func:`contact_tip_jacobian` with all columns, laid out per parameter).

    Parameters and errors as :func:`contact_tip_jacobian`.

    Returns
    -------
    ContactTipDerivatives
    """
    jac = contact_tip_jacobian(robot, alpha, beta, solution, settings, standard=standard)
    n = robot.n_tubes
    block = _blocks(contact_parameter_columns(robot))
    dp, dt = jac.d_position, jac.d_tangent
    pc = block["precurvature"]
    Ssec = (pc.stop - pc.start) // (2 * n)
    return ContactTipDerivatives(
        tip_position=jac.tip_position, tip_tangent=jac.tip_tangent,
        d_position_d_precurvature=dp[:, pc].reshape(3, n, Ssec, 2),
        d_tangent_d_precurvature=dt[:, pc].reshape(3, n, Ssec, 2),
        **{f"d_{what}_d_{kind}": x[:, block[kind]] for kind in ("k_xy", "k_z", "clearance", "mu", "alpha")
           for what, x in (("position", dp), ("tangent", dt))},
        active=jac.active, set_margin=jac.set_margin, jacobian_products=jac.jacobian_products)


def contact_parameter_columns(robot) -> list[tuple]:
    """The tube parameters of :func:`contact_tip_jacobian`, in column order: ``("precurvature",
    tube, section, component)`` for every tube, section slot and component (x, y) (S the largest
    number of sections; slots past a tube's last section give zero columns), then
    ``("k_xy", tube)``, ``("k_z", tube)`` for every tube, ``("clearance", pair)`` and
    ``("mu", pair)`` for every pair, then the base rotations ``("alpha", tube)`` (0-based
    indices; not the translations beta, which move the grid nodes).

    Returns
    -------
    list of tuple
        P = n (2 S + 3) + 2 (n - 1) labels.
    """
    n = robot.n_tubes
    Ssec = pack_robot(robot).precurvature.shape[1]
    cols = [("precurvature", i, j, c) for i in range(n) for j in range(Ssec) for c in range(2)]
    cols += [("k_xy", i) for i in range(n)] + [("k_z", i) for i in range(n)]
    cols += [("clearance", i) for i in range(n - 1)] + [("mu", i) for i in range(n - 1)]
    cols += [("alpha", i) for i in range(n)]
    return cols


def _blocks(labels) -> dict:
    """``{kind: slice}`` of the columns of each kind in ``labels`` (:func:`contact_parameter_columns`)."""
    out = {}
    for i, label in enumerate(labels):
        out[label[0]] = slice(out[label[0]].start if label[0] in out else i, i + 1)
    return out


def _set_margin(lam, act, d, c):
    """Smallest active multiplier over the largest, or the smallest relative gap c / |d| - 1 of an
    inactive contact, whichever is smaller [-] (inf without contacts of that kind)."""
    inactive = np.setdiff1d(np.arange(lam.size), act)
    margin_l = float(lam[act].min() / lam[act].max()) if act.size else np.inf
    if not inactive.size:
        return margin_l
    gaps = np.linalg.norm(d[inactive], axis=1)
    return min(margin_l, float(np.min(c[inactive] / np.maximum(gaps, 1e-300) - 1.0)))


class _FrozenJacobian:
    """The solver's linearization at the solution (A, B and the torques' directions frozen) as
    a preconditioner of the full Jacobian of (F1, F2): with U = K^-1 A^T (3S, 2m),
    L = blockdiag(lambda_a M_a), Y_a = K^-1 (A_a^T (-M_a d_a) + z_a) and D = blockdiag(d_a^T),

        [I + U L A   -Y] [x]   [r1]          [I + A U L   -A Y] [z]   [A r1]
        [  D A        0] [y] = [r2]   via    [    D         0 ] [y] = [ r2 ],  x = r1 - U L z + Y y

    (the Woodbury reduction of Appendix A of Ha et al. 2019 onto the active contacts; compiled,
    ``_contact_sensitivity_kernels.frozen_factors``)."""

    def __init__(self, eq, R, d, lam, Jp, Jw):
        arr, act = eq.arr, eq.act
        self.eq = eq
        self.A, self.ULt, self.Y, self.LU, self.piv, ok = frozen_factors(
            act, lam, np.ascontiguousarray(d), R, eq.scr.B, Jp, Jw, arr.jo, arr.ji,
            np.ascontiguousarray(arr.kinv.reshape(-1)), arr.tq_out, arr.tq_in, arr.Mblk)
        if not ok:
            raise ConvergenceError("the solver's linearization at the contact solution is singular: "
                                   "no derivative on this contact set")
        # multipliers are solved for in units of the largest one: the preconditioned operator is
        # then well conditioned (in N/m it is not)
        self.lam_scale = float(lam[act].max()) if act.size else 1.0

    def solve_exact(self, u, lam, rhs):
        """Columns of the full Jacobian's solution for ``rhs`` (3S + m, P): GCR on the
        left-preconditioned system, products with the full Jacobian by central differences of
        the explicit equilibrium (``_contact_sensitivity_kernels.gcr_solve``). Returns
        (solution, products, largest relative residual)."""
        eq = self.eq
        return gcr_solve(np.ascontiguousarray(u), lam, eq.act, eq.arr, eq.scr, self.A, self.ULt, self.Y, self.LU,
                         self.piv, self.lam_scale, np.ascontiguousarray(rhs, dtype=float), _JVP_STEP, _GCR_RTOL,
                         _GCR_MAXIT)


def _alpha_rhs(prob, u, lam, act, out):
    """-dF/dalpha (3S + m, n) into ``out``: the base rotations move the tubes' frames, so F depends
    on them through the kinematics alone; central differences of the explicit F over
    :data:`_ALPHA_STEP` (no solve). Evaluated on a copy of the problem's scratch arrays."""
    arr = prob.outer_arrays()
    scr = type(prob.outer_scratch())(*(a.copy() for a in prob.outer_scratch()))
    F1 = np.empty_like(u)
    F2 = np.empty(act.size)
    for i in range(prob.n):
        cols = []
        for sign in (1.0, -1.0):
            a = arr.alpha.copy()
            a[i] += sign * _ALPHA_STEP
            equilibrium_residual(u, lam, act, arr._replace(alpha=a), scr, F1, F2)
            cols.append(np.concatenate([F1.reshape(-1), F2]))
        out[:, i] = -(cols[0] - cols[1]) / (2 * _ALPHA_STEP)


def _parameter_rhs(robot, prob, standard, beta, u, lam, act, d, R, Jp, Jw, friction, eta):
    """-dF/dq (3S + m, P) for the columns precurvature (n, S, 2), k_xy (n), k_z (n),
    clearance (n - 1), mu (n - 1), alpha (n) (:func:`contact_parameter_columns`)."""
    n = prob.n
    arr = prob.outer_arrays()
    pk = pack_robot(robot)
    Ssec = pk.precurvature.shape[1]
    S3 = 3 * prob.S
    m = act.size
    labels = contact_parameter_columns(robot)
    col = {label: i for i, label in enumerate(labels)}
    rhs = np.zeros((S3 + m, len(labels)))
    _alpha_rhs(prob, u, lam, act, rhs[:, _blocks(labels)["alpha"]])
    g = standard.grid
    first = np.asarray(g.first, dtype=np.int64)
    sec = section_index(np.ascontiguousarray(g.s, dtype=float), np.ascontiguousarray(g.present, dtype=bool),
                        np.ascontiguousarray(beta, dtype=float), pk.breaks, pk.n_breaks)
    kinv = arr.kinv.reshape(-1)
    w = (u - arr.uhat)                       # K^-1 (generalized force) at the solution
    for t in range(n):
        k0, k1 = prob.seg_off[t], prob.seg_off[t + 1]
        secs = sec[first[t]:first[t] + (k1 - k0), t]
        for j in range(Ssec):
            rows = np.arange(k0, k1)[secs == j]
            for comp in range(2):
                rhs[3 * rows + comp, col[("precurvature", t, j, comp)]] = 1.0    # dF1/duhat = -I
        # F1 = u - uhat - K^-1 g, K^-1 = 1 / (k h): dF1/dk = (u - uhat) / k
        seg = np.arange(k0, k1)
        for comp in range(2):
            rhs[3 * seg + comp, col[("k_xy", t)]] = -w[seg, comp] / pk.k_xy[t]
        rhs[3 * seg + 2, col[("k_z", t)]] = -w[seg, 2] / pk.k_z[t]
    if m == 0:
        return rhs
    jo, ji, pair = arr.jo[act], arr.ji[act], arr.pair[act]
    lam_a = lam[act]
    ta = R[jo][:, :, 2]
    tb = R[ji][:, :, 2]
    Jpa, Jpb = Jp[:m], Jp[m:2 * m]
    Jwa, Jwb = Jw[:m], Jw[m:2 * m]
    B = prob.outer_scratch().B[act]
    c = arr.c[act]
    r_in, r_out = (pk.contact_radii(robot) if friction else (np.zeros(n - 1), np.zeros(n - 1)))
    for i in range(n - 1):
        on = pair == i
        if not np.any(on):
            continue
        # clearance: F2 = (|d|^2 - c^2) / 2 -> dF2/dc = -c; torques eta mu c r lam are linear in c
        rhs[S3 + np.nonzero(on)[0], col[("clearance", i)]] = c[on]
        if friction and eta[i] != 0.0:
            tq_o = arr.tq_out[act][on] / c[on]
            tq_i = arr.tq_in[act][on] / c[on]
            gen = (np.einsum("m,mr,mrx->x", lam_a[on] * tq_o, ta[on], Jwa[on])
                   + np.einsum("m,mr,mrx->x", lam_a[on] * tq_i, tb[on], Jwb[on]))
            rhs[:S3, col[("clearance", i)]] += kinv * gen
            # mu: M = I + eta mu J -> dphi/dmu = -lam eta J d; torques eta c r lam
            Jd = np.stack([-d[act][on, 1], d[act][on, 0]], axis=1)      # J d, J the +90 deg rotation
            dphi = -(lam_a[on] * eta[i])[:, None] * Jd                  # (k, 2)
            force = np.einsum("mrq,mq->mr", B[on], dphi)                # on the outer tube's node
            gen = np.einsum("mr,mrx->x", force, Jpa[on] - Jpb[on])
            gen += (np.einsum("m,mr,mrx->x", lam_a[on] * eta[i] * c[on] * r_in[i], ta[on], Jwa[on])
                    - np.einsum("m,mr,mrx->x", lam_a[on] * eta[i] * c[on] * r_out[i], tb[on], Jwb[on]))
            rhs[:S3, col[("mu", i)]] = kinv * gen
    return rhs


@dataclass(frozen=True)
class BoundDerivatives:
    """The friction bound of a configuration (:func:`~ctrplan.mechanics.evaluate_bound`) and its
    derivatives along Q directions in the tube parameters (:func:`bound_derivatives`).

    Attributes
    ----------
    position, angle : float
        The bound: largest tip distance [m] and tangent angle [rad] between a friction solution
        and the standard model.
    position_eta, angle_eta : tuple of int, shape (n - 1,)
        The friction directions that attain them (Eq. (39)).
    d_position, d_angle : ndarray, shape (Q,)
        Their derivatives [m], [rad] per unit of each direction: those of the solution that
        attains the bound (where two directions tie, of the first in ``all_eta`` order).
    translation_last_position, translation_last_angle : float
        The clearance solution's distance [m] and angle [rad] from the standard model's tip.
    d_translation_last_position, d_translation_last_angle : ndarray, shape (Q,)
    """

    position: float
    angle: float
    position_eta: tuple
    angle_eta: tuple
    d_position: np.ndarray
    d_angle: np.ndarray
    translation_last_position: float
    translation_last_angle: float
    d_translation_last_position: np.ndarray
    d_translation_last_angle: np.ndarray


def _distance_derivatives(p1, t1, dp1, dt1, p0, t0, dp0, dt0):
    """Derivatives (Q,) of |p1 - p0| and of the angle between unit tangents t1, t0 from their
    columns (3, Q); zero where the distance or the angle is zero (not differentiable there)."""
    diff = p1 - p0
    dist = float(np.linalg.norm(diff))
    d_dist = diff @ (dp1 - dp0) / dist if dist > 0 else np.zeros(dp1.shape[1])
    c = float(np.clip(t1 @ t0, -1.0, 1.0))
    s = np.sqrt(max(1.0 - c * c, 0.0))
    d_ang = -(t0 @ dt1 + t1 @ dt0) / s if s > 1e-12 else np.zeros(dp1.shape[1])
    return d_dist, d_ang


def bound_derivatives(robot, alpha, beta, settings: ModelSettings | None = None, *, bound=None,
                      directions=None) -> BoundDerivatives:
    """Derivatives of the per-configuration friction bound with respect to the tube parameters.

    The bound is a maximum over the 2^(n-1) friction solutions of their distance from the
    standard model's tip; its derivative is that of the attaining solution's distance, with
    both tips differentiated (:func:`contact_tip_jacobian`; the standard model's tip by
    :func:`~ctrplan.mechanics.standard_tip_derivatives`, which does not depend on clearances
    or friction coefficients).

    Parameters
    ----------
    robot : Robot
    alpha, beta : array-like, shape (n,)
        Base rotations [rad] and translations [m].
    settings : ModelSettings, optional
    bound : BoundResult, optional
        :func:`~ctrplan.mechanics.evaluate_bound` at this configuration and settings (evaluated
        when not given).
    directions : array-like, shape (P, Q), optional
        As in :func:`contact_tip_jacobian` (default: every tube parameter one by one).

    Returns
    -------
    BoundDerivatives

    Raises
    ------
    ConvergenceError
        A solution of the bound did not converge.
    ValueError
        As :func:`contact_tip_jacobian`.

    Notes
    -----
    Section III and Eqs. (37)-(47) of Ha, Fagogenis & Dupont 2019 for the solutions; a friction
    coefficient of 0 makes a pair's solutions the clearance model's, whose derivative with
    respect to that coefficient is left at 0 (the bound is not differentiable there).
    """
    from .bound import evaluate_bound
    from .sensitivity import standard_tip_derivatives

    settings = settings or ModelSettings()
    if bound is None:
        bound = evaluate_bound(robot, alpha, beta, settings)
    if not bound.diagnostics.converged:
        raise ConvergenceError(f"friction bound at alpha={np.round(np.asarray(alpha, float), 4)} rad: "
                               f"{bound.diagnostics.message}")
    n = robot.n_tubes
    labels = contact_parameter_columns(robot)
    D = np.eye(len(labels)) if directions is None else np.asarray(directions, dtype=float)
    st = bound.standard
    sd = standard_tip_derivatives(robot, alpha, beta, settings, solution=st)
    # the standard tip's columns in contact_parameter_columns order (no clearance or mu columns)
    std_p = np.concatenate([sd.d_position_d_precurvature.reshape(3, -1), sd.d_position_d_k_xy, sd.d_position_d_k_z,
                            np.zeros((3, 2 * (n - 1))), sd.d_position_d_alpha], axis=1) @ D
    std_t = np.concatenate([sd.d_tangent_d_precurvature.reshape(3, -1), sd.d_tangent_d_k_xy, sd.d_tangent_d_k_z,
                            np.zeros((3, 2 * (n - 1))), sd.d_tangent_d_alpha], axis=1) @ D
    jac = {}

    def of(sol):
        key = id(sol)
        if key not in jac:
            jac[key] = contact_tip_jacobian(robot, alpha, beta, sol, settings, directions=D, standard=st)
        return jac[key]

    etas = list(bound.friction)
    dist = [float(np.linalg.norm(bound.friction[e].tip_position - st.tip_position)) for e in etas]
    angs = [float(np.arccos(np.clip(bound.friction[e].tip_tangent @ st.tip_tangent, -1.0, 1.0))) for e in etas]
    e_pos, e_ang = etas[int(np.argmax(dist))], etas[int(np.argmax(angs))]
    out = {}
    for label, sol in (("position", bound.friction[e_pos]), ("angle", bound.friction[e_ang]),
                       ("translation_last", bound.clearance)):
        j = of(sol)
        out[label] = _distance_derivatives(j.tip_position, j.tip_tangent, j.d_position, j.d_tangent,
                                           st.tip_position, st.tip_tangent, std_p, std_t)
    return BoundDerivatives(
        position=bound.position, angle=bound.angle, position_eta=tuple(e_pos), angle_eta=tuple(e_ang),
        d_position=out["position"][0], d_angle=out["angle"][1],
        translation_last_position=bound.translation_last_position,
        translation_last_angle=bound.translation_last_angle,
        d_translation_last_position=out["translation_last"][0], d_translation_last_angle=out["translation_last"][1])
