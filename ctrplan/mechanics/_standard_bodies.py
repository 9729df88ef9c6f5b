"""Standard-model robot bodies for many configurations in one compiled call.

:func:`solve_standard_bodies` runs, per configuration, exactly the steps of
:func:`~ctrplan.mechanics.solve_standard_batch` with ``initial_guess=None`` (the common
arc-length grid of Section II-C of Ha, Fagogenis & Dupont 2019 built by ``grid._grid``, Newton
shooting on the base torsions through the coarse-grid predictor and its restarts,
``standard._shoot``, and the shared centerline of Eq. (57), ``standard._centerline``) and keeps
what collision checking needs: the body of
:meth:`~ctrplan.mechanics.results.StandardSolution.body`, i.e. the centerline points at or
distal to the most distal tube base, each with the outer radius of the outermost tube present.
The kernels of ``_standard_batch`` are reused unchanged; only the body extraction is new.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from ..constants import GRID_MERGE_TOL, PREDICTOR_STEP_FACTOR
from .grid import _grid
from .packed import PackedRobot, pack_robot
from .results import BODY_TOL, ModelSettings
from ._standard_batch import BatchOptions, BatchTubes, configuration_arrays
from .standard import _centerline, _shoot

__all__ = ["StandardBodies", "solve_standard_bodies"]

_PREDICTOR_STEP_FACTOR = PREDICTOR_STEP_FACTOR  # frozen into the compiled code
# Slack of the body tests of StandardSolution.body [m]: a node belongs to the body when
# s >= max(beta) - _BODY_TOL, and tube i is present at s when
# beta_i - _BODY_TOL <= s <= beta_i + L_i + _BODY_TOL (results.BODY_TOL, frozen into the kernels).
_BODY_TOL = BODY_TOL


class _BodiesOutput(NamedTuple):
    """Outputs of :func:`_bodies`, written in place (K configurations, P points at most per
    body): ``points`` (K, P, 3) [m], ``radii`` (K, P) [m], ``counts`` (K,) int64, ``tips``
    (K, 3) [m], ``conv`` and ``unst`` (K,) bool, ``iters`` (K,) int64 (the fields of
    :class:`StandardBodies`)."""

    points: np.ndarray
    radii: np.ndarray
    counts: np.ndarray
    tips: np.ndarray
    conv: np.ndarray
    unst: np.ndarray
    iters: np.ndarray


@dataclass
class StandardBodies:
    """Robot bodies of the standard model at K configurations, as padded arrays.

    Body k is ``points[k, :counts[k]]`` with radii ``radii[k, :counts[k]]``, equal to
    ``solve_standard(robot, alpha[k], beta[k], settings.replace(multistart=0)).body(robot)``.

    Attributes
    ----------
    points : ndarray, shape (K, P, 3)
        Centerline points of each body [m], from the most distal tube base to the tip; NaN
        beyond ``counts[k]``. P is the largest count of the batch (0 when no configuration is
        possible).
    radii : ndarray, shape (K, P)
        Outer radius of the outermost tube present at each point [m] (0 where no tube is, as
        in ``StandardSolution.body``); NaN beyond ``counts[k]``.
    counts : ndarray of int, shape (K,)
        Points of each body; 0 for impossible configurations.
    tip_position : ndarray, shape (K, 3)
        [m]; NaN where the configuration is impossible.
    converged : ndarray of bool, shape (K,)
        Newton shooting reached ``shooting_tol`` (``diagnostics.converged``).
    unstable : ndarray of bool, shape (K,)
        Converged with a shooting-Jacobian determinant that is not positive
        (``diagnostics.unstable`` with ``multistart=0``).
    valid : ndarray of bool, shape (K,)
        The configuration passed ``Robot.check_configuration``
        (``Robot.configurations_possible``); the others are not solved.
    iterations : ndarray of int, shape (K,)
        Newton iterations of all shooting stages (``diagnostics.iterations``).
    """

    points: np.ndarray
    radii: np.ndarray
    counts: np.ndarray
    tip_position: np.ndarray
    converged: np.ndarray
    unstable: np.ndarray
    valid: np.ndarray
    iterations: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """``valid & converged & ~unstable``, shape (K,): ``diagnostics.ok`` of a possible
        configuration."""
        return self.valid & self.converged & ~self.unstable

    def body(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Body of configuration ``k``: points (counts[k], 3) [m] and radii (counts[k],) [m]."""
        c = int(self.counts[k])
        return self.points[k, :c], self.radii[k, :c]


@njit(cache=True)
def _body_counts(alpha, beta, valid, tubes, opts, counts):
    """Body points of each possible configuration (grid nodes with s >= max(beta) - tol), to
    size the padded outputs exactly when the capacity bound of :func:`solve_standard_bodies_packed` did not
    hold; writes ``counts`` (K,) and returns their maximum. ``alpha``, ``beta`` (K, n) [rad],
    [m]; ``valid`` (K,) bool; ``tubes`` a ``BatchTubes``, ``opts`` a ``BatchOptions``
    (``_standard_batch``)."""
    lengths, brk, nbrk, curv = tubes.lengths, tubes.breaks, tubes.n_breaks, tubes.precurvature
    ds, merge_tol, refine_ratio, refine_length = opts.ds, opts.merge_tol, opts.refine_ratio, opts.refine_length
    largest = 0
    for k in range(alpha.shape[0]):
        if not valid[k]:
            continue
        s, _, _, _, _ = _grid(beta[k], lengths, brk, nbrk, curv, ds, merge_tol, refine_ratio, refine_length)
        front = np.max(beta[k]) - _BODY_TOL
        c = 0
        for q in range(s.shape[0]):
            if s[q] >= front:
                c += 1
        counts[k] = c
        largest = max(largest, c)
    return largest


@njit(cache=True)
def _bodies(alpha, beta, valid, tubes, opts, r_out, out):
    """Per possible configuration k: the grid, Newton shooting from no twist through the coarse
    predictor (``_shoot`` with ``predict``, as ``_standard_batch._solve_one`` with no initial
    guess), the centerline, and the body of ``StandardSolution.body`` written into
    ``out.points[k]`` (P, 3) and ``out.radii[k]`` (P,), with its length in ``out.counts[k]``;
    -1 there if the body has more than P points (the caller then sizes the arrays exactly and
    runs again).

    Parameters
    ----------
    alpha, beta : ndarray, shape (K, n)
        Base rotations [rad] and translations [m].
    valid : ndarray of bool, shape (K,)
        Configurations to solve.
    tubes : BatchTubes
        From the packed robot (``_standard_batch``).
    opts : BatchOptions
        Reads ``ds``, the grid options, ``tol`` and ``maxit``.
    r_out : ndarray, shape (n,)
        Outer radius of each tube for collision checking [m].
    out : _BodiesOutput
        Written in place.
    """
    lengths, brk, nbrk, curv = tubes.lengths, tubes.breaks, tubes.n_breaks, tubes.precurvature
    kxy, ratio = tubes.k_xy, tubes.stiffness_ratio
    ds, tol, maxit = opts.ds, opts.tol, opts.maxit
    merge_tol, refine_ratio, refine_length = opts.merge_tol, opts.refine_ratio, opts.refine_length
    points, radii, counts, tips = out.points, out.radii, out.counts, out.tips
    conv, unst, iters = out.conv, out.unst, out.iters
    n = alpha.shape[1]
    cap = points.shape[1]
    for k in range(alpha.shape[0]):
        if not valid[k]:
            continue
        b = beta[k]
        s, first, last, present, uhat = _grid(b, lengths, brk, nbrk, curv, ds, merge_tol, refine_ratio,
                                              refine_length)
        cs, _, _, cpresent, cuhat = _grid(b, lengths, brk, nbrk, curv, _PREDICTOR_STEP_FACTOR * ds, merge_tol,
                                          refine_ratio, refine_length)
        a = alpha[k].copy()
        _, _, it, ok, detJ, psi, sig = _shoot(s, present, uhat, cs, cpresent, cuhat, kxy, ratio, a, np.zeros(n),
                                              lengths, tol, maxit, bool(True))
        iters[k] = it
        conv[k] = ok
        unst[k] = ok and not detJ > 0.0
        _, _, _, _, p, _ = _centerline(s, present, uhat, kxy, psi, sig)
        tips[k] = p[-1]
        front = np.max(b) - _BODY_TOL
        c = 0
        for q in range(s.shape[0]):
            sq = s[q]
            if sq < front:
                continue
            if c == cap:
                c = -1
                break
            points[k, c] = p[q]
            r = 0.0
            for i in range(n):   # outermost tube present: the smallest index (tube 1 is outermost)
                if b[i] - _BODY_TOL <= sq <= b[i] + lengths[i] + _BODY_TOL:
                    r = r_out[i]
                    break
            radii[k, c] = r
            c += 1
        counts[k] = c


def solve_standard_bodies(robot, alpha, beta, settings: ModelSettings | None = None) -> StandardBodies:
    """Solve the standard model at many configurations and return each robot body.

    Parameters
    ----------
    robot : Robot
    alpha : array-like, shape (K, n)
        Base rotations [rad] (the paper's theta_b).
    beta : array-like, shape (K, n)
        Base translations [m] (the paper's l_b).
    settings : ModelSettings, optional
        Uses ``ds``, ``refine_ratio``, ``refine_length`` (the grid), ``shooting_tol`` and
        ``max_shooting_iterations``; ``multistart`` is ignored (no multistart search is run).

    Returns
    -------
    StandardBodies
        Bodies as padded arrays, with the convergence and determinant-stability flags.
        Configurations that fail ``Robot.configurations_possible`` are flagged
        ``valid = False`` (no body, ``counts = 0``) instead of raising.

    Raises
    ------
    ValueError
        If ``alpha`` and ``beta`` are not both of shape (K, n).

    Notes
    -----
    Section II-A of Ha, Fagogenis & Dupont 2019 (doi:10.1109/TRO.2018.2878906) and its refs
    [10], [11]; the same grid, predictor, Newton iteration, tolerances and flags as
    :func:`~ctrplan.mechanics.solve_standard_batch` with ``initial_guess=None``, hence as
    :func:`~ctrplan.mechanics.solve_standard` with ``multistart=0``. The body is that of
    :meth:`~ctrplan.mechanics.results.StandardSolution.body` (the part outside the drive, from
    the most distal base to the tip, with the outer radius ``Robot.outer_radius`` of the
    outermost tube present at each node, tolerances ``results.BODY_TOL``), also for configurations that
    did not converge (the last Newton iterate), as ``body`` gives it for them.
    """
    settings = settings or ModelSettings()
    alpha, beta = configuration_arrays(robot, alpha, beta)
    return solve_standard_bodies_packed(pack_robot(robot), alpha, beta, robot.configurations_possible(alpha, beta), settings)



def _body_capacity(lengths, nbrk, settings) -> int:
    """Points allocated per body before solving: the grid's own node bound (``grid._grid``'s
    buffer size) over the body's span, which is at most the longest tube, at the finest step
    ``refine_ratio * ds``, plus its slack of 2 nodes per breakpoint interval. The kernel checks
    it, so a body that does not fit costs one exact sizing pass, never memory outside the
    arrays; saves the grid pass that exact sizing costs (~30 us per configuration)."""
    return int(np.max(lengths) / (min(settings.refine_ratio, 1.0) * settings.ds)) + 3 * int(np.sum(nbrk)) + 4


def solve_standard_bodies_packed(packed, alpha, beta, valid, settings) -> StandardBodies:
    """:func:`solve_standard_bodies` on a robot packed once by
    :func:`ctrplan.mechanics.packed.pack_robot`, for callers that check many batches of one robot
    (the planner's validity checker) and have checked the configurations already.

    Parameters
    ----------
    packed : PackedRobot
        ``pack_robot(robot)``.
    alpha, beta : ndarray, shape (K, n), C-contiguous
        Base rotations [rad] and translations [m].
    valid : ndarray of bool, shape (K,)
        The configurations that are possible (``Robot.configurations_possible``); the others
        are not solved.
    settings : ModelSettings

    Returns
    -------
    StandardBodies
        As :func:`solve_standard_bodies`.
    """
    tubes = BatchTubes(packed.lengths, packed.breaks, packed.n_breaks, packed.precurvature, packed.k_xy,
                       packed.stiffness_ratio)
    opts = BatchOptions(ds=float(settings.ds), merge_tol=float(GRID_MERGE_TOL),
                        refine_ratio=float(settings.refine_ratio), refine_length=float(settings.refine_length),
                        tol=float(settings.shooting_tol), maxit=int(settings.max_shooting_iterations),
                        multistart=0, predict=True, follow=False)
    K = alpha.shape[0]
    counts = np.zeros(K, dtype=np.int64)
    P = _body_capacity(packed.lengths, packed.n_breaks, settings) if K else 0
    for attempt in range(2):
        points = np.full((K, P, 3), np.nan)
        radii = np.full((K, P), np.nan)
        tips = np.full((K, 3), np.nan)
        conv = np.zeros(K, dtype=bool)
        unst = np.zeros(K, dtype=bool)
        iters = np.zeros(K, dtype=np.int64)
        if K:
            _bodies(alpha, beta, valid, tubes, opts, packed.outer_radius,
                    _BodiesOutput(points, radii, counts, tips, conv, unst, iters))
        if not np.any(counts < 0):
            break
        P = int(_body_counts(alpha, beta, valid, tubes, opts, counts))
    P = int(counts.max()) if K else 0
    points = np.ascontiguousarray(points[:, :P])
    radii = np.ascontiguousarray(radii[:, :P])
    return StandardBodies(points=points, radii=radii, counts=counts, tip_position=tips, converged=conv,
                          unstable=unst, valid=valid, iterations=iters)
