"""Logging helpers of the library (private).

Every module logs through ``logging.getLogger(__name__)``, under the ``ctrplan`` logger, which has
only a ``logging.NullHandler`` (``ctrplan/__init__.py``): the library prints nothing unless the
caller configures logging. Levels: progress and summary lines INFO, details DEBUG, cautions
WARNING.

- :func:`progress_level` is the level of a stage's progress and summary lines: INFO, or DEBUG
  inside :func:`details` (a study of many scenarios keeps one line per scenario at INFO and
  lowers each scenario's own lines to DEBUG).
- :func:`deprecated_echo` keeps the deprecated ``echo`` arguments working: for one call, the
  INFO and higher records of the ``ctrplan`` logger are passed to the callable as text.
"""

from __future__ import annotations

import contextvars
import functools
import inspect
import logging
import warnings
from contextlib import contextmanager
from typing import Any, Callable

#: Name of the library's root logger.
ROOT = "ctrplan"

_PROGRESS_LEVEL = contextvars.ContextVar("ctrplan_progress_level", default=logging.INFO)


def progress_level() -> int:
    """Level of progress and summary lines here: ``logging.INFO``, or ``logging.DEBUG`` inside
    :func:`details`."""
    return _PROGRESS_LEVEL.get()


@contextmanager
def details():
    """Within this block (this thread or task), progress and summary lines are DEBUG records."""
    token = _PROGRESS_LEVEL.set(logging.DEBUG)
    try:
        yield
    finally:
        _PROGRESS_LEVEL.reset(token)


class _CallableHandler(logging.Handler):
    """Passes each record's message, as text, to a callable."""

    def __init__(self, echo: Callable[[str], Any]):
        super().__init__(logging.INFO)
        self.echo = echo

    def emit(self, record):
        try:
            self.echo(record.getMessage())
        except Exception:  # noqa: BLE001 - logging's own convention: report, never raise
            self.handleError(record)


class _EchoForwarding:
    """Context manager: the deprecated ``echo`` callable of a public function, for one call.

    With ``echo`` None it does nothing. Otherwise it warns (``DeprecationWarning``, pointing at
    the caller of ``function``) and, inside the block, passes the message of every INFO or higher
    record of the ``ctrplan`` logger to ``echo``, lowering that logger's level to INFO if needed.
    Created by :func:`deprecated_echo`'s wrapper (the warning's stack level counts on it).
    """

    def __init__(self, echo: Callable[[str], Any] | None, function: str):
        self.handler = None
        if echo is None:
            return
        warnings.warn(f"{function}(echo=...) is deprecated: ctrplan logs through the logging module (logger "
                      f"'{ROOT}'); configure logging instead, e.g. logging.basicConfig(level=logging.INFO)",
                      DeprecationWarning, stacklevel=3)
        self.handler = _CallableHandler(echo)

    def __enter__(self):
        if self.handler is not None:
            logger = logging.getLogger(ROOT)
            self._level = logger.level
            if logger.getEffectiveLevel() > logging.INFO:
                logger.setLevel(logging.INFO)
            logger.addHandler(self.handler)
        return self

    def __exit__(self, *exc):
        if self.handler is not None:
            logger = logging.getLogger(ROOT)
            logger.removeHandler(self.handler)
            logger.setLevel(self._level)
        return False


def deprecated_echo(function):
    """Decorator of a public function whose parameter ``echo`` (default None) is deprecated.

    The function itself ignores ``echo``; a call that passes a callable, by position or by
    keyword, warns and gets the function's messages forwarded to it (:class:`_EchoForwarding`).
    """
    signature = inspect.signature(function)

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        echo = signature.bind(*args, **kwargs).arguments.get("echo")
        if echo is None:
            return function(*args, **kwargs)
        with _EchoForwarding(echo, function.__name__):
            return function(*args, **kwargs)

    return wrapper
