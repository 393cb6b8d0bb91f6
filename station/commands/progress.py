"""Stage progress of a long command on stderr (never on stdout, which may carry ``--json``).

:func:`stderr_progress` gives the :class:`station.diagnose.diagnosis_progress.Progress` callback ``station diagnose``
passes to the diagnosis: one line per stage, with the elapsed time, when stderr is a terminal or the user
asked for it; None (no callback) otherwise.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from station.diagnose.diagnosis_progress import Progress, Stage


def wants_progress(flag: bool | None, stream: TextIO | None = None) -> bool:
    """``--progress`` / ``--no-progress`` as given; unset: on when ``stream`` (default stderr) is a terminal."""
    if flag is not None:
        return flag
    stream = stream if stream is not None else sys.stderr
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def stderr_progress(flag: bool | None, *, what: str = "diagnosis") -> Progress | None:
    """The callback printing each stage to stderr, or None when progress is not wanted."""
    if not wants_progress(flag):
        return None

    def show(stage: Stage) -> None:
        if stage.done:
            line = f"{what}: done in {stage.elapsed_s:.1f} s"
        else:
            line = (f"{what}: [{stage.index + 1}/{stage.total}] {stage.name} "
                    f"({stage.samples:,} samples, {stage.elapsed_s:.1f} s)")
        try:
            sys.stderr.write(line + "\n")
            sys.stderr.flush()
        except (OSError, ValueError):  # a closed or broken stderr must not stop the diagnosis
            pass

    return show


__all__ = ["stderr_progress", "wants_progress"]
