"""station.kernel.datafiles: the source tree's files first, the wheel's installed copies otherwise."""

from __future__ import annotations

from pathlib import Path

import pytest

from station.kernel import datafiles
from station.kernel.limits_file import DEFAULT_LIMITS_PATH, load_limits
from station.store.db import MIGRATIONS_DIR


def test_source_tree_files_are_found() -> None:
    assert (MIGRATIONS_DIR / "env.py").is_file()
    assert DEFAULT_LIMITS_PATH.is_file()
    assert load_limits().path == DEFAULT_LIMITS_PATH


def test_installed_copy_when_the_source_tree_is_absent(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(datafiles, "SOURCE_ROOT", tmp_path / "no-source")
    monkeypatch.setattr(datafiles, "INSTALLED_ROOT", tmp_path / "share" / "station")
    assert datafiles.data_path("migrations") == tmp_path / "share" / "station" / "migrations"


def test_pyproject_ships_every_migration_and_limits_file() -> None:
    import tomllib

    root = datafiles.SOURCE_ROOT
    spec = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["data-files"]
    shipped = {Path(p).name for patterns in spec.values() for pat in patterns for p in root.glob(pat)}
    needed = {p.name for p in (root / "migrations").rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    needed |= {p.name for p in (root / "fixtures" / "limits").glob("*.toml")}
    assert needed <= shipped
