"""The child processes of :mod:`ctrplan.mechanics.warmup`: :func:`main` compiles and caches the
contact-model kernels from a straight-tube linearization point, without the standard-model
kernels; :func:`main_threaded_batch` compiles the threaded standard-model batch kernel."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from . import warmup

__all__ = ["compile_contact_kernels", "compile_threaded_batch", "main", "main_threaded_batch"]


def _straight_state(robot, alpha, beta, settings):
    """A linearization point for the contact solver that needs no standard-model kernel: the
    common grid of ``robot`` at ``beta``, psi = alpha, no bending and no torsion, with the
    fields of :class:`~ctrplan.mechanics.results.StandardSolution` that the solver reads."""
    from .grid import build_grid

    g = build_grid(robot, beta, settings.ds, settings.refine_ratio, settings.refine_length)
    k = g.s.size - 1
    n = robot.n_tubes
    return SimpleNamespace(
        grid=g, alpha=np.asarray(alpha, dtype=float), beta=np.asarray(beta, dtype=float),
        psi_mid=np.tile(np.asarray(alpha, dtype=float), (k, 1)), torsion_mid=np.zeros((k, n)),
        bending_mid=np.zeros((k, 2)),
        diagnostics=SimpleNamespace(unstable=False, n_equilibria=1))


def _small_robot():
    """A small three-tube robot with diameters and friction (types are what matter here)."""
    from ..robot import Robot, Section, Tube

    tubes = (Tube("tube 1", (Section(0.10, (0.0, 5.0)),), k_xy=0.05, poisson_ratio=0.3,
                  outer_diameter=2.6e-3, inner_diameter=2.4e-3),
             Tube("tube 2", (Section(0.05), Section(0.08, (0.0, 8.0))), k_xy=0.04, poisson_ratio=0.3,
                  outer_diameter=2.3e-3, inner_diameter=1.9e-3),
             Tube("tube 3", (Section(0.10), Section(0.06, (0.0, 15.0))), k_xy=0.01, poisson_ratio=0.3,
                  outer_diameter=1.8e-3, inner_diameter=None))
    return Robot("compile", tubes, friction_coefficients=(0.2, 0.1))


def compile_contact_kernels() -> None:
    """Compile (and cache) the contact-model kernels: a clearance solve and a friction solve of a
    small three-tube robot from the straight-tube state of :func:`_straight_state`."""
    from .contact import solve_contact
    from .results import ModelSettings

    robot = _small_robot()
    settings = ModelSettings()
    alpha, beta = (0.0, 1.0, 2.0), (0.0, -0.02, -0.04)
    state = _straight_state(robot, alpha, beta, settings)
    solve_contact(robot, alpha, beta, settings, standard=state, raise_on_failure=False)
    solve_contact(robot, alpha, beta, settings, eta=(1, -1), standard=state, raise_on_failure=False)


def main() -> None:
    """The child process of :func:`ctrplan.mechanics.warmup.start`: it holds the lock (an
    inherited file descriptor) while it compiles, so its own solves must not wait for it."""
    warmup._READY[0] = True
    compile_contact_kernels()


def compile_threaded_batch() -> None:
    """Compile (and cache) the threaded standard-model batch kernel with the argument types of
    ``ctrplan evaluate --model standard`` (stability check, rows followed)."""
    from ._standard_batch import solve_standard_batch

    robot = _small_robot()
    alpha = np.array([[0.0, 1.0, 2.0], [0.0, 1.5, 2.5]])
    beta = np.array([[0.0, -0.02, -0.04], [0.0, -0.02, -0.04]])
    solve_standard_batch(robot, alpha, beta, check_stability=True, follow=True, n_threads=2, compile_threads=True)


def main_threaded_batch() -> None:
    """The child process of :func:`ctrplan.mechanics.warmup.start_threaded_batch`: it holds the
    lock while it compiles, so its own call must not wait for it."""
    warmup._THREADED_READY[0] = True
    compile_threaded_batch()
