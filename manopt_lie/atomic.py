"""Atomic file writing: a file is either written whole or left as it was.

Every file the project writes (g2o solutions, JSON, reports, figures) goes through
:func:`atomic_write`: the content goes to a temporary file in the target's directory,
is flushed and ``fsync``-ed, and only then renamed over the target (``os.replace`` is
atomic on POSIX and Windows within one file system). A write that fails halfway — a
full disk, ``ulimit -f``, an exception or Ctrl-C while producing the content — removes
the temporary file and leaves the target untouched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_write", "check_writable"]


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w", **open_options: Any) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path`` for writing; on a clean exit, make it ``path``.

    Parameters
    ----------
    path : path
        The target. Its directory must exist (see :func:`check_writable`).
    mode : {"w", "wb"}
        Text or binary.
    **open_options
        Passed to :func:`open` (e.g. ``encoding="utf-8", newline="\\n"`` for text).

    Examples
    --------
    >>> with atomic_write("out.json") as f:  # doctest: +SKIP
    ...     f.write(text)
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write: mode must be 'w' or 'wb', got {mode!r}")
    target = Path(path)
    if mode == "w":
        open_options.setdefault("encoding", "utf-8")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with open(fd, mode, **open_options) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        # Keep the permissions a plain open() would give (mkstemp makes the file 0600).
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def check_writable(path: str | os.PathLike[str], what: str = "output") -> Path:
    """Check, before any work is done, that ``path`` can be written: not a directory, and its
    directory exists (or can be created) and is writable. Creates missing directories.

    Raises
    ------
    ValueError
        (``OutputPathError``) naming ``what`` and the reason.
    """
    target = Path(path)
    if target.is_dir():
        raise OutputPathError(f"{what} {target} is a directory")
    parent = target.parent
    existing = parent
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise OutputPathError(f"{what} {target}: {existing} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputPathError(f"{what} {target}: {existing} is not writable")
    parent.mkdir(parents=True, exist_ok=True)
    return target


class OutputPathError(ValueError):
    """An output path that cannot be written."""
