"""One registry type for every extension point: names to entries, with one way to add, remove,
borrow and look up.

:class:`Registry` holds the mechanics models (:data:`ctrplan.models.MODEL_REGISTRY`), the planners
(:data:`ctrplan.planner_info.PLANNER_REGISTRY`) and the obstacle types
(:data:`ctrplan.obstacles.OBSTACLE_REGISTRY`). Each has the same methods:

- ``register(name, entry)`` adds an entry (a name already taken is an error unless
  ``replace=True``); ``unregister(name)`` removes it;
- ``with registry.registered(name, entry):`` adds it for the length of a block and restores what
  was there before (for tests and notebooks);
- ``registry[name]`` / ``registry.get(name)`` look an entry up; an unknown name raises
  :class:`UnknownNameError`, one line listing the registered names;
- ``registry.view`` is a live read-only mapping in registration order, and ``names()`` the names.

This module imports nothing from the package, so that every layer can hold a registry.
"""

from __future__ import annotations

from contextlib import contextmanager
from types import MappingProxyType
from typing import Callable, Generic, Iterator, Mapping, TypeVar

__all__ = ["Registry", "UnknownNameError"]

T = TypeVar("T")


class UnknownNameError(KeyError, ValueError):
    """A name that no entry of a registry has.

    A :class:`KeyError` (a failed look-up) and a :class:`ValueError` (a bad argument or file
    value); its message is one line naming the registry, the name and the registered names.

    Attributes
    ----------
    kind : str
        What the registry holds, e.g. ``"planner"``.
    name : str
        The name asked for.
    known : tuple of str
        The registered names, in order.
    """

    def __init__(self, kind: str, name, known: tuple):
        self.kind, self.name, self.known = kind, name, tuple(known)
        super().__init__(f"unknown {kind} {name!r}; registered: {', '.join(self.known) or 'none'}")

    def __str__(self) -> str:   # KeyError's own __str__ would quote the message
        return str(self.args[0])


class Registry(Generic[T]):
    """Entries of one kind by name, in registration order.

    Parameters
    ----------
    kind : str
        What the entries are, singular ("mechanics model", "planner", "obstacle type"); it
        names the registry in error messages.
    check : callable, optional
        ``check(name, entry)``, called before an entry is added; it raises ``TypeError`` or
        ``ValueError`` for an entry of the wrong shape.

    Examples
    --------
    >>> colours = Registry("colour")
    >>> colours.register("red", (1.0, 0.0, 0.0))
    (1.0, 0.0, 0.0)
    >>> with colours.registered("blue", (0.0, 0.0, 1.0)):
    ...     colours.names()
    ('red', 'blue')
    >>> colours.names()
    ('red',)
    """

    def __init__(self, kind: str, *, check: Callable[[str, T], None] | None = None):
        self.kind = str(kind)
        self._check = check
        self._entries: dict[str, T] = {}
        self._view = MappingProxyType(self._entries)

    # ------------------------------------------------------------------ changing it
    def register(self, name: str, entry: T, *, replace: bool = False) -> T:
        """Add ``entry`` under ``name`` (at the end of the order; a replaced entry keeps its place).

        Parameters
        ----------
        name : str
            A non-empty name.
        entry : T
        replace : bool, keyword-only
            Replace an entry registered under the same name (else that is an error; registering
            the very same entry again is allowed and changes nothing).

        Returns
        -------
        T
            ``entry``.

        Raises
        ------
        TypeError
            ``name`` is not a non-empty str, or the registry's check refuses the entry.
        ValueError
            ``name`` is taken by another entry and ``replace`` is false, or the registry's check
            refuses the entry.
        """
        if not isinstance(name, str) or not name:
            raise TypeError(f"a {self.kind} name must be a non-empty str, got {name!r}")
        if self._check is not None:
            self._check(name, entry)
        old = self._entries.get(name)
        if old is not None and old is not entry and not replace:
            raise ValueError(f"{self.kind} {name!r} is already registered ({_describe(old)}); pass replace=True "
                             f"to replace it")
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> T:
        """Remove the entry ``name`` and return it.

        Raises
        ------
        UnknownNameError
            No entry of that name.
        """
        if name not in self._entries:
            raise UnknownNameError(self.kind, name, self.names())
        return self._entries.pop(name)

    @contextmanager
    def registered(self, name: str, entry: T, *, replace: bool = False) -> Iterator[T]:
        """Register ``entry`` for the length of a ``with`` block, then restore the registry.

        An entry replaced (``replace=True``) comes back at its place afterwards; a new one is
        removed. Arguments and errors as :meth:`register`.

        Yields
        ------
        T
            ``entry``.
        """
        before = dict(self._entries)
        self.register(name, entry, replace=replace)
        try:
            yield entry
        finally:
            self._entries.clear()
            self._entries.update(before)

    # ------------------------------------------------------------------ reading it
    def get(self, name: str) -> T:
        """The entry registered under ``name``.

        Raises
        ------
        UnknownNameError
            No entry of that name; the message lists the registered ones.
        """
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise UnknownNameError(self.kind, name, self.names()) from None

    __getitem__ = get

    def check(self, name: str) -> str:
        """``name`` unchanged if an entry has it (for validators).

        Raises
        ------
        UnknownNameError
            As :meth:`get`.
        """
        self.get(name)
        return name

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self._entries)

    @property
    def view(self) -> Mapping[str, T]:
        """A live read-only mapping of the entries by name, in registration order."""
        return self._view

    def __contains__(self, name) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(self._entries))

    def __len__(self) -> int:
        return len(self._entries)

    def items(self):
        """``(name, entry)`` pairs in registration order (a snapshot)."""
        return tuple(self._entries.items())

    def values(self):
        """The entries in registration order (a snapshot)."""
        return tuple(self._entries.values())

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._entries)})"


def _describe(entry) -> str:
    """A short name of an entry for messages: its class's or function's name, else its repr."""
    name = getattr(entry, "__name__", None) or getattr(entry, "name", None)
    return str(name) if name is not None else type(entry).__name__
