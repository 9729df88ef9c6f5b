"""Fakes shared by the planning tests: a three-tube robot with the joints of the paper's robot,
an analytic "standard model" and a smooth fake bound (no mechanics needed, all fast)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ctrplan.robot import Joint, Robot, Section, Tube


def fake_robot() -> Robot:
    """Joints alpha_2, alpha_3 in [-pi, pi] (periodic) and beta_3 in [-0.104, -0.034] m."""
    tubes = (
        Tube("tube 1", (Section(0.10),), k_xy=0.1, outer_diameter=2.0e-3, inner_diameter=1.6e-3),
        Tube("tube 2", (Section(0.05), Section(0.05, (10.0, 0.0))), k_xy=0.05,
             outer_diameter=1.4e-3, inner_diameter=1.0e-3),
        Tube("tube 3", (Section(0.15), Section(0.04, (15.0, 0.0))), k_xy=0.01,
             outer_diameter=0.8e-3, inner_diameter=0.5e-3),
    )
    joints = (Joint("rotation", 1, -np.pi, np.pi), Joint("rotation", 2, -np.pi, np.pi),
              Joint("translation", 2, -0.104, -0.034))
    return Robot("fake", tubes, friction_coefficients=(0.1, 0.1), joints=joints,
                 home_beta=(0.0, 0.0, -0.07))


def fake_tip(alpha, beta):
    """Analytic tip position [m]: two 'arms' set by alpha_2, alpha_3 and an extension by beta_3."""
    a2, a3 = alpha[1], alpha[2]
    return np.array([0.02 * np.cos(a2) + 0.01 * np.cos(a3), 0.02 * np.sin(a2) + 0.01 * np.sin(a3),
                     0.1 + beta[2]])


class FakeSolution:
    def __init__(self, alpha, beta, ok=True):
        self.alpha, self.beta = np.asarray(alpha), np.asarray(beta)
        self.tip_position = fake_tip(alpha, beta)
        self.diagnostics = SimpleNamespace(converged=ok, unstable=not ok, ok=ok)

    def body(self, robot):
        """Straight line from the origin to the tip, 21 points, radius of tube 1 (1 mm)."""
        t = np.linspace(0.0, 1.0, 21)[:, None]
        return t * self.tip_position[None, :], np.full(21, 1e-3)


def fake_solve_standard(robot, alpha, beta, settings=None):
    return FakeSolution(alpha, beta)


def bump(alpha, beta, center=(0.0, 0.0), width=0.5, height=10e-3, base=0.5e-3):
    """Smooth bound [m]: a Gaussian bump over (alpha_2, alpha_3) (periodic distance)."""
    d2 = np.angle(np.exp(1j * (alpha[1] - center[0])))
    d3 = np.angle(np.exp(1j * (alpha[2] - center[1])))
    return base + height * np.exp(-(d2 ** 2 + d3 ** 2) / (2 * width ** 2))


def fake_bound(robot, alpha, beta, settings=None):
    """BoundResult-like object with a bump in position and smooth other quantities."""
    p = bump(alpha, beta)
    return SimpleNamespace(position=p, angle=10.0 * p, translation_last_position=0.3 * p + 0.01 * (beta[2] + 0.104),
                           translation_last_angle=3.0 * p,
                           diagnostics=SimpleNamespace(converged=True, unstable=False))


fake_bound.name = "fake-bound"
