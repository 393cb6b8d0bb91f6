"""Output paths are checked before any work starts: a command never runs for minutes to fail at the end.

:func:`check_output` refuses, with one line (:class:`~station.kernel.errors.StationError`), an output
that is a directory, whose directory does not exist or cannot be written, that is (or resolves to)
one of the command's inputs, whose suffix is not the format written, or where no file can be written
now (a probe file is written and removed: /proc, a read-only or full file system). :func:`write_failed` names
the cause of a write that fails later (a disk that filled meanwhile).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from station.kernel.errors import StationError, path_problem, shorten


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
    try:
        _check_output(path, inputs, suffix, what)
    except (OSError, ValueError) as exc:
        raise OutputPathError(f"{what} {shorten(str(path), 120)}: {path_problem(exc, str(path))}") from None


def write_failed(exc: OSError, path: Path, what: str = "output") -> OutputPathError:
    """A write that failed (a full disk, a vanished directory) as one line naming the cause."""
    return OutputPathError(f"could not write {what} {shorten(str(path), 120)}: {path_problem(exc, str(path))}")


def _check_output(path: Path, inputs: Iterable[Path], suffix: str | None, what: str) -> None:
    if path.is_dir():
        raise OutputPathError(f"{what} {path} is a directory; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise OutputPathError(f"{what} {path}: {parent} is a file, not a directory")
    if not parent.is_dir():
        raise OutputPathError(f"{what} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise OutputPathError(f"{what} {path}: not writable")
    for source in inputs:
        if _same_file(path, source):
            raise OutputPathError(f"{what} {path} is the input {source}; write to another file")
    if suffix is not None and path.suffix.lower() != suffix:
        raise OutputPathError(f"{what} {path}: the file written is {suffix[1:].upper()}; name it *{suffix}")
    # a directory that takes no file (/proc, a read-only or full file system) is found now, not after the work
    with tempfile.TemporaryFile(dir=parent) as probe:
        probe.write(b"\0" * 4096)
        probe.flush()
        os.fsync(probe.fileno())
