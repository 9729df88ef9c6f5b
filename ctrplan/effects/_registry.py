"""The registry of model effects: one entry per effect, everything about it in one place."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from ..choices import EffectStore
from ..models import MODEL_REGISTRY
from ..registry import Registry
from ._fit import NESTED, FitStrategy

__all__ = ["ParameterSpec", "Effect", "EFFECT_REGISTRY", "REGISTRY", "STORES", "register",
           "unregister", "registered", "get", "effect_names", "effect_of_parameter", "parameter_spec"]

#: Where a robot file keeps an effect's values (:class:`ctrplan.choices.EffectStore`).
STORES = tuple(EffectStore)


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter of an effect (or of the baseline calibration).

    Attributes
    ----------
    name : str
        E.g. ``"backlash_2"`` (1-based tube or pair index, tube 1 outermost).
    kind : str
        The name without its index.
    index : int
        0-based tube, pair or axis index.
    unit : str
        SI unit (``"rad"``, ``"s"``, ``"m"``, ``"1/m"``, ``"-"``).
    lower, upper : float
        Optimizer bounds, in ``unit``.
    scale : float
        Typical size of a change (scales the optimizer's steps).
    typical : tuple of float or None
        ``(lower, upper)`` that robots of this kind usually have: strictly inside the optimizer
        bounds, except a lower end at which the effect vanishes (``vanishes_at_lower``). A fitted
        value outside it is reported with a caution (``check``), not refused.
    typical_source : str
        Where the typical range comes from (source or reasoning).
    check : str
        What to check on a robot whose fitted value lies outside the typical range (e.g. "the
        couplings of the rotation drives").
    vanishes_at_lower : bool
        At ``lower`` (a physical limit, e.g. a dead band of 0) the effect is absent: a fit that
        ends there found no effect.
    resolution : float or None
        Spacing of the scan that starts its fit, in ``unit`` (None: no scan).
    limit : tuple of float or None
        ``(lower, upper)``: how far a fit that ends at an optimizer bound may have that bound
        widened (:meth:`widened`); the values a robot file may hold. None: the optimizer bounds
        are the limit.

    Raises
    ------
    ValueError
        Bounds not increasing, a typical range that does not lie strictly inside them, or a limit
        that does not contain them.
    """

    name: str
    kind: str
    index: int
    unit: str
    lower: float
    upper: float
    scale: float
    typical: tuple | None = None
    typical_source: str = ""
    check: str = ""
    vanishes_at_lower: bool = False
    resolution: float | None = None
    limit: tuple | None = None

    def __post_init__(self):
        if not self.lower < self.upper:
            raise ValueError(f"parameter {self.name!r}: bounds must increase, got [{self.lower}, {self.upper}]")
        if self.typical is not None:
            lo, hi = self.typical
            low_ok = (lo > self.lower) or (self.vanishes_at_lower and lo == self.lower)
            if not (low_ok and lo < hi < self.upper):
                raise ValueError(f"parameter {self.name!r}: typical range [{lo}, {hi}] must lie strictly inside "
                                 f"the optimizer bounds [{self.lower}, {self.upper}]")
        if self.limit is not None and not (self.limit[0] <= self.lower and self.upper <= self.limit[1]):
            raise ValueError(f"parameter {self.name!r}: limit {list(self.limit)} must contain the optimizer bounds "
                             f"[{self.lower}, {self.upper}]")

    @property
    def hard(self) -> tuple:
        """``(lower, upper)``: the widest the optimizer bounds may become (:attr:`limit`)."""
        return (self.lower, self.upper) if self.limit is None else tuple(self.limit)

    def within_limit(self, value: float) -> bool:
        """Whether ``value`` lies within :attr:`hard` (what a robot file may hold)."""
        lo, hi = self.hard
        return bool(np.isfinite(value) and lo <= value <= hi)

    def widened(self, side: str) -> "ParameterSpec | None":
        """The spec with the optimizer bound on ``side`` (``"lower"`` or ``"upper"``) moved out by
        the bounds' width, at most to :attr:`hard`; None when it is there already (or the lower
        bound is where the effect vanishes)."""
        import dataclasses

        width = self.upper - self.lower
        lo, hi = self.hard
        if side == "upper" and self.upper < hi:
            return dataclasses.replace(self, upper=min(hi, self.upper + width))
        if side == "lower" and self.lower > lo and not self.vanishes_at_lower:
            return dataclasses.replace(self, lower=max(lo, self.lower - width))
        return None

    def typical_text(self) -> str:
        """The typical range for a report (rad as deg), e.g. ``"0..5 deg"``; ``"-"`` without one."""
        return "-" if self.typical is None else _typical_text(self)

    def is_typical(self, value: float) -> bool:
        """Whether ``value`` lies in the typical range (True when there is none)."""
        if self.typical is None:
            return True
        span = self.typical[1] - self.typical[0]
        return self.typical[0] - 1e-9 * span <= value <= self.typical[1] + 1e-9 * span

    def at_bound(self, value: float, rtol: float = 1e-6) -> str | None:
        """``"lower"`` or ``"upper"`` when ``value`` sits at an optimizer bound (within ``rtol``
        of the bound width), else None."""
        tol = rtol * (self.upper - self.lower)
        if value <= self.lower + tol:
            return "lower"
        if value >= self.upper - tol:
            return "upper"
        return None


@dataclass(frozen=True)
class Effect:
    """One effect a model may miss: what it is, what it changes, how it is tested and fitted.

    Hooks are plain functions of arrays and robots (no files, no printing). ``values`` below is
    a mapping of the effect's parameter names to values in SI units.

    Attributes
    ----------
    name : str
        Key of the registry (``--effects`` of ``ctrplan discrepancy``).
    label : str
        Human-readable name for reports.
    model : str
        The mechanics model it needs (a name of :data:`ctrplan.models.MODEL_REGISTRY`).
    parameters : callable
        ``parameters(robot) -> tuple of ParameterSpec``: every parameter the effect can carry on
        this robot (the order of its ``ctrplan synth`` option's values).
    description : str
        What it does, one sentence with its source.
    store : EffectStore or str
        Where a robot file keeps its values (:class:`ctrplan.choices.EffectStore`; a string is
        stored as its member).
    fitted : callable, optional
        ``fitted(robot, data) -> tuple of str``: the parameters the workflow fits on ``data``
        (``MeasuredData``: e.g. only the drives that move); default all of ``parameters``.
    read : callable, optional
        ``read(robot) -> dict``: the values at which the effect is off on ``robot`` (default 0
        for every parameter), where its fit starts.
    apply_robot : callable, optional
        ``apply_robot(robot, values) -> Robot``: a robot with the effect.
    operator : callable, optional
        ``operator(robot, values) -> HistoryOperator``: how it changes the motion
        (:mod:`ctrplan.history`).
    friction_angle : callable, optional
        ``friction_angle(values) -> float``: theta_c [rad] of gradually developing friction.
    apply_output : callable, optional
        ``apply_output(tip (K, 3), tangent (K, 3), values) -> (tip, tangent)``: how the
        measurement shows the tip (e.g. a registration) [m].
    active : callable, optional
        ``active(values) -> bool``: the values switch the effect on (default: True).
    present : callable, optional
        ``present(robot) -> bool``: the robot itself carries the effect (e.g. positive friction
        coefficients in its pair tables); default False.
    signature : callable, optional
        ``signature(ctx) -> SignatureTest``: the test of its pattern in held-out residuals; ``ctx``
        is the discrepancy workflow's :class:`~ctrplan.discrepancy.verdict.signatures.SignatureContext`
        (arrays of the held-out data and the tests to run on them).
    synth_option : str, optional
        Its option of ``ctrplan synth`` (e.g. ``"--backlash-rad"``): comma-separated values of
        ``parameters`` in order.
    synth_help : str
    needs_motion : bool
        Only data with motion between samples can show it (``ctrplan synth --protocol
        trajectory``).
    scan : tuple of float, optional
        Start scan of a nested fit or the values of a ``SCAN`` fit (every fitted parameter set
        to each value in turn), in the parameters' unit.
    fit : FitStrategy
        How the discrepancy workflow fits it: ``ctrplan.effects.NESTED`` (the default), ``GRID``,
        ``NO_FIT``, ``SCAN``, or a strategy of one's own.
    after : str, optional
        The effect whose fit this one starts from and whose fitted parameters it carries (gradual
        friction after friction).
    requires : callable, optional
        ``requires(robot, data) -> str or None``: why the effect cannot be tried on this robot and
        data (e.g. "the data has no 'time' column"), None when it can.
    contains : tuple of str
        Effects it contains (never tried together with it).
    plan : str
        What ``ctrplan plan`` does with it.
    separated_by : str
        What data would tell it apart from another effect that explains the same data (the
        report of an ambiguous verdict quotes it).
    """

    name: str
    label: str
    model: str
    parameters: Callable[[Any], tuple]
    description: str
    store: EffectStore = EffectStore.EFFECTS
    fitted: Callable | None = None
    read: Callable | None = None
    apply_robot: Callable | None = None
    operator: Callable | None = None
    friction_angle: Callable | None = None
    apply_output: Callable | None = None
    active: Callable | None = None
    present: Callable | None = None
    signature: Callable | None = None
    synth_option: str | None = None
    synth_help: str = ""
    needs_motion: bool = False
    scan: tuple | None = None
    fit: FitStrategy = NESTED
    after: str | None = None
    requires: Callable | None = None
    contains: tuple = ()
    plan: str = ""
    separated_by: str = ""

    def __post_init__(self):
        if self.model not in MODEL_REGISTRY:
            raise ValueError(f"effect {self.name!r}: model must be a registered mechanics model "
                             f"({', '.join(MODEL_REGISTRY.names())}), got {self.model!r}")
        if not isinstance(self.fit, FitStrategy):
            raise TypeError(f"effect {self.name!r}: fit must be a FitStrategy (ctrplan.effects.NESTED, GRID, "
                            f"NO_FIT, SCAN or one's own), got {self.fit!r}")
        try:
            object.__setattr__(self, "store", EffectStore(self.store))
        except ValueError:
            raise ValueError(f"effect {self.name!r}: store must be one of {', '.join(STORES)}, got {self.store!r}") from None
        if self.fit.needs_scan and (self.scan is None or self.after is None):
            raise ValueError(f"effect {self.name!r}: a scan fit needs scan values and the effect it follows")

    @property
    def needs_solve(self) -> bool:
        """A change of its values needs the model solved again (it changes the robot or the motion)."""
        return self.apply_robot is not None or self.operator is not None or self.friction_angle is not None

    def parameter_names(self, robot) -> tuple:
        """Names of every parameter it can carry on ``robot``."""
        return tuple(p.name for p in self.parameters(robot))

    def fitted_names(self, robot, data=None) -> tuple:
        """Names of the parameters the workflow fits on ``data`` (all of them by default)."""
        if self.fitted is None or data is None:
            return self.parameter_names(robot) if self.fitted is None else tuple(self.fitted(robot, None))
        return tuple(self.fitted(robot, data))

    def off_values(self, robot) -> dict:
        """Values at which the effect is off on ``robot``."""
        base = {p.name: 0.0 for p in self.parameters(robot)}
        if self.read is not None:
            base.update(self.read(robot))
        return base

    def is_active(self, values: Mapping) -> bool:
        """The values switch the effect on."""
        return True if self.active is None else bool(self.active(values))

    def is_present(self, robot) -> bool:
        """The robot itself carries the effect."""
        return False if self.present is None else bool(self.present(robot))

    def why_not(self, robot, data=None) -> str | None:
        """Why the effect cannot be tried on this robot (and data), or None."""
        return None if self.requires is None else self.requires(robot, data)


def _check_effect(name: str, effect) -> None:
    """A registry entry must be an :class:`Effect` of the same name whose ``after`` is registered."""
    if not isinstance(effect, Effect) or effect.name != name:
        raise TypeError(f"an effect entry must be an Effect named {name!r}, got {effect!r}")
    if effect.after is not None and effect.after not in EFFECT_REGISTRY:
        raise ValueError(f"effect {name!r} follows {effect.after!r}, which is not registered")


#: The effects by name (a :class:`ctrplan.registry.Registry`), in the order the workflow tries
#: them (an effect with ``after`` comes after that effect).
EFFECT_REGISTRY: Registry[Effect] = Registry("effect", check=_check_effect)
#: A live read-only view of :data:`EFFECT_REGISTRY`: ``{name: Effect}``.
REGISTRY = EFFECT_REGISTRY.view


def _entry(effect) -> Effect:
    """``effect`` itself, refused with a :class:`TypeError` unless it is an :class:`Effect`."""
    if not isinstance(effect, Effect):
        raise TypeError(f"an effect entry must be an Effect, got {effect!r}")
    return effect


def register(effect: Effect, *, replace: bool = False) -> Effect:
    """Add an effect to :data:`EFFECT_REGISTRY` under its name (at the end of the order).

    Raises
    ------
    TypeError
        ``effect`` is not an :class:`Effect`.
    ValueError
        A name that is taken by another effect (unless ``replace``), or ``after`` naming an
        unknown effect.
    """
    return EFFECT_REGISTRY.register(_entry(effect).name, effect, replace=replace)


def unregister(name: str) -> Effect:
    """Remove the effect ``name`` and return it.

    Raises
    ------
    ctrplan.registry.UnknownNameError
        No effect of that name (a :class:`KeyError`).
    """
    return EFFECT_REGISTRY.unregister(name)


def registered(effect: Effect, *, replace: bool = False):
    """Register ``effect`` for the length of a ``with`` block, then restore the registry
    (tests, notebooks). Errors as :func:`register`."""
    return EFFECT_REGISTRY.registered(_entry(effect).name, effect, replace=replace)


def get(name: str) -> Effect:
    """The registered effect ``name``.

    Raises
    ------
    ctrplan.registry.UnknownNameError
        A :class:`KeyError` whose message lists the registered names.
    """
    return EFFECT_REGISTRY.get(name)


def effect_names() -> tuple:
    """Registered effect names, in order."""
    return tuple(REGISTRY)


def effect_of_parameter(robot, name: str) -> Effect | None:
    """The registered effect that carries the parameter ``name`` on ``robot``, or None."""
    for e in REGISTRY.values():
        if name in e.parameter_names(robot):
            return e
    return None


def parameter_spec(robot, name: str) -> ParameterSpec | None:
    """The spec of an effect parameter ``name`` on ``robot``, or None if no effect carries it."""
    for e in REGISTRY.values():
        for p in e.parameters(robot):
            if p.name == name:
                return p
    return None


def _typical_text(p: ParameterSpec) -> str:
    lo, hi = p.typical
    if p.unit == "rad":
        return f"{np.rad2deg(lo):.3g}..{np.rad2deg(hi):.3g} deg"
    return f"{lo:.3g}..{hi:.3g}" + ("" if p.unit == "-" else f" {p.unit}")


