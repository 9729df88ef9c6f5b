"""The uniqueness screen of the standard model (mechanics/_uniqueness.py) against the analytic
two-tube stability condition, and against the multistart search on real robots."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.constants import UNIQUENESS_SCREEN_MARGIN
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, solve_standard, solve_standard_batch
from ctrplan.mechanics._uniqueness import (_twist_bounds, unique_equilibrium_certified,
                                          unique_equilibrium_certified_at)
from ctrplan.mechanics.grid import build_grid
from ctrplan.mechanics.packed import pack_robot

ROOT = Path(__file__).resolve().parents[1]


def _two_tubes(lam, G=121, L=0.1, k=(0.05, 0.02), nu=0.3):
    """Two fully overlapping tubes of length L [m] with equal constant precurvature chosen so
    that L sqrt(c (1/k_1z + 1/k_2z)) = lam, c = k_1 k_2 u^2 / (k_1 + k_2): the classical
    stability parameter (Dupont et al. 2010), critical at pi / 2."""
    k = np.array(k)
    kz = k / (1.0 + nu)
    u = lam / np.sqrt(k[0] * k[1] / k.sum() * (1 / kz[0] + 1 / kz[1]) * L ** 2)
    uhat = np.zeros((G - 1, 2, 2))
    uhat[:, :, 1] = u
    return (np.linspace(0.0, L, G), np.array([0, 0]), np.array([G - 1, G - 1]), np.ones((G - 1, 2), bool),
            uhat, k, kz)


@pytest.mark.parametrize("fraction, margin, certified", [
    (0.90, 0.0, True), (0.99, 0.0, True), (1.01, 0.0, False), (1.10, 0.0, False),
    (0.90, UNIQUENESS_SCREEN_MARGIN, True), (0.97, UNIQUENESS_SCREEN_MARGIN, False),
])
def test_screen_threshold_is_the_analytic_two_tube_critical_value(fraction, margin, certified):
    """Without margin the screen certifies exactly below L sqrt(c (1/k_1z + 1/k_2z)) = pi/2 (to
    1 %: the grid's O(h^2) error), with the project's margin only below pi/2 / sqrt(1 + margin).
    Catches a wrong coupling (stiffness weights, a missing 1/K, lumping) or boundary
    conditions (a clamped tip would move the critical value to pi)."""
    args = _two_tubes(fraction * np.pi / 2)
    assert unique_equilibrium_certified(*args, margin) is certified


def test_screen_is_converged_in_the_grid_step():
    """The certificate at 0.995 and 1.005 of the critical value does not depend on the grid
    (41 to 321 nodes): the screen tests the continuous condition, not an artefact of h."""
    for G in (41, 81, 161, 321):
        assert unique_equilibrium_certified(*_two_tubes(0.995 * np.pi / 2, G=G), 0.0)
        assert not unique_equilibrium_certified(*_two_tubes(1.005 * np.pi / 2, G=G), 0.0)


@pytest.mark.parametrize("robot_file", ["ha2019-table2-nominal.toml", "ha2019-table2-six-joint.toml"])
def test_certified_configurations_have_one_equilibrium(robot_file):
    """Seeded random configurations, biased towards opposed curved tubes: wherever the screen
    certifies a configuration, solve_standard's multistart search finds a single stable
    equilibrium. Catches a screen that is not conservative."""
    robot = load_robot(ROOT / "model" / robot_file)
    rng = np.random.default_rng(11)
    lo, hi = robot.joint_lower, robot.joint_upper
    q = lo + rng.random((60, lo.size)) * (hi - lo)
    cfg = [robot.configuration(x) for x in q]
    alpha = np.array([a for a, _ in cfg])
    beta = np.array([b for _, b in cfg])
    alpha[::2, -1] = alpha[::2, -2] + np.pi          # every other one: innermost tubes opposed
    settings = ModelSettings()
    res = solve_standard_batch(robot, alpha, beta, settings, check_stability=True)
    assert res.certified.any()
    for k in np.nonzero(res.certified)[0]:
        ref = solve_standard(robot, alpha[k], beta[k], settings)
        assert ref.diagnostics.converged and not ref.diagnostics.unstable
        assert ref.diagnostics.n_equilibria == 1
        np.testing.assert_allclose(res.tip_position[k], ref.tip_position, atol=1e-9)


def _two_tubes_at(lam, theta0, G=121):
    """:func:`_two_tubes` with the inner tube's base rotated by ``theta0`` [rad]."""
    return (*_two_tubes(lam, G=G), np.array([0.0, theta0]))


@pytest.mark.parametrize("theta0", [np.pi, np.pi - 0.05, np.pi + 0.05])
def test_screen_with_rotations_does_not_certify_opposed_tubes_past_the_critical_value(theta0):
    """Two tubes rotated (nearly) opposite are bistable past L sqrt(c (1/k_1z + 1/k_2z)) = pi/2,
    so the alpha-aware screen must not certify them there, and must still certify them below it.
    Catches a twist bound or a worst cosine that wrongly excludes theta = pi (a bound that is
    too small, or a wrong distance to pi modulo 2 pi)."""
    args = _two_tubes_at(1.01 * np.pi / 2, theta0)
    assert not unique_equilibrium_certified_at(*args[:7], 0.0, args[7])
    args = _two_tubes_at(0.9 * np.pi / 2, theta0)
    assert unique_equilibrium_certified_at(*args[:7], 0.0, args[7])


@pytest.mark.parametrize("theta0", [0.0, 0.2, -0.2, 2 * np.pi])
def test_screen_with_rotations_certifies_nearly_aligned_tubes_past_the_worst_case(theta0):
    """With the precurvatures nearly aligned the energy is convex over every twist an equilibrium
    can have, beyond the worst-case critical value (1.2 of it here, where the worst-case screen
    fails; the twist bound is then about (1.2 pi / 2)^2 / 2 = 1.8 rad per pair). Catches a screen
    that ignores alpha (it would be no better than the worst case)."""
    args = _two_tubes_at(1.2 * np.pi / 2, theta0)
    assert not unique_equilibrium_certified(*args[:7], 0.0)
    assert unique_equilibrium_certified_at(*args[:7], 0.0, args[7])


@pytest.mark.parametrize("robot_file", ["ha2019-table2-nominal.toml", "ha2019-table7-calibrated.toml"])
def test_equilibria_twist_within_the_a_priori_bounds(robot_file):
    """Every node angle of solved equilibria (seeded random configurations, half of them with the
    innermost tubes opposed) lies within the twist bound Delta_i(s) of its base rotation, and the
    bound is not vacuous (some twist reaches half of it; measured 0.99). Catches a bound integrated in the
    wrong direction (from the tip), a missing 1/K or a k_xy / k_z mix-up."""
    robot = load_robot(ROOT / "model" / robot_file)
    rng = np.random.default_rng(5)
    lo, hi = robot.joint_lower, robot.joint_upper
    settings = ModelSettings()
    pk = pack_robot(robot)
    used = 0.0
    for m in range(40):
        a, b = robot.configuration(lo + rng.random(lo.size) * (hi - lo))
        if m % 2:
            a[-1] = a[-2] + np.pi
        try:
            sol = solve_standard(robot, a, b, settings, check_stability=False)
        except Exception:       # an impossible configuration
            continue
        g = build_grid(robot, b, settings.ds, settings.refine_ratio, settings.refine_length)
        delta = np.zeros((g.s.size, robot.n_tubes))
        _twist_bounds(g.s, g.first, g.last, g.present, g.precurvature, pk.k_xy, pk.k_xy / pk.stiffness_ratio, delta)
        for i in range(robot.n_tubes):
            nodes = np.arange(g.first[i], g.last[i] + 1)
            twist = np.abs(sol.psi[nodes, i] - a[i])
            assert np.all(twist <= delta[nodes, i] * (1 + 1e-6) + 1e-12)
            used = max(used, np.max(twist / np.maximum(delta[nodes, i], 1e-12)))
    assert used > 0.5


def test_screen_with_rotations_certifies_what_the_worst_case_screen_does():
    """Seeded random grids and rotations: wherever the worst-case screen certifies, so does the
    alpha-aware one (its coupling is never larger). Catches a sign error in the stabilizing
    coupling term (cos > 0) or a margin applied the wrong way."""
    rng = np.random.default_rng(3)
    more = 0
    for _ in range(200):
        lam = rng.uniform(0.5, 2.5)
        theta0 = rng.uniform(-np.pi, 3 * np.pi)
        args = _two_tubes_at(lam, theta0, G=41)
        old = unique_equilibrium_certified(*args[:7], UNIQUENESS_SCREEN_MARGIN)
        new = unique_equilibrium_certified_at(*args[:7], UNIQUENESS_SCREEN_MARGIN, args[7])
        assert new or not old
        more += new and not old
    assert more > 0
