"""Every command's help reads as text: no value type on a flag (``<bool>``) and no literal double backticks."""

from __future__ import annotations

from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from station.cli import app


def _commands(group: Any, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    out = [path]
    if hasattr(group, "commands"):  # a group (typer's own click, not necessarily the installed one's class)
        for name, cmd in sorted(group.commands.items()):
            out += _commands(cmd, (*path, name))
    return out


COMMANDS = _commands(typer.main.get_command(app))


def test_the_command_tree_is_walked() -> None:
    assert ("fit",) in COMMANDS and ("eeprom", "write") in COMMANDS and ("import", "openaxes") in COMMANDS


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p) or "station")
def test_help_has_no_flag_type_and_no_literal_backticks(path: tuple[str, ...]) -> None:
    r = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "120"})
    assert r.exit_code == 0, r.output
    assert "<bool>" not in r.output
    assert "``" not in r.output
    if path == ("fit",):  # a flag without a type, an option with one, the docstring's code as text
        assert "--json" in r.output and "<path>" in r.output and "quality.goodness_of_fit" in r.output


@pytest.mark.parametrize("module", ["station", "station.cli"])
def test_python_dash_m_runs_the_same_command_line(module: str) -> None:
    """``python -m station.cli`` once failed: the simulator's commands imported ``station.cli`` by name while it ran as
    ``__main__``, so each half-loaded the other."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", module, "demo", "--help"], capture_output=True, text=True,
                       env={"COLUMNS": "120", "PATH": "/usr/bin:/bin"}, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "Usage:" in r.stdout and "demo" in r.stdout
