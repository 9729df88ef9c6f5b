"""Mechanics of concentric tube robots (pure numerics: arrays and dataclasses in and out).

- :func:`solve_standard`: zero-clearance, torsionally compliant model (Section II-A).
- :func:`solve_clearance`: clearance model (Sections II-B to II-E, Appendices A and B).
- :func:`solve_friction`: one maximal torsional friction solution (Section III).
- :func:`evaluate_bound`: the per-configuration friction bound over all 2^(n-1) directions.
- :func:`predict_tip`: the tip and shape after a given motion history (Section V-B).
- :func:`solve_standard_batch`: the standard model at many configurations in one compiled call.

:data:`MECHANICS_VERSION` names the version of their results (bound maps record it).

All from Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906.
"""

from ..constants import MECHANICS_VERSION
from .bound import all_eta, evaluate_bound
from .contact import solve_clearance, solve_contact, solve_friction
from .discrete import TubeChain, chain_jacobians, forward_kinematics
from .grid import ArcLengthGrid, build_grid
from .prediction import PAIR_CASES, Prediction, pair_cases, predict_tip
from .results import BoundResult, ContactSolution, Diagnostics, ModelSettings, StandardSolution
from ._standard_batch import StandardBatch, solve_standard_batch
from ._standard_bodies import StandardBodies, solve_standard_bodies
from .standard import solve_standard

__all__ = [
    "MECHANICS_VERSION", "solve_standard", "solve_standard_batch", "StandardBatch", "solve_clearance", "solve_friction", "solve_contact", "evaluate_bound",
    "all_eta", "ModelSettings", "StandardSolution", "ContactSolution", "BoundResult", "Diagnostics",
    "TubeChain", "forward_kinematics", "chain_jacobians", "ArcLengthGrid", "build_grid",
    "StandardBodies", "solve_standard_bodies",
    "predict_tip", "Prediction", "pair_cases", "PAIR_CASES",
]
