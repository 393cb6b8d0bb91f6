"""Where the station's non-Python files are: the Alembic migrations and the default limits file.

They live at the top of the source tree (``migrations/``, ``fixtures/limits/``). An editable
install (the README's set-up) uses them there; a wheel installs copies under
``<prefix>/share/station/`` (``[tool.setuptools.data-files]`` in ``pyproject.toml``).
"""

from __future__ import annotations

import sys
from pathlib import Path

SOURCE_ROOT = Path(__file__).resolve().parents[2]
INSTALLED_ROOT = Path(sys.prefix) / "share" / "station"


def data_path(*parts: str) -> Path:
    """The source tree's ``parts`` path when it exists, else the installed copy's (which may be missing too)."""
    source = SOURCE_ROOT.joinpath(*parts)
    return source if source.exists() else INSTALLED_ROOT.joinpath(*parts)


__all__ = ["INSTALLED_ROOT", "SOURCE_ROOT", "data_path"]
