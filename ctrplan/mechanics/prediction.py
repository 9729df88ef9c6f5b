"""History-aware prediction of the tip and the shape (Ha, Fagogenis & Dupont 2019, Section V-B).

The friction model of Section III gives 2^(n-1) bounding solutions, one per direction eta_k of
the last relative rotation of each contacting pair (Eqs. (38)-(39)). Given the motion history
that reaches a configuration, one of them is the prediction, not only a bound:

- a pair whose last relative rotation had direction eta_k and was not followed by a translation
  carries the maximal torsional friction in that direction (Eqs. (37)-(47));
- a pair whose last rotation was followed by a translation ("translation-last") is released:
  friction then acts mostly along the axis and the tip sits near the frictionless clearance
  solution (Section V-B, Figs. 19-21), so the pair gets mu = 0;
- a pair that has not rotated yet (eta_k = 0, no history) gets mu = 0;
- a pair whose robot friction coefficient is 0 is frictionless anyway;
- with gradually developing friction, the friction state e_k in [-1, 1] scales the coefficient.

When every pair ends with mu = 0 the prediction is the clearance solution (Sections II-B to
II-E); otherwise it is the friction solution with the per-pair eta and mu.

Pure numerics: arrays and dataclasses in and out. The history of a configuration, as one rule
for planned and recorded motions, is :mod:`ctrplan.history`'s (:class:`ctrplan.history.PairState`,
with the robot file's history effects: :func:`ctrplan.effects.history_state`; planned paths:
:func:`ctrplan.planning.path_history`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConvergenceError
from ..history import PAIR_CASES, PairState, pair_friction
from .contact import solve_contact
from .results import ContactSolution, ModelSettings, StandardSolution
from .standard import solve_standard

__all__ = ["Prediction", "predict_tip", "PAIR_CASES"]


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
    alpha, beta : ndarray, shape (n,)
        The configuration solved: the commanded one plus the state's offsets (e.g. the lag of a
        drive with backlash) [rad], [m].
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
    alpha: np.ndarray
    beta: np.ndarray
    reused: bool = False

    @property
    def offset(self) -> float:
        """Distance of the predicted tip from the standard model's tip [m]."""
        return float(np.linalg.norm(self.tip_position - self.standard.tip_position))

    @property
    def ok(self) -> bool:
        """The contact solve converged and the standard equilibrium is not flagged unstable."""
        return bool(self.solution.diagnostics.ok)


def _state(robot, eta, translation_last, state) -> PairState:
    """The history of the prediction: ``state``, or the paper's abrupt model for ``eta`` and
    ``translation_last`` on a robot without history effects."""
    m = robot.n_tubes - 1
    if state is not None:
        if eta is not None:
            raise ValueError("give either eta and translation_last, or state, not both")
        if np.shape(state.eta) != (m,) or np.shape(state.alpha_offset) != (robot.n_tubes,):
            raise ValueError(f"state is for {np.size(state.eta) + 1} tubes; robot {robot.name!r} has {robot.n_tubes}")
        return state
    if eta is None:
        raise ValueError("give eta (and translation_last) or a state (ctrplan.history.PairState)")
    from ..effects import REGISTRY, robot_effects

    file_effects = robot_effects(robot)
    acting = [n for n in file_effects.active()
              if REGISTRY[n].operator is not None or REGISTRY[n].friction_angle is not None]
    if acting:
        raise ValueError(f"robot {robot.name!r} has history effects ({', '.join(REGISTRY[n].label for n in acting)}): "
                         f"the prediction needs the configuration's state with them, state=... "
                         f"(ctrplan.effects.history_state of the motion, or ctrplan.planning.approach_history)")
    e = np.asarray(eta)
    if e.shape == () and m == 1:
        e = e.reshape(1)
    if e.shape != (m,):
        raise ValueError(f"eta must have shape ({m},) (one value per tube pair of robot {robot.name!r}), "
                         f"got shape {e.shape}")
    return PairState.abrupt(e, translation_last, robot.n_tubes)


def predict_tip(robot, alpha, beta, eta=None, translation_last=False, settings: ModelSettings | None = None, *,
                state: PairState | None = None, standard: StandardSolution | None = None, bound=None,
                warm_start=None, initial_guess=None) -> Prediction:
    """Predict the tip and the shape of a configuration reached by a given motion history.

    Parameters
    ----------
    robot : Robot
        Needs clearances (tube diameters or the override) and, for a friction prediction, the
        diameters of each pair (Eq. (41)).
    alpha : array-like, shape (n,)
        Commanded base rotations [rad].
    beta : array-like, shape (n,)
        Commanded base translations [m].
    eta : array-like of int, shape (n - 1,), optional
        Direction of the last relative rotation of tube i+1 with respect to tube i per pair:
        +1 CCW (``alpha_(i+1) - alpha_i`` increasing), -1 CW, 0 the pair has not rotated yet
        (eta_k of Eqs. (38)-(39)); the paper's abrupt friction model. Give this or ``state``.
    translation_last : bool or array-like of bool, shape (n - 1,)
        Per pair: a base translation came after the pair's last relative rotation (Section
        V-B). One bool applies to every pair. Default False.
    settings : ModelSettings, optional
    state : PairState, optional, keyword-only
        The configuration's history (:mod:`ctrplan.history`): offsets of the configuration the
        tubes reach from the commanded one (a drive's backlash), direction, release and friction
        state per pair (gradually developing friction). Needed when the robot file has history
        effects (:func:`ctrplan.effects.history_state` of the motion;
        :func:`ctrplan.planning.approach_history` for one approach).
    standard : StandardSolution, optional, keyword-only
        Standard solution at the configuration the tubes reach (solved if not given).
    bound : BoundResult, optional, keyword-only
        :func:`~ctrplan.mechanics.evaluate_bound` at the commanded configuration with the same
        settings: its clearance solution or its friction solution for these directions is reused
        when the prediction needs exactly that one (every pair with its full friction, or none,
        and no offset), so a prediction next to a bound costs no solve. A partial history (some
        pairs released or partly developed) is solved, warm-started from its clearance solution.
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
        or shape (n - 1,); neither or both of ``eta`` and ``state``; ``eta`` on a robot whose
        file has history effects (they need ``state``).
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
    model is solved (with ``state``: ``mu_k = |e_k| mu_robot_k`` in direction sign(e_k)). The
    paper's friction model assumes rotations "of sufficient angle" for the full Coulomb force to
    develop; with ``eta`` a small last rotation is treated as a full one. Pairs with
    mu_k = 0 are passed to the solver with eta +1 (the friction terms scale with eta_k mu_k,
    Eqs. (40)-(41)). The solution does not depend on the path beyond (eta, translation-last):
    the quasi-static model has no other memory.
    """
    settings = settings or ModelSettings()
    st = _state(robot, eta, translation_last, state)
    eta_used, mu_used, cases = pair_friction(st, robot.friction_coefficients)
    shifted = bool(np.any(st.alpha_offset != 0.0) or np.any(st.beta_offset != 0.0))
    alpha = np.asarray(alpha, dtype=float) + st.alpha_offset
    beta = np.asarray(beta, dtype=float) + st.beta_offset
    if shifted:
        bound = None        # the bound is at the commanded configuration, the tubes are elsewhere
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
            if np.array_equal(mu_used, mu_robot):   # every pair that can carry friction does, fully
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
                      model="friction" if friction else "clearance", alpha=alpha, beta=beta, reused=reused)
