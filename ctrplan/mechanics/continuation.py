"""A friction solution followed in the friction coefficient from the clearance solution.

The friction model of Section III of Ha, Fagogenis & Dupont 2019 (Eqs. (37)-(47)) is solved at
the robot's friction coefficients mu directly from the clearance solution
(:func:`~ctrplan.mechanics.evaluate_bound`). When that solve does not converge, the cause can be
the solver or the model: the branch of equilibria that starts at the clearance solution (mu = 0)
may end at a fold (a limit point) below the robot's mu, so that under maximal friction in that
direction no equilibrium near it exists and the tubes would snap. :func:`continue_friction` tells
the two apart: it solves the friction model at increasing fractions of mu, each solve started from
the last, halving the step where a solve fails, and reports how far the branch was followed and
how fast the tip moved along it. A tip that moves ever faster per unit of mu as the steps shrink is
the signature of a fold: at a saddle-node fold the tip moves like sqrt(mu_c - mu), so its
sensitivity grows like 1 / sqrt(mu_c - mu).

Measured on the 8x8x8 grid (Table II robot, mu = 0.2): the four configurations whose
bound does not converge end their branches at mu = 0.179-0.197, within 0.001 of the same at
ds = 3 and 1.5 mm, and equal between mirror-image configurations (docs/mechanics.md, Sec. 5;
``tests/test_mechanics_grid_solutions.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import CONTINUATION_GROWTH, CONTINUATION_INITIAL_STEP, CONTINUATION_MIN_STEP
from ..errors import ConvergenceError
from .contact import friction_directions, solve_contact
from .results import ContactSolution, ModelSettings
from .standard import solve_standard

__all__ = ["FrictionBranch", "continue_friction"]


@dataclass(frozen=True)
class FrictionBranch:
    """One friction solution followed in mu from the clearance solution (:func:`continue_friction`).

    Attributes
    ----------
    eta : ndarray of int, shape (n - 1,)
        Directions of the last relative rotations (+1 CCW, -1 CW; Eq. (39)).
    mu : ndarray, shape (n - 1,)
        Friction coefficients [-] the branch was to be followed to (fraction 1).
    fraction : ndarray, shape (k,)
        Fractions of ``mu`` at which the friction model converged, increasing; 0 first (the
        clearance solution).
    tip_position : ndarray, shape (k, 3)
        Tip positions [m] at ``fraction``.
    tip_sensitivity : ndarray, shape (k - 1,)
        Distance the tip moved between consecutive fractions divided by the change of the
        friction coefficients' largest entry [m per unit mu]. Growth as the steps shrink near
        ``fraction[-1]`` is the signature of a fold.
    solution : ContactSolution
        The friction solution at ``fraction[-1]`` (the clearance solution if none converged).
    failed_fraction : float
        Smallest fraction above ``fraction[-1]`` at which a solve failed; NaN when the branch
        reached 1. The branch ends between ``fraction[-1]`` and this.
    solves : int
        Friction solves run (converged or not).
    """

    eta: np.ndarray
    mu: np.ndarray
    fraction: np.ndarray
    tip_position: np.ndarray
    tip_sensitivity: np.ndarray
    solution: ContactSolution
    failed_fraction: float
    solves: int

    @property
    def reached(self) -> bool:
        """The branch was followed to the full friction coefficients (``fraction[-1] == 1``)."""
        return bool(self.fraction[-1] == 1.0)

    @property
    def critical_mu(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(lower, upper)``, each shape (n - 1,): friction coefficients between which the branch
        ended (``mu`` times ``fraction[-1]`` and ``failed_fraction``); None when it reached mu."""
        if self.reached:
            return None
        return self.mu * self.fraction[-1], self.mu * self.failed_fraction

    @property
    def message(self) -> str:
        """One line: how far the branch was followed, in the friction coefficient."""
        top = float(np.max(self.mu))
        if self.reached:
            return f"friction branch followed to mu = {top:.4g} in {self.solves} solves"
        lo, hi = (float(np.max(x)) for x in self.critical_mu)
        if not self.tip_sensitivity.size:
            return (f"friction branch ends below mu = {hi:.4g}: no friction solve converged "
                    f"({self.solves} solves)")
        first, last = self.tip_sensitivity[[0, -1]] * 1e3
        return (f"friction branch ends between mu = {lo:.4g} and {hi:.4g} (below the robot's "
                f"{top:.4g}; tip sensitivity grew from {first:.3g} to {last:.3g} mm per unit mu "
                f"in {self.solves} solves)")


def continue_friction(robot, alpha, beta, eta, settings: ModelSettings | None = None, *,
                      mu=None, standard=None, clearance: ContactSolution | None = None,
                      initial_step: float = CONTINUATION_INITIAL_STEP,
                      min_step: float = CONTINUATION_MIN_STEP) -> FrictionBranch:
    """Follow the friction solution for directions ``eta`` in mu, from the clearance solution.

    Solves the friction model (:func:`~ctrplan.mechanics.solve_contact`) at the fractions
    ``initial_step``, ``2 initial_step``, ... of ``mu``, each solve started from the last converged
    one (curvatures and multipliers). A failed solve halves the step; a converged one lets it grow
    by 1.5x, up to ``initial_step``. Stops at fraction 1 or when the step falls below
    ``min_step``.

    Parameters
    ----------
    robot : Robot
    alpha, beta : array-like, shape (n,)
        Base rotations [rad] and translations [m].
    eta : array-like of int, shape (n - 1,)
        Direction of the last relative rotation of each pair (+1 CCW, -1 CW; Eq. (39)).
    settings : ModelSettings, optional
        Tolerances of every solve along the branch.
    mu : array-like, shape (n - 1,), optional
        Friction coefficients [-] at fraction 1; default the robot's.
    standard : StandardSolution, optional
        Standard-model solution at the configuration (computed if not given).
    clearance : ContactSolution, optional
        Clearance solution at the configuration (fraction 0; computed if not given).
    initial_step : float
        First and largest step in the fraction of ``mu``, in (0, 1].
    min_step : float
        Smallest step, in (0, ``initial_step``]: the branch's end is bracketed to within it.

    Returns
    -------
    FrictionBranch

    Raises
    ------
    ValueError
        ``eta`` is not n - 1 values of +1 or -1, ``mu`` has the wrong shape or a negative
        value, or the steps are out of range.
    JointLimitError
        Kinematically impossible configuration.
    ConvergenceError
        The clearance solve, the branch's start, did not converge.

    Notes
    -----
    The friction model of Section III of Ha, Fagogenis & Dupont 2019 (Eqs. (37)-(47)) at
    mu(t) = t mu, t in [0, 1]; natural-parameter continuation. A fold of the branch (a
    saddle-node limit point) cannot be passed this way: that is the point, since there the
    equilibrium that friction builds up during the rotation ceases to exist.
    """
    settings = settings or ModelSettings()
    n = robot.n_tubes
    eta = friction_directions(eta, n)
    mu = np.asarray(robot.friction_coefficients if mu is None else mu, dtype=float).reshape(-1)
    if mu.size != n - 1 or not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise ValueError(f"mu must hold {n - 1} finite non-negative friction coefficients, got {mu}")
    if not 0.0 < initial_step <= 1.0:
        raise ValueError(f"initial_step must lie in (0, 1], got {initial_step}")
    if not 0.0 < min_step <= initial_step:
        raise ValueError(f"min_step must lie in (0, initial_step = {initial_step}], got {min_step}")
    if standard is None:
        standard = solve_standard(robot, alpha, beta, settings, check_stability=False)
    if clearance is None:
        clearance = solve_contact(robot, alpha, beta, settings, standard=standard)
    if not clearance.diagnostics.converged:
        raise ConvergenceError(f"at alpha={np.round(np.asarray(alpha, dtype=float), 4)} rad, "
                               f"beta={np.round(np.asarray(beta, dtype=float) * 1e3, 3)} mm: the branch "
                               f"starts at the clearance solution, which did not converge "
                               f"({clearance.diagnostics.message})")
    fractions, tips = [0.0], [np.asarray(clearance.tip_position, dtype=float)]
    current, step, solves, failed = clearance, initial_step, 0, np.nan
    while fractions[-1] < 1.0 and step >= min_step:
        t = min(1.0, fractions[-1] + step)
        trial = solve_contact(robot, alpha, beta, settings, eta=eta, mu=t * mu, standard=standard,
                              warm_start=current)
        solves += 1
        if trial.diagnostics.converged:
            current = trial
            fractions.append(t)
            tips.append(np.asarray(trial.tip_position, dtype=float))
            step = min(initial_step, CONTINUATION_GROWTH * step)
            if not t < failed:      # passed an earlier failure: it no longer bounds the end
                failed = np.nan
        else:
            failed = t if np.isnan(failed) else min(failed, t)
            step = 0.5 * step
    fractions, tips = np.array(fractions), np.array(tips)
    top = float(np.max(mu))
    moved = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    sensitivity = moved / (np.diff(fractions) * top) if top > 0 else np.zeros_like(moved)
    return FrictionBranch(eta=eta.astype(int), mu=mu, fraction=fractions, tip_position=tips,
                          tip_sensitivity=sensitivity, solution=current,
                          failed_fraction=float(failed),    # NaN at 1: every failure was passed
                          solves=solves)
