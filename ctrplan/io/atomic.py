"""Atomic file writes: a file is either fully written or left untouched.

Each writer writes to a temporary file in the destination's directory (same file system, so the
final :func:`os.replace` is atomic on POSIX and Windows), flushes it to disk, then renames it over
the destination. An exception or an interrupted run leaves the old file (or no file) and no
half-written one; the temporary file is removed on failure.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_path", "atomic_write_text", "atomic_write_bytes", "atomic_savez"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; move it onto ``path`` when the block succeeds.

    Parameters
    ----------
    path : str or path-like
        Destination file. Its directory must exist.

    Yields
    ------
    pathlib.Path
        Temporary file (already created, empty) in the same directory. Write to it by name,
        e.g. ``frame.to_csv(tmp)``; it replaces ``path`` when the ``with`` block exits normally.

    Raises
    ------
    FileNotFoundError
        If the destination directory does not exist.
    Exception
        Whatever the block raises; the temporary file is then removed and ``path`` is untouched.

    Examples
    --------
    >>> with atomic_path("result.csv") as tmp:  # doctest: +SKIP
    ...     frame.to_csv(tmp, index=False)
    """
    dest = Path(path)
    directory = dest.parent if str(dest.parent) else Path(".")
    if not directory.is_dir():
        raise FileNotFoundError(f"cannot write {dest}: directory {directory} does not exist")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=directory)
    os.close(fd)
    tmp = Path(tmp_name)
    # mkstemp creates the file readable by its owner only; give it the permissions a plain
    # open() would (or those of the file it replaces).
    os.chmod(tmp, dest.stat().st_mode & 0o777 if dest.exists() else 0o666 & ~_umask())
    try:
        yield tmp
        # Flush the written content to disk before the rename makes it visible.
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, dest)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or path-like
    data : bytes
    """
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or path-like
    text : str
    encoding : str
        Text encoding; newlines are written as given (no platform translation).
    """
    atomic_write_bytes(path, text.encode(encoding))


def atomic_savez(path: str | os.PathLike, **arrays) -> None:
    """Write ``arrays`` to one compressed ``.npz`` at ``path`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or path-like
        Destination file, written exactly there (no ``.npz`` suffix is appended, unlike
        :func:`numpy.savez_compressed` given a name). Its directory must exist.
    **arrays : array-like
        Stored under their keyword names, as :func:`numpy.savez_compressed` stores them.

    Raises
    ------
    FileNotFoundError
        If the destination directory does not exist.
    Exception
        Whatever :func:`numpy.savez_compressed` raises; ``path`` is then untouched.
    """
    import numpy as np

    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
