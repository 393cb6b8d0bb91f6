"""The session reader's bounds: streamed reading, size and row limits, inputs that are not files."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from station.kernel.errors import SessionFormatError, StationError
from station.session import Session, check_session_file, format_session, parse_session, read_session
from station.session.line_source import MAX_LINE_BYTES
from station.session.session_limits import (
    DEFAULT_MAX_BYTES,
    DEFAULT_MAX_ROWS,
    MAX_BYTES_ENV,
    MAX_ROWS_ENV,
    SessionLimitError,
    SessionLimits,
)
from tests.test_session_csv import synthetic_session, text_of, valid_lines

FIELDS = ("t_s", "segment", "kind", "accel_mps2", "gyro_radps", "temp_degc", "ref_accel_mps2", "ref_gyro_radps")


class Trickle(io.RawIOBase):
    """A binary stream that hands out at most ``step`` bytes per read (a pipe, a slow disk)."""

    def __init__(self, data: bytes, step: int) -> None:
        self._data, self._pos, self._step = data, 0, step

    def readable(self) -> bool:
        return True

    def read(self, n: int = -1) -> bytes:
        size = self._step if n < 0 else min(n, self._step)
        out = self._data[self._pos:self._pos + size]
        self._pos += len(out)
        return out


def same(a: Session, b: Session) -> None:
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
        assert getattr(a, f).dtype == getattr(b, f).dtype
    assert dict(a.metadata) == dict(b.metadata) and dict(a.angles_deg) == dict(b.angles_deg)


def error_of(data: str | bytes | io.RawIOBase, **kw: object) -> SessionFormatError:
    with pytest.raises(SessionFormatError) as info:
        parse_session(data, **kw)  # type: ignore[arg-type]
    return info.value


# --------------------------------------------------------------------------- streaming gives the same session


@pytest.mark.parametrize("step", [1, 7, 64, 1000])
def test_pieces_of_any_size_give_the_same_session(step: int) -> None:
    text = format_session(synthetic_session(n=300)).encode()
    same(parse_session(Trickle(text, step)), parse_session(text))


@settings(max_examples=30, deadline=None)
@given(step=st.integers(1, 400), bad=st.integers(0, 59), what=st.sampled_from(["pad", "letter", "repeat_t"]))
def test_errors_and_padded_lines_in_pieces_match_the_whole_text(step: int, bad: int, what: str) -> None:
    lines = format_session(synthetic_session(n=60)).splitlines()
    first = lines.index(next(x for x in lines if x.startswith("t,"))) + 1
    i = first + bad
    if what == "pad":
        lines[i] = " " + lines[i].replace(",", " ,", 4)  # valid: only the reference parser reads it
    elif what == "letter":
        lines[i] = lines[i].replace(",", ",x", 1)
    elif bad:
        lines[i] = lines[i - 1]
    text = ("\n".join(lines) + "\n").encode()
    try:
        whole = parse_session(text)
    except SessionFormatError as err:
        assert str(error_of(Trickle(text, step))) == str(err)
        return
    same(parse_session(Trickle(text, step)), whole)


def test_reader_arrays_are_taken_by_the_session_without_a_copy(tmp_path: Path) -> None:
    path = tmp_path / "s.csv"
    path.write_text(format_session(synthetic_session(n=200)))
    s = read_session(path)
    for f in FIELDS:
        a = getattr(s, f)
        assert not a.flags.writeable and a.flags.owndata
    again = Session(metadata=s.metadata, **{f: getattr(s, f) for f in FIELDS})
    assert all(getattr(again, f) is getattr(s, f) for f in FIELDS)
    writable = np.array(s.t_s)  # a caller's own array is still copied
    assert Session(metadata=s.metadata, **{**{f: getattr(s, f) for f in FIELDS}, "t_s": writable}).t_s is not writable


# --------------------------------------------------------------------------- refusals


def test_a_device_is_refused_without_reading_it() -> None:
    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    with pytest.raises(SessionFormatError, match="not a regular file \\(a character device\\)") as info:
        read_session("/dev/zero")
    assert info.value.path == "/dev/zero"


def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    with pytest.raises(SessionFormatError, match="not a regular file \\(a FIFO\\)"):
        read_session(fifo)


def test_a_directory_is_refused_as_before(tmp_path: Path) -> None:
    with pytest.raises(SessionFormatError, match="cannot read session file: Is a directory"):
        read_session(tmp_path)


def test_a_sparse_file_larger_than_the_limit_is_refused_by_its_size(tmp_path: Path) -> None:
    path = tmp_path / "sparse.csv"
    with path.open("wb") as f:
        f.truncate(2 * 2**30)  # no blocks on disk: 2 GiB of zero bytes
    with pytest.raises(SessionLimitError, match=f"2.0 GiB, more than the reader's limit of 1.0 GiB.*{MAX_BYTES_ENV}"):
        read_session(path)
    # with the limit raised the first line (no line end in 2 GiB) is refused after one read
    with pytest.raises(SessionFormatError, match="line 1: missing '# imu-session: 1'"):
        read_session(path, limits=SessionLimits(max_bytes=4 * 2**30))


def test_row_limit_names_the_first_row_over_it() -> None:
    text = text_of(valid_lines())  # data on lines 8..12
    err = error_of(text, limits=SessionLimits(max_rows=3))
    assert isinstance(err, SessionLimitError) and err.line == 11 and MAX_ROWS_ENV in str(err)
    assert len(parse_session(text, limits=SessionLimits(max_rows=5))) == 5


def test_byte_limit_applies_to_streams_too() -> None:
    text = text_of(valid_lines()).encode()
    err = error_of(Trickle(text, 50), limits=SessionLimits(max_bytes=len(text) - 1))
    assert isinstance(err, SessionLimitError) and "limit" in str(err)
    assert len(parse_session(Trickle(text, 50), limits=SessionLimits(max_bytes=len(text)))) == 5


def test_cr_only_line_ends_give_one_short_line() -> None:
    text = text_of(valid_lines()).replace("\n", "\r") * 2000  # one line of ~1.3 MB
    err = error_of(text)
    assert err.line == 1 and "lone CR" in str(err) and len(str(err)) < 200


def test_a_huge_field_gives_a_short_message() -> None:
    lines = valid_lines()
    lines[9 - 1] = lines[9 - 1].replace(",23.1,", "," + "7" * 10_000_000 + ",")
    err = error_of(text_of(lines))
    assert err.line == 9 and f"longer than {MAX_LINE_BYTES} bytes" in str(err) and len(str(err)) < 200
    lines = valid_lines()
    lines[9 - 1] = lines[9 - 1].replace(",23.1,", "," + "7" * 400 + ",")  # within the line limit: infinite
    err = error_of(text_of(lines))
    assert err.line == 9 and "infinite value" in str(err) and len(str(err)) < 200


def test_long_metadata_values_are_cut_in_messages() -> None:
    lines = valid_lines()
    lines[0] = "# imu-session: " + "9" * 5000
    assert len(str(error_of(text_of(lines)))) < 200
    lines = valid_lines()
    lines[2] = "# sample_rate_hz: " + "x" * 5000
    assert len(str(error_of(text_of(lines)))) < 200


# --------------------------------------------------------------------------- limits from the environment


def test_limits_from_the_environment() -> None:
    assert SessionLimits.from_env({}) == SessionLimits(DEFAULT_MAX_BYTES, DEFAULT_MAX_ROWS)
    limits = SessionLimits.from_env({MAX_BYTES_ENV: "3G", MAX_ROWS_ENV: "12_000_000"})
    assert limits == SessionLimits(max_bytes=3 * 2**30, max_rows=12_000_000)
    assert SessionLimits.from_env({MAX_BYTES_ENV: "512 MiB"}).max_bytes == 512 * 2**20
    for env in ({MAX_BYTES_ENV: "lots"}, {MAX_BYTES_ENV: "0"}, {MAX_ROWS_ENV: "-5"}, {MAX_ROWS_ENV: "1e6"}):
        with pytest.raises(StationError):
            SessionLimits.from_env(env)


def test_environment_limit_reaches_read_session(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "s.csv"
    path.write_text(text_of(valid_lines()))
    monkeypatch.setenv(MAX_ROWS_ENV, "2")
    with pytest.raises(SessionLimitError, match="more than 2 data rows"):
        read_session(path)


# --------------------------------------------------------------------------- the check before a command's imports


def _refusal(read: object, path: Path | str, limits: SessionLimits | None = None) -> str:
    with pytest.raises(SessionFormatError) as info:
        read(path, limits=limits)  # type: ignore[operator]
    return str(info.value)


def test_the_check_before_the_imports_refuses_as_the_reader_does(tmp_path: Path) -> None:
    """``check_session_file`` (what ``station fit`` and ``diagnose`` call before importing the fit) refuses what
    the reader refuses before the data rows, with the reader's message, and passes a good file."""
    sparse = tmp_path / "sparse.csv"
    with sparse.open("wb") as f:
        f.truncate(2 * 2**30)
    foreign = tmp_path / "foreign.csv"
    foreign.write_text("time,ax,ay\n0,1,2\n")
    no_header = tmp_path / "no_header.csv"
    no_header.write_text("# imu-session: 1\n# serial: X\n")
    cases: list[tuple[Path | str, SessionLimits | None]] = [
        (sparse, None), (sparse, SessionLimits(max_bytes=4 * 2**30)), (foreign, None), (no_header, None),
        (tmp_path, None),
    ]
    if os.path.exists("/dev/zero"):
        cases.append(("/dev/zero", None))
    for path, limits in cases:
        expected = _refusal(read_session, path, limits)
        assert _refusal(check_session_file, path, limits) == expected
    good = tmp_path / "good.csv"
    good.write_text(format_session(synthetic_session()))
    check_session_file(good)  # no error
    # the data rows are the reader's: a bad row passes the check and is refused by the reader
    lines = format_session(synthetic_session()).splitlines()
    lines[-3] = lines[-3].replace(",", ";", 1)
    bad_row = tmp_path / "bad_row.csv"
    bad_row.write_text("\n".join(lines) + "\n")
    check_session_file(bad_row)
    with pytest.raises(SessionFormatError):
        read_session(bad_row)
