"""The registry of obstacle types (a :class:`ctrplan.registry.Registry`): ``type`` name -> class,
and the conversions that use it."""

from __future__ import annotations

import inspect
import typing
from typing import Mapping

import pydantic

from ..registry import Registry
from ._base import Obstacle

__all__ = ["OBSTACLE_REGISTRY", "OBSTACLE_TYPES", "register_obstacle_type", "unregister_obstacle_type",
           "obstacle_from_dict", "as_obstacle"]


def _check_class(name: str, cls) -> None:
    """A registry entry: a concrete :class:`Obstacle` subclass whose ``type`` field is ``name``."""
    if not (isinstance(cls, type) and issubclass(cls, Obstacle)):
        raise TypeError(f"an obstacle type must be a subclass of ctrplan.obstacles.Obstacle, got {cls!r}")
    if inspect.isabstract(cls):
        missing = ", ".join(sorted(cls.__abstractmethods__))
        raise TypeError(f"{cls.__name__} does not implement {missing}")
    if _type_name(cls) != name:
        raise ValueError(f"obstacle type {cls.__name__} is named {_type_name(cls)!r} by its type field, not {name!r}")


#: The obstacle types, ``{type name: Obstacle subclass}`` in registration order (the built-in
#: ``sphere``, ``capsule``, ``box``, ``mesh``, ``triangles`` first). Scenario files, dicts, the
#: collision checker and the drawings look types up here. :func:`register_obstacle_type` adds a
#: class under the name of its ``type`` field (``OBSTACLE_REGISTRY.registered(name, cls)`` for a
#: block).
OBSTACLE_REGISTRY: Registry[type[Obstacle]] = Registry("obstacle type", check=_check_class)

#: A live read-only view of :data:`OBSTACLE_REGISTRY`: ``{type name: class}``.
OBSTACLE_TYPES = OBSTACLE_REGISTRY.view


def _type_name(cls) -> str:
    """The name in ``cls``'s field ``type: Literal["<name>"] = "<name>"``."""
    field = cls.model_fields.get("type")
    args = typing.get_args(field.annotation) if field is not None else ()
    if (field is None or typing.get_origin(field.annotation) is not typing.Literal or len(args) != 1
            or not isinstance(args[0], str) or field.default != args[0]):
        raise TypeError(f"{cls.__name__} needs a field type: Literal['<name>'] = '<name>' (one str, "
                        f"default equal to it), got {None if field is None else field.annotation!r}")
    return args[0]


def register_obstacle_type(cls: type[Obstacle], *, replace: bool = False) -> type[Obstacle]:
    """Make an obstacle type known by its ``type`` name (usable as a class decorator).

    After this, scenario files accept ``[[obstacles]]`` tables with ``type = "<name>"`` (validated
    by ``cls``), :func:`obstacle_from_dict` accepts dicts with it, and the collision checker and
    the plots use the class's :meth:`~Obstacle.collision_object`, :meth:`~Obstacle.aabb` and
    :meth:`~Obstacle.triangles`.

    Parameters
    ----------
    cls : type
        A concrete subclass of :class:`Obstacle` with a field
        ``type: Literal["<name>"] = "<name>"``.
    replace : bool, keyword-only
        Replace a type registered under the same name (else that is an error).

    Returns
    -------
    type
        ``cls``.

    Raises
    ------
    TypeError
        ``cls`` is not an :class:`Obstacle` subclass, leaves an abstract method out, or has no
        such ``type`` field.
    ValueError
        The name is taken and ``replace`` is false.
    """
    if not (isinstance(cls, type) and issubclass(cls, Obstacle)):
        raise TypeError(f"an obstacle type must be a subclass of ctrplan.obstacles.Obstacle, got {cls!r}")
    return OBSTACLE_REGISTRY.register(_type_name(cls), cls, replace=replace)


def unregister_obstacle_type(name: str) -> None:
    """Remove an obstacle type from :data:`OBSTACLE_REGISTRY`.

    Parameters
    ----------
    name : str
        Its ``type`` name.

    Raises
    ------
    ctrplan.registry.UnknownNameError
        No type of that name is registered (a :class:`KeyError`; the message lists the
        registered ones).
    """
    OBSTACLE_REGISTRY.unregister(name)


def obstacle_from_dict(d: Mapping) -> Obstacle:
    """Build an obstacle from a plain dict with a ``type`` key, through :data:`OBSTACLE_TYPES`.

    Parameters
    ----------
    d : mapping
        The keys of a scenario file's obstacle table, e.g.
        ``{"type": "sphere", "center_m": [0.03, 0.0, 0.15], "radius_m": 0.01}`` (vectors as
        lists, tuples or arrays [m, rad]). Older spellings some types accept are listed with
        the type (e.g. :meth:`~ctrplan.obstacles.Mesh.from_dict`).

    Returns
    -------
    Obstacle
        An instance of the registered class.

    Raises
    ------
    ValueError
        Unknown type (naming the registered ones), or a missing, unknown or bad key: one line
        naming the type, the key and the value.
    """
    kind = d.get("type") if isinstance(d, Mapping) else None
    if not isinstance(kind, str) or kind not in OBSTACLE_TYPES:
        raise ValueError(f"unknown type {kind!r} (registered obstacle types: {', '.join(OBSTACLE_TYPES)})")
    try:
        return OBSTACLE_TYPES[kind].from_dict(d)
    except pydantic.ValidationError as exc:
        raise ValueError(f"{kind} obstacle: {_one_line(exc)}") from None


def as_obstacle(obstacle) -> Obstacle:
    """An obstacle given as an :class:`Obstacle` or as a dict (:func:`obstacle_from_dict`).

    Parameters
    ----------
    obstacle : Obstacle, mapping, or an object with ``collision_object()``
        The last is passed through as it is, for the collision checker (a duck-typed obstacle
        without :meth:`~Obstacle.aabb` is never culled by its broad phase).

    Returns
    -------
    Obstacle
        Or the duck-typed object.

    Raises
    ------
    ValueError
        A dict that :func:`obstacle_from_dict` refuses.
    TypeError
        Anything else.
    """
    if isinstance(obstacle, Mapping):
        return obstacle_from_dict(obstacle)
    if isinstance(obstacle, Obstacle) or callable(getattr(obstacle, "collision_object", None)):
        return obstacle
    raise TypeError(f"an obstacle must be a ctrplan.obstacles.Obstacle or a dict with a 'type' key, "
                    f"got {type(obstacle).__name__}")


def _one_line(exc: pydantic.ValidationError) -> str:
    """The first error of ``exc`` as ``key 'a.b[2]': message; got value`` (indices 1-based, as
    in scenario files)."""
    errors = exc.errors(include_url=False)
    first = errors[0]
    key = ""
    for part in first["loc"]:
        key += f"[{part + 1}]" if isinstance(part, int) else ("." if key else "") + str(part)
    if first["type"] == "missing":
        text = "missing required key"
    elif first["type"] == "value_error" and "ctx" in first:
        text = str(first["ctx"]["error"])
    else:
        text = f"{first['msg']}; got {first.get('input')!r}"
    more = f" (and {len(errors) - 1} more problem(s))" if len(errors) > 1 else ""
    return f"key '{key or '<top level>'}': {text}{more}"
