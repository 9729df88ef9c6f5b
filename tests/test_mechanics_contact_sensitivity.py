"""Implicit-function derivatives of the clearance and friction models' tips
(ctrplan.mechanics.contact_sensitivity) against central differences of tightly converged solves.

The reference re-solves the model at q +- h from the base solution (outer tolerance 3e-11 m) and
takes (tip(q + h) - tip(q - h)) / 2h; a column whose contact set changes between q - h and q + h
is not a derivative of one smooth branch and is counted, not compared.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from ctrplan.errors import ConvergenceError
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, solve_contact, solve_standard
from ctrplan.mechanics import contact_sensitivity as cs
from ctrplan.mechanics.contact_sensitivity import (contact_parameter_columns, contact_tip_derivatives,
                                                   contact_tip_jacobian)

MODEL = Path(__file__).resolve().parents[1] / "model"
TIGHT = dataclasses.replace(ModelSettings(), outer_tol=3e-11, complementarity_tol=1e-11, max_outer_iterations=400)
# relative tolerance of a column against the reference (errors seen: 1e-7..3e-5; the solver's
# own linearization without the derivative of the chain Jacobian and contact frames is 1-250 %
# off, test_the_frozen_linearization_alone_is_not_the_derivative)
RTOL = 2e-4


def _configuration(robot, seed, friction):
    rng = np.random.default_rng(seed)
    n = robot.n_tubes
    alpha = rng.uniform(-np.pi, np.pi, n)
    beta = np.zeros(n)
    eta = np.where(rng.uniform(size=n - 1) < 0.5, -1, 1) if friction else None
    return alpha, beta, eta


def _solve(robot, alpha, beta, eta, settings=TIGHT, warm_start=None):
    std = solve_standard(robot, alpha, beta, settings, check_stability=False)
    sol = solve_contact(robot, alpha, beta, settings, eta=eta, standard=std, warm_start=warm_start)
    assert sol.diagnostics.converged, sol.diagnostics.message
    return std, sol


def _with_tube(robot, i, **changes):
    tubes = list(robot.tubes)
    tubes[i] = dataclasses.replace(tubes[i], **changes)
    return robot.replace(tubes=tuple(tubes))


def _with_precurvature(robot, i, j, comp, h):
    secs = list(robot.tubes[i].sections)
    pc = list(secs[j].precurvature)
    pc[comp] += h
    secs[j] = dataclasses.replace(secs[j], precurvature=tuple(pc))
    return _with_tube(robot, i, sections=tuple(secs))


def _perturbations(robot, friction):
    """(label, robot(h) or ("alpha", tube), step, analytic column from a ContactTipDerivatives) of
    every parameter."""
    out = []
    for i, tube in enumerate(robot.tubes):
        for j, sec in enumerate(tube.sections):
            if sec.is_straight:
                continue
            for comp in range(2):
                out.append((f"precurvature {i} {j} {comp}", lambda h, i=i, j=j, c=comp: _with_precurvature(robot, i, j, c, h),
                            1e-3, lambda d, i=i, j=j, c=comp: d.d_position_d_precurvature[:, i, j, c]))
        k, nu = tube.k_xy, tube.poisson_ratio
        # k_xy with nu held moves k_z too: d/dk_xy|nu = d_k_xy + d_k_z / (1 + nu)
        out.append((f"k_xy {i}", lambda h, i=i, k=k: _with_tube(robot, i, k_xy=k + h), 1e-4 * k,
                    lambda d, i=i, nu=nu: d.d_position_d_k_xy[:, i] + d.d_position_d_k_z[:, i] / (1 + nu)))
        out.append((f"nu {i}", lambda h, i=i, nu=nu: _with_tube(robot, i, poisson_ratio=nu + h), 1e-4,
                    lambda d, i=i, k=k, nu=nu: -k / (1 + nu) ** 2 * d.d_position_d_k_z[:, i]))
    c0 = np.asarray(robot.clearances, float)
    for i in range(robot.n_tubes):
        # a base rotation: the configuration, not the robot, moves (see _compare)
        out.append((f"alpha {i}", ("alpha", i), 1e-5, lambda d, i=i: d.d_position_d_alpha[:, i]))
    for i in range(robot.n_tubes - 1):
        out.append((f"clearance {i}",
                    lambda h, i=i: robot.replace(clearances_override=tuple(c0 + h * (np.arange(c0.size) == i))),
                    1e-7, lambda d, i=i: d.d_position_d_clearance[:, i]))
        if friction:
            mu0 = np.asarray(robot.friction_coefficients, float)
            out.append((f"mu {i}",
                        lambda h, i=i: robot.replace(friction_coefficients=tuple(mu0 + h * (np.arange(mu0.size) == i))),
                        1e-4, lambda d, i=i: d.d_position_d_mu[:, i]))
    return out


def _compare(robot, alpha, beta, eta, der, sol):
    """Every column's error over its allowance (pass: below 1) where the contact set holds over
    +-h, and the labels skipped."""
    act = sol.multipliers > 0
    errors, skipped = {}, []
    for label, make, h, analytic in _perturbations(robot, eta is not None):
        tips, same = [], True
        for step in (h, -h):
            rob, a = robot, alpha
            if isinstance(make, tuple):
                a = alpha + step * (np.arange(robot.n_tubes) == make[1])
            else:
                rob = make(step)
            _, s = _solve(rob, a, beta, eta, warm_start=sol)
            tips.append(s.tip_position)
            same &= np.array_equal(s.multipliers > 0, act)
        ref = (tips[0] - tips[1]) / (2 * h)
        if not same:
            skipped.append(label)
            continue
        # a column passes within RTOL of itself, or within the reference's own error: the solves'
        # tolerance over the step (a derivative that vanishes cannot be checked below it)
        noise = 20 * TIGHT.outer_tol / h
        err = float(np.linalg.norm(analytic(der) - ref))
        errors[label] = err / (RTOL * float(np.linalg.norm(ref)) + noise)
    return errors, skipped


CASES = [("ha2019-table1-tube-pair.toml", 3), ("ha2019-table1-tube-pair.toml", 5),
         ("ha2019-table7-calibrated.toml", 2), ("ha2019-table2-six-joint.toml", 3)]


@pytest.mark.parametrize("friction", [False, True], ids=["clearance", "friction"])
@pytest.mark.parametrize("name,seed", CASES)
def test_tip_derivatives_match_central_differences_of_tight_solves(name, seed, friction):
    robot = load_robot(MODEL / name)
    alpha, beta, eta = _configuration(robot, seed, friction)
    std, sol = _solve(robot, alpha, beta, eta)
    der = contact_tip_derivatives(robot, alpha, beta, sol, TIGHT, standard=std)
    errors, skipped = _compare(robot, alpha, beta, eta, der, sol)
    assert len(errors) >= len(skipped) + 4, f"too few columns compared: {sorted(errors)}, skipped {skipped}"
    worst = max(errors, key=errors.get)
    assert errors[worst] < 1.0, f"{worst}: error {errors[worst]:.2e} times its allowance ({errors})"
    assert np.allclose(der.tip_position, sol.tip_position, rtol=0, atol=1e-12)
    assert der.active == int(np.sum(sol.multipliers > 0)) > 0


def test_the_frozen_linearization_alone_is_not_the_derivative(monkeypatch):
    """Without the products with the full Jacobian (the solver's own linearization solved once:
    the chain Jacobian, the contact frames and the friction torques' directions held at the
    solution) the columns are 1-250 % off; the test above then fails."""
    robot = load_robot(MODEL / "ha2019-table1-tube-pair.toml")
    alpha, beta, eta = _configuration(robot, 3, True)
    std, sol = _solve(robot, alpha, beta, eta)
    from ctrplan.mechanics._contact_sensitivity_kernels import frozen_solve

    def frozen_only(u, lam, act, arr, scr, A, ULt, Y, LU, piv, lam_scale, rhs, *_):
        out = np.zeros_like(rhs)
        for j in range(rhs.shape[1]):
            col = np.empty(rhs.shape[0])
            frozen_solve(A, ULt, Y, LU, piv, np.ascontiguousarray(rhs[:, j]), col)
            out[:, j] = col
        return out, 0, 0.0

    monkeypatch.setattr(cs, "gcr_solve", frozen_only)
    der = contact_tip_derivatives(robot, alpha, beta, sol, TIGHT, standard=std)
    errors, _ = _compare(robot, alpha, beta, eta, der, sol)
    assert max(errors.values()) > 50.0, errors


def test_derivatives_of_a_default_tolerance_solution_are_those_of_the_tight_one():
    """The derivative depends on the solution, not on a difference of two solves, so the
    solver's default tolerance (1e-6 m) costs little accuracy at these configurations (forward
    differences from such solves are 4 % to several times off, benchmarks/friction_columns_accuracy.py;
    where a loose solve settles a contact at the edge of the set on the other side, the
    derivative is that set's, docs/mechanics.md Sec. 6)."""
    robot = load_robot(MODEL / "ha2019-table7-calibrated.toml")
    for seed in range(2):
        alpha, beta, eta = _configuration(robot, seed, True)
        jac = []
        for settings in (TIGHT, ModelSettings()):
            std, sol = _solve(robot, alpha, beta, eta, settings)
            jac.append(contact_tip_jacobian(robot, alpha, beta, sol, settings, standard=std).d_position)
        err = np.linalg.norm(jac[1] - jac[0], axis=0) / np.maximum(np.linalg.norm(jac[0], axis=0),
                                                                   1e-3 * np.abs(jac[0]).max())
        assert err.max() < 1e-4, err


def test_directions_are_combinations_of_the_columns():
    """Solving only for combinations (a fit's parameter moves several tube parameters) gives the
    same combinations of the one-by-one columns (the system is linear in its right-hand side)."""
    robot = load_robot(MODEL / "ha2019-table2-six-joint.toml")
    alpha, beta, eta = _configuration(robot, 2, True)
    std, sol = _solve(robot, alpha, beta, eta)
    full = contact_tip_jacobian(robot, alpha, beta, sol, TIGHT, standard=std)
    labels = contact_parameter_columns(robot)
    assert full.d_position.shape == (3, len(labels))
    D = np.random.default_rng(0).normal(size=(len(labels), 3))
    part = contact_tip_jacobian(robot, alpha, beta, sol, TIGHT, standard=std, directions=D)
    assert np.allclose(part.d_position, full.d_position @ D, rtol=1e-6, atol=1e-8 * np.abs(full.d_position).max())
    assert np.allclose(part.d_tangent, full.d_tangent @ D, rtol=1e-6, atol=1e-8 * np.abs(full.d_tangent).max())
    # the tangent's derivative stays normal to the tangent (it is a rotation of a unit vector)
    assert np.abs(full.tip_tangent @ full.d_tangent).max() < 1e-9 * np.abs(full.d_tangent).max()


def test_a_multiplier_near_zero_is_reported_and_each_side_that_keeps_the_set_agrees():
    """At a configuration where an active contact carries 4e-4 of the largest multiplier, the
    derivative is that of the set the solver found: the one-sided differences of both sides that
    keep the set agree with it to O(h), and the result says how close the set is to changing."""
    robot = load_robot(MODEL / "ha2019-table2-six-joint.toml")
    alpha, beta, eta = _configuration(robot, 3, True)
    std, sol = _solve(robot, alpha, beta, eta)
    der = contact_tip_derivatives(robot, alpha, beta, sol, TIGHT, standard=std)
    assert der.set_margin < 1e-2
    lam = sol.multipliers
    # the margin from the solution's own record: multipliers, and gaps against each pair's clearance
    clearance = np.asarray(robot.clearances, float)[sol.contact_pair]
    off = lam == 0
    with np.errstate(divide="ignore"):     # concentric contacts: no gap, an infinite margin
        expected = min(np.min(lam[~off]) / lam.max(), np.min(clearance[off] / sol.contact_gap[off] - 1.0))
    assert der.set_margin == pytest.approx(expected, rel=1e-6)
    c0 = np.asarray(robot.clearances, float)
    col = der.d_position_d_clearance[:, 0]
    for h in (1e-8, -1e-8):
        rob = robot.replace(clearances_override=(c0[0] + h, *c0[1:]))
        _, s = _solve(rob, alpha, beta, eta, warm_start=sol)
        assert np.array_equal(s.multipliers > 0, lam > 0)
        one_sided = (s.tip_position - sol.tip_position) / h
        assert np.linalg.norm(one_sided - col) < 2e-4 * np.linalg.norm(col)


def test_bad_input_is_refused():
    robot = load_robot(MODEL / "ha2019-table1-tube-pair.toml")
    alpha, beta, eta = _configuration(robot, 3, True)
    std, sol = _solve(robot, alpha, beta, eta)
    with pytest.raises(ValueError, match="directions must have shape"):
        contact_tip_jacobian(robot, alpha, beta, sol, TIGHT, standard=std, directions=np.ones((3, 1)))
    with pytest.raises(ValueError, match="alpha must be"):
        contact_tip_jacobian(robot, alpha[:1], beta, sol, TIGHT)
    # the solution of another configuration is not an equilibrium here
    other = alpha + np.array([0.0, 0.7])
    with pytest.raises(ValueError, match="not an equilibrium"):
        contact_tip_jacobian(robot, other, beta, sol, TIGHT)
    flagged = dataclasses.replace(sol, diagnostics=dataclasses.replace(sol.diagnostics, converged=False))
    with pytest.raises(ConvergenceError, match="did not converge"):
        contact_tip_jacobian(robot, alpha, beta, flagged, TIGHT, standard=std)
    with pytest.raises(ValueError, match="multipliers do not match"):
        contact_tip_jacobian(robot, alpha, beta, dataclasses.replace(sol, multipliers=None), TIGHT, standard=std)
    # a solution flagged converged whose curvatures are NaN (the outer loop's test lets them pass)
    nan = dataclasses.replace(sol, curvatures=[np.full_like(c, np.nan) for c in sol.curvatures])
    with pytest.raises(ConvergenceError, match="not finite"):
        contact_tip_jacobian(robot, alpha, beta, nan, TIGHT, standard=std)


def test_the_bound_derivative_is_that_of_the_attaining_solution():
    """d(bound)/dq against central differences of evaluate_bound: the friction coefficient (only
    the friction solution moves) and a bending stiffness (both tips move; their columns are
    about 0.19 m per N m^2 and the bound's about 1.5e-3, so the allowance is relative to the
    tips' columns)."""
    from ctrplan.mechanics import evaluate_bound
    from ctrplan.mechanics.contact_sensitivity import bound_derivatives

    robot = load_robot(MODEL / "ha2019-table7-calibrated.toml")
    alpha, beta, _ = _configuration(robot, 2, False)
    bd = bound_derivatives(robot, alpha, beta, TIGHT)
    labels = contact_parameter_columns(robot)
    assert bd.d_position.shape == (len(labels),) and bd.position > 0
    mu0 = np.asarray(robot.friction_coefficients, float)
    k, nu = robot.tubes[1].k_xy, robot.tubes[1].poisson_ratio
    cases = [(lambda h: robot.replace(friction_coefficients=(mu0[0] + h, mu0[1])), 1e-4,
              bd.d_position[labels.index(("mu", 0))], bd.d_angle[labels.index(("mu", 0))], 3e-4),
             (lambda h: _with_tube(robot, 1, k_xy=k + h), 1e-4 * k,
              bd.d_position[labels.index(("k_xy", 1))] + bd.d_position[labels.index(("k_z", 1))] / (1 + nu),
              bd.d_angle[labels.index(("k_xy", 1))] + bd.d_angle[labels.index(("k_z", 1))] / (1 + nu), 0.19)]
    for make, h, d_pos, d_ang, tip_scale in cases:
        up, down = evaluate_bound(make(h), alpha, beta, TIGHT), evaluate_bound(make(-h), alpha, beta, TIGHT)
        assert np.isclose(d_pos, (up.position - down.position) / (2 * h), rtol=0, atol=1e-4 * tip_scale)
        assert np.isclose(d_ang, (up.angle - down.angle) / (2 * h), rtol=1e-3, atol=1e-4 * tip_scale)
    # clearances and friction do not move the standard tip: the translation-last bound's mu
    # column is the clearance solution's, which has no friction
    assert bd.d_translation_last_position[labels.index(("mu", 0))] == 0.0


@pytest.mark.parametrize("name,seed", [("ha2019-table7-calibrated.toml", 5), ("ha2019-table1-tube-pair.toml", 5)])
def test_the_taylor_remainder_falls_as_h_squared(name, seed):
    """|tip(q + h v) - tip(q) - h J v| along a direction that moves every curved section's u_y and
    mu_1 together falls 100-fold per decade of h (seen: slopes 2.00 from h = 3e-2 to 1e-3, the
    contact set held); a derivative off by a relative e leaves a remainder of slope 1 once
    h < e, which a slope of at least 1.9 over these decades excludes down to e of about 1e-5."""
    robot = load_robot(MODEL / name)
    alpha, beta, eta = _configuration(robot, seed, True)
    std, sol = _solve(robot, alpha, beta, eta)
    labels = contact_parameter_columns(robot)
    D = np.zeros((len(labels), 1))
    for i, tube in enumerate(robot.tubes):
        for j, sec in enumerate(tube.sections):
            if not sec.is_straight:
                D[labels.index(("precurvature", i, j, 1)), 0] = 1.0
    D[labels.index(("mu", 0)), 0] = 0.1
    jac = contact_tip_jacobian(robot, alpha, beta, sol, TIGHT, standard=std, directions=D)
    mu0 = np.asarray(robot.friction_coefficients, float)
    hs = np.array([3e-2, 1e-2, 3e-3, 1e-3])
    rem = []
    for h in hs:
        tubes = [dataclasses.replace(t, sections=tuple(
            s if s.is_straight else dataclasses.replace(s, precurvature=(s.precurvature[0], s.precurvature[1] + h))
            for s in t.sections)) for t in robot.tubes]
        rob = robot.replace(tubes=tuple(tubes), friction_coefficients=(mu0[0] + 0.1 * h, *mu0[1:]))
        _, s = _solve(rob, alpha, beta, eta, warm_start=sol)
        assert np.array_equal(s.multipliers > 0, sol.multipliers > 0), f"contact set changed at h = {h}"
        rem.append(np.linalg.norm(s.tip_position - sol.tip_position - h * jac.d_position[:, 0]))
    slopes = np.diff(np.log(rem)) / np.diff(np.log(hs))
    assert np.all((slopes > 1.9) & (slopes < 2.1)), (rem, slopes)


def test_a_common_base_rotation_turns_the_tip_about_the_axis():
    """Rotating every tube's base by the same angle rotates the whole solution about the z axis
    (nothing else changes), so sum_i d tip / d alpha_i = e_z x tip and the same for the tangent,
    computed without differences. Catches a missing direct term of the tip tube's rotation or a
    wrong alpha column of the equilibrium."""
    for name, seed in (("ha2019-table1-tube-pair.toml", 3), ("ha2019-table7-calibrated.toml", 2)):
        robot = load_robot(MODEL / name)
        alpha, beta, eta = _configuration(robot, seed, True)
        std, sol = _solve(robot, alpha, beta, eta)
        der = contact_tip_derivatives(robot, alpha, beta, sol, TIGHT, standard=std)
        ez = np.array([0.0, 0.0, 1.0])
        scale = np.linalg.norm(der.d_position_d_alpha, axis=0).max()
        assert np.allclose(der.d_position_d_alpha.sum(axis=1), np.cross(ez, sol.tip_position), rtol=0, atol=1e-6 * scale)
        assert np.allclose(der.d_tangent_d_alpha.sum(axis=1), np.cross(ez, sol.tip_tangent), rtol=0,
                           atol=1e-6 * np.linalg.norm(der.d_tangent_d_alpha, axis=0).max())
