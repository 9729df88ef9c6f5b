"""History-aware prediction of the tip and the shape (Ha, Fagogenis & Dupont 2019, Section V-B).

The friction model of Section III gives 2^(n-1) bounding solutions, one per direction eta_k of
the last relative rotation of each contacting pair (Eqs. (38)-(39)). Given the motion history
that reaches a configuration, one of them is the prediction, not only a bound:

- a pair whose last relative rotation had direction eta_k and was not followed by a translation
  carries the maximal torsional friction in that direction (Eqs. (37)-(47));
- a pair whose last rotation was followed by a translation ("translation-last") is released:
  friction then acts mostly along the axis and the tip sits near the frictionless clearance
  solution (Section V-B, Figs. 19-21), so the pair gets mu = 0;
- a pair that has not rotated yet (eta_k = 0, no history) gets mu = 0, the policy of
  :func:`ctrplan.discrepancy.simulate.simulate`;
- a pair whose robot friction coefficient is 0 is frictionless anyway.

When every pair ends with mu = 0 the prediction is the clearance solution (Sections II-B to
II-E); otherwise it is the friction solution with the per-pair eta and mu.

Pure numerics: arrays and dataclasses in and out. Deriving eta and the translation-last flags
from a joint-space motion is the caller's business (planned paths:
:func:`ctrplan.planning.history.path_history`; recorded motions:
:func:`ctrplan.discrepancy.simulate.motion_history`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConvergenceError
from .contact import solve_contact
from .results import ContactSolution, ModelSettings, StandardSolution
from .standard import solve_standard

__all__ = ["Prediction", "predict_tip", "pair_cases", "PAIR_CASES"]

# What governs each pair in a prediction (one line each; ``Prediction.cases``).
PAIR_CASES = {
    "friction": "last motion of the pair a relative rotation: maximal torsional friction in direction eta",
    "translation_last": "a translation followed the pair's last relative rotation: released (mu = 0)",
    "no_history": "the pair has not rotated yet (eta 0): taken frictionless (mu = 0)",
    "frictionless": "the robot's friction coefficient of the pair is 0",
}


@dataclass(frozen=True, eq=False)
class Prediction:
    """Predicted tip and shape of one configuration after one motion history.

    Attributes
    ----------
    tip_position : ndarray, shape (3,)
        Predicted tip position in the robot base frame [m].
    tip_tangent : ndarray, shape (3,)
        Predicted unit tip tangent [-].
    solution : ContactSolution
        The clearance or friction solution: the predicted shape (``centerlines[i]``, shape
        (N_i, 3) [m], and ``frames[i]``, shape (N_i, 3, 3), per tube, outermost first), contact
        forces and diagnostics.
    standard : StandardSolution
        The standard (zero-clearance, frictionless) solution at the same configuration, the
        linearization point of the contact solve.
    eta : ndarray of int, shape (n - 1,)
        Friction direction applied per pair (+1 CCW, -1 CW, Eq. (39)); 0 where the pair is
        frictionless in this prediction.
    mu : ndarray, shape (n - 1,)
        Friction coefficient applied per pair [-] (0 where released, without history or
        frictionless).
    cases : tuple of str, length n - 1
        Which case governs each pair: a key of :data:`PAIR_CASES`.
    model : {"clearance", "friction"}
        The model solved: ``"clearance"`` when every pair has mu = 0.
    reused : bool
        The solution was taken from a given :class:`~ctrplan.mechanics.BoundResult` (no solve).
    """

    tip_position: np.ndarray
    tip_tangent: np.ndarray
    solution: ContactSolution
    standard: StandardSolution
    eta: np.ndarray
    mu: np.ndarray
    cases: tuple
    model: str
    reused: bool = False

    @property
    def offset(self) -> float:
        """Distance of the predicted tip from the standard model's tip [m]."""
        return float(np.linalg.norm(self.tip_position - self.standard.tip_position))

    @property
    def ok(self) -> bool:
        """The contact solve converged and the standard equilibrium is not flagged unstable."""
        return bool(self.solution.diagnostics.ok)


def _history_arrays(robot, eta, translation_last):
    """Checked eta (n-1,) int in {-1, 0, 1} and translation-last flags (n-1,) bool."""
    m = robot.n_tubes - 1
    e = np.asarray(eta)
    if e.shape == () and m == 1:
        e = e.reshape(1)
    if e.shape != (m,):
        raise ValueError(f"eta must have shape ({m},) (one value per tube pair of robot {robot.name!r}), "
                         f"got shape {e.shape}")
    ef = e.astype(float)
    if not np.all(np.isin(ef, (-1.0, 0.0, 1.0))):
        raise ValueError(f"eta values must be -1, 0 or +1 (0: the pair has not rotated yet), got {e.tolist()}")
    t = np.asarray(translation_last)
    if t.shape == ():
        t = np.full(m, t)
    if t.shape != (m,):
        raise ValueError(f"translation_last must be one bool or shape ({m},), got shape {t.shape}")
    if t.dtype != bool and not np.all(np.isin(t.astype(float), (0.0, 1.0))):
        raise ValueError(f"translation_last must hold booleans, got {t.tolist()}")
    return ef.astype(int), t.astype(bool)


def pair_cases(robot, eta, translation_last) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Per-pair friction state of a history: (eta applied (n-1,) int, mu applied (n-1,), cases).

    Parameters and errors as :func:`predict_tip`.
    """
    e, t = _history_arrays(robot, eta, translation_last)
    mu_robot = np.asarray(robot.friction_coefficients, dtype=float)
    cases = []
    for ek, tk, mk in zip(e, t, mu_robot):
        if not mk > 0.0:
            cases.append("frictionless")
        elif ek == 0:
            cases.append("no_history")
        elif tk:
            cases.append("translation_last")
        else:
            cases.append("friction")
    active = np.array([c == "friction" for c in cases], dtype=bool)
    return np.where(active, e, 0), np.where(active, mu_robot, 0.0), tuple(cases)


def predict_tip(robot, alpha, beta, eta, translation_last=False, settings: ModelSettings | None = None, *,
                standard: StandardSolution | None = None, bound=None, warm_start=None,
                initial_guess=None) -> Prediction:
    """Predict the tip and the shape of a configuration reached by a given motion history.

    Parameters
    ----------
    robot : Robot
        Needs clearances (tube diameters or the override) and, for a friction prediction, the
        diameters of each pair (Eq. (41)).
    alpha : array-like, shape (n,)
        Base rotations [rad].
    beta : array-like, shape (n,)
        Base translations [m].
    eta : array-like of int, shape (n - 1,)
        Direction of the last relative rotation of tube i+1 with respect to tube i per pair:
        +1 CCW (``alpha_(i+1) - alpha_i`` increasing), -1 CW, 0 the pair has not rotated yet
        (eta_k of Eqs. (38)-(39)).
    translation_last : bool or array-like of bool, shape (n - 1,)
        Per pair: a base translation came after the pair's last relative rotation (Section
        V-B). One bool applies to every pair. Default False.
    settings : ModelSettings, optional
    standard : StandardSolution, optional, keyword-only
        Standard solution at this configuration (solved if not given).
    bound : BoundResult, optional, keyword-only
        :func:`~ctrplan.mechanics.evaluate_bound` at this configuration with the same settings:
        its clearance solution or its friction solution for these directions is reused when the
        prediction needs exactly that one (every pair with friction active, or none), so a
        prediction next to a bound costs no solve. A partial history (some pairs released) is
        solved, warm-started from its clearance solution.
    warm_start : ContactSolution, optional, keyword-only
        A contact solution at a nearby configuration to start the friction solve from (used only
        when its grid matches; a friction solve that does not converge from it is repeated from
        the clearance solution).
    initial_guess : array-like, shape (n,), optional, keyword-only
        Base torsions [1/m] to start the standard model from (branch following).

    Returns
    -------
    Prediction
        Tip position (3,) [m], tangent (3,), the solution (the shape), the standard solution,
        eta and mu applied per pair and which case governs each pair.

    Raises
    ------
    ValueError
        ``eta`` not of shape (n - 1,) or not in {-1, 0, +1}; ``translation_last`` not one bool
        or shape (n - 1,).
    JointLimitError
        Kinematically impossible configuration.
    ConvergenceError
        The standard model did not converge at this configuration (no linearization point).
    PhysicalParameterError
        No clearances, or friction without tube diameters.

    Notes
    -----
    Section V-B of Ha, Fagogenis & Dupont, "Modeling Tube Clearance and Bounding the Effect of
    Friction in Concentric Tube Robot Kinematics", IEEE T-RO 35(2):353-370, 2019,
    doi:10.1109/TRO.2018.2878906: pure rotations of sufficient angle reach the bounding friction
    solutions (Section III, Eqs. (37)-(47), direction eta_k of Eq. (38)); a final translation
    brings the tip close to the frictionless solution, here the clearance model (Sections II-B
    to II-E, Eqs. (10)-(36)). Per pair ``mu_k = robot.friction_coefficients[k]`` if
    ``eta_k != 0`` and not ``translation_last[k]``, else 0; with every mu_k = 0 the clearance
    model is solved. The paper's friction model assumes rotations "of sufficient angle" for the
    full Coulomb force to develop; a small last rotation is treated as a full one. Pairs with
    mu_k = 0 are passed to the solver with eta +1 (the friction terms scale with eta_k mu_k,
    Eqs. (40)-(41)). The solution does not depend on the path beyond (eta, translation-last):
    the quasi-static model has no other memory.
    """
    settings = settings or ModelSettings()
    eta_used, mu_used, cases = pair_cases(robot, eta, translation_last)
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    if bound is not None and standard is None:
        standard = bound.standard
    if standard is None:
        standard = solve_standard(robot, alpha, beta, settings, initial_guess=initial_guess,
                                  check_stability=False)
    if not standard.diagnostics.converged:
        raise ConvergenceError(f"standard model at alpha={np.round(alpha, 4)} rad, "
                               f"beta={np.round(beta * 1e3, 3)} mm: {standard.diagnostics.message}")
    friction = bool(np.any(mu_used > 0.0))
    sol, reused = None, False
    if bound is not None:
        if not friction:
            sol, reused = bound.clearance, True
        else:
            mu_robot = np.asarray(robot.friction_coefficients, dtype=float)
            if np.array_equal(mu_used > 0.0, mu_robot > 0.0):   # every pair that can carry friction does
                key = tuple(int(e) if e != 0 else 1 for e in eta_used)
                if key in bound.friction:
                    sol, reused = bound.friction[key], True
    if sol is None:
        if not friction:
            sol = solve_contact(robot, alpha, beta, settings, standard=standard)
        else:
            eta_solve = np.where(eta_used == 0, 1, eta_used)
            start = warm_start
            if start is None and bound is not None:
                start = bound.clearance
            sol = None
            if start is not None:
                sol = solve_contact(robot, alpha, beta, settings, eta=eta_solve, mu=mu_used,
                                    standard=standard, warm_start=start)
            if sol is None or not sol.diagnostics.converged:
                # a friction solve started from the standard linearization can wander for its whole
                # iteration budget; from the clearance solution it converges in a few steps (as in
                # evaluate_bound and simulate)
                cl = bound.clearance if bound is not None else solve_contact(robot, alpha, beta, settings,
                                                                             standard=standard)
                sol = solve_contact(robot, alpha, beta, settings, eta=eta_solve, mu=mu_used, standard=standard,
                                    warm_start=cl if cl.diagnostics.converged else None)
    return Prediction(tip_position=np.asarray(sol.tip_position, dtype=float).copy(),
                      tip_tangent=np.asarray(sol.tip_tangent, dtype=float).copy(), solution=sol,
                      standard=standard, eta=eta_used.astype(int), mu=mu_used, cases=cases,
                      model="friction" if friction else "clearance", reused=reused)
