"""The friction bound (ctrplan/mechanics/bound.py logic) on the FROZEN REFERENCE solvers.

The bound's own logic was not part of the speed work, so it is shared; only the
standard and contact solvers are the frozen copies (standard_reference, contact_reference).
"""

from __future__ import annotations

from ctrplan.mechanics.bound import _evaluate_bound, all_eta

from .contact_reference import solve_contact
from .standard_reference import solve_standard

__all__ = ["evaluate_bound", "all_eta"]


def evaluate_bound(robot, alpha, beta, settings=None, *, standard=None, initial_guess=None):
    """:func:`ctrplan.mechanics.evaluate_bound` with the reference solvers."""
    return _evaluate_bound(robot, alpha, beta, settings, standard, initial_guess,
                           solve_standard=solve_standard, solve_contact=solve_contact)
