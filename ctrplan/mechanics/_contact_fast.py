"""Driver of the compiled clearance / friction solver (see ``_contact_kernels`` for the maths).

Same algorithm and stopping rules as the reference implementation kept in
tests/ctrplan_reference/contact_reference.py: outer re-linearization with Anderson mixing (Section II-E of
Ha, Fagogenis & Dupont 2019), semismooth Newton on the complementarity conditions with the
active-set Woodbury reduction of Appendix A, friction as in Section III. The Newton method's
residual differs from the reference's on loaded contacts (the natural residual min(a, b) instead
of Fischer-Burmeister, ``_contact_kernels._residual``): same solution and stopping test, a third
fewer iterations.
What changed is the cost: every per-linearization quantity is computed in O(number of nodes +
number of contacts x number of touched contacts) by compiled kernels, instead of forming the
dense (2M x number of unknowns) constraint Jacobian.
"""

from __future__ import annotations

import copy
from typing import NamedTuple

import numpy as np
from numba import njit

from ..constants import (ANDERSON_MIXING, INNER_TOL_FACTOR, INNER_TOL_MAX, MAX_FAILED_INNER_STEPS,
                         OUTER_STAGNATION_WINDOW)
from . import _contact_kernels as ck
from ._chain_kernels import chain_kinematics
from .packed import pack_robot

__all__ = ["FlatProblem", "Anderson", "run_outer_loop"]


class Anderson:
    """Anderson acceleration (type II) of the outer fixed-point iteration u <- F(u).

    The re-linearization loop of Section II-E converges linearly (the geometric stiffness of
    the contact forces is not in the linearization); mixing the last few iterates removes most
    of that. The history is reset whenever the residual grows. The compiled outer loop
    (:func:`_outer_loop`) calls :func:`_anderson_step` on its own history arrays; this class keeps
    that history for a Python caller, with the same step.

    Parameters
    ----------
    depth : int
        Number of past differences mixed (0: plain iteration).
    mixing : float
        Mixing parameter beta in (0, 1]: the next iterate is
        ``u_bar + beta f_bar`` with ``u_bar``, ``f_bar`` the least-squares combinations of the
        past iterates and their residuals f = F(u) - u (beta = 1: ``g_bar``, undamped). Not
        applied when ``depth`` is 0.

    Notes
    -----
    The history lives in two preallocated (depth + 1, size) arrays, oldest first, and the
    least-squares problem min |f - dF gamma| is solved by :func:`_anderson_combination` (a
    compiled QR of the at most ``depth`` difference columns) instead of ``np.linalg.lstsq``
    on stacked columns (cProfile of the 4x4x4 bounds, 1098 unknowns: 162 us per ``lstsq`` call
    against 32 us per compiled combination).
    """

    def __init__(self, depth, mixing=1.0):
        self.depth = int(depth)
        self.mixing = float(mixing)
        self.F = None   # residual history f = g - u, (depth + 1, size), oldest first
        self.G = None   # image history g = F(u)
        self.count = 0
        self.last = np.inf

    def step(self, u, g, residual_size):
        """Next iterate from the current one ``u`` (S*3,) and its image ``g = F(u)`` (S*3,):
        ``g`` itself when nothing is mixed, else a new array (:func:`_anderson_step`)."""
        if self.depth <= 0:
            return g
        if self.F is None or self.F.shape[1] != g.size:
            self.F = np.empty((self.depth + 1, g.size))
            self.G = np.empty((self.depth + 1, g.size))
            self.count = 0
        out = np.empty_like(g)
        mixed, self.count, self.last = _anderson_step(self.F, self.G, self.count, self.last, u, g,
                                                      residual_size, self.depth, self.mixing, out)
        return out if mixed else g


@njit(cache=True)
def _anderson_step(F, G, count, last, u, g, residual_size, depth, mixing, out):
    """One step of :class:`Anderson` on the history ``F``, ``G`` ((depth + 1, size), the
    ``count`` newest rows valid, oldest first) and the last residual size ``last``: appends
    f = g - u and g, restarting the history when the residual grew or is not finite, and writes
    the next iterate into ``out`` (size,). Returns (mixed, count, last); ``mixed`` False: the
    next iterate is ``g`` itself (``out`` not written)."""
    if depth <= 0:
        return False, count, last
    if residual_size > last:
        count = 0
    last = residual_size
    n = g.shape[0]
    for i in range(n):
        if not (np.isfinite(g[i] - u[i]) and np.isfinite(g[i])):
            return False, 0, last      # restart the history; plain fixed-point step
    if count == depth + 1:
        for j in range(depth):
            F[j] = F[j + 1]
            G[j] = G[j + 1]
        count -= 1
    for i in range(n):
        F[count, i] = g[i] - u[i]
        G[count, i] = g[i]
    count += 1
    if count < 2:
        if mixing == 1.0:
            return False, count, last
        damp = 1.0 - mixing
        for i in range(n):
            out[i] = g[i] - damp * F[count - 1, i]
        return True, count, last
    _anderson_combination(F, G, count, mixing, out)
    return True, count, last


@njit(cache=True)
def _anderson_combination(F, G, m, mixing, out):
    """Anderson (type II) mixing of the ``m`` newest history rows (oldest first) of the residuals
    ``F`` and images ``G`` (each (depth + 1, size)), into ``out`` (size,):

        gamma = argmin |f - dF gamma|,  out = g - dG gamma - (1 - mixing) (f - dF gamma),

    dF, dG the m - 1 successive differences and f, g the newest rows. The least-squares problem
    is solved by modified Gram-Schmidt with one re-orthogonalization; a difference column whose
    part orthogonal to the earlier ones is below 1e-12 of the largest column norm is left out
    (gamma 0), as a rank-revealing least-squares solve would drop it."""
    k = m - 1
    n = F.shape[1]
    f = F[m - 1]
    g = G[m - 1]
    Q = np.empty((k, n))
    Rm = np.zeros((k, k))
    keep = np.zeros(k, dtype=np.bool_)
    scale = 0.0
    for j in range(k):
        s = 0.0
        for i in range(n):
            v = F[j + 1, i] - F[j, i]
            Q[j, i] = v
            s += v * v
        scale = max(scale, np.sqrt(s))
    for j in range(k):
        for _ in range(2):
            for q in range(j):
                if not keep[q]:
                    continue
                r = 0.0
                for i in range(n):
                    r += Q[q, i] * Q[j, i]
                Rm[q, j] += r
                for i in range(n):
                    Q[j, i] -= r * Q[q, i]
        s = 0.0
        for i in range(n):
            s += Q[j, i] * Q[j, i]
        s = np.sqrt(s)
        if s > 1e-12 * scale and s > 0.0:
            keep[j] = True
            Rm[j, j] = s
            for i in range(n):
                Q[j, i] /= s
    # gamma = R^-1 Q^T f on the kept columns
    gamma = np.zeros(k)
    qf = np.zeros(k)
    for j in range(k):
        if keep[j]:
            r = 0.0
            for i in range(n):
                r += Q[j, i] * f[i]
            qf[j] = r
    for j in range(k - 1, -1, -1):
        if not keep[j]:
            continue
        r = qf[j]
        for q in range(j + 1, k):
            if keep[q]:
                r -= Rm[j, q] * gamma[q]
        gamma[j] = r / Rm[j, j]
    damp = 1.0 - mixing
    for i in range(n):
        fb = f[i]
        gb = g[i]
        for j in range(k):
            if keep[j]:
                fb -= (F[j + 1, i] - F[j, i]) * gamma[j]
                gb -= (G[j + 1, i] - G[j, i]) * gamma[j]
        out[i] = gb - damp * fb


_ROT90 = np.array([[0.0, -1.0], [1.0, 0.0]])


class FlatProblem:
    """All tubes of one configuration on flat arrays (nodes and segments tube after tube).

    Attributes
    ----------
    n : int
        Number of tubes.
    node_off : ndarray of int, shape (n + 1,)
        Tube t owns global nodes ``node_off[t]:node_off[t + 1]``.
    seg_off : ndarray of int, shape (n + 1,)
        Tube t owns segments ``seg_off[t]:seg_off[t + 1]``.
    s : list of ndarray, shape (N_t,)
        Node arc lengths of each tube [m].
    h : ndarray, shape (S,)
        Segment lengths [m].
    uhat, kinv : ndarray, shape (S, 3)
        Precurvatures [1/m] and inverse diagonal stiffness 1 / (k_xy h, k_xy h, k_z h)
        [1/(N m^3)] (Eq. (10)).
    u0 : ndarray, shape (S, 3)
        Standard solution as linearization point: u_i = Rz(-psi_i) u_xy + psi_i' e_z.
    pair, jo, ji : ndarray of int, shape (M,)
        Pair index i of each contact (tubes i, i + 1) and its global node on the outer and the
        inner tube.
    c, s_contact : ndarray, shape (M,)
        Clearance and arc length of each contact [m].
    Mblk : ndarray, shape (M, 2, 2)
        I + eta mu J (Eqs. (38), (40)).
    tq_out, tq_in : ndarray, shape (M,)
        Friction-torque factors eta mu c r_(i,in) and -eta mu c r_(i+1,out) [m^2] (Eq. (41)).
    friction : bool
    """

    def __init__(self, robot, standard, eta, mu):
        g = standard.grid
        n = robot.n_tubes
        self.n = n
        first = np.asarray(g.first, dtype=np.int64)
        last = np.asarray(g.last, dtype=np.int64)
        counts = last - first + 1
        self.node_off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.seg_off = (self.node_off - np.arange(n + 1)).astype(np.int64)
        self.s = [g.s[first[i]:last[i] + 1] for i in range(n)]
        self.h = np.concatenate([np.diff(s) for s in self.s])
        packed = pack_robot(robot)
        uhat, stiff, u0 = [], [], []
        for i in range(n):
            a, b = int(first[i]), int(last[i])
            hi = np.diff(self.s[i])
            uh = np.zeros((hi.size, 3))
            uh[:, :2] = g.precurvature[a:b, i]
            uhat.append(uh)
            kxy, kz = packed.k_xy[i], packed.k_z[i]
            stiff.append(np.column_stack([kxy * hi, kxy * hi, kz * hi]))
            psi = standard.psi_mid[a:b, i]
            ub = standard.bending_mid[a:b]
            c, sn = np.cos(psi), np.sin(psi)
            u0.append(np.column_stack([c * ub[:, 0] + sn * ub[:, 1], -sn * ub[:, 0] + c * ub[:, 1],
                                       standard.torsion_mid[a:b, i]]))
        self.uhat = np.concatenate(uhat)
        self.kinv = 1.0 / np.concatenate(stiff)
        self.u0 = np.concatenate(u0)
        self.alpha = np.asarray(standard.alpha, dtype=float)
        self.beta = np.asarray(standard.beta, dtype=float)
        # contacts: every common grid node of each adjacent pair
        clear = packed.clearance
        pair, jo, ji, cvec, svec = [], [], [], [], []
        for i in range(n - 1):
            lo = max(first[i], first[i + 1])
            hi = min(last[i], last[i + 1])
            nodes = np.arange(lo, hi + 1)
            pair.append(np.full(nodes.size, i))
            jo.append(self.node_off[i] + nodes - first[i])
            ji.append(self.node_off[i + 1] + nodes - first[i + 1])
            cvec.append(np.full(nodes.size, clear[i]))
            svec.append(g.s[nodes])
        cat = (lambda xs, dt: np.concatenate(xs).astype(dt) if xs else np.zeros(0, dtype=dt))
        self.pair = cat(pair, np.int64)
        self.jo = cat(jo, np.int64)
        self.ji = cat(ji, np.int64)
        self.c = cat(cvec, float)
        self.s_contact = cat(svec, float)
        self.M = self.pair.size
        self.N = int(self.node_off[-1])
        self.S = self.h.size
        self._packed = packed
        self._set_law(robot, eta, mu)
        self._allocate_work()

    def _set_law(self, robot, eta, mu):
        """The friction directions' part: ``Mblk``, ``tq_out``, ``tq_in``, ``friction``."""
        n = self.n
        mu = np.asarray(mu, dtype=float)
        r_in, r_out = (self._packed.contact_radii(robot) if np.any(mu > 0)
                       else (np.zeros(n - 1), np.zeros(n - 1)))
        eta = np.zeros(n - 1) if eta is None else np.asarray(eta, dtype=float)
        em = (eta * mu)[self.pair]
        self.Mblk = np.eye(2)[None, :, :] + em[:, None, None] * _ROT90[None, :, :]
        self.tq_out = em * self.c * r_in[self.pair]
        self.tq_in = -em * self.c * r_out[self.pair]
        self.friction = bool(np.any(em != 0.0))

    def _allocate_work(self):
        """Scratch arrays of the linearization kernels (each problem owns its own)."""
        N, S = self.N, self.S
        self._Omega = np.empty((S, 3, 3))
        self._base = np.empty((S, 3, 3))
        self._H1 = np.empty((N, 3, 3))
        self._H2 = np.empty((N, 3, 3))
        self._F3 = np.empty((N, 3, 3))
        self._Jpv = np.empty((N, 3))
        self._B = np.empty((self.M, 3, 2))
        self._dfree = np.empty((self.M, 2))
        self._diagW = np.empty((self.M, 2, 2))
        self._Pc = np.empty((self.M, 2, 3, 2, 3))
        # W and Z stored transposed (ck.fill_columns), reused by every linearization: only the
        # entries flagged in ``have`` (columns) and ``rows`` are ever read
        M = self.M
        self._work = ck.ContactWork(np.empty((2 * M, 2 * M)),
                                    np.empty((M, 2 * M)) if self.friction else np.empty((1, 1)),
                                    np.zeros(M, dtype=np.bool_), np.zeros(M, dtype=np.bool_))

    def with_directions(self, robot, eta, mu):
        """The same configuration with other friction directions ``eta`` (n - 1,) and
        coefficients ``mu`` (n - 1,): shares the grid, stiffness and contact arrays (read only)
        and gets its own friction law and scratch arrays. Costs about a fifth of building the
        problem again (measured 70 vs 330 us; the five solves of a bound share one configuration).

        Raises
        ------
        PhysicalParameterError
            Friction (mu > 0) on a pair without tube diameters (``Robot.contact_radii``).
        """
        other = copy.copy(self)
        other._set_law(robot, eta, mu)
        other._allocate_work()
        return other

    def kinematics(self, u):
        """Frames (N, 3, 3) and centerline points (N, 3) [m] of all tubes for curvatures u (S, 3)."""
        R = np.empty((self.N, 3, 3))
        p = np.empty((self.N, 3))
        chain_kinematics(u, self.h, self.alpha, self.beta, self.node_off, R, p)
        return R, p

    def split_nodes(self, arr):
        """Per-tube views of a node array (N, ...)."""
        return [arr[self.node_off[i]:self.node_off[i + 1]] for i in range(self.n)]

    def split_segments(self, arr):
        """Per-tube views of a segment array (S, ...)."""
        return [arr[self.seg_off[i]:self.seg_off[i + 1]] for i in range(self.n)]

    def contact_geometry(self, R, p):
        """The contacts and compliance factors of the current linearization (frames R (N, 3, 3),
        points p (N, 3) [m]) as the kernels take them (:class:`_contact_kernels.ContactGeometry`,
        built by :func:`_contact_geometry`, as in the compiled outer loop)."""
        return _contact_geometry(self.outer_arrays(), self.outer_scratch(), R, p)

    def contact_law(self, kappa):
        """Clearances, friction factors and the FB scale ``kappa`` [N/m] as the kernels take them
        (:class:`_contact_kernels.ContactLaw`, built by :func:`_contact_law`)."""
        return _contact_law(self.outer_arrays(), float(kappa))

    def outer_arrays(self):
        """The read-only arrays of the compiled outer loop (:class:`OuterArrays`)."""
        return OuterArrays(self.uhat, self.kinv, self.h, self.node_off, self.alpha, self.beta, self.pair, self.jo,
                           self.ji, self.c, self.Mblk, self.tq_out, self.tq_in, self.friction)

    def outer_scratch(self):
        """This problem's scratch arrays of the linearization kernels (:class:`OuterScratch`)."""
        return OuterScratch(self._Omega, self._base, self._H1, self._H2, self._F3, self._Jpv, self._B, self._dfree,
                            self._diagW, self._Pc)


class OuterArrays(NamedTuple):
    """The arrays of a :class:`FlatProblem` that the compiled outer loop reads (same names and
    shapes as there): ``uhat``, ``kinv`` (S, 3), ``h`` (S,), ``node_off`` (n + 1,), ``alpha``,
    ``beta`` (n,), ``pair``, ``jo``, ``ji``, ``c`` (M,), ``Mblk`` (M, 2, 2), ``tq_out``, ``tq_in``
    (M,), ``friction``."""

    uhat: np.ndarray
    kinv: np.ndarray
    h: np.ndarray
    node_off: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    pair: np.ndarray
    jo: np.ndarray
    ji: np.ndarray
    c: np.ndarray
    Mblk: np.ndarray
    tq_out: np.ndarray
    tq_in: np.ndarray
    friction: bool


class OuterScratch(NamedTuple):
    """Scratch arrays of the linearization kernels (``ck.linearize``, ``ck.contact_frames``,
    ``ck.contact_projections``), owned by one :class:`FlatProblem`."""

    Omega: np.ndarray
    base: np.ndarray
    H1: np.ndarray
    H2: np.ndarray
    F3: np.ndarray
    Jpv: np.ndarray
    B: np.ndarray
    dfree: np.ndarray
    diagW: np.ndarray
    Pc: np.ndarray


class OuterOptions(NamedTuple):
    """Stopping rules and constants of :func:`_outer_loop` (from ``ModelSettings`` and
    ``constants``): outer and complementarity tolerances [m], [-], iteration limits, Anderson
    depth and mixing, the stagnation window, the failed-solve limit and the inexact inner
    tolerance's factor and ceiling."""

    outer_tol: float
    complementarity_tol: float
    max_newton: int
    max_outer: int
    depth: int
    mixing: float
    window: int
    max_failed: int
    inner_factor: float
    inner_max: float


@njit(cache=True)
def _contact_geometry(arr, scr, R, p):
    """:class:`_contact_kernels.ContactGeometry` of a problem's arrays ``arr``
    (:class:`OuterArrays`) and scratch ``scr`` (:class:`OuterScratch`) at frames ``R``
    (N, 3, 3) and points ``p`` (N, 3) [m]."""
    return ck.ContactGeometry(arr.pair, arr.jo, arr.ji, scr.B, scr.Pc, R, p, scr.H1, scr.H2, scr.F3, scr.Omega,
                              scr.base, arr.kinv, arr.node_off)


@njit(cache=True)
def _contact_law(arr, kappa):
    """:class:`_contact_kernels.ContactLaw` of a problem's arrays ``arr`` (:class:`OuterArrays`)
    with the FB scale ``kappa`` [N/m]."""
    return ck.ContactLaw(arr.c, arr.Mblk, kappa, arr.tq_out, arr.tq_in, arr.friction)


@njit(cache=True)
def _outer_step(u, R, p, lam, arr, scr, work, tol, maxit, g):
    """One re-linearization at curvatures ``u`` (S, 3) with frames ``R`` (N, 3, 3) and points
    ``p`` (N, 3): the compliance factors, the contact frames, the multipliers to ``tol``
    (``ck.solve_contacts`` from ``lam`` (M,)) and the image F(u) into ``g`` (S, 3). Returns
    (lam, ok, Newton iterations)."""
    ck.linearize(u, arr.uhat, arr.kinv, arr.h, arr.node_off, R, p, scr.Omega, scr.base, scr.H1, scr.H2, scr.F3,
                 scr.Jpv)
    ck.contact_frames(R, p, arr.jo, arr.ji, scr.Jpv, scr.B, scr.dfree, scr.diagW, scr.H1, scr.H2, arr.pair)
    ck.contact_projections(scr.B, p, arr.jo, arr.ji, scr.H1, scr.H2, scr.Pc)
    M = arr.c.shape[0]
    diag_sum = 0.0
    for k in range(M):
        diag_sum += scr.diagW[k, 0, 0]
    for k in range(M):
        diag_sum += scr.diagW[k, 1, 1]
    kappa = 1.0 / max(diag_sum / max(2 * M, 1), 1e-300)
    geometry = _contact_geometry(arr, scr, R, p)
    law = _contact_law(arr, kappa)
    work.have[:] = False   # no column or row of this linearization computed yet
    work.rows[:] = False
    lam, d, ok, its, _ = ck.solve_contacts(lam, scr.dfree, geometry, law, work, tol, maxit)
    ck.generalized_curvature(lam, d, geometry, law, arr.uhat, g)
    return lam, ok, its


@njit(cache=True)
def _inner_tolerance(change, opt):
    """Tolerance of the complementarity solve of one outer iteration (inexact fixed-point
    iteration): ``opt.inner_factor`` x (last centerline change / ``outer_tol``) x
    ``complementarity_tol``, between ``complementarity_tol`` and ``opt.inner_max`` (this at the
    first iteration; ``constants.INNER_TOL_FACTOR``, ``INNER_TOL_MAX``). Far from the fixed
    point the multipliers of a linearization that will be replaced anyway need not be exact; an
    iteration counts as converged only when its solve used ``complementarity_tol`` itself."""
    tol = opt.complementarity_tol
    if not np.isfinite(change):
        return max(tol, opt.inner_max)
    return min(max(tol, opt.inner_max), max(tol, tol * opt.inner_factor * change / opt.outer_tol))


@njit(cache=True)
def _outer_loop(u, lam, arr, scr, work, opt):
    """:func:`run_outer_loop` compiled: the same iteration, stopping rules and Anderson steps,
    without a Python call per outer iteration (about a tenth of the bound's time in cProfile
    of the 4x4x4 grid). ``u`` (S, 3) and ``lam`` (M,) are not modified."""
    N = arr.node_off[-1]
    S = u.shape[0]
    M = arr.c.shape[0]
    R = np.empty((N, 3, 3))
    p = np.empty((N, 3))
    chain_kinematics(u, arr.h, arr.alpha, arr.beta, arr.node_off, R, p)
    converged = False
    inner_total = 0
    inner_ok = True
    change = np.inf
    outer = 0
    failed_in_a_row = 0
    depth = max(opt.depth, 0)
    Fh = np.empty((depth + 1, 3 * S))
    Gh = np.empty((depth + 1, 3 * S))
    count = int(0)   # a run-time int64 from the start: numba types _anderson_step once
    last = np.inf
    best = np.inf
    best_at = 0
    lam = lam.copy()
    for outer in range(1, opt.max_outer + 1):
        if M == 0:
            converged = True
            break
        inner_tol = _inner_tolerance(change, opt)
        g = np.empty((S, 3))
        lam, inner_ok, its = _outer_step(u, R, p, lam, arr, scr, work, inner_tol, opt.max_newton, g)
        inner_total += its
        failed_in_a_row = 0 if inner_ok else failed_in_a_row + 1
        if failed_in_a_row >= opt.max_failed:
            break
        Rg = np.empty((N, 3, 3))
        pg = np.empty((N, 3))
        chain_kinematics(g, arr.h, arr.alpha, arr.beta, arr.node_off, Rg, pg)
        change = 0.0
        for j in range(N):
            for q in range(3):
                change = max(change, abs(pg[j, q] - p[j, q]))
        if change < opt.outer_tol and inner_ok and inner_tol <= opt.complementarity_tol:
            u, R, p = g, Rg, pg
            converged = True
            break
        if change < best:
            best, best_at = change, outer
        elif outer - best_at >= opt.window:
            break
        out = np.empty((S, 3))
        mixed, count, last = _anderson_step(Fh, Gh, count, last, u.reshape(3 * S), g.reshape(3 * S), change,
                                            opt.depth, opt.mixing, out.reshape(3 * S))
        if not mixed:
            u, R, p = g, Rg, pg
        else:
            u = out
            R = np.empty((N, 3, 3))
            p = np.empty((N, 3))
            chain_kinematics(u, arr.h, arr.alpha, arr.beta, arr.node_off, R, p)
    return u, R, p, lam, converged, outer, inner_total, inner_ok, change


def run_outer_loop(prob, u, lam, settings):
    """Outer re-linearization loop (Section II-E, alpha = 1, Anderson-accelerated).

    Stops unconverged after ``MAX_FAILED_INNER_STEPS`` consecutive failed complementarity
    solves, which do not recover, or when the centerline change has not fallen below its
    smallest value so far for ``OUTER_STAGNATION_WINDOW`` iterations (``constants``): the
    iteration then wanders without approaching a fixed point (measured on the 8x8x8 grid of
    no configuration that converges does so after such a stretch).

    Parameters
    ----------
    prob : FlatProblem
    u : ndarray, shape (S, 3)
        First linearization point [1/m].
    lam : ndarray, shape (M,)
        Initial multipliers.
    settings : ModelSettings

    Returns
    -------
    u, R, p, lam, converged, outer iterations, Newton iterations, inner ok, last change [m]
    """
    opt = OuterOptions(float(settings.outer_tol), float(settings.complementarity_tol),
                       int(settings.max_newton_iterations), int(settings.max_outer_iterations),
                       int(settings.anderson_depth), float(ANDERSON_MIXING), int(OUTER_STAGNATION_WINDOW),
                       int(MAX_FAILED_INNER_STEPS), float(INNER_TOL_FACTOR), float(INNER_TOL_MAX))
    u, R, p, lam, converged, outer, inner_total, inner_ok, change = _outer_loop(
        np.ascontiguousarray(u, dtype=float), np.ascontiguousarray(lam, dtype=float), prob.outer_arrays(),
        prob.outer_scratch(), prob._work, opt)
    return u, R, p, lam, bool(converged), int(outer), int(inner_total), bool(inner_ok), float(change)
