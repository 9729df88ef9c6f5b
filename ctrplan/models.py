"""The registry of mechanics models: the one list of model names the package accepts.

The models are entries of :data:`MODEL_REGISTRY` (a :class:`ctrplan.registry.Registry`). A
name here is what ``ctrplan evaluate --model``, a robot file's ``model`` key, the batch
evaluator and the discrepancy simulator accept. Each entry says in one line what the model is and
which part of Ha, Fagogenis & Dupont, "Modeling Tube Clearance and Bounding the Effect of Friction
in Concentric Tube Robot Kinematics", IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906, it
implements. The solvers themselves are in :mod:`ctrplan.mechanics`.

This module imports nothing heavy, so that the command line can build its options from it.
"""

from __future__ import annotations

from dataclasses import dataclass

from .registry import Registry, UnknownNameError

__all__ = ["ModelInfo", "MODEL_REGISTRY", "MODEL_INFO", "MODELS", "check_model"]


@dataclass(frozen=True)
class ModelInfo:
    """One mechanics model of the registry.

    Attributes
    ----------
    name : str
        Its name in files, tables and on the command line.
    description : str
        One line: what the model assumes.
    source : str
        Where in Ha, Fagogenis & Dupont 2019 it is defined.
    solver : str
        The :mod:`ctrplan.mechanics` function that solves it (this module sits below the
        mechanics and names it only).
    contact : bool
        Whether it needs the contact solve: the tubes' clearances, the contact forces and the
        compiled contact kernels (a configuration costs milliseconds, not microseconds).
    friction : bool
        Whether it needs the friction directions eta, shape (n - 1,), and the robot's friction
        coefficient mu; over all 2^(n-1) directions it gives the error bound (Section III).
    """

    name: str
    description: str
    source: str
    solver: str
    contact: bool
    friction: bool


def _check_entry(name: str, info) -> None:
    """A registry entry must be a :class:`ModelInfo` of the same name."""
    if not isinstance(info, ModelInfo) or info.name != name:
        raise TypeError(f"a mechanics model entry must be a ModelInfo named {name!r}, got {info!r}")
    if info.friction and not info.contact:
        raise ValueError(f"mechanics model {name!r}: friction needs the contact solve (contact=True)")


#: The mechanics models by name, in the order the package lists them.
MODEL_REGISTRY: Registry[ModelInfo] = Registry("mechanics model", check=_check_entry)
for _info in (
        ModelInfo("standard", "zero clearance between the tubes, torsionally compliant, no friction",
                  "Section II-A", "solve_standard", contact=False, friction=False),
        ModelInfo("clearance", "tubes move inside each other's clearance, contact forces, no friction",
                  "Sections II-B to II-E, Appendices A and B", "solve_clearance", contact=True, friction=False),
        ModelInfo("friction", "clearance model with maximal torsional friction in given directions eta",
                  "Section III, Eqs. (37)-(43)", "solve_friction", contact=True, friction=True)):
    MODEL_REGISTRY.register(_info.name, _info)
del _info

#: A live read-only view of :data:`MODEL_REGISTRY`: ``{name: ModelInfo}``.
MODEL_INFO = MODEL_REGISTRY.view

#: Names of the mechanics models, in registry order: ``("standard", "clearance", "friction")``.
MODELS: tuple[str, ...] = tuple(MODEL_INFO)


def check_model(model: str) -> str:
    """Return ``model`` if it names a registered mechanics model.

    Parameters
    ----------
    model : str
        A model name.

    Returns
    -------
    str
        ``model`` unchanged.

    Raises
    ------
    UnknownNameError
        ``model`` is not registered (a :class:`ValueError`; the message lists the registered
        models).
    """
    if model not in MODEL_REGISTRY:
        raise UnknownNameError(MODEL_REGISTRY.kind, model, MODEL_REGISTRY.names())
    return model
