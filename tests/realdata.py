"""Where the real recordings are, for every test that needs them: one way, one switch.

The recordings nobody here made live outside the repository (read-only): ``$STATION_REAL`` if set, else
``../shared/real`` beside the repository's root. A test that needs them says which files with
``@pytest.mark.real("imucal/example_ferraris_session.csv", ...)`` (paths relative to that folder) and reads
them through :func:`real_path`. The conftest's hooks then

* skip it where a file is missing, on a developer's fresh clone, and print ONE line at the end of the run
  naming what was skipped and how to get the data;
* FAIL it under ``CI=true``, where the data is always laid beside the repository: a missing data set there is
  a broken setup, not a reason to pass quietly.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV_VAR = "STATION_REAL"
REPO_ROOT = Path(__file__).resolve().parents[1]

#: The files of each real data set the tests use (relative to :func:`real_dir`).
DATA_SETS = {
    "imucal": ("imucal/example_ferraris_session.csv", "imucal/example_ferraris_session_list.json",
               "imucal/annotated_session.csv"),
    "openaxes": ("openaxes/log_imu9_2022-06-22_22-13-55.csv",),
}

IMUCAL_FERRARIS = "imucal/example_ferraris_session.csv"
IMUCAL_SECTIONS = "imucal/example_ferraris_session_list.json"
IMUCAL_ANNOTATED = "imucal/annotated_session.csv"
OPENAXES_LOG = "openaxes/log_imu9_2022-06-22_22-13-55.csv"


def real_dir() -> Path:
    """The folder holding the real recordings: ``$STATION_REAL`` or ``../shared/real`` beside the repository."""
    return Path(os.environ.get(ENV_VAR) or REPO_ROOT.parent / "shared" / "real")


def real_path(*parts: str) -> Path:
    """A file of the real recordings (see :func:`real_dir`); it may be absent (mark the test ``real``)."""
    return real_dir().joinpath(*parts)


def missing(paths: tuple[str, ...]) -> list[str]:
    """Which of ``paths`` (relative to :func:`real_dir`) are not there."""
    return [p for p in paths if not real_path(p).is_file()]


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() == "true"


__all__ = ["DATA_SETS", "ENV_VAR", "IMUCAL_ANNOTATED", "IMUCAL_FERRARIS", "IMUCAL_SECTIONS", "OPENAXES_LOG",
           "in_ci", "missing", "real_dir", "real_path"]
