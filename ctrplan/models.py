"""The registry of mechanics models: the one list of model names the package accepts.

The models are entries of :data:`MODEL_REGISTRY` (a :class:`ctrplan.registry.Registry`). A
name here is what ``ctrplan evaluate --model``, a robot file's ``model`` key, the batch
evaluator and the discrepancy simulator accept. Each entry says in one line what the model is and
which part of Ha, Fagogenis & Dupont, "Modeling Tube Clearance and Bounding the Effect of Friction
in Concentric Tube Robot Kinematics", IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906, it
implements, and holds the function that solves it (:attr:`ModelInfo.solve`). The solvers
themselves are in :mod:`ctrplan.mechanics`.

A model is solved at a configuration on top of the standard model's solution there, the
linearization point of the contact models (Section II-E): the callers (:mod:`ctrplan.batch`,
:mod:`ctrplan.discrepancy.fits.simulate`) solve the standard model, with their own branch following,
and pass it to ``solve``. Adding a model is one :meth:`~ctrplan.registry.Registry.register` call
with a :class:`ModelInfo` (docs/architecture.md has a worked example).

This module imports nothing heavy, so that the command line can build its options from it: the
contact solver is imported when :func:`contact_solution` is first called.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .registry import Registry, UnknownNameError

__all__ = ["ModelInfo", "MODEL_REGISTRY", "MODEL_INFO", "MODELS", "check_model", "standard_solution",
           "contact_solution"]


def standard_solution(robot, alpha, beta, settings, *, standard, eta=None, mu=None, warm_start=None):
    """The standard model's solution: the standard solve itself (Section II-A of Ha et al. 2019).

    The ``solve`` of the registry's ``"standard"`` entry. Arguments as :attr:`ModelInfo.solve`;
    ``eta``, ``mu`` and ``warm_start`` are not used.

    Returns
    -------
    StandardSolution
        ``standard``.
    """
    return standard


def contact_solution(robot, alpha, beta, settings, *, standard, eta=None, mu=None, warm_start=None):
    """The clearance model (``eta`` None) or one maximal-torsional-friction solution (``eta``
    given): :func:`ctrplan.mechanics.solve_contact` about the standard solution ``standard``
    (Sections II-B to II-E and III, Eqs. (37)-(47) of Ha et al. 2019).

    The ``solve`` of the registry's ``"clearance"`` and ``"friction"`` entries. Arguments as
    :attr:`ModelInfo.solve`.

    Returns
    -------
    ContactSolution

    Raises
    ------
    ctrplan.errors.PhysicalParameterError
        A robot without clearances, or friction without a diameter per pair.
    """
    from .mechanics.contact import solve_contact   # the contact kernels load on the first solve

    return solve_contact(robot, alpha, beta, settings, eta=eta, mu=mu, standard=standard, warm_start=warm_start)


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
    solve : callable
        ``solve(robot, alpha, beta, settings, *, standard, eta=None, mu=None, warm_start=None)
        -> solution``: the model at one configuration, ``alpha`` and ``beta`` shape (n,) [rad],
        [m], given the standard model's solution ``standard`` there (a
        :class:`~ctrplan.mechanics.StandardSolution`); ``eta`` shape (n - 1,) in {-1, +1} and
        ``mu`` shape (n - 1,) the friction directions and coefficients (friction models), and
        ``warm_start`` a solution of the same model to start from. The solution has
        ``tip_position`` (3,) [m], ``tip_tangent`` (3,) and ``diagnostics`` (a
        :class:`~ctrplan.mechanics.Diagnostics`); a model that does not converge says so there
        rather than raising.
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
    solve: Callable
    contact: bool
    friction: bool

    @property
    def standard_only(self) -> bool:
        """Its solution is the standard model's (the batched standard solver may evaluate it)."""
        return self.solve is standard_solution


def _check_entry(name: str, info) -> None:
    """A registry entry must be a :class:`ModelInfo` of the same name."""
    if not isinstance(info, ModelInfo) or info.name != name:
        raise TypeError(f"a mechanics model entry must be a ModelInfo named {name!r}, got {info!r}")
    if not callable(info.solve):
        raise TypeError(f"mechanics model {name!r}: solve must be a function, got {info.solve!r}")
    if info.friction and not info.contact:
        raise ValueError(f"mechanics model {name!r}: friction needs the contact solve (contact=True)")


#: The mechanics models by name, from the least to the most complete (an effect set is evaluated
#: with the most complete model any of its effects needs: :func:`ctrplan.effects.model_of`).
MODEL_REGISTRY: Registry[ModelInfo] = Registry("mechanics model", check=_check_entry)
for _info in (
        ModelInfo("standard", "zero clearance between the tubes, torsionally compliant, no friction",
                  "Section II-A", standard_solution, contact=False, friction=False),
        ModelInfo("clearance", "tubes move inside each other's clearance, contact forces, no friction",
                  "Sections II-B to II-E, Appendices A and B", contact_solution, contact=True, friction=False),
        ModelInfo("friction", "clearance model with maximal torsional friction in given directions eta",
                  "Section III, Eqs. (37)-(43)", contact_solution, contact=True, friction=True)):
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
