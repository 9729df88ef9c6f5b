"""Values of effects on a robot, and what they do: to the robot, the motion and the measurement."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ..errors import ModelFileError, PhysicalParameterError
from ..history import HistoryState, MotionRecord, apply_history
from ..choices import EffectStore
from ..models import MODEL_REGISTRY
from ._registry import REGISTRY, effect_of_parameter, get

__all__ = ["EffectSet", "robot_effects", "apply_robot_effects", "history_operators", "history_state",
           "apply_output_effects", "model_of", "file_key", "effects_from_file", "effects_to_file"]

#: Suffix of a robot file key by unit (``[effects]`` table: ``backlash_2_rad``).
_UNIT_SUFFIX = {"rad": "_rad", "s": "_s", "m": "_m", "1/m": "_per_m", "-": ""}


class EffectSet(Mapping):
    """Values of registered effects: ``{effect: {parameter: value}}`` in SI units, immutable.

    Parameters
    ----------
    values : mapping, optional
        Effect name -> mapping of its parameter names to values.
    robot : Robot, optional
        Checks every parameter against the effect's parameters on this robot and their limits
        (``ParameterSpec.hard``: the optimizer bounds as far as a fit may widen them).

    Raises
    ------
    PhysicalParameterError
        Unknown effect or parameter, a value that is not finite or outside its limits,
        or an effect that needs another one (``Effect.after``) without it; the message names the
        effect, the parameter and the value.
    """

    def __init__(self, values: Mapping | None = None, robot=None):
        items = {}
        for name, params in (values or {}).items():
            if name not in REGISTRY:
                raise PhysicalParameterError(f"unknown effect {name!r}; registered: {', '.join(REGISTRY)}")
            vals = {}
            for p, v in dict(params).items():
                v = float(v)
                if not np.isfinite(v):
                    raise PhysicalParameterError(f"effect {name!r}: {p} = {v!r} is not finite")
                vals[str(p)] = v
            items[name] = vals
        self._items = {k: dict(v) for k, v in items.items()}
        if robot is not None:
            self.check(robot)

    def check(self, robot) -> None:
        """Raise if a parameter does not fit ``robot`` (see the class docstring)."""
        for name, vals in self._items.items():
            effect = REGISTRY[name]
            specs = {p.name: p for p in effect.parameters(robot)}
            for p, v in vals.items():
                if p not in specs:
                    raise PhysicalParameterError(
                        f"effect {name!r}: robot {robot.name!r} has no parameter {p!r}; expected some of "
                        f"{', '.join(specs) or 'none'}")
                s = specs[p]
                if not s.within_limit(v):
                    lo, hi = s.hard
                    raise PhysicalParameterError(f"effect {name!r}: {p} = {v:.6g} {s.unit} is outside "
                                                 f"[{lo:.6g}, {hi:.6g}] {s.unit}")
            after = REGISTRY.get(effect.after) if effect.after else None
            if after is not None and effect.is_active(vals) and not (
                    (effect.after in self._items and after.is_active(self._items[effect.after]))
                    or after.is_present(robot)):
                raise PhysicalParameterError(f"effect {name!r} needs the effect {effect.after!r} ({after.label}), "
                                             f"which neither these effects nor robot {robot.name!r} have")

    def __getitem__(self, name):
        return dict(self._items[name])

    def __iter__(self):
        order = [n for n in REGISTRY if n in self._items] + [n for n in self._items if n not in REGISTRY]
        return iter(order)

    def __len__(self):
        return len(self._items)

    def __repr__(self):
        return f"EffectSet({self._items!r})"

    def active(self) -> list:
        """Names of the effects whose values switch them on, in registry order."""
        return [n for n in self if REGISTRY[n].is_active(self._items[n])]

    def merged(self, other: Mapping) -> "EffectSet":
        """A copy with the effects of ``other`` added (their values replace these)."""
        out = {k: dict(v) for k, v in self._items.items()}
        for k, v in other.items():
            out.setdefault(k, {}).update(dict(v))
        return EffectSet(out)

    def to_dict(self) -> dict:
        """Plain nested dict (JSON-ready, SI units)."""
        return {k: dict(self._items[k]) for k in self}

    @classmethod
    def from_values(cls, robot, values: Mapping) -> "EffectSet":
        """Effects from value lists in the order of each effect's parameters on ``robot`` (the
        order of its ``ctrplan synth`` option), e.g. ``{"backlash": (0.0, 0.08)}`` for a dead band
        of 0.08 rad on tube 2's drive.

        Raises
        ------
        PhysicalParameterError
            Unknown effect, a count that does not match the effect's parameters, or a value the
            class refuses.
        """
        out = {}
        for name, vals in values.items():
            if name not in REGISTRY:
                raise PhysicalParameterError(f"unknown effect {name!r}; registered: {', '.join(REGISTRY)}")
            names = REGISTRY[name].parameter_names(robot)
            vals = np.atleast_1d(np.asarray(vals, dtype=float))
            if vals.shape != (len(names),):
                raise PhysicalParameterError(f"effect {name!r} on robot {robot.name!r}: needs {len(names)} values "
                                             f"({', '.join(names)}), got {vals.size}")
            out[name] = dict(zip(names, vals.tolist()))
        return cls(out, robot)

    @classmethod
    def from_parameters(cls, robot, names, values) -> tuple["EffectSet", dict]:
        """Group calibration parameters by the effect that carries them.

        Returns
        -------
        EffectSet
            The effect parameters among ``names``.
        dict
            The other parameters (e.g. the baseline's precurvatures), name -> value.
        """
        grouped, rest = {}, {}
        for n, v in zip(names, values):
            e = effect_of_parameter(robot, n)
            if e is None:
                rest[n] = float(v)
            else:
                grouped.setdefault(e.name, {})[n] = float(v)
        return cls(grouped), rest


def robot_effects(robot) -> EffectSet:
    """The effects a robot file gives (its ``[effects]`` table), as an :class:`EffectSet`."""
    return EffectSet({name: dict(params) for name, params in getattr(robot, "effects", ())})


def apply_robot_effects(robot, effects: Mapping):
    """The robot with the effects that change it (friction, clearance, precurvature, Poisson ratio).

    Raises
    ------
    PhysicalParameterError
        The modified robot is impossible.
    """
    for name in EffectSet(effects):
        e = REGISTRY[name]
        if e.apply_robot is not None:
            robot = e.apply_robot(robot, effects[name])
    return robot


def history_operators(robot, effects: Mapping) -> list:
    """The history operators of the active effects, in registry order."""
    out = []
    es = EffectSet(effects)
    for name in es:
        e = REGISTRY[name]
        if e.operator is not None and e.is_active(es[name]):
            out.append(e.operator(robot, es[name]))
    return out


def _friction_angle(effects: EffectSet) -> float:
    angles = [REGISTRY[n].friction_angle(effects[n]) for n in effects
              if REGISTRY[n].friction_angle is not None and REGISTRY[n].is_active(effects[n])]
    return float(max(angles)) if angles else 0.0


def history_state(robot, record: MotionRecord, effects: Mapping | None = None, *, tracker: bool = True,
                  given_eta=None) -> HistoryState:
    """The friction state along a commanded motion with the robot file's history effects and ``effects``.

    The robot's own ``[effects]`` (:func:`robot_effects`) with ``effects`` added (their values
    replace the file's), applied by :func:`ctrplan.history.apply_history`: drive operators
    (backlash), then, with ``tracker``, tracker operators (a time offset); gradual friction sets
    the friction angle.

    Parameters
    ----------
    robot : Robot
    record : MotionRecord
        Commanded motion (rad, m).
    effects : mapping, optional
        ``{effect: {parameter: value}}`` in SI units.
    tracker : bool
        Apply the tracker's effects (measured data); planning predicts the robot and passes False.
    given_eta : array-like of int, shape (K, n - 1), optional
        Approach directions before the record (:func:`ctrplan.history.motion_state`).

    Returns
    -------
    HistoryState

    Raises
    ------
    PhysicalParameterError
        Unknown effects or parameters.
    ValueError
        From an operator (a time offset without times).
    """
    es = robot_effects(robot).merged(effects or {})
    return apply_history(record, history_operators(robot, es), friction_angle=_friction_angle(es), tracker=tracker,
                         given_eta=given_eta)


def apply_output_effects(tip, tangent, effects: Mapping):
    """How the measurement shows tip poses: the output effects (registration, ...) in registry order.

    Parameters
    ----------
    tip : array-like, shape (K, 3) or (3,)
        [m], robot base frame.
    tangent : array-like of the same shape, or None
    effects : mapping

    Returns
    -------
    tip, tangent : ndarray (tangent None if given None)
    """
    es = EffectSet(effects)
    tip = np.asarray(tip, float)
    for name in es:
        e = REGISTRY[name]
        if e.apply_output is not None:
            tip, tangent = e.apply_output(tip, tangent, es[name])
    return tip, tangent


def model_of(effects: Mapping, base: str = "standard") -> str:
    """The most complete mechanics model the active effects (and ``base``) need: the last of
    them in the order of :data:`ctrplan.models.MODEL_REGISTRY` (least to most complete)."""
    es = EffectSet(effects)
    models = [base] + [REGISTRY[n].model for n in es.active()]
    return max(models, key=MODEL_REGISTRY.names().index)


# --------------------------------------------------------------------------- robot files
def file_key(spec) -> str:
    """Key of a parameter in a robot file's ``[effects.<name>]`` table: its name and unit suffix."""
    return spec.name + _UNIT_SUFFIX.get(spec.unit, "")


def effects_from_file(robot, table: Mapping, file: str) -> tuple:
    """Validate a robot file's ``[effects]`` table and return it in the robot's form.

    Parameters
    ----------
    robot : Robot
        Built from the rest of the file (gives the tubes and pairs).
    table : mapping
        ``{effect: {key: value}}`` as parsed (keys :func:`file_key`).
    file : str
        For messages.

    Returns
    -------
    tuple
        ``((effect, ((parameter, value), ...)), ...)`` in registry order (``Robot.effects``).

    Raises
    ------
    ModelFileError
        Unknown effect, an effect the file keeps elsewhere, unknown key, a value that is not a
        number, outside the parameter's limits (a value outside its typical range is accepted:
        the ``[effects_source]`` table's ``cautions`` say why it was written), or an effect that
        needs another; the key is
        ``effects.<effect>.<key>``.
    """
    out = {}
    for name, params in table.items():
        where = f"effects.{name}"
        if name not in REGISTRY:
            raise ModelFileError(file, where, "unknown effect; known: "
                                 + ", ".join(n for n, e in REGISTRY.items() if e.store == EffectStore.EFFECTS))
        effect = get(name)
        if effect.store != EffectStore.EFFECTS:
            home = ("[[tubes]] and [[pairs]]" if effect.store == EffectStore.ROBOT else "[tracker_registration]")
            raise ModelFileError(file, where, f"the {effect.label} belongs in {home}, not in [effects]")
        if not isinstance(params, Mapping):
            raise ModelFileError(file, where, f"expected a table of parameters, got {params!r}")
        specs = {file_key(p): p for p in effect.parameters(robot)}
        vals = {}
        for key, value in params.items():
            if key not in specs:
                raise ModelFileError(file, f"{where}.{key}", f"unknown key; allowed keys here: {', '.join(specs)}")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ModelFileError(file, f"{where}.{key}", f"expected a finite number, got {value!r}")
            s = specs[key]
            if not s.within_limit(value):
                shown = f"{np.rad2deg(value):.4g} deg" if s.unit == "rad" else f"{value:.6g} {s.unit}"
                lo, hi = s.hard
                span = (f"{np.rad2deg(lo):.4g}..{np.rad2deg(hi):.4g} deg" if s.unit == "rad"
                        else f"{lo:.6g}..{hi:.6g} {s.unit}")
                raise ModelFileError(file, f"{where}.{key}", f"{value!r} ({shown}) is outside the values this "
                                     f"parameter can take, {span}")
            vals[s.name] = float(value)
        out[name] = vals
    try:
        es = EffectSet(out, robot)
    except PhysicalParameterError as exc:
        raise ModelFileError(file, "effects", str(exc)) from None
    return tuple((n, tuple(es[n].items())) for n in es)


def effects_to_file(robot) -> list:
    """Lines of the ``[effects.<name>]`` tables of a robot file for ``robot.effects``."""
    lines = []
    for name, params in getattr(robot, "effects", ()):
        effect = get(name)
        specs = {p.name: p for p in effect.parameters(robot)}
        lines += ["", f"[effects.{name}]                # {effect.label}"]
        for p, v in params:
            s = specs[p]
            note = f"   # {np.rad2deg(v):.4g} deg" if s.unit == "rad" else ""
            lines.append(f"{file_key(s)} = {float(v)!r}{note}")
    return lines
