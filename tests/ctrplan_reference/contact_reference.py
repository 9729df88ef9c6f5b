"""FROZEN REFERENCE COPY of ctrplan/mechanics/contact.py as of commit d2d3ee6 (before the
speed work). Slow and simple on purpose: tests/test_mechanics_fast_vs_reference.py
holds the fast path in ctrplan.mechanics to it. Do not optimise; only imports were changed:
the discrete chain kinematics (ctrplan.mechanics.discrete, not
changed by the speed work) is shared, not copied. One later change of the outer loop's iteration
(not of the equations) is mirrored here, so that both solvers follow the same path: the Anderson
mixing parameter ``constants.ANDERSON_MIXING`` and the stagnation stop
``constants.OUTER_STAGNATION_WINDOW``.

Original module docstring follows.

Clearance model (Section II) and maximal torsional Coulomb friction model (Section III).

Linearized problem (Eqs. (10)-(25) of Ha, Fagogenis & Dupont 2019). About a linearization
point u* (first the standard zero-clearance solution), with segment curvatures u = u* + du,

    min_du  1/2 du^T K du + g^T du,   g = K (u* - uhat)                        (12), (13)
    s.t.    |d_k(du)| <= c_k,  d_k = B_k^T S_k (p* + J_p du)                      (19)-(24)

where S_k picks p_i - p_(i+1) at constraint k and B_k = [x_i, y_i] spans the outer tube's
cross section (B_k B_k^T = P_k of Eq. (22)). We keep the paper's multipliers lambda_k >= 0 of
the constraints 1/2 (|d_k|^2 - c_k^2) <= 0 (Eq. (26)-(27)), whose stationarity gives the
equilibrium (34)-(36):

    K (u - uhat) = sum_k A_k^T phi_k + sum_k lambda_k z_k,   phi_k = -lambda_k M_k d_k

with A_k = B_k^T S_k J_p, the contact force on the outer tube B_k phi_k (|f_k| = c_k lambda_k
at an active contact, Eq. (33)), and, for friction (Eqs. (37)-(43)):

- M_k = I + eta_k mu_k J (J the +90 deg in-plane rotation): the circumferential friction force
  eta_k mu_k [t_k]x f_normal,k of Eq. (38) acting on the centerlines (Eq. (40));
- z_k = eta_k mu_k c_k (r_(i,in) J_omega,i^T e_z - r_(i+1,out) J_omega,i+1^T e_z): the friction
  torques about each tube's axis of Eq. (41) (see the errata note on Eq. (42)).

Instead of the paper's fixed-step projected gradient ascent on the dual (Section II-E), the
multipliers are found by a semismooth (Fischer-Burmeister) Newton method on the complementarity
conditions lambda_k >= 0, c_k^2 - |d_k|^2 >= 0, lambda_k (c_k^2 - |d_k|^2) = 0, with the
Woodbury-type reduction of Appendix A (Eqs. (50)-(56)) restricted to active contacts: all that
is needed is the contact compliance W = A K^-1 A^T. Without friction this is exactly the
optimum of the convex dual (26); with friction, where Q(lambda) of Eq. (45) is not symmetric,
it solves the equilibrium of Eq. (44) directly. The outer loop re-linearizes about the new
solution (Section II-E, alpha = 1) until the centerlines stop moving.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from ctrplan.constants import ANDERSON_MIXING, OUTER_STAGNATION_WINDOW
from ctrplan.errors import ConvergenceError
from ctrplan.mechanics.discrete import TubeChain, chain_jacobians, forward_kinematics
from ctrplan.mechanics.results import ContactSolution, Diagnostics, ModelSettings
from .standard_reference import solve_standard

__all__ = ["solve_clearance", "solve_friction", "solve_contact"]

_ROT90 = np.array([[0.0, -1.0], [1.0, 0.0]])


class _Setup:
    """Chains, contact list and linear-algebra data of one configuration."""

    def __init__(self, robot, standard, eta, mu):
        g = standard.grid
        n = robot.n_tubes
        self.robot = robot
        self.n = n
        self.chains = []
        self.u0 = []
        for i, t in enumerate(robot.tubes):
            a, b = int(g.first[i]), int(g.last[i])
            s = g.s[a:b + 1]
            h = np.diff(s)
            uhat = np.zeros((h.size, 3))
            uhat[:, :2] = g.precurvature[a:b, i]
            stiff = np.column_stack([t.k_xy * h, t.k_xy * h, t.k_z * h])
            self.chains.append(TubeChain(first=a, s=s, h=h, uhat=uhat, stiffness=stiff,
                                         alpha=float(standard.alpha[i]), beta=float(standard.beta[i])))
            # standard solution as linearization point: u_i = Rz(-psi_i) u_xy + psi_i' e_z
            psi = standard.psi_mid[a:b, i]
            ub = standard.bending_mid[a:b]
            c, sn = np.cos(psi), np.sin(psi)
            u = np.column_stack([c * ub[:, 0] + sn * ub[:, 1], -sn * ub[:, 0] + c * ub[:, 1],
                                 standard.torsion_mid[a:b, i]])
            self.u0.append(u)
        self.offsets = np.concatenate([[0], np.cumsum([3 * ch.n_segments for ch in self.chains])])
        self.n_u = int(self.offsets[-1])
        self.uhat_flat = np.concatenate([ch.uhat.ravel() for ch in self.chains])
        self.kinv = 1.0 / np.concatenate([ch.stiffness.ravel() for ch in self.chains])
        # contacts: every common grid node of each adjacent pair
        clear = robot.clearances
        r_in, r_out = robot.contact_radii() if (np.any(np.asarray(mu) > 0)) else (np.zeros(n - 1), np.zeros(n - 1))
        pair, node_o, node_i, cvec, svec = [], [], [], [], []
        for i in range(n - 1):
            lo = max(g.first[i], g.first[i + 1])
            hi = min(g.last[i], g.last[i + 1])
            for gnode in range(lo, hi + 1):
                pair.append(i)
                node_o.append(gnode - g.first[i])
                node_i.append(gnode - g.first[i + 1])
                cvec.append(clear[i])
                svec.append(g.s[gnode])
        self.pair = np.asarray(pair, dtype=int)
        self.node_o = np.asarray(node_o, dtype=int)
        self.node_i = np.asarray(node_i, dtype=int)
        self.c = np.asarray(cvec, dtype=float)
        self.s_contact = np.asarray(svec, dtype=float)
        self.M = self.pair.size
        eta = np.zeros(n - 1) if eta is None else np.asarray(eta, dtype=float)
        mu = np.asarray(mu, dtype=float)
        self.eta_pair = eta
        self.mu_pair = mu
        em = (eta * mu)[self.pair] if self.M else np.zeros(0)
        self.Mblk = np.eye(2)[None, :, :] + em[:, None, None] * _ROT90[None, :, :]
        self.torque_out = em * self.c * (r_in[self.pair] if self.M else 0.0)
        self.torque_in = -em * self.c * (r_out[self.pair] if self.M else 0.0)
        self.has_friction = bool(np.any(em != 0.0))

    def split(self, flat):
        return [flat[self.offsets[i]:self.offsets[i + 1]].reshape(-1, 3) for i in range(self.n)]

    def kinematics(self, u_list):
        return [forward_kinematics(ch, u) for ch, u in zip(self.chains, u_list)]

    def linearize(self, u_list, fk):
        """A (2M, n_u), b (2M,), torque matrix Zt (M, n_u) at the linearization point."""
        M, n_u = self.M, self.n_u
        A = np.zeros((M, 2, n_u))
        zt = np.zeros((M, n_u))
        b = np.zeros((M, 2))
        for i in range(self.n - 1):
            ks = np.nonzero(self.pair == i)[0]
            if ks.size == 0:
                continue
            Ro, po = fk[i]
            Ri, pi = fk[i + 1]
            ao, ai = self.node_o[ks], self.node_i[ks]
            Bt = np.swapaxes(Ro[ao][:, :, :2], 1, 2)                 # (m, 2, 3): rows x_i, y_i
            b[ks] = np.einsum("kab,kb->ka", Bt, po[ao] - pi[ai])
            for tube, nodes, sign, tq in ((i, ao, 1.0, self.torque_out[ks]),
                                          (i + 1, ai, -1.0, self.torque_in[ks])):
                Jp, Jw = chain_jacobians(self.chains[tube], u_list[tube], *fk[tube], rows=nodes)
                m = nodes.size
                cols = slice(self.offsets[tube], self.offsets[tube + 1])
                A[ks, :, cols] = sign * np.einsum("kab,kbc->kac", Bt, Jp.reshape(m, 3, -1))
                if self.has_friction:
                    zt[ks, cols] += tq[:, None] * Jw.reshape(m, 3, -1)[:, 2, :]
        return A.reshape(2 * M, n_u), b, zt


class _Anderson:
    """Anderson acceleration (type II) of the outer fixed-point iteration u <- F(u).

    The re-linearization loop of Section II-E converges linearly (the geometric stiffness of
    the contact forces is not in the linearization); mixing the last few iterates removes most
    of that. The history is reset whenever the residual grows.
    """

    def __init__(self, depth, mixing=1.0):
        self.depth = depth
        self.mixing = mixing
        self.u_hist, self.f_hist, self.g_hist = [], [], []
        self.last = np.inf

    def step(self, u, g, residual_size):
        if self.depth <= 0:
            return g
        if residual_size > self.last:
            self.u_hist, self.f_hist, self.g_hist = [], [], []
        self.last = residual_size
        f = g - u
        self.f_hist.append(f)
        self.g_hist.append(g)
        if len(self.f_hist) > self.depth + 1:
            self.f_hist.pop(0)
            self.g_hist.pop(0)
        if len(self.f_hist) < 2:
            return g if self.mixing == 1.0 else g - (1.0 - self.mixing) * f
        dF = np.column_stack([self.f_hist[j + 1] - self.f_hist[j] for j in range(len(self.f_hist) - 1)])
        dG = np.column_stack([self.g_hist[j + 1] - self.g_hist[j] for j in range(len(self.g_hist) - 1)])
        gamma = np.linalg.lstsq(dF, f, rcond=None)[0]
        return g - dG @ gamma - (1.0 - self.mixing) * (f - dF @ gamma)


def _fb(a, b):
    r = np.sqrt(a * a + b * b)
    phi = a + b - r
    small = r < 1e-300
    rs = np.where(small, 1.0, r)
    da = np.where(small, 1.0 - 1.0 / np.sqrt(2.0), 1.0 - a / rs)
    db = np.where(small, 1.0 - 1.0 / np.sqrt(2.0), 1.0 - b / rs)
    return phi, da, db


class _Complementarity:
    """Semismooth Newton on the contact complementarity conditions of one linearization."""

    def __init__(self, W, Z, dfree, Mblk, c):
        self.W, self.Z, self.dfree, self.Mblk, self.c = W, Z, dfree, Mblk, c
        self.M = c.size
        dw = np.diag(W)
        self.kappa = 1.0 / max(float(np.mean(dw)), 1e-300)

    def displacements(self, lam):
        """Relative displacement d (M, 2) for multipliers lam, plus the active-set factorization."""
        r = self.dfree + self.Z @ lam
        act = np.nonzero(lam > 0.0)[0]
        if act.size == 0:
            return r.reshape(-1, 2), None
        idx = (2 * act[:, None] + np.arange(2)[None, :]).ravel()
        m = act.size
        LM = np.zeros((m, 2, m, 2))
        diag = np.arange(m)
        LM[diag, :, diag, :] = lam[act, None, None] * self.Mblk[act]   # block diagonal
        LM = LM.reshape(2 * m, 2 * m)
        S = np.eye(idx.size) + self.W[np.ix_(idx, idx)] @ LM
        lu = lu_factor(S, check_finite=False)
        da = lu_solve(lu, r[idx], check_finite=False)
        d = r - self.W[:, idx] @ (LM @ da)
        return d.reshape(-1, 2), (lu, idx, LM)

    def residual(self, lam, d):
        c = self.c
        gap = (c * c - np.sum(d * d, axis=1)) / (2.0 * c)
        return _fb(c * lam, self.kappa * gap)

    def jacobian_d(self, d, fact):
        """d d / d lambda, shape (2M, M)."""
        M = self.M
        Md = np.einsum("kab,kb->ka", self.Mblk, d)
        WE = np.einsum("rkb,kb->rk", self.W.reshape(2 * M, M, 2), Md)
        C = self.Z - WE
        if fact is None:
            return C
        lu, idx, LM = fact
        Da = lu_solve(lu, C[idx], check_finite=False)
        return C - self.W[:, idx] @ (LM @ Da)

    def solve(self, lam0, tol, maxit):
        lam = np.maximum(np.asarray(lam0, dtype=float), 0.0)
        c = self.c
        scale = self.kappa * c
        d, fact = self.displacements(lam)
        phi, da, db = self.residual(lam, d)
        merit = float(phi @ phi)
        for it in range(1, maxit + 1):
            err = float(np.max(np.abs(phi) / scale)) if self.M else 0.0
            if err < tol:
                return lam, d, True, it - 1, err
            D = self.jacobian_d(d, fact)
            dgap = -np.einsum("ka,kal->kl", d, D.reshape(self.M, 2, self.M)) / c[:, None]
            J = np.diag(da * c) + (db * self.kappa)[:, None] * dgap
            try:
                step = np.linalg.solve(J, -phi)
            except np.linalg.LinAlgError:
                step = np.linalg.lstsq(J, -phi, rcond=None)[0]
            t = 1.0
            for _ in range(40):
                lam_t = np.maximum(lam + t * step, 0.0)
                d_t, fact_t = self.displacements(lam_t)
                phi_t, da_t, db_t = self.residual(lam_t, d_t)
                m_t = float(phi_t @ phi_t)
                if m_t <= (1.0 - 1e-4 * t) * merit:
                    break
                t *= 0.5
            else:
                err = float(np.max(np.abs(phi) / scale))
                return lam, d, False, it, err
            lam, d, fact, phi, da, db, merit = lam_t, d_t, fact_t, phi_t, da_t, db_t, m_t
        err = float(np.max(np.abs(phi) / scale)) if self.M else 0.0
        return lam, d, err < tol, maxit, err


def solve_contact(robot, alpha, beta, settings: ModelSettings | None = None, *, eta=None,
                  mu=None, standard=None, warm_start: ContactSolution | None = None,
                  raise_on_failure: bool = False) -> ContactSolution:
    """Solve the clearance model (``eta=None``) or one friction solution (``eta`` given).

    Parameters
    ----------
    robot : Robot
        Clearances from tube diameters (Eq. (15)) or the robot's override.
    alpha, beta : array-like, shape (n,)
        Base rotations [rad] and translations [m].
    settings : ModelSettings, optional
    eta : array-like of int, shape (n - 1,), optional
        Direction of the last relative rotation of each pair (+1 CCW, -1 CW; Eq. (39)).
        ``None``: frictionless clearance model.
    mu : array-like, shape (n - 1,), optional
        Friction coefficients; default the robot's when ``eta`` is given, else zero.
    standard : StandardSolution, optional
        Standard-model solution at the same configuration (first linearization point).
    warm_start : ContactSolution, optional
        Start from this solution's curvatures and multipliers (same configuration and grid).
    raise_on_failure : bool
        Raise ConvergenceError instead of flagging ``diagnostics.converged = False``.

    Returns
    -------
    ContactSolution
        Centerlines, frames, curvatures, contact forces f_k = c_i lambda_k [N] (Eq. (33)) with
        arc lengths and directions, and diagnostics (outer and Newton iteration counts,
        largest constraint violation relative to the clearance in ``residual``).

    Raises
    ------
    JointLimitError
        Kinematically impossible configuration.
    ConvergenceError
        If ``raise_on_failure`` and the solve did not converge.
    PhysicalParameterError
        Non-positive clearance, or friction without tube diameters.

    Notes
    -----
    Eqs. (10)-(36) (clearance) and (37)-(47) (friction) of Ha, Fagogenis & Dupont 2019, with the
    Woodbury reduction of Appendix A and the Jacobians of Appendix B; see the module docstring
    for the differences from the paper's gradient ascent.
    """
    settings = settings or ModelSettings()
    n = robot.n_tubes
    if eta is not None:
        eta = np.asarray(eta, dtype=float).reshape(-1)
        if eta.size != n - 1 or not np.all(np.isin(eta, (-1.0, 1.0))):
            raise ValueError(f"eta must hold {n - 1} values of +1 or -1, got {eta}")
        mu = np.asarray(robot.friction_coefficients if mu is None else mu, dtype=float)
    else:
        mu = np.zeros(n - 1) if mu is None else np.asarray(mu, dtype=float)
    if standard is None:
        standard = solve_standard(robot, alpha, beta, settings, check_stability=False)
    setup = _Setup(robot, standard, eta, mu)
    if warm_start is not None and len(warm_start.curvatures) == n and all(
            w.shape == u.shape for w, u in zip(warm_start.curvatures, setup.u0)):
        u_list = [w.copy() for w in warm_start.curvatures]
        lam = np.array(warm_start.multipliers, dtype=float) if warm_start.multipliers is not None else np.zeros(setup.M)
    else:
        u_list = [u.copy() for u in setup.u0]
        lam = np.zeros(setup.M)
    fk = setup.kinematics(u_list)
    converged = False
    inner_total = 0
    inner_ok = True
    change = np.inf
    outer = 0
    anderson = _Anderson(settings.anderson_depth, ANDERSON_MIXING)
    best, best_at = np.inf, 0
    u_flat = np.concatenate([u.ravel() for u in u_list])
    for outer in range(1, settings.max_outer_iterations + 1):
        if setup.M == 0:
            converged = True
            break
        A, b, zt = setup.linearize(u_list, fk)
        AK = A * setup.kinv[None, :]
        W = AK @ A.T
        Z = AK @ zt.T if setup.has_friction else np.zeros((2 * setup.M, setup.M))
        dfree = b.ravel() - A @ (u_flat - setup.uhat_flat)
        comp = _Complementarity(W, Z, dfree, setup.Mblk, setup.c)
        lam, d, inner_ok, its, err = comp.solve(lam, settings.complementarity_tol,
                                                 settings.max_newton_iterations)
        inner_total += its
        phi = -lam[:, None] * np.einsum("kab,kb->ka", setup.Mblk, d)
        gen = A.T @ phi.ravel() + zt.T @ lam
        g_flat = setup.uhat_flat + setup.kinv * gen          # fixed-point map u -> F(u)
        g_list = setup.split(g_flat)
        fk_g = setup.kinematics(g_list)
        change = max(float(np.max(np.abs(pn - po))) for (_, pn), (_, po) in zip(fk_g, fk))
        if change < settings.outer_tol and inner_ok:
            u_list, fk, u_flat = g_list, fk_g, g_flat
            converged = True
            break
        if change < best:
            best, best_at = change, outer
        elif outer - best_at >= OUTER_STAGNATION_WINDOW:
            break
        u_flat = anderson.step(u_flat, g_flat, change)
        u_list = setup.split(u_flat)
        fk = setup.kinematics(u_list) if u_flat is not g_flat else fk_g
    # final contact state from the converged kinematics
    forces = setup.c * lam
    dirs = np.zeros((setup.M, 3))
    gaps = np.zeros(setup.M)
    for k in range(setup.M):
        i = setup.pair[k]
        Ro, po = fk[i]
        _, pi = fk[i + 1]
        rel = po[setup.node_o[k]] - pi[setup.node_i[k]]
        t = Ro[setup.node_o[k]][:, 2]
        rel = rel - t * (t @ rel)
        gaps[k] = np.linalg.norm(rel)
        dirs[k] = -rel / gaps[k] if gaps[k] > 0 else 0.0
    viol = float(np.max(gaps / setup.c - 1.0)) if setup.M else 0.0
    ends = robot.tube_ends(np.asarray(beta, dtype=float))
    tip_tube = int(max(range(n), key=lambda i: (ends[i], i)))
    Rt, pt = fk[tip_tube]
    model = "clearance" if eta is None else f"friction eta={eta.astype(int).tolist()}"
    msg = (f"{model}: converged in {outer} outer iterations" if converged else
           f"{model}: not converged after {outer} outer iterations (centerline change "
           f"{change:.3g} m, complementarity {'ok' if inner_ok else 'failed'})")
    diag = Diagnostics(converged=converged, iterations=outer, inner_iterations=inner_total,
                       unstable=standard.diagnostics.unstable, n_equilibria=standard.diagnostics.n_equilibria,
                       message=msg, residual=viol)
    if raise_on_failure and not converged:
        raise ConvergenceError(f"at alpha={np.round(alpha, 4)} rad, beta={np.round(np.asarray(beta) * 1e3, 3)} mm: {msg}")
    return ContactSolution(
        s=[ch.s for ch in setup.chains], centerlines=[p for _, p in fk], frames=[R for R, _ in fk],
        curvatures=u_list, contact_s=setup.s_contact, contact_pair=setup.pair, contact_force=forces,
        contact_direction=dirs, contact_gap=gaps,
        eta=np.zeros(n - 1, dtype=int) if eta is None else eta.astype(int), mu=mu,
        tip_position=pt[-1].copy(), tip_tangent=Rt[-1][:, 2].copy(), tip_rotation=Rt[-1].copy(),
        diagnostics=diag, multipliers=lam)


def solve_clearance(robot, alpha, beta, settings=None, **kwargs) -> ContactSolution:
    """Frictionless clearance model (Section II of Ha et al. 2019). See :func:`solve_contact`."""
    return solve_contact(robot, alpha, beta, settings, eta=None, **kwargs)


def solve_friction(robot, alpha, beta, eta, settings=None, **kwargs) -> ContactSolution:
    """One maximal-torsional-friction solution for directions ``eta`` (Section III, Eqs. (37)-(47)
    of Ha et al. 2019). See :func:`solve_contact`."""
    return solve_contact(robot, alpha, beta, settings, eta=eta, **kwargs)
