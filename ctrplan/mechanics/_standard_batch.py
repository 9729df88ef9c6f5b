"""Standard model for many configurations in one compiled call (:func:`solve_standard_batch`).

Per configuration, the same steps as :func:`ctrplan.mechanics.solve_standard` with
``check_stability=False``: the common arc-length grid of Section II-C of Ha, Fagogenis & Dupont
2019 (``grid.build_grid``), damped Newton shooting on the base torsions with the exact
variational Jacobian (``standard._shoot``: coarse-grid predictor, then ``standard._newton``),
and the tip of the shared centerline from midpoint curvatures (``standard._tip_frame``), all in
numba with no Python work per configuration.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import config, get_num_threads, njit, parallel_chunksize, prange, set_num_threads

from ..constants import (GRID_MERGE_TOL, PREDICTOR_STEP_FACTOR,
                         UNIQUENESS_SCREEN_MARGIN)
from .grid import _grid
from .packed import pack_robot
from .results import ModelSettings
from . import warmup
from ._uniqueness import unique_equilibrium_certified_at
from .standard import _damping, _integrate, _multistart_search, _newton, _shoot, _solve_small, _tip_frame

__all__ = ["StandardBatch", "StandardPath", "solve_standard_batch", "solve_standard_path"]

_PREDICTOR_STEP_FACTOR = PREDICTOR_STEP_FACTOR  # frozen into the compiled code
# With ``follow`` on threads, the rows are cut into contiguous blocks of at least this many rows,
# up to _FOLLOW_BLOCKS_PER_THREAD per thread, handed out one at a time: a thread slowed by
# another process then takes fewer blocks instead of holding the others at the end of the call
# (trajectory x4 in chunks of 2048, one core 30 % busy with another process: 2 threads
# 1.52-1.53x one with a block per thread, 1.60-1.68x with 8 per thread, two runs; idle machine
# 1.83-1.87x and 1.85-1.86x). A block's first row starts without a previous row, which costs
# nothing measurable at 128 rows.
_FOLLOW_BLOCK_MIN_ROWS = 128
_FOLLOW_BLOCKS_PER_THREAD = 8
# following rows (:func:`_follow_shoot`): coarse quasi-Newton sweeps and fine chord sweeps at most
_FOLLOW_COARSE_SWEEPS = 8
_FOLLOW_FINE_SWEEPS = 3


@dataclass
class StandardBatch:
    """Tips of the standard model at K configurations.

    Attributes
    ----------
    tip_position : ndarray, shape (K, 3)
        [m]; NaN where the configuration is impossible.
    tip_tangent : ndarray, shape (K, 3)
        Unit tangent at the tip.
    base_torsion : ndarray, shape (K, n)
        Base torsions u_(i,z)(beta_i) [1/m] (``initial_guess`` of :func:`solve_standard`).
    converged : ndarray of bool, shape (K,)
        Newton shooting reached ``shooting_tol``.
    unstable : ndarray of bool, shape (K,)
        Shooting-Jacobian determinant not positive, or (with ``check_stability``) more than one
        equilibrium found: the flag of :func:`solve_standard` with the same ``check_stability``.
    valid : ndarray of bool, shape (K,)
        Configuration passed ``Robot.check_configuration`` (``Robot.configurations_possible``).
    iterations : ndarray of int, shape (K,)
        Newton iterations (including the multistart search's).
    n_equilibria : ndarray of int, shape (K,)
        Equilibria found (0: not checked, without ``check_stability`` or not converged).
    certified : ndarray of bool, shape (K,)
        The uniqueness screen proved a single equilibrium (``_uniqueness``; only with
        ``check_stability``), so no multistart search was needed.
    """

    tip_position: np.ndarray
    tip_tangent: np.ndarray
    base_torsion: np.ndarray
    converged: np.ndarray
    unstable: np.ndarray
    valid: np.ndarray
    iterations: np.ndarray
    n_equilibria: np.ndarray
    certified: np.ndarray


class BatchTubes(NamedTuple):
    """The arrays of :class:`~ctrplan.mechanics.packed.PackedRobot` that the batch kernels read
    (n tubes, B breaks at most per tube).

    Attributes
    ----------
    lengths : ndarray, shape (n,)
        Tube lengths [m].
    breaks : ndarray, shape (n, B)
        Tube-local section breaks [m].
    n_breaks : ndarray of int64, shape (n,)
        Breaks per tube.
    precurvature : ndarray, shape (n, B - 1, 2)
        Section precurvatures [1/m].
    k_xy : ndarray, shape (n,)
        Bending stiffnesses [N m^2].
    stiffness_ratio : ndarray, shape (n,)
        k_xy / k_z [-].
    """

    lengths: np.ndarray
    breaks: np.ndarray
    n_breaks: np.ndarray
    precurvature: np.ndarray
    k_xy: np.ndarray
    stiffness_ratio: np.ndarray


class BatchOptions(NamedTuple):
    """Discretization and solver options of the batch kernels (from ``ModelSettings``).

    Attributes
    ----------
    ds : float
        Largest grid step [m].
    merge_tol, refine_ratio, refine_length : float
        Grid options of ``grid._grid``: breakpoint merge tolerance [m], step at a breakpoint of
        the overlap as a fraction of ``ds`` [-], grading length [m].
    tol : float
        Shooting tolerance on the tip torsions [1/m].
    maxit : int
        Newton iterations per start.
    multistart : int
        Restarts of the multistart search (0: determinant test only).
    predict : bool
        Start from zero twist through the coarse-grid predictor (no ``initial_guess`` given).
    follow : bool
        Rows are a path (see :func:`solve_standard_batch`).
    """

    ds: float
    merge_tol: float
    refine_ratio: float
    refine_length: float
    tol: float
    maxit: int
    multistart: int
    predict: bool
    follow: bool


class BatchOutput(NamedTuple):
    """Per-configuration outputs of the batch kernels, written in place (K configurations,
    n tubes); the fields of :class:`StandardBatch` of the same names.

    Attributes
    ----------
    tips, tans : ndarray, shape (K, 3)
        Tip positions [m] and unit tip tangents.
    sig_out : ndarray, shape (K, n)
        Base torsions [1/m].
    conv, unst : ndarray of bool, shape (K,)
        Converged; unstable.
    iters, n_eq : ndarray of int64, shape (K,)
        Newton iterations; equilibria found.
    certified : ndarray of bool, shape (K,)
        Uniqueness screen passed.
    """

    tips: np.ndarray
    tans: np.ndarray
    sig_out: np.ndarray
    conv: np.ndarray
    unst: np.ndarray
    iters: np.ndarray
    n_eq: np.ndarray
    certified: np.ndarray


@njit(cache=True, error_model="numpy")
def _follow_shoot(s, present, uh, cs, cpresent, cuh, kxy, ratio, alpha, lengths, tol, state):
    """Shooting for a row that follows the row before on a path, without sensitivity sweeps.

    ``state`` (n + 4, n) carries from the rows before: a coarse-grid shooting Jacobian (rows
    0..n-1; NaN: none yet, then one coarse sweep with sensitivities gives it), the coarse-grid
    solution (row n) and the offset of the fine-grid solution from it (row n + 1) of the row
    before, and those of the row before that (rows n + 2, n + 3; NaN: none). The coarse problem
    is solved to ``tol`` by quasi-Newton steps with Broyden updates of the Jacobian (sweeps
    without sensitivities, which cost a third of a sweep with them on the coarse grid), from
    the previous solution extrapolated linearly over the rows; the fine grid starts from the
    coarse solution plus the offset, extrapolated the same way, and takes chord steps with the
    coarse Jacobian until a sweep meets ``tol``. On the measured trajectory (Table VII robot,
    300 rows) that is 4.6 coarse and 1.6 fine sweeps per row (without extrapolation 5.0 and
    1.9), against 2.6 coarse sweeps with sensitivities and 2 fine ones of the predictor. Each
    iteration must decrease the residual; anything else gives up (``ok`` False, ``state``
    unchanged) and the caller solves the row from scratch (:func:`standard._shoot`).

    Returns (sig0, residual, sweeps, ok, detJ, psi, sigma) like :func:`standard._newton`, with
    detJ the determinant of the coarse quasi-Newton Jacobian (used only for rows that the
    uniqueness screen certified, whose equilibrium is stable); updates ``state`` on success.
    """
    n = alpha.shape[0]
    J = state[:n].copy()
    x = state[n].copy()
    off = state[n + 1].copy()
    if np.all(np.isfinite(state[n + 2:])):
        x += state[n] - state[n + 2]
        off += state[n + 1] - state[n + 3]
    empty = np.zeros((1, n))
    sweeps = 1
    if np.all(np.isfinite(J)):
        _, r, _, _, _, _, _ = _integrate(cs, cpresent, cuh, kxy, ratio, alpha, x, False, False)
    else:
        _, r, _, Ss, _, _, _ = _integrate(cs, cpresent, cuh, kxy, ratio, alpha, x, False, True)
        J = Ss.copy()
    res = np.max(np.abs(r))
    converged = False
    for _ in range(_FOLLOW_COARSE_SWEEPS):
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
            break
        if res < tol:
            converged = True
            break
        det, step = _solve_small(J, r)
        if not abs(det) > 0.0:
            break
        dx = -_damping(step, lengths) * step
        xn = x + dx
        _, rn, _, _, _, _, _ = _integrate(cs, cpresent, cuh, kxy, ratio, alpha, xn, False, False)
        sweeps += 1
        res_n = np.max(np.abs(rn))
        if not res_n < res:
            break
        # Broyden's update: J dx = rn - r afterwards, J unchanged across dx
        y = rn - r - J @ dx
        J += np.outer(y, dx) / np.dot(dx, dx)
        x, r, res = xn, rn, res_n
    if not converged:
        return x, np.inf, sweeps, False, np.nan, empty, empty
    x1 = x + off
    for _ in range(_FOLLOW_FINE_SWEEPS):
        _, r1, _, _, psi, sig, _ = _integrate(s, present, uh, kxy, ratio, alpha, x1, True, False)
        sweeps += 1
        if not np.all(np.isfinite(r1)):
            break
        res1 = np.max(np.abs(r1))
        if res1 < tol:
            detJ = _solve_small(J, r1)[0]
            if not detJ > 0.0:
                break
            state[:n] = J
            state[n + 2] = state[n]
            state[n + 3] = state[n + 1]
            state[n] = x
            state[n + 1] = x1 - x
            return x1, res1, sweeps, True, detJ, psi, sig
        det, step = _solve_small(J, r1)
        if not abs(det) > 0.0:
            break
        x1 = x1 - _damping(step, lengths) * step
    return x1, np.inf, sweeps, False, np.nan, empty, empty


@njit(cache=True)
def _restart_state(state, sig0, ok):
    """The state of :func:`_follow_shoot` after a row solved from scratch: its solution as the
    next coarse start, no offset, no Jacobian (NaN: computed at the next row) and no rows before
    it to extrapolate from; all NaN if the row did not converge."""
    n = sig0.shape[0]
    state[:] = np.nan
    if ok:
        state[n] = sig0
        state[n + 1] = 0.0


@njit(cache=True)
def _solve_one(k, alpha, beta, sig_init, tubes, opts, follow_from, out, state):
    """Configuration ``k`` of the batch: grid, Newton shooting (retried from zero twist), tip.

    ``alpha``, ``beta`` (K, n) [rad], [m]; ``sig_init`` (K, n) [1/m] starts; ``tubes`` a
    :class:`BatchTubes`, ``opts`` a :class:`BatchOptions`; ``follow_from`` (n,) [1/m];
    results into row ``k`` of ``out`` (:class:`BatchOutput`).

    With ``multistart`` > 0, the stability check of :func:`ctrplan.mechanics.solve_standard`:
    configurations that the uniqueness screen (``_uniqueness``) certifies have one equilibrium
    and need no search; the others get the multistart search for other equilibria. A certified
    configuration may also start from ``follow_from`` (the base torsions of the row before;
    NaN: none): its only equilibrium is found from any start that converges. With ``predict``
    such a row is first solved by :func:`_follow_shoot` from the rows before (``state``
    (n + 4, n), carried along the rows; see there), and if that gives up, from ``follow_from``
    through the coarse-grid predictor (``standard._shoot``: coarse Newton, chord step, fine
    Newton); without ``predict`` by Newton on the fine grid. Starting the fine Newton from the
    previous row directly, as before, took fewer but dearer iterations: 0.67 against
    0.50 ms per row without following on the Table VII trajectory (all rows certified), 0.45
    with the predictor (CPU time, docs/mechanics.md, Sec. 10)."""
    lengths, brk, nbrk, curv = tubes.lengths, tubes.breaks, tubes.n_breaks, tubes.precurvature
    kxy, ratio = tubes.k_xy, tubes.stiffness_ratio
    ds, tol, maxit, multistart, predict = opts.ds, opts.tol, opts.maxit, opts.multistart, opts.predict
    merge_tol, refine_ratio, refine_length = opts.merge_tol, opts.refine_ratio, opts.refine_length
    tips, tans, sig_out, conv, unst = out.tips, out.tans, out.sig_out, out.conv, out.unst
    iters, n_eq, certified = out.iters, out.n_eq, out.certified
    n = alpha.shape[1]
    s, first, last, present, uhat = _grid(beta[k], lengths, brk, nbrk, curv, ds, merge_tol, refine_ratio,
                                          refine_length)
    # the coarse grid: read by the predictor, the uniqueness screen and the multistart search
    cs, cpresent, cuhat = s, present, uhat
    if predict or multistart > 0:
        cs, cfirst, clast, cpresent, cuhat = _grid(beta[k], lengths, brk, nbrk, curv, _PREDICTOR_STEP_FACTOR * ds,
                                                   merge_tol, refine_ratio, refine_length)
    unique = False
    if multistart > 0:
        # on the coarse grid (a quarter of the nodes): see _uniqueness, "Grid"
        unique = unique_equilibrium_certified_at(cs, cfirst, clast, cpresent, cuhat, kxy, kxy / ratio,
                                                 UNIQUENESS_SCREEN_MARGIN, alpha[k])
        certified[k] = unique
    a = alpha[k].copy()
    it = 0
    ok = False
    if unique and np.all(np.isfinite(follow_from)):
        if predict:
            if np.all(np.isfinite(state[n:n + 2])):
                sig0, _, it, ok, detJ, psi, sig = _follow_shoot(s, present, uhat, cs, cpresent, cuhat, kxy, ratio,
                                                                a, lengths, tol, state)
            if not ok:
                sig0, _, it2, ok, detJ, psi, sig = _shoot(s, present, uhat, cs, cpresent, cuhat, kxy, ratio, a,
                                                          follow_from.copy(), lengths, tol, maxit, bool(True))
                it += it2
                _restart_state(state, sig0, ok)
        else:
            sig0, _, it, ok, detJ, psi, sig = _newton(s, present, uhat, kxy, ratio, a, follow_from.copy(), lengths,
                                                      tol, maxit, np.empty((n, n)))
    if not ok:
        sig0, _, it2, ok, detJ, psi, sig = _shoot(s, present, uhat, cs, cpresent, cuhat, kxy, ratio, a,
                                                  sig_init[k], lengths, tol, maxit, predict)
        it += it2
        _restart_state(state, sig0, ok)
        if not ok and not predict:   # a given initial guess failed: retry from no twist
            sig0, _, it2, ok, detJ, psi, sig = _newton(s, present, uhat, kxy, ratio, a, np.zeros(n), lengths,
                                                       tol, maxit, np.empty((n, n)))
            it += it2
    unstable = ok and not detJ > 0.0
    count = 0
    if ok and multistart > 0 and not unique:
        # the multistart search of solve_standard (same guesses, coarse-grid restarts)
        count, ms_it = _multistart_search(s, present, uhat, cs, cpresent, cuhat, kxy, ratio, a, sig0, lengths,
                                          tol, maxit, multistart)
        it += ms_it
        if count > 1:
            unstable = True
    elif ok and unique:
        count = 1
    n_eq[k] = count
    iters[k] = it
    conv[k] = ok
    unst[k] = unstable
    sig_out[k] = sig0
    p, R = _tip_frame(s, present, uhat, kxy, psi, sig)
    tips[k] = p
    tans[k] = R[:, 2]


@njit(cache=True)
def _rows(lo, hi, alpha, beta, valid, sig_init, tubes, opts, out):
    """Rows ``lo`` to ``hi - 1`` in order; with ``opts.follow``, each certified row starts from
    the row before (its base torsions and the quasi-Newton state of :func:`_follow_shoot`)."""
    n = alpha.shape[1]
    prev = np.full(n, np.nan)
    state = np.full((n + 4, n), np.nan)
    for k in range(lo, hi):
        if valid[k]:
            _solve_one(k, alpha, beta, sig_init, tubes, opts, prev, out, state)
            if opts.follow and out.conv[k]:
                prev = out.sig_out[k].copy()
            else:
                prev = np.full(n, np.nan)


@njit(cache=True)
def _batch(alpha, beta, valid, sig_init, tubes, opts, out):
    """All configurations in order (serial; with ``opts.follow``, each certified row starts
    from the previous row's base torsions).

    Parameters
    ----------
    alpha, beta : ndarray, shape (K, n)
        Base rotations [rad] and translations [m].
    valid : ndarray of bool, shape (K,)
        Configurations to solve (the others are left as initialized).
    sig_init : ndarray, shape (K, n)
        Starting base torsions [1/m] (read when ``opts.predict`` is False).
    tubes : BatchTubes
    opts : BatchOptions
    out : BatchOutput
        Written in place.
    """
    _rows(0, alpha.shape[0], alpha, beta, valid, sig_init, tubes, opts, out)


@njit(cache=True, parallel=True)
def _batch_parallel(alpha, beta, valid, sig_init, tubes, opts, out, n_blocks):
    """:func:`_batch` with the configurations shared by numba threads (``prange``). With
    ``opts.follow`` the rows are cut into ``n_blocks`` contiguous blocks, one per task, each
    followed in order as by :func:`_batch` (a block's first row starts without a previous row);
    without, the rows themselves are shared. Same parameters, and ``n_blocks`` (int >= 1)."""
    K, n = alpha.shape
    if opts.follow:
        for b in prange(n_blocks):
            _rows(b * K // n_blocks, (b + 1) * K // n_blocks, alpha, beta, valid, sig_init, tubes, opts, out)
    else:
        for k in prange(K):
            if valid[k]:
                _solve_one(k, alpha, beta, sig_init, tubes, opts, np.full(n, np.nan), out,
                           np.full((n + 4, n), np.nan))


@njit(cache=True, error_model="numpy")
def _path_row(k, alpha, beta, start, predict, tubes, opts, out, res_out, det_out):
    """Configuration ``k`` exactly as :func:`ctrplan.mechanics.solve_standard` solves it from
    ``start`` (n,) [1/m] (``predict``: no initial guess, ``start`` is zero twist): Newton
    shooting (``standard._shoot``), retried from zero twist if a given start fails, the
    determinant test, with ``opts.multistart`` > 0 the multistart search, and the tip. Writes
    row ``k`` of ``out`` and the tip-torsion residual [1/m] and shooting-Jacobian determinant
    into ``res_out``, ``det_out``."""
    lengths, brk, nbrk, curv = tubes.lengths, tubes.breaks, tubes.n_breaks, tubes.precurvature
    kxy, ratio = tubes.k_xy, tubes.stiffness_ratio
    n = alpha.shape[1]
    s, first, last, present, uhat = _grid(beta[k], lengths, brk, nbrk, curv, opts.ds, opts.merge_tol,
                                          opts.refine_ratio, opts.refine_length)
    cs, cpresent, cuhat = s, present, uhat
    if predict or opts.multistart > 0:
        cs, _, _, cpresent, cuhat = _grid(beta[k], lengths, brk, nbrk, curv, _PREDICTOR_STEP_FACTOR * opts.ds,
                                          opts.merge_tol, opts.refine_ratio, opts.refine_length)
    a = alpha[k].copy()
    sig0, res, it, ok, detJ, psi, sig = _shoot(s, present, uhat, cs, cpresent, cuhat, kxy, ratio, a, start.copy(),
                                               lengths, opts.tol, opts.maxit, predict)
    if not ok and not predict:
        sig0, res, it2, ok, detJ, psi, sig = _shoot(s, present, uhat, s, present, uhat, kxy, ratio, a, np.zeros(n),
                                                    lengths, opts.tol, opts.maxit, False)
        it += it2
    unstable = ok and not detJ > 0.0
    count = 0
    if ok and opts.multistart > 0:
        count, ms_it = _multistart_search(s, present, uhat, cs, cpresent, cuhat, kxy, ratio, a, sig0, lengths,
                                          opts.tol, opts.maxit, opts.multistart)
        it += ms_it
        if count > 1:
            unstable = True
    out.n_eq[k] = count
    out.iters[k] = it
    out.conv[k] = ok
    out.unst[k] = unstable
    out.sig_out[k] = sig0
    res_out[k] = res
    det_out[k] = detJ
    if ok:
        p, R = _tip_frame(s, present, uhat, kxy, psi, sig)
        out.tips[k] = p
        out.tans[k] = R[:, 2]


@njit(cache=True)
def _path(alpha, beta, valid, guess, follow, tubes, opts, out, res_out, det_out, reused):
    """Rows in order, each started as a sequence of :func:`ctrplan.mechanics.solve_standard`
    calls starts it (see :func:`solve_standard_path`); ``reused`` (K,) bool is set where a row
    repeats the previous row's configuration and start and takes its solution."""
    K, n = alpha.shape
    prev = -1              # row of the last converged solution (-1: none)
    prev_start = np.zeros(n)
    prev_start_kind = 0    # start of the last row: 0 none (no guess, or reset), 1 given
    start = np.zeros(n)
    for k in range(K):
        if not valid[k]:
            prev = -1
            prev_start_kind = 0
            continue
        if follow[k]:
            given = prev >= 0
            if given:
                start[:] = out.sig_out[prev]
        else:
            given = not np.isnan(guess[k, 0])
            if given:
                start[:] = guess[k]
        same_config = prev >= 0 and np.array_equal(alpha[k], alpha[prev]) and np.array_equal(beta[k], beta[prev])
        same_start = follow[k] or (not given and prev_start_kind == 0) or (
            given and prev_start_kind == 1 and np.array_equal(start, prev_start))
        if same_config and same_start:
            out.tips[k] = out.tips[prev]
            out.tans[k] = out.tans[prev]
            out.sig_out[k] = out.sig_out[prev]
            out.conv[k] = out.conv[prev]
            out.unst[k] = out.unst[prev]
            out.n_eq[k] = out.n_eq[prev]
            res_out[k] = res_out[prev]
            det_out[k] = det_out[prev]
            reused[k] = True
        else:
            if not given:
                start[:] = 0.0
            _path_row(k, alpha, beta, start, not given, tubes, opts, out, res_out, det_out)
        if given:
            prev_start[:] = start
        prev_start_kind = 1 if given else 0
        prev = k if out.conv[k] else -1


@dataclass
class StandardPath(StandardBatch):
    """:class:`StandardBatch` of :func:`solve_standard_path`, with per row:

    Attributes
    ----------
    residual : ndarray, shape (K,)
        Largest tip-torsion residual [1/m] of the last Newton iterate.
    determinant : ndarray, shape (K,)
        Shooting-Jacobian determinant at the solution (NaN where not converged).
    reused : ndarray of bool, shape (K,)
        The row repeated the previous row's configuration and start and took its solution
        without solving.
    """

    residual: np.ndarray = None
    determinant: np.ndarray = None
    reused: np.ndarray = None


def solve_standard_path(robot, alpha, beta, settings: ModelSettings | None = None, *, initial_guess=None,
                        follow=None, check_stability: bool = False) -> StandardPath:
    """The standard model along rows in order, each solved as one :func:`solve_standard` call
    started the way a caller following a path would start it, in one compiled call.

    Row k is ``solve_standard(robot, alpha[k], beta[k], settings, initial_guess=start,
    check_stability=check_stability)`` with ``start`` the base torsions of the last row whose
    shooting converged if ``follow[k]`` (none if that row was impossible or did not converge),
    else ``initial_guess[k]`` (none where it is NaN). A row whose configuration and start equal
    the previous row's takes its solution without solving (``reused``). The numbers are those
    of :func:`solve_standard` (same grids, iterations and tip arithmetic).

    Parameters
    ----------
    robot : Robot
    alpha, beta : array-like, shape (K, n)
        Base rotations [rad] and translations [m].
    settings : ModelSettings, optional
    initial_guess : array-like, shape (K, n), optional
        Base torsions [1/m]; NaN rows (default all): no initial guess.
    follow : array-like of bool, shape (K,), optional
        Rows that start from the previous solution (default none).
    check_stability : bool
        Run the multistart search of :func:`solve_standard` at every converged row.

    Returns
    -------
    StandardPath
        Impossible configurations are flagged ``valid = False`` (NaN tips) instead of raising;
        tips are NaN where the shooting did not converge.

    Raises
    ------
    ValueError
        If the arrays do not have the shapes above.

    Notes
    -----
    Section II-A of Ha, Fagogenis & Dupont 2019 (refs [10], [11]), as :func:`solve_standard`.
    """
    settings = settings or ModelSettings()
    n = robot.n_tubes
    alpha, beta = configuration_arrays(robot, alpha, beta)
    K = alpha.shape[0]
    guess = (np.full((K, n), np.nan) if initial_guess is None
             else np.ascontiguousarray(np.broadcast_to(initial_guess, (K, n)), dtype=float))
    follow = np.zeros(K, dtype=bool) if follow is None else np.ascontiguousarray(follow, dtype=bool)
    if follow.shape != (K,):
        raise ValueError(f"follow must have shape ({K},), got {follow.shape}")
    valid = robot.configurations_possible(alpha, beta)
    pk = pack_robot(robot)
    out = BatchOutput(np.full((K, 3), np.nan), np.full((K, 3), np.nan), np.full((K, n), np.nan),
                      np.zeros(K, dtype=bool), np.zeros(K, dtype=bool), np.zeros(K, dtype=np.int64),
                      np.zeros(K, dtype=np.int64), np.zeros(K, dtype=bool))
    residual = np.full(K, np.nan)
    determinant = np.full(K, np.nan)
    reused = np.zeros(K, dtype=bool)
    tubes = BatchTubes(pk.lengths, pk.breaks, pk.n_breaks, pk.precurvature, pk.k_xy, pk.stiffness_ratio)
    opts = BatchOptions(ds=float(settings.ds), merge_tol=float(GRID_MERGE_TOL),
                        refine_ratio=float(settings.refine_ratio), refine_length=float(settings.refine_length),
                        tol=float(settings.shooting_tol), maxit=int(settings.max_shooting_iterations),
                        multistart=int(settings.multistart) if check_stability else 0, predict=False,
                        follow=True)
    _path(alpha, beta, valid, guess, follow, tubes, opts, out, residual, determinant, reused)
    determinant[~out.conv] = np.nan
    return StandardPath(tip_position=out.tips, tip_tangent=out.tans, base_torsion=out.sig_out,
                        converged=out.conv, unstable=out.unst, valid=valid, iterations=out.iters,
                        n_equilibria=out.n_eq, certified=out.certified, residual=residual,
                        determinant=determinant, reused=reused)


def configuration_arrays(robot, alpha, beta):
    """``alpha``, ``beta`` as contiguous float arrays, checked to be both of shape (K, n).

    Raises
    ------
    ValueError
        Naming both shapes.
    """
    n = robot.n_tubes
    alpha = np.ascontiguousarray(alpha, dtype=float)
    beta = np.ascontiguousarray(beta, dtype=float)
    if alpha.ndim != 2 or alpha.shape[1] != n or beta.shape != alpha.shape:
        raise ValueError(f"alpha and beta must both have shape (K, {n}), got {alpha.shape} and {beta.shape}")
    return alpha, beta


def solve_standard_batch(robot, alpha, beta, settings: ModelSettings | None = None, *,
                         initial_guess=None, n_threads: int = 1, check_stability: bool = False,
                         follow: bool = False, compile_threads: bool = False) -> StandardBatch:
    """Solve the standard zero-clearance model at many configurations in one compiled call.

    Parameters
    ----------
    robot : Robot
    alpha : array-like, shape (K, n)
        Base rotations [rad].
    beta : array-like, shape (K, n)
        Base translations [m].
    settings : ModelSettings, optional
        Uses ``ds``, ``refine_ratio``, ``refine_length``, ``shooting_tol`` and ``max_shooting_iterations``
        (no multistart search).
    initial_guess : array-like, shape (K, n), optional
        Base torsions [1/m] to start each Newton solve from (default: no twist, through the
        coarse-grid predictor and, where Newton stalls, the restarts of :func:`solve_standard`);
        as in :func:`solve_standard`, a failed given start is retried from zero twist.
    n_threads : int
        Threads sharing the configurations (numba ``prange``, at most ``NUMBA_NUM_THREADS``); 1 (default) runs serially, as
        fits a call from inside a worker process. Results do not depend on it. The threaded
        kernel costs about a minute of compilation more than the serial one, which threads
        pay back only over millions of rows: until it is compiled or cached, a call runs
        serially and compiles it in a background process for later calls
        (:func:`ctrplan.mechanics.warmup.threaded_batch_usable`).
    compile_threads : bool
        With ``n_threads`` > 1, use the threaded kernel even if it has to be compiled first.
    check_stability : bool
        Flag configurations with more than one equilibrium as :func:`solve_standard` does
        (``settings.multistart`` restarts), but run that search only where the uniqueness
        screen cannot prove a single equilibrium (``_uniqueness``: the worst-case second
        variation of the energy is positive definite). Default False: determinant test only.
    follow : bool
        Rows are a path: where the screen proves a single equilibrium, start from the previous
        row's base torsions (through the coarse-grid predictor when no ``initial_guess`` is
        given; with ``n_threads`` > 1 the threads take contiguous blocks of the rows, at least 128
        rows and up to 8 per thread, one at a time, and follow each from its first row). The
        result is the same equilibrium to the shooting tolerance (tips within 2e-11 m on the
        trajectory), found in fewer sweeps.

    Returns
    -------
    StandardBatch
        Tip positions and tangents, base torsions and per-configuration flags. Impossible
        configurations are flagged ``valid = False`` (NaN tips) instead of raising.

    Raises
    ------
    ValueError
        If ``alpha`` and ``beta`` are not both of shape (K, n), or ``n_threads`` < 1.

    Notes
    -----
    Section II-A of Ha, Fagogenis & Dupont 2019 (refs [10], [11]); the same discretization,
    tolerances and Newton iteration as :func:`solve_standard` with ``check_stability=False``,
    so tips agree with it to the shooting tolerance. The stability flag is the
    Jacobian-determinant test only, unless ``check_stability``.
    """
    settings = settings or ModelSettings()
    n = robot.n_tubes
    alpha, beta = configuration_arrays(robot, alpha, beta)
    if int(n_threads) < 1:
        raise ValueError(f"n_threads must be at least 1, got {n_threads!r}")
    K = alpha.shape[0]
    sig_init = (np.zeros((K, n)) if initial_guess is None
                else np.ascontiguousarray(np.broadcast_to(initial_guess, (K, n)), dtype=float))
    valid = robot.configurations_possible(alpha, beta)
    pk = pack_robot(robot)
    tips = np.full((K, 3), np.nan)
    tans = np.full((K, 3), np.nan)
    sig_out = np.full((K, n), np.nan)
    conv = np.zeros(K, dtype=bool)
    unst = np.zeros(K, dtype=bool)
    iters = np.zeros(K, dtype=np.int64)
    n_eq = np.zeros(K, dtype=np.int64)
    certified = np.zeros(K, dtype=bool)
    multistart = int(settings.multistart) if check_stability else 0
    tubes = BatchTubes(pk.lengths, pk.breaks, pk.n_breaks, pk.precurvature, pk.k_xy, pk.stiffness_ratio)
    opts = BatchOptions(ds=float(settings.ds), merge_tol=float(GRID_MERGE_TOL),
                        refine_ratio=float(settings.refine_ratio), refine_length=float(settings.refine_length),
                        tol=float(settings.shooting_tol), maxit=int(settings.max_shooting_iterations),
                        multistart=multistart, predict=initial_guess is None, follow=bool(follow))
    out = BatchOutput(tips, tans, sig_out, conv, unst, iters, n_eq, certified)
    args = (alpha, beta, valid, sig_init, tubes, opts, out)
    if int(n_threads) == 1 or not warmup.threaded_batch_usable(_batch_parallel, compile_threads):
        _batch(*args)
    else:
        before = get_num_threads()
        set_num_threads(min(int(n_threads), config.NUMBA_NUM_THREADS))
        try:
            nt = get_num_threads()
            n_blocks = max(nt, min(_FOLLOW_BLOCKS_PER_THREAD * nt, K // _FOLLOW_BLOCK_MIN_ROWS))
            with parallel_chunksize(1 if follow else 0):
                _batch_parallel(*args, n_blocks)
        finally:
            set_num_threads(before)
    return StandardBatch(tip_position=tips, tip_tangent=tans, base_torsion=sig_out, converged=conv,
                         unstable=unst, valid=valid, iterations=iters, n_equilibria=n_eq,
                         certified=certified)
