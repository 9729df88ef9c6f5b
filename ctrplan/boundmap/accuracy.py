"""How far a bound map is from the exact model, at random valid configurations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..parallel import Executor
from .compute import _run_chunks
from .field import QUANTITIES

__all__ = ["InterpolationError", "interpolation_error", "sample_exact"]

# Draw at most this many times the wanted number of random configurations when looking for
# valid ones (regions where the standard model is unstable are rare on the shipped robots).
_MAX_DRAW_FACTOR = 5
# Configurations per task when the exact model runs on several workers.
_TASK_SIZE = 8


@dataclass
class InterpolationError:
    """A map versus the exact model at random configurations.

    Attributes
    ----------
    q : ndarray, shape (m, n_joints)
        Configurations where both the map and the exact model are valid [rad or m].
    exact, interpolated : ndarray, shape (m,)
        Bound of ``quantity`` [m or rad].
    errors : ndarray, shape (m,)
        ``|interpolated - exact|`` [m or rad].
    n_invalid : int
        Sampled configurations left out: the exact model or the map is invalid there.
    quantity : str
    n_refused : int
        Of those, configurations where the exact model is valid but the map is not (the map
        refuses them, e.g. next to an unstable node): the planner cannot go there.
    n_exact_invalid : int
        Configurations where the exact model failed or was unstable.
    """

    q: np.ndarray
    exact: np.ndarray
    interpolated: np.ndarray
    errors: np.ndarray
    n_invalid: int
    quantity: str
    n_refused: int = 0
    n_exact_invalid: int = 0

    def _stat(self, f) -> float:
        return float(f(self.errors)) if self.errors.size else float("nan")

    @property
    def median(self) -> float:
        """Median absolute error [m or rad]."""
        return self._stat(np.median)

    @property
    def p95(self) -> float:
        """95th-percentile absolute error [m or rad]."""
        return self._stat(lambda e: np.percentile(e, 95))

    @property
    def mean(self) -> float:
        """Mean absolute error [m or rad]."""
        return self._stat(np.mean)

    @property
    def max(self) -> float:
        """Largest absolute error [m or rad]."""
        return self._stat(np.max)


def sample_exact(robot, evaluator, q, settings=None, n_jobs: int = 1, scheduler=None):
    """The exact map quantities at joint vectors.

    Parameters
    ----------
    robot : Robot
    evaluator : callable
        ``evaluator(robot, alpha, beta, settings) -> BoundResult``.
    q : array-like, shape (m, n_joints)
        [rad or m].
    settings : ModelSettings, optional
    n_jobs : int
        Local worker processes (1: this process).
    scheduler : str or distributed.Client, optional

    Returns
    -------
    values : ndarray, shape (m, 4)
        :data:`~ctrplan.boundmap.field.QUANTITIES` [m, rad] (NaN where invalid).
    ok : ndarray of bool, shape (m,)
        Converged and stable.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    values = np.full((len(q), len(QUANTITIES)), np.nan)
    ok = np.zeros(len(q), dtype=bool)
    tasks = []
    for start in range(0, len(q), _TASK_SIZE):
        cfg = [robot.configuration(x) for x in q[start:start + _TASK_SIZE]]
        tasks.append((start, np.array([a for a, _ in cfg]), np.array([b for _, b in cfg])))
    with Executor(n_jobs, scheduler) as ex:
        for start, (vals, good, *_rest) in _run_chunks(ex, tasks, robot, evaluator, settings):
            values[start:start + len(vals)] = vals
            ok[start:start + len(vals)] = good
    return values, ok


def interpolation_error(field, robot, evaluator, n: int = 100, seed: int = 0, settings=None,
                        quantity: str | tuple = "position", *, n_jobs: int = 1, valid_only: bool = False):
    """Compare a map with the exact model at uniformly random configurations of the joint box.

    Parameters
    ----------
    field : BoundField
    robot : Robot
    evaluator : callable
        The exact model, ``evaluator(robot, alpha, beta, settings) -> BoundResult``.
    n : int
        Random configurations (uniform within the joint limits); with ``valid_only``, the number
        of configurations valid in the exact model to collect.
    seed : int
        numpy Generator seed.
    settings : ModelSettings, optional
    quantity : str or tuple of str
        One of :data:`~ctrplan.boundmap.field.QUANTITIES`, or several.
    n_jobs : int, keyword-only
        Local worker processes for the exact model.
    valid_only : bool, keyword-only
        Keep drawing until ``n`` configurations are valid in the exact model (at most
        5 n draws); their errors, and how many of them the map refuses, are reported.

    Returns
    -------
    InterpolationError or dict of str to InterpolationError
        One per quantity (a dict when ``quantity`` is a tuple).
    """
    rng = np.random.default_rng(seed)
    lo, hi = robot.joint_lower, robot.joint_upper
    quantities = (quantity,) if isinstance(quantity, str) else tuple(quantity)
    qs, values, ok = np.empty((0, len(lo))), np.empty((0, len(QUANTITIES))), np.empty(0, dtype=bool)
    while True:
        need = n - (int(ok.sum()) if valid_only else len(ok))
        if need <= 0 or len(ok) >= _MAX_DRAW_FACTOR * n:
            break
        batch = lo + rng.random((need, len(lo))) * (hi - lo)
        v, g = sample_exact(robot, evaluator, batch, settings, n_jobs)
        qs, values, ok = np.vstack([qs, batch]), np.vstack([values, v]), np.concatenate([ok, g])
        if not valid_only:
            break
    if valid_only:   # the first n valid ones, and the invalid ones drawn before them
        last = np.flatnonzero(ok)[:n]
        stop = int(last[-1]) + 1 if last.size else len(ok)
        qs, values, ok = qs[:stop], values[:stop], ok[:stop]
    fvalid = field.is_valid(qs)
    keep = ok & fvalid
    out = {}
    for name in quantities:
        col = QUANTITIES.index(name)
        interp = np.asarray(field(qs, name), dtype=float)
        exact = values[:, col]
        out[name] = InterpolationError(
            q=qs[keep], exact=exact[keep], interpolated=interp[keep], errors=np.abs(interp[keep] - exact[keep]),
            n_invalid=int(len(qs) - keep.sum()), quantity=name, n_refused=int(np.count_nonzero(ok & ~fvalid)),
            n_exact_invalid=int(np.count_nonzero(~ok)))
    return out[quantity] if isinstance(quantity, str) else out
