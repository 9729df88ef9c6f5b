"""Mechanics of concentric tube robots (pure numerics: arrays and dataclasses in and out).

- :func:`solve_standard`: zero-clearance, torsionally compliant model (Section II-A).
- :func:`solve_clearance`: clearance model (Sections II-B to II-E, Appendices A and B).
- :func:`solve_friction`: one maximal torsional friction solution (Section III).
- :func:`evaluate_bound`: the per-configuration friction bound over all 2^(n-1) directions.
- :func:`continue_friction`: one friction solution followed in mu from the clearance solution
  (where it ends below the robot's mu, under maximal friction the tubes snap).
- :func:`predict_tip`: the tip and shape after a given motion history (Section V-B).
- :func:`solve_standard_batch`: the standard model at many configurations in one compiled call.
- :func:`standard_tip_derivatives` (and ``_batch``): exact derivatives of the standard model's tip
  with respect to base rotations, precurvatures and stiffnesses (implicit-function theorem).

:data:`MECHANICS_VERSION` names the version of their results (bound maps record it).

All from Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906.
"""

import importlib

from ..constants import MECHANICS_VERSION
from .discrete import TubeChain, chain_jacobians, forward_kinematics
from .grid import ArcLengthGrid, build_grid
from .results import BoundResult, ContactSolution, Diagnostics, ModelSettings, StandardSolution
from ._standard_batch import StandardBatch, StandardPath, solve_standard_batch, solve_standard_path
from ._lie import angle_between
from ._standard_bodies import StandardBodies, solve_standard_bodies, solve_standard_bodies_packed
from .standard import solve_standard
from .sensitivity import (StandardTipDerivatives, StandardTipDerivativesBatch, standard_tip_derivatives,
                          standard_tip_derivatives_batch)

# The contact models (and the bound and prediction built on them) are imported on first use
# (PEP 562), so a standard-model-only command (`ctrplan evaluate --model standard`) does not
# import the contact kernels. That saves only about 40 ms of a ~2.8 s one-row run (measured
# idle; no difference within noise over 12 alternated runs): numba's own linear algebra loads
# scipy.linalg anyway when the compiled standard kernels are loaded.
_LAZY = {"all_eta": ".bound", "evaluate_bound": ".bound",
         "continue_friction": ".continuation", "FrictionBranch": ".continuation",
         "solve_clearance": ".contact", "solve_contact": ".contact", "solve_friction": ".contact",
         "PAIR_CASES": ".prediction", "Prediction": ".prediction",
         "predict_tip": ".prediction"}


def __getattr__(name):
    """The lazily imported names of :data:`_LAZY`, imported on first access (PEP 562).

    Raises
    ------
    AttributeError
        ``name`` is not a name of this package.
    """
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "MECHANICS_VERSION", "solve_standard", "solve_standard_batch", "StandardBatch",
    "solve_standard_path", "StandardPath", "solve_clearance", "solve_friction", "solve_contact", "evaluate_bound",
    "all_eta", "continue_friction", "FrictionBranch", "ModelSettings", "StandardSolution", "ContactSolution", "BoundResult", "Diagnostics",
    "TubeChain", "forward_kinematics", "chain_jacobians", "ArcLengthGrid", "build_grid",
    "StandardBodies", "solve_standard_bodies", "solve_standard_bodies_packed", "angle_between",
    "predict_tip", "Prediction", "PAIR_CASES", "standard_tip_derivatives", "StandardTipDerivatives",
    "standard_tip_derivatives_batch", "StandardTipDerivativesBatch",
]
