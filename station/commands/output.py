"""Output paths are checked before any work starts: a command never runs for minutes to fail at the end.

:func:`check_output` refuses, with one line (:class:`~station.kernel.errors.StationError`), an output
that is a directory, whose directory does not exist or cannot be written, that is (or resolves to)
one of the command's inputs, or whose suffix is not the format written.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from station.kernel.errors import StationError


class OutputPathError(StationError):
    """An output path the command cannot or must not write."""


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def check_output(path: Path, *, inputs: Iterable[Path] = (), suffix: str | None = None, what: str = "output") -> None:
    """Refuse ``path`` as the command's output (see the module docstring)."""
    if str(path) == "":
        raise OutputPathError(f"{what}: empty path")
    if path.is_dir():
        raise OutputPathError(f"{what} {path} is a directory; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise OutputPathError(f"{what} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise OutputPathError(f"{what} {path}: not writable")
    for source in inputs:
        if _same_file(path, source):
            raise OutputPathError(f"{what} {path} is the input {source}; write to another file")
    if suffix is not None and path.suffix.lower() != suffix:
        raise OutputPathError(f"{what} {path}: the file written is {suffix[1:].upper()}; name it *{suffix}")
