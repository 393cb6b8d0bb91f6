"""Every URL, path and size argument is checked before anything starts: one line, exit 2, never a traceback;
error lines quote the input cut to a readable length with its position."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from station.cli import app
from station.fit.calibrate import fit_session
from station.kernel.errors import FitError, StationError, quote_input, shorten
from station.kernel.urls import split_url
from station.sim.session_sim import simulate_session

A5000 = "a" * 5000


def one_line_exit_2(args: list[str]) -> str:
    res = CliRunner().invoke(app, args)
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 2, res.output[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: ") and len(lines[0]) <= 500, lines
    assert res.exception is None or isinstance(res.exception, SystemExit)
    return lines[0]


@pytest.mark.parametrize(("rig", "words"), [
    ("modbus-tcp://127.0.0.1:99999", "port '99999' is not a number in 1..65535"),
    ("modbus-tcp://127.0.0.1:65536", "port '65536'"),
    ("modbus-tcp://[::1", "'[' in the host is not closed"),
    ("modbus-tcp://127.0.0.1:0", "port 0"),
    ("modbus-tcp://" + "h" * 3000, "longer than 2048 characters"),
    ("nonsense://x", "scheme must be one of"),
])
def test_bad_rig_urls_are_refused_before_anything(tmp_path: Path, rig: str, words: str) -> None:
    db = tmp_path / "s.sqlite"
    line = one_line_exit_2(["run", "--rig", rig, "--sensor", "serial:///dev/null", "--db", f"sqlite:///{db}",
                            "--out", str(tmp_path / "out")])
    assert words in line
    assert not db.exists() and not (tmp_path / "out").exists()  # nothing was created


def test_bad_sensor_and_chamber_urls(tmp_path: Path) -> None:
    db = f"sqlite:///{tmp_path / 's.sqlite'}"
    line = one_line_exit_2(["run", "--rig", "modbus-tcp://127.0.0.1:1502", "--sensor", "serial:///dev/tty\x01",
                            "--db", db])
    assert "control character" in line
    line = one_line_exit_2(["run", "--rig", "modbus-tcp://127.0.0.1:1502", "--sensor", "serial:///dev/null",
                            "--chamber", "modbus-tcp://h:70000", "--db", db])
    assert "chamber URL" in line and "70000" in line


@pytest.mark.parametrize(("url", "words"), [
    ("postgresql://[::1", "not a database URL"),
    (f"sqlite:///{A5000}", "file name too long (5000 characters"),
])
def test_bad_database_urls(url: str, words: str) -> None:
    assert words in one_line_exit_2(["units", "list", "--db", url])


def test_output_paths_refused_before_the_work(tmp_path: Path) -> None:
    regular = tmp_path / "file"
    regular.write_text("x")
    assert "nothing can be created there" in one_line_exit_2(["simulate", "-o", "/proc/x.csv"])
    assert "is a file, not a directory" in one_line_exit_2(["simulate", "-o", str(regular / "x.csv")])
    assert "file name too long" in one_line_exit_2(["simulate", "-o", str(tmp_path / f"{A5000}.csv")])
    line = one_line_exit_2(["run", "--rig", "modbus-tcp://127.0.0.1:1502", "--sensor", "serial:///dev/null",
                            "--db", f"sqlite:///{tmp_path / 's.sqlite'}", "--out", str(regular / "sub")])
    assert "is a file, not a directory" in line and not (tmp_path / "s.sqlite").exists()


def test_negative_time_stamps_are_refused_in_words() -> None:
    session = simulate_session(5).session
    shifted = session.replace(t_s=np.asarray(session.t_s) - 1000.0)
    with pytest.raises(FitError, match="time starts at -1000 s: t is seconds since power-on"):
        fit_session(shifted)


@given(st.text(max_size=3000), st.integers(min_value=0, max_value=2999))
def test_quote_input_stays_short_and_says_where(text: str, position: int) -> None:
    position = min(position, max(len(text) - 1, 0))
    quoted = quote_input(text, position if text else None)
    assert len(quoted) <= 60 * 10 + 80  # repr may escape a character into up to 10; the frame adds the rest
    if len(text) > 60:
        assert f"({len(text)} characters)" in quoted and f"at character {position + 1}" in quoted
    assert len(shorten(text)) <= 60 + 30


def test_quote_input_of_ten_megabytes() -> None:
    line = quote_input("x" * 10_000_000, 5_000_000)
    assert len(line) < 120 and "at character 5000001 (10000000 characters)" in line


@given(st.text(max_size=200))
def test_split_url_never_raises_anything_but_a_station_error(url: str) -> None:
    try:
        split_url(url, "rig")
    except StationError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 400
