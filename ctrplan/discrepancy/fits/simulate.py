"""The robot models evaluated along a measured or planned motion.

:func:`simulate` evaluates the standard, clearance or friction model at every sample (Ha,
Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906), following the elastic
branch along each motion (each solve starts from the previous sample's solution) and in
parallel over independent motions or chunks of samples. The friction applied per pair and
sample (direction and coefficient) comes from the motion history, read by
:mod:`ctrplan.history` (:meth:`ctrplan.history.HistoryState.applied`); a sample whose pairs all
carry no friction is solved with the clearance model.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...errors import CtrplanError
from ...history import MotionRecord, motion_state, sequence_segments
from ...mechanics import ModelSettings, solve_standard, solve_standard_path
from ...models import MODEL_INFO, MODELS, check_model, standard_solution  # the one registry of models
from ...parallel import Executor

__all__ = ["MODELS", "Simulation", "simulate", "WarmStarts", "WARM_OUTER_TOL"]

# Rows per parallel task when rows are independent: enough to amortize the inter-process
# transfer (a contact solve takes ~0.1 s, a task ~1 s), few enough to balance 2-8 workers.
_ROWS_PER_TASK = 16
# Rough serial cost of one sample [s] (Table VII robot, ds 3 mm, one core): a standard solve
# from the previous sample's solution in the compiled path (83 us a row on a random walk of 400
# rows, 124 us through solve_standard one row at a time), and a contact solve. Work estimated
# below _MIN_PARALLEL_SECONDS runs in this process: starting or feeding loky workers costs about
# a second.
_STANDARD_COST_S = 1e-4
_CONTACT_COST_S = 0.1
_MIN_PARALLEL_SECONDS = 2.0
#: Outer (centerline change [m]) and complementarity tolerances of contact solves that use
#: :class:`WarmStarts`. A forward difference of the tip over a relative parameter step of 1e-4
#: (a few micrometres) needs solutions that agree far below that: with the default 1e-6 m,
#: solves started from another evaluation's solution put errors of 5 % (median) to 50 % into
#: such differences on Ha's trajectory (Table II robot), with 1e-8 m 0.1 % (median) and 0.7 %
#: (max), below the 3.7 % of the default tolerance from cold starts.
WARM_OUTER_TOL = 1e-8


def _sequence_groups(sequence, K: int) -> list[np.ndarray] | None:
    """Row indices of each sequence (:func:`ctrplan.history.sequence_segments`), or None when
    every row is independent."""
    return None if sequence is None else sequence_segments(sequence, K)


def _check_joints(alpha, beta):
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    if alpha.ndim != 2 or beta.shape != alpha.shape:
        raise ValueError(f"alpha and beta must both have shape (K, n), got {alpha.shape} and {beta.shape}")
    return alpha, beta


class WarmStarts:
    """Contact solutions of earlier evaluations of the same samples, to start the next ones from.

    A fit evaluates a contact model at the same samples again and again with parameters that
    differ a little (a least-squares step, a finite-difference column, the next point of a
    grid). Started from the solution of the previous evaluation at the same configuration, a
    contact solve converges in about 3 outer iterations instead of 6-8 from the standard model's
    curvatures (Section II-E of Ha, Fagogenis & Dupont 2019). The store keeps, per configuration
    (``alpha``, ``beta``) and friction direction, the curvatures and multipliers of the last
    solution found there; a start is used only when its grid has the new problem's shape
    (:func:`~ctrplan.mechanics.solve_contact`), and a warm friction solve that does not
    converge is solved again as without the store.

    A store belongs to one sequence of evaluations (one fit, :class:`~ctrplan.discrepancy.fits.objective.FitObjective`):
    what it holds depends only on that sequence, so a fit gives the same values whichever
    process runs it. The solver tolerances of a fit that uses it must be tight enough for
    finite differences of solutions started from different points (:data:`WARM_OUTER_TOL`).
    """

    def __init__(self):
        self._entries: dict = {}

    def __len__(self) -> int:
        return len(self._entries)

    @staticmethod
    def key(alpha, beta, eta=None) -> tuple:
        """Key of a configuration and friction state.

        Parameters
        ----------
        alpha, beta : array-like, shape (n,)
            Base rotations [rad] and translations [m]; matched exactly (their bytes).
        eta : array-like of int, shape (n - 1,), optional
            Friction direction per pair (+1, -1; Eq. (39) of Ha et al. 2019) of a friction solve;
            None: the clearance model.

        Returns
        -------
        tuple
            Hashable.
        """
        return (np.asarray(alpha, float).tobytes(), np.asarray(beta, float).tobytes(),
                None if eta is None else tuple(int(e) for e in eta))

    def get(self, key):
        """The stored start for ``key`` (:meth:`key`): an object with ``curvatures`` (list of n
        arrays, shape (S_i, 3) [1/m]) and ``multipliers`` (shape (M,) or None), or None."""
        return self._entries.get(key)

    def update(self, items) -> None:
        """Store ``(key, start)`` pairs (:meth:`key`, :meth:`get`'s starts); a later pair
        replaces an earlier one of its key. Raises nothing."""
        for key, start in items:
            self._entries[key] = start


@dataclass(frozen=True, eq=False)
class _Start:
    """What a warm start of a contact solve needs (:func:`~ctrplan.mechanics.solve_contact`)."""

    curvatures: list
    multipliers: np.ndarray | None


def _start_of(sol) -> _Start:
    return _Start([np.array(c, float) for c in sol.curvatures],
                  None if sol.multipliers is None else np.array(sol.multipliers, float))


# --------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class Simulation:
    """Model tip poses along a motion history.

    Attributes
    ----------
    tip : ndarray, shape (K, 3)
        Tip positions in the robot base frame [m]; NaN where the solve failed.
    tangent : ndarray, shape (K, 3)
        Unit tip tangents; NaN where the solve failed.
    ok : ndarray of bool, shape (K,)
        Solve converged and the equilibrium is not flagged unstable.
    message : list of str, length K
        Solver message, or the error of a failed sample.
    model : str
        ``"standard"``, ``"clearance"`` or ``"friction"``.
    eta : ndarray of int, shape (K, n - 1)
        Friction direction applied per pair (0: that pair frictionless); all 0 except for the
        friction model.
    mu : ndarray, shape (K, n - 1)
        Friction coefficient applied per pair (0 where released or without history).
    base_torsion : ndarray, shape (K, n)
        Standard-model base torsions u_(i,z)(beta_i) [1/m] of the branch followed (NaN where
        the standard solve failed).
    n_standard : int
        Standard-model solves.
    n_contact : int
        Clearance/friction solves.
    n_warm : int
        Contact solves warm-started from another solution at the same configuration.
    n_reused : int
        Samples whose configuration and friction state equal the previous sample's in the same
        task: the solution was reused without solving.
    n_released : int
        Friction-model samples solved frictionless (translation-last or no history at all).
    n_failed : int
        Samples with ``ok`` False.
    elapsed : float
        Wall-clock time [s].
    """

    tip: np.ndarray
    tangent: np.ndarray
    ok: np.ndarray
    message: list
    model: str
    eta: np.ndarray
    mu: np.ndarray
    base_torsion: np.ndarray
    n_standard: int = 0
    n_contact: int = 0
    n_warm: int = 0
    n_reused: int = 0
    n_released: int = 0
    n_failed: int = 0
    elapsed: float = field(default=0.0)


# --------------------------------------------------------------------------- kernel
def _no_results(m, n):
    """Per-row outputs before solving: tips, tangents (m, 3) and base torsions (m, n) NaN, ok
    False, empty messages, and zero work counters."""
    return (np.full((m, 3), np.nan), np.full((m, 3), np.nan), np.zeros(m, dtype=bool), [""] * m,
            np.full((m, n), np.nan), dict(n_standard=0, n_contact=0, n_warm=0, n_reused=0))


def _solve_rows(robot, alpha, beta, guess, follow, eta, mu, solve, contact, settings, check_stability, stored=None):
    """Solve rows in order (one task; pure, runs in a worker).

    alpha, beta (m, n); guess (m, n) with NaN rows for "none"; follow (m,) bool: start from
    the previous row's base torsion (same branch) instead of ``guess``; eta (m, n - 1) in
    {-1, +1} and mu (m, n - 1) (all mu 0: clearance model); solve: the model's
    :attr:`ctrplan.models.ModelInfo.solve`; contact: it is a contact model (warm starts, reuse);
    stored: None, or the :class:`WarmStarts` entries of these rows (``{key: start}``), whose
    contact solves then start from them and whose solutions are returned as new entries.
    """
    if not contact and solve is standard_solution:
        return _standard_rows(robot, alpha, beta, guess, follow, settings, check_stability)
    m, n = alpha.shape
    tip, tan, ok, msg, torsion, counts = _no_results(m, n)
    new = [] if stored is not None else None
    prev_std = prev_cont = prev_key = None
    prev_start = None
    for k in range(m):
        a, b = alpha[k], beta[k]
        if follow[k]:
            start = prev_std.base_torsion if prev_std is not None else None
        else:
            start = None if np.isnan(guess[k, 0]) else guess[k]
        same_config = (prev_std is not None and np.array_equal(a, prev_std.alpha)
                       and np.array_equal(b, prev_std.beta))
        same_start = follow[k] or (start is None and prev_start is None) or (
            start is not None and prev_start is not None and np.array_equal(start, prev_start))
        key = (tuple(eta[k]), tuple(mu[k]))
        try:
            if same_config and same_start:
                std = prev_std
                reused = True
            else:
                prev_cont = prev_key = None
                std = solve_standard(robot, a, b, settings, initial_guess=start,
                                     check_stability=check_stability)
                counts["n_standard"] += 1
                reused = False
            torsion[k] = std.base_torsion
            if not std.diagnostics.ok:
                # no contact solve about an unconverged or unstable linearization point
                msg[k] = f"standard model: {std.diagnostics.message}"
                prev_std = std if std.diagnostics.converged else None
                prev_start = start
                if not std.diagnostics.converged:
                    torsion[k] = np.nan
                continue
            prev_std, prev_start = std, start
            if not contact:
                sol = solve(robot, a, b, settings, standard=std)
                counts["n_reused"] += reused
            else:
                if prev_cont is not None and key == prev_key:
                    sol = prev_cont
                    counts["n_reused"] += 1
                else:
                    friction = bool(np.any(mu[k] > 0.0))
                    sol = None
                    if stored is not None:
                        # a solution of an earlier evaluation here: this direction's, else the
                        # clearance model's
                        own = WarmStarts.key(a, b, eta[k] if friction else None)
                        start = stored.get(own) or (stored.get(WarmStarts.key(a, b)) if friction else None)
                        if start is not None:
                            sol = solve(robot, a, b, settings, eta=eta[k] if friction else None,
                                        mu=mu[k] if friction else None, standard=std, warm_start=start)
                            counts["n_contact"] += 1
                            counts["n_warm"] += 1
                            if not sol.diagnostics.converged:
                                sol = None   # solved again below as without the store
                    if sol is None:
                        warm = prev_cont
                        if friction and warm is None:
                            # a friction solve started from the standard model's linearization can
                            # wander for its whole iteration budget; started from the clearance
                            # solution at the same configuration it converges in a few steps (as in
                            # evaluate_bound)
                            warm = solve(robot, a, b, settings, standard=std)
                            counts["n_contact"] += 1
                            if not warm.diagnostics.converged:
                                warm = None
                            elif new is not None:
                                new.append((WarmStarts.key(a, b), _start_of(warm)))
                        sol = solve(robot, a, b, settings, eta=eta[k] if friction else None,
                                    mu=mu[k] if friction else None, standard=std, warm_start=warm)
                        counts["n_contact"] += 1
                        counts["n_warm"] += warm is not None
                    if new is not None and sol.diagnostics.converged:
                        new.append((WarmStarts.key(a, b, eta[k] if friction else None), _start_of(sol)))
                    prev_cont, prev_key = sol, key
            ok[k] = sol.diagnostics.ok
            msg[k] = sol.diagnostics.message
            tip[k] = sol.tip_position
            tan[k] = sol.tip_tangent
        except (CtrplanError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
            msg[k] = f"{type(exc).__name__}: {exc}"
            prev_std = prev_cont = prev_key = prev_start = None
    return tip, tan, ok, msg, torsion, counts, new


def _standard_rows(robot, alpha, beta, guess, follow, settings, check_stability):
    """:func:`_solve_rows` of the standard model in one compiled call
    (:func:`ctrplan.mechanics.solve_standard_path`: the same starts, reuse and numbers as the
    loop over :func:`~ctrplan.mechanics.solve_standard`), with the same messages."""
    m, n = alpha.shape
    tip, tan, ok, msg, torsion, counts = _no_results(m, n)
    path = solve_standard_path(robot, alpha, beta, settings, initial_guess=guess, follow=follow,
                               check_stability=check_stability)
    conv, unstable = path.converged & path.valid, path.unstable & path.valid
    ok[:] = conv & ~unstable
    tip[ok], tan[ok] = path.tip_position[ok], path.tip_tangent[ok]
    torsion[conv] = path.base_torsion[conv]
    counts["n_standard"] = int(np.sum(path.valid & ~path.reused))
    counts["n_reused"] = int(np.sum(ok & path.reused))
    for k in range(m):
        if ok[k]:
            msg[k] = "converged"
        elif not path.valid[k]:
            try:
                robot.check_configuration(alpha[k], beta[k])
                msg[k] = "configuration not possible"
            except CtrplanError as exc:
                msg[k] = f"{type(exc).__name__}: {exc}"
        elif not conv[k]:
            msg[k] = ("standard model: shooting did not converge (tip torsion residual "
                      f"{path.residual[k]:.3g} 1/m)")
        elif path.n_equilibria[k] > 1:
            msg[k] = (f"standard model: elastically unstable: {path.n_equilibria[k]} equilibria found by "
                      "the multistart search")
        else:
            msg[k] = (f"standard model: elastically unstable: shooting Jacobian determinant "
                      f"{path.determinant[k]:.3g} <= 0")
    return tip, tan, ok, msg, torsion, counts, None


def _tasks_from_groups(groups, size):
    """Bundle whole sequences (lists of row indices) into tasks of about ``size`` rows."""
    tasks, cur, cur_n = [], [], 0
    for g in groups:
        cur.append(g)
        cur_n += g.size
        if cur_n >= size:
            tasks.append(cur)
            cur, cur_n = [], 0
    if cur:
        tasks.append(cur)
    return tasks


def _chunks(order, alpha, beta, size):
    """Split a processing order into runs of about ``size`` rows, never inside a run of
    identical configurations (so the same-configuration reuse is not lost)."""
    cuts = []
    k = size
    while k < order.size:
        while k < order.size and np.array_equal(alpha[order[k]], alpha[order[k - 1]]) and \
                np.array_equal(beta[order[k]], beta[order[k - 1]]):
            k += 1
        if k < order.size:
            cuts.append(k)
        k += size
    return np.split(order, cuts)


def _solve_task(single_thread, *args):
    """:func:`_solve_rows` as a task of the executor; ``single_thread``: with one BLAS / OpenMP
    thread (``threadpoolctl``) for the length of the task (a worker process; a worker's BLAS may
    otherwise start with several threads, which only oversubscribe the cores)."""
    if not single_thread:
        return _solve_rows(*args)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return _solve_rows(*args)


def _run(tasks, alpha, beta, guess, follow, eta, mu, solve, contact, robot, settings, check_stability,
         n_jobs, progress, desc, K, warm_starts=None):
    """Run tasks (each an index array in processing order) and scatter results to rows, in task
    order (the results arrive in order of completion). With ``warm_starts`` (a
    :class:`WarmStarts`; contact models), each task gets the stored starts of its rows and the
    store takes the new solutions, in task order."""
    tip, tan, ok, msg, torsion, counts = _no_results(K, alpha.shape[1])
    workers = n_jobs if n_jobs > 1 and len(tasks) > 1 else 1
    use = warm_starts is not None and contact

    def stored(idx):
        if not use:
            return None
        keys = [WarmStarts.key(alpha[k], beta[k], eta[k] if np.any(mu[k] > 0.0) else None) for k in idx]
        keys += [WarmStarts.key(alpha[k], beta[k]) for k in idx]
        return {key: warm_starts.get(key) for key in keys if warm_starts.get(key) is not None}

    jobs = [(t, (workers > 1, robot, alpha[idx], beta[idx], guess[idx], follow[idx], eta[idx], mu[idx], solve,
                 contact, settings, check_stability, stored(idx))) for t, idx in enumerate(tasks)]
    results = [None] * len(tasks)
    from tqdm.auto import tqdm

    with Executor(workers) as ex, tqdm(total=K, disable=not progress, unit="sample", desc=desc) as bar:
        for t, result in ex.run(_solve_task, jobs):
            results[t] = result
            bar.update(tasks[t].size)
    for idx, (t, g, o, m, s, c, new) in zip(tasks, results):
        tip[idx], tan[idx], ok[idx], torsion[idx] = t, g, o, s
        for j, k in enumerate(idx):
            msg[k] = m[j]
        for name in counts:
            counts[name] += c[name]
        if use and new:
            warm_starts.update(new)
    return tip, tan, ok, msg, torsion, counts


def simulate(robot, alpha, beta, *, model: str, eta=None, mu=None, sequence=None,
             settings: ModelSettings | None = None, n_jobs: int = 1, progress: bool = False,
             check_stability: bool = False, warm_starts: WarmStarts | None = None) -> Simulation:
    """Evaluate a model at every sample of a motion history, following the elastic branch.

    Parameters
    ----------
    robot : Robot
        Apply candidate effects first (:func:`ctrplan.effects.apply_robot_effects`).
    alpha, beta : array-like, shape (K, n)
        Base rotations [rad] and translations [m] the tubes reach (after history effects:
        :attr:`ctrplan.history.HistoryState.alpha`).
    model : str
        A registered mechanics model (:data:`ctrplan.models.MODEL_REGISTRY`), solved by its
        entry's ``solve`` on top of the followed standard solution: zero-clearance model
        (``"standard"``, Section II-A), clearance model (``"clearance"``, Sections II-B to II-E)
        or maximal torsional friction model with the robot's friction coefficients
        (``"friction"``, Section III) of Ha, Fagogenis & Dupont 2019, or one registered by the
        user (with ``n_jobs`` > 1 its ``solve`` goes to the worker processes, which must be able
        to unpickle it).
    eta : array-like of int, shape (K, n - 1), optional
        Friction direction applied per pair and sample (+1, -1; 0: the pair carries no friction
        there), Eq. (38). Friction model only; default: the state of
        :func:`ctrplan.history.motion_state` along each ``sequence``.
    mu : array-like, shape (K, n - 1), optional
        Friction coefficient applied per pair and sample [-], >= 0 (e.g. partly developed
        friction); default the robot's where ``eta`` is not 0, else 0. Friction model only.
    sequence : array-like of int, shape (K,), optional
        Motion id per row (rows of one id in time order). Rows of a sequence are solved in
        order, each standard solve starting from the previous sample's base torsions (branch
        following; ``initial_guess`` of :func:`~ctrplan.mechanics.solve_standard`). ``None``:
        every row is independent (solved from zero twist).
    settings : ModelSettings, optional
    n_jobs : int
        Worker processes (:class:`ctrplan.parallel.Executor`, one BLAS thread each); 1 solves in
        this process, as does any call whose estimated serial work is below about 2 s (e.g. fewer
        than about 700 standard-model samples or 20 contact samples).
    progress : bool
        tqdm progress bar.
    check_stability : bool
        Run the multistart search for other equilibria at every standard solve (4 extra
        shootings each); samples with several equilibria are then flagged not ok. Default
        False: along a history the followed branch is the answer; the shooting-Jacobian test
        for equilibria past a bifurcation still runs.
    warm_starts : WarmStarts, optional
        Contact models: start each contact solve from the solution an earlier call with the same
        store found at the same configuration (and friction direction), and store this call's
        solutions (:class:`WarmStarts`). Use it with tolerances tight enough that solutions
        started from different points agree to well below the differences wanted of them
        (:data:`WARM_OUTER_TOL`).

    Returns
    -------
    Simulation
        Tips and tangents in input row order, ok flags, messages and work counters.

    Raises
    ------
    ValueError
        Unknown model, shapes that do not match, eta outside {-1, 0, 1}, bad ``mu``, friction model
        without ``eta`` or ``sequence``, ``n_jobs`` < 1.
    PhysicalParameterError
        Contact models without clearances (diameters or override), friction without a
        diameter per pair (Eq. (41)).

    Notes
    -----
    Failed samples (solver not converged, elastic instability, impossible configuration) get
    ``ok`` False, NaN poses and the message; they never stop the run, and the next sample of
    the sequence starts from zero twist.

    Branch following runs in two stages when a contact model has sequences: the standard model
    sequentially along each sequence (about 0.1 ms a sample, one compiled call per task:
    :func:`~ctrplan.mechanics.solve_standard_path`), then the contact solves in
    parallel chunks, each standard solve restarted from the first stage's base torsions (it
    converges in one Newton step to the same branch). A contact solve is warm-started only from
    a solution at the same configuration (same grid): the previous sample's when it did not
    move, e.g. another friction direction. The first friction solve at a configuration is
    warm-started from a clearance solve there: a cold friction solve can fail after its whole
    iteration budget where the warm one converges in a few steps.

    Friction model per sample: the given directions and coefficients (the rule that derives
    them from a motion, release by a translation included, is :mod:`ctrplan.history`'s); if all
    ``mu_i`` are 0 the clearance model is solved. Pairs with ``mu_i = 0`` are passed to the
    solver with eta +1 (no effect since the friction terms scale with eta_i mu_i, Eqs.
    (40)-(41)).
    """
    t0 = time.perf_counter()
    info = MODEL_INFO[check_model(model)]
    if not isinstance(n_jobs, (int, np.integer)) or n_jobs < 1:
        raise ValueError(f"n_jobs must be an integer >= 1, got {n_jobs!r}")
    settings = settings or ModelSettings()
    alpha, beta = _check_joints(alpha, beta)
    K, n = alpha.shape
    if n != robot.n_tubes:
        raise ValueError(f"alpha has {n} columns but robot {robot.name!r} has {robot.n_tubes} tubes")
    groups = _sequence_groups(sequence, K)
    contact = info.contact
    if K * (_CONTACT_COST_S if contact else _STANDARD_COST_S) < _MIN_PARALLEL_SECONDS:
        n_jobs = 1   # not worth the worker overhead
    eta_used = np.zeros((K, n - 1), dtype=int)
    mu_used = np.zeros((K, n - 1))
    n_released = 0
    if contact:
        robot.clearances  # noqa: B018 - raises PhysicalParameterError without clearances
    if info.friction:
        if eta is None:
            if groups is None:
                raise ValueError("model 'friction' needs eta or sequence (the motion history)")
            state = motion_state(MotionRecord(alpha, beta, sequence=sequence))
            eta, mu_default = state.applied(robot.friction_coefficients)
            mu = mu_default if mu is None else mu
        eta = np.asarray(eta)
        if eta.shape != (K, n - 1) or not np.all(np.isin(eta, (-1, 0, 1))):
            raise ValueError(f"eta must have shape ({K}, {n - 1}) with values -1, 0, +1")
        eta = eta.astype(int)
        if mu is None:
            mu_rows = np.where(eta != 0, np.asarray(robot.friction_coefficients, dtype=float)[None, :], 0.0)
        else:
            mu_rows = np.asarray(mu, dtype=float)
            if mu_rows.shape != (K, n - 1) or not np.all(np.isfinite(mu_rows)) or np.any(mu_rows < 0):
                raise ValueError(f"mu must have shape ({K}, {n - 1}) with finite values >= 0")
        active = (eta != 0) & (mu_rows > 0.0)
        mu_used = np.where(active, mu_rows, 0.0)
        eta_used = np.where(active, eta, 0)
        n_released = int(np.sum(~np.any(active, axis=1)))
        if np.any(active):
            robot.contact_radii()  # raises PhysicalParameterError without diameters
    eta_solve = np.where(eta_used == 0, 1, eta_used)
    guess = np.full((K, n), np.nan)
    follow = np.zeros(K, dtype=bool)
    counts = dict(n_standard=0, n_contact=0, n_warm=0, n_reused=0)
    size = max(1, min(_ROWS_PER_TASK, -(-K // max(1, 4 * n_jobs))))
    if groups is not None and all(g.size == 1 for g in groups):
        groups = None  # one-sample sequences: nothing to follow
    if groups is not None:
        for g in groups:
            follow[g[1:]] = True
        order = np.concatenate(groups) if groups else np.zeros(0, dtype=int)
        # stage 1: standard model along each sequence (branch following)
        tasks = [np.concatenate(t) for t in _tasks_from_groups(groups, 8 * size if contact else size)]
        tip, tan, ok, msg, torsion, c = _run(
            tasks, alpha, beta, guess, follow, eta_solve, mu_used, standard_solution if contact else info.solve, False,
            robot, settings, check_stability, n_jobs, progress and not contact, "standard model", K)
        for name in counts:
            counts[name] += c[name]
        if contact:
            # stage 2 restarts each sample on its branch; samples whose branch failed stay failed
            guess = torsion
            follow = np.zeros(K, dtype=bool)
            order = order[ok[order]]
    else:
        order = np.arange(K)
    if contact or groups is None:
        tasks = _chunks(order, alpha, beta, size) if order.size else []
        tip2, tan2, ok2, msg2, torsion2, c = _run(
            tasks, alpha, beta, guess, follow, eta_solve, mu_used, info.solve, contact, robot, settings,
            check_stability, n_jobs, progress, f"{model} model", K, warm_starts)
        for name in counts:
            counts[name] += c[name]
        if groups is None:
            tip, tan, ok, msg, torsion = tip2, tan2, ok2, msg2, torsion2
        else:
            tip, tan, ok = tip2, tan2, ok2
            solved = np.zeros(K, dtype=bool)
            solved[order] = True
            msg = [msg2[k] if solved[k] else msg[k] for k in range(K)]
    return Simulation(tip=tip, tangent=tan, ok=ok, message=msg, model=model, eta=eta_used,
                      mu=mu_used, base_torsion=torsion, n_released=n_released if info.friction else 0,
                      n_failed=int(np.sum(~ok)), elapsed=time.perf_counter() - t0, **counts)
