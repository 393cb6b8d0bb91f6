"""Session recording file format, CSV v1 (spec: shared/spec/session-csv-v1.md).

Reading: :func:`read_session` / :func:`parse_session`. The file is read in blocks of whole lines
(about 4 MiB, :mod:`station.session.line_source`) into arrays grown in place, so memory follows the
arrays kept, not the text; a size and a row limit (:mod:`station.session.session_limits`) and a line
limit bound it, and a path that is not a regular file is refused before it is read. The happy path
hands each block to the pandas C parser after cheap byte-level screening. When anything looks wrong the data is
retried in blocks of lines, and a slow line-by-line reference parser reads the blocks the fast
parser refuses: it either names the offending 1-based line in a
:class:`~station.kernel.errors.SessionFormatError` or (for lines the fast path merely could not handle,
e.g. cells padded with spaces) returns their values. The reference parser defines what is
accepted; the fast path only ever accepts a subset of it.

Writing: :func:`write_session` / :func:`format_session` produce deterministic bytes: fixed
decimals per column, ``\\n`` line ends, metadata in a stable order.

Units: the file stores angular rates (``g*``, ``ref_g*``) in deg/s; the in-memory
:class:`~station.session.model.Session` holds rad/s. Everything else is SI in both.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import stat
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, cast

import numpy as np

from station.kernel.errors import SessionFormatError, UnsupportedVersionError
from station.session.line_source import MAX_LINE_BYTES, LineSource, LineTooLong, TooManyBytes
from station.session.metadata import metadata_problem
from station.session.model import KIND_LABELS, REQUIRED_KEYS, Session
from station.session.session_limits import MAX_BYTES_ENV, MAX_ROWS_ENV, SessionLimitError, SessionLimits, size_text

__all__ = [
    "COLUMNS",
    "FORMAT_VERSION",
    "UnsupportedSessionVersionError",
    "check_session_file",
    "format_session",
    "parse_session",
    "read_session",
    "write_session",
]

FORMAT_VERSION = "1"
VERSION_KEY = "imu-session"
COLUMNS: tuple[str, ...] = (
    "t", "segment", "kind",
    "ax", "ay", "az",
    "gx", "gy", "gz",
    "temp",
    "ref_ax", "ref_ay", "ref_az",
    "ref_gx", "ref_gy", "ref_gz",
)  # fmt: skip
HEADER = ",".join(COLUMNS)
NUMERIC_KEYS = ("sample_rate_hz", "gravity_mps2")
_N_COLS = len(COLUMNS)
_FLOAT_COLUMNS = tuple(c for c in COLUMNS if c not in ("segment", "kind"))
_EMPTY_OK = frozenset(("temp", "ref_ax", "ref_ay", "ref_az", "ref_gx", "ref_gy", "ref_gz"))
_KIND_CODE = {label: code for code, label in enumerate(KIND_LABELS)}

# Decimals written per column: t to 1 us (enough for 1 kHz+), m/s^2 and deg/s to 1e-6, degC to 1e-3.
_DECIMALS: dict[str, int] = {c: 6 for c in _FLOAT_COLUMNS}
_DECIMALS["temp"] = 3

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_SEGMENT = re.compile(r"\+?0*(\d{1,19})", re.ASCII)
_DIGITS = re.compile(r"\+?\d+", re.ASCII)
_ANGLE_KEY = re.compile(r"angle\.(.*)")
_NONFINITE_WORDS = frozenset(("nan", "inf", "infinity"))
_PAD = " \t"
_INT64_MAX = int(np.iinfo(np.int64).max)

# Bytes that may appear in the data block on the fast path: digits, number syntax, the comma,
# line ends and the letters of the kind labels. Anything else (spaces, quotes, "nan", "inf", '#',
# non-ASCII, ...) sends the block to the reference parser.
_FAST_BYTES = bytes(sorted(set(b"0123456789.,+-eE\n" + "".join(KIND_LABELS).encode("ascii"))))


class UnsupportedSessionVersionError(SessionFormatError, UnsupportedVersionError):
    """The file declares an ``imu-session`` version this software does not read."""


# --------------------------------------------------------------------------- reading


def read_session(path: str | os.PathLike[str], *, limits: SessionLimits | None = None) -> Session:
    """Read a CSV v1 session file (gyro columns deg/s in the file, rad/s in the Session).

    The file is read in pieces of about 4 MiB, so memory follows the arrays kept, not the text. Refused
    with a :class:`~station.kernel.errors.SessionFormatError` before anything is parsed: a path that is not
    a regular file (a device such as ``/dev/zero``, a FIFO, a socket, a directory) and a file larger than
    ``limits.max_bytes``; while reading: more than ``limits.max_rows`` data rows (a
    :class:`~station.session.session_limits.SessionLimitError`) and a line longer than 64 KiB.
    ``limits`` default to :meth:`SessionLimits.from_env`.
    """
    name = os.fspath(path)
    limits = SessionLimits.from_env() if limits is None else limits
    with _open_checked(name, limits) as handle:
        return _parse_stream(_reader(handle, name), name, limits)


def check_session_file(path: str | os.PathLike[str], *, limits: SessionLimits | None = None) -> None:
    """Refuse, as :func:`read_session` would and with its messages, a path that is no session file: not a regular
    file, larger than the size limit, or a first line, metadata or header that is not CSV v1's (only the preamble
    is read). For a command to call before it imports its heavy machinery (the fit, the diagnosis), so that
    ``/dev/zero`` or a 2 GB sparse file is refused in the time it takes to start Python; the data rows are checked
    by :func:`read_session`, which checks all of this again."""
    name = os.fspath(path)
    limits = SessionLimits.from_env() if limits is None else limits
    with _open_checked(name, limits) as handle:
        # the preamble is a few hundred bytes: small reads, not the 4 MiB of the reader's pieces
        source = LineSource(_reader(handle, name), limits.max_bytes, read_bytes=64 * 2**10)
        try:
            _read_preamble(source, name)
        except TooManyBytes as exc:
            raise SessionLimitError(f"more than {size_text(exc.limit)} of text, the reader's limit "
                                    f"(set {MAX_BYTES_ENV} to read larger recordings)", path=name) from None


def _reader(handle: IO[bytes], name: str) -> Callable[[int], bytes]:
    """``read(n)`` of an open session file: b"" at its end, an OSError as a :class:`SessionFormatError`."""

    def read(n: int) -> bytes:
        try:
            return handle.read(n) or b""
        except OSError as exc:
            raise SessionFormatError(f"cannot read session file: {exc.strerror or exc}", path=name) from exc

    return read


def _open_checked(name: str, limits: SessionLimits) -> IO[bytes]:
    """The file ``name`` opened for reading, unbuffered; refused (:class:`SessionFormatError`) before anything is
    read when it is not a regular file or larger than ``limits.max_bytes``."""
    try:  # O_NONBLOCK: opening a FIFO must not wait for a writer (it is refused below)
        fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise SessionFormatError(f"cannot read session file: {exc.strerror or exc}", path=name) from exc
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise SessionFormatError("cannot read session file: Is a directory", path=name)
        if not stat.S_ISREG(info.st_mode):
            raise SessionFormatError(f"cannot read session file: not a regular file ({_file_type(info.st_mode)}); "
                                     "a recording is read from a file", path=name)
        if info.st_size > limits.max_bytes:
            raise SessionLimitError(
                f"the file is {size_text(info.st_size)}, more than the reader's limit of "
                f"{size_text(limits.max_bytes)} (set {MAX_BYTES_ENV} to read larger recordings)", path=name)
        return os.fdopen(fd, "rb", buffering=0)
    except BaseException:
        os.close(fd)
        raise


def _file_type(mode: int) -> str:
    for test, what in ((stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return "not a file"


def parse_session(
    text_or_stream: str | bytes | IO[str] | IO[bytes], *, path: str | None = None, limits: SessionLimits | None = None
) -> Session:
    """Parse CSV v1 content given as text, bytes or a readable (text or binary) stream.

    ``path`` is only used to name the source in error messages. A stream is read in pieces, under the same
    ``limits`` as :func:`read_session` (bytes counted as read).
    """
    limits = SessionLimits.from_env() if limits is None else limits
    if isinstance(text_or_stream, str):
        return _parse_stream(io.BytesIO(text_or_stream.encode("utf-8", errors="surrogatepass")).read, path, limits)
    if isinstance(text_or_stream, bytes | bytearray | memoryview):
        return _parse_stream(io.BytesIO(text_or_stream).read, path, limits)
    if not hasattr(text_or_stream, "read"):
        raise TypeError(f"parse_session needs str, bytes or a readable stream, not {type(text_or_stream).__name__}")
    stream = text_or_stream

    def read(n: int) -> bytes:
        piece = stream.read(n)
        if isinstance(piece, str):
            return piece.encode("utf-8", errors="surrogatepass")
        return bytes(piece or b"")

    return _parse_stream(read, path, limits)


def _fail(message: str, line: int | None, path: str | None) -> SessionFormatError:
    return SessionFormatError(message, line=line, path=path)


def _parse_stream(read: Callable[[int], bytes], path: str | None, limits: SessionLimits) -> Session:
    source = LineSource(read, limits.max_bytes)
    try:
        metadata, angles, header_line = _read_preamble(source, path)
        first_data_line = header_line + 1
        if not source.peek():
            raise _fail("no data rows after the header", first_data_line, path)
        fields = _parse_body_stream(source, first_data_line, path, limits.max_rows)
    except TooManyBytes as exc:
        raise SessionLimitError(f"more than {size_text(exc.limit)} of text, the reader's limit "
                                f"(set {MAX_BYTES_ENV} to read larger recordings)", path=path) from None
    return _build_session(metadata, angles, fields)


def _read_preamble(
    source: LineSource, path: str | None
) -> tuple[dict[str, str], dict[int, tuple[float, float, float]], int]:
    """The preamble (:func:`_parse_preamble`) after an optional byte-order mark, refusing an empty input."""
    if source.peek().startswith(b"\xef\xbb\xbf"):  # UTF-8 byte-order mark written by some spreadsheet tools
        source.skip(3)
    _check_not_empty(source, path)
    return _parse_preamble(source, path)


def _check_not_empty(source: LineSource, path: str | None) -> None:
    """Refuse an empty or all-white-space input ("empty file"), reading no more than the white space."""
    head = source.peek()
    if head and not head.isspace():
        return  # the usual case; a file that starts with white space fails the version check on line 1
    while head:
        if not head.isspace():
            raise _fail(f"missing '# {VERSION_KEY}: {FORMAT_VERSION}' on the first line", 1, path)
        head = source.discard()
    raise _fail("empty file", 1, path)


def _line_text(raw: bytes) -> bytes:
    """A line without its line end (LF or CR LF; a lone CR stays and is refused later)."""
    if raw.endswith(b"\n"):
        raw = raw[:-1]
        if raw.endswith(b"\r"):
            raw = raw[:-1]
    return raw


def _long_line(head: bytes) -> str:
    lone_cr = b"\r" in head.replace(b"\r\n", b"")
    return f"line longer than {MAX_LINE_BYTES} bytes" + (
        " (its lines end in a lone CR; expected LF or CR LF line ends)" if lone_cr else "")


def _parse_preamble(
    source: LineSource, path: str | None
) -> tuple[dict[str, str], dict[int, tuple[float, float, float]], int]:
    """Metadata lines and the header. Returns (metadata, angles, header line number)."""
    entries: list[tuple[int, str, str, str]] = []  # (line number, key, value, line text)
    lineno = 0
    header: str | None = None
    while True:
        lineno += 1
        try:
            raw = source.line()
        except LineTooLong as exc:
            if not exc.head.startswith(b"#"):  # the header's place: a file without the version line says so
                _check_version(entries, path)
            raise _fail(_long_line(exc.head), lineno, path) from None
        if raw is None:
            break
        try:
            line = _line_text(raw).decode("utf-8")
        except UnicodeDecodeError:
            raise _fail("line is not valid UTF-8 text", lineno, path) from None
        if not line.startswith("#"):
            header = line
            break
        key, sep, value = line[1:].partition(":")
        key, value = key.strip(), value.strip()
        if not sep or not key:
            raise _fail(f"metadata line is not '# key: value': {_show(line)}", lineno, path)
        entries.append((lineno, key, value, line))
    _check_version(entries, path)
    if header is None:
        raise _fail("end of file before the header line", lineno, path)
    header_line = lineno
    _check_header(header, header_line, path)

    metadata: dict[str, str] = {}
    angles: dict[int, tuple[float, float, float]] = {}
    key_lines: dict[str, int] = {}
    for number, key, value, _ in entries[1:]:
        if key in key_lines:
            raise _fail(f"duplicate metadata key {_show(key, 40)} (first on line {key_lines[key]})", number, path)
        key_lines[key] = number
        if (m := _ANGLE_KEY.fullmatch(key)) is not None:
            index_text = m.group(1)
            if not index_text.isascii() or not index_text.isdigit() or len(index_text) > 18:
                raise _fail(f"angle key needs a segment index, 'angle.N' with N >= 0: {_show(key, 40)}", number, path)
            angles[int(index_text)] = _parse_angle(value, number, path)
        else:
            metadata[key] = value
    missing = [k for k in REQUIRED_KEYS if k not in metadata]
    if missing:
        raise _fail(f"missing required metadata key(s) before the header: {', '.join(missing)}", header_line, path)
    for key in NUMERIC_KEYS:
        problem = _metadata_number_problem(metadata[key])
        if problem:
            raise _fail(f"metadata {key}: {problem}", key_lines[key], path)
    for key, value in metadata.items():
        problem = metadata_problem(key, value)
        if problem:
            raise _fail(f"metadata {key}: {problem}", key_lines[key], path)
    return metadata, angles, header_line


def _check_version(entries: list[tuple[int, str, str, str]], path: str | None) -> None:
    """``# imu-session: 1`` must be the first line, exactly once."""
    version_lines = [number for number, key, _, _ in entries if key == VERSION_KEY]
    if not entries or entries[0][0] != 1 or entries[0][1] != VERSION_KEY:
        if version_lines:
            raise _fail(f"'{VERSION_KEY}' must be on the first line, not here", version_lines[0], path)
        raise _fail(f"missing '# {VERSION_KEY}: {FORMAT_VERSION}' on the first line", 1, path)
    value = entries[0][2]
    if value != FORMAT_VERSION:
        raise UnsupportedSessionVersionError(
            f"unknown {VERSION_KEY} version {_show(value, 40)} (this reader reads version {FORMAT_VERSION})",
            line=1, path=path,
        )
    if len(version_lines) > 1:
        raise _fail(f"duplicate '{VERSION_KEY}' line (it belongs on the first line only)", version_lines[1], path)


def _metadata_number_problem(text: str) -> str | None:
    """Why a required numeric metadata value is unusable, or None. It must be finite and > 0."""
    if not _NUMBER.fullmatch(text):
        return f"{_show(text, 40)} is not a number"
    value = float(text)
    if not math.isfinite(value):
        return f"{_show(text, 40)} is not finite"
    if value <= 0.0:
        return f"{_show(text, 40)} must be positive"
    return None


def _parse_angle(value: str, lineno: int, path: str | None) -> tuple[float, float, float]:
    parts = [p.strip(_PAD) for p in value.split(",")]
    if len(parts) != 3:
        raise _fail(f"angle needs three comma-separated numbers (deg), found {len(parts)}: {_show(value, 40)}",
                    lineno, path)
    out: list[float] = []
    for axis, text in zip("xyz", parts, strict=True):
        if text.lower().lstrip("+-") in _NONFINITE_WORDS:
            raise _fail(f"angle {axis} is NaN or infinite: {_show(text, 40)}", lineno, path)
        if not _NUMBER.fullmatch(text):
            raise _fail(f"angle {axis} is not a number: {_show(text, 40)}", lineno, path)
        number = float(text)
        if not math.isfinite(number):
            raise _fail(f"angle {axis} is not finite: {_show(text, 40)}", lineno, path)
        out.append(number)
    return out[0], out[1], out[2]


def _check_header(line: str, lineno: int, path: str | None) -> None:
    names = [c.strip(_PAD) for c in line.split(",")]
    if tuple(names) == COLUMNS:
        return
    expected = list(COLUMNS)
    if sorted(names) == sorted(expected):
        problem = "header columns are reordered"
    else:
        missing = [c for c in expected if c not in names]
        unknown = [c for c in names if c not in expected]
        bits = [f"{len(names)} columns instead of {_N_COLS}"] if len(names) != _N_COLS else []
        if missing:
            bits.append(f"missing {', '.join(missing)}")
        if unknown:
            bits.append(f"unknown {', '.join(repr(u) for u in unknown)}")
        duplicates = sorted({c for c in names if names.count(c) > 1})
        if duplicates:
            bits.append(f"duplicate {', '.join(duplicates)}")
        problem = "wrong header (" + "; ".join(bits) + ")"
    raise _fail(f"{problem}; expected exactly '{HEADER}', found {_show(line)}", lineno, path)


def _show(text: str, limit: int = 80) -> str:
    return repr(text if len(text) <= limit else text[:limit] + "...")


_Arrays = dict[str, np.ndarray]


def _parse_body_fast(body: bytes, *, newlines: int | None = None) -> _Arrays | None:
    """Vectorized parse of the data block; None whenever the block is not plainly valid.

    ``newlines``: the number of line ends in ``body`` when the caller has counted them.
    """
    import pandas as pd  # deferred: importing pandas costs ~0.3 s and only reading needs it

    if body.translate(None, _FAST_BYTES):
        return None  # characters outside the plain-file alphabet
    octets = np.frombuffer(body, dtype=np.uint8)  # numpy counts bytes about twice as fast as bytes.count
    if newlines is None:
        newlines = int(np.count_nonzero(octets == ord("\n")))
    n_rows = newlines + (0 if body.endswith(b"\n") else 1)
    # Every row has exactly 15 commas: pandas refuses rows with too many fields, so with the total
    # right no row can have too few (pandas would silently pad those with NaN).
    if int(np.count_nonzero(octets == ord(","))) != (_N_COLS - 1) * n_rows:
        return None
    dtypes: dict[str, object] = {c: np.float64 for c in _FLOAT_COLUMNS}
    dtypes["segment"] = str
    dtypes["kind"] = str
    frame = pd.read_csv(
        io.BytesIO(body),
        header=None,
        names=list(COLUMNS),
        dtype=dtypes,
        engine="c",
        quoting=csv.QUOTE_NONE,
        keep_default_na=False,
        na_values=[""],
        skip_blank_lines=False,
    )
    if len(frame) != n_rows:
        return None
    arrays: _Arrays = {c: frame[c].to_numpy(dtype=np.float64) for c in _FLOAT_COLUMNS}
    for c in _FLOAT_COLUMNS:
        a = arrays[c]
        if c in _EMPTY_OK:
            if np.isinf(a).any():
                return None
        elif not np.isfinite(a).all():
            return None
    if not (np.diff(arrays["t"]) > 0).all():
        return None
    codes, uniques = pd.factorize(frame["segment"], use_na_sentinel=True)
    if (codes < 0).any():
        return None
    seg_values = np.empty(len(uniques), dtype=np.int64)
    for i, text in enumerate(uniques):
        m = _SEGMENT.fullmatch(text) if isinstance(text, str) else None
        if m is None or int(m.group(1)) > _INT64_MAX:
            return None
        seg_values[i] = int(m.group(1))
    arrays["segment"] = seg_values[codes]
    codes, uniques = pd.factorize(frame["kind"], use_na_sentinel=True)
    if (codes < 0).any():
        return None
    kind_values = np.empty(len(uniques), dtype=np.int8)
    for i, text in enumerate(uniques):
        if text not in _KIND_CODE:
            return None
        kind_values[i] = _KIND_CODE[text]
    arrays["kind"] = kind_values[codes]
    return arrays


_Row = tuple[float, int, int, list[float]]  # t (s), segment, kind code, the 13 other numbers in file units
_KIND_CODE_BYTES = {label.encode("ascii"): code for label, code in _KIND_CODE.items()}
_NAN = math.nan
_NUMBER_COLUMNS = COLUMNS[3:]
_REQUIRED_IN_ROW = sum(1 for c in _NUMBER_COLUMNS if c not in _EMPTY_OK)  # ax..gz come first


# Lines per block when the whole-body fast path failed: the fast parser retries each block and the
# reference parser only reads the blocks it refuses, so an error near the end of a long file is found
# quickly and a padded file costs no more than the reference parser.
_BLOCK_LINES = 8192  # measured: fewer blocks cost pandas call overhead, more cost slow-parser time


def _parse_body_blocks(body: bytes, first_line: int, path: str | None, block_lines: int = _BLOCK_LINES, *,
                       previous_t: float = -math.inf) -> _Arrays:
    """Block-wise parse: identical result (or error) to the reference parser on the whole body.

    ``previous_t`` is the time of the row before ``body`` (s) when ``body`` is a piece of a file.
    """
    newlines = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == ord("\n"))
    ends = (newlines[block_lines - 1 :: block_lines] + 1).tolist()
    if not ends or ends[-1] != len(body):
        ends.append(len(body))
    pieces: list[_Arrays] = []
    line = first_line
    start = 0
    for end in ends:
        block = body[start:end]
        try:
            arrays = _parse_body_fast(block)
        except Exception:  # pandas/numpy internals: the reference parser decides
            arrays = None
        if arrays is None or not arrays["t"][0] > previous_t:
            arrays = _parse_body_slow(block, line, path, previous_t=previous_t)
        pieces.append(arrays)
        previous_t = float(arrays["t"][-1])
        line += block.count(b"\n")
        start = end
    return {column: np.concatenate([piece[column] for piece in pieces]) for column in COLUMNS}


def _parse_body_slow(body: bytes, first_line: int, path: str | None, *, previous_t: float = -math.inf) -> _Arrays:
    """Reference parser, one line at a time: returns the arrays or names the first bad line.

    Cells may be padded with spaces or tabs. Empty cells are allowed only in temp and ref_*.
    ``previous_t`` is the time of the row before ``body`` (s) when parsing a block of a file.
    """
    lines = body.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()  # the final line end
    if not lines:
        raise _fail("no data rows after the header", first_line, path)
    t_values: list[float] = []
    segments: list[int] = []
    kinds: list[int] = []
    numbers: list[list[float]] = []
    for row, raw in enumerate(lines):
        lineno = first_line + row
        parsed = _quick_row(raw)
        if parsed is None:
            parsed = _checked_row(raw, lineno, path)
        t, segment, kind, values = parsed
        if not t > previous_t:
            raise _fail(f"t does not increase: {t!r} s after {previous_t!r} s on line {lineno - 1}", lineno, path)
        previous_t = t
        t_values.append(t)
        segments.append(segment)
        kinds.append(kind)
        numbers.append(values)
    arrays: _Arrays = {"t": np.array(t_values, dtype=np.float64)}
    table = np.array(numbers, dtype=np.float64).reshape(len(lines), len(_NUMBER_COLUMNS))
    for i, column in enumerate(_NUMBER_COLUMNS):
        arrays[column] = table[:, i]
    arrays["segment"] = np.array(segments, dtype=np.int64)
    arrays["kind"] = np.array(kinds, dtype=np.int8)
    return arrays


def _quick_row(raw: bytes) -> _Row | None:
    """A plainly valid row (no padding, no odd characters), or None to look closer."""
    if raw.translate(None, _FAST_BYTES):
        return None
    cells = raw.split(b",")
    if len(cells) != _N_COLS:
        return None
    try:
        t = float(cells[0])
        values = [float(c) if c else _NAN for c in cells[3:]]
    except ValueError:
        return None
    # Inside this alphabet float() accepts exactly the _NUMBER syntax; overflow gives inf.
    if not (math.isfinite(t) and all(math.isfinite(v) for v in values[:_REQUIRED_IN_ROW])):
        return None
    if any(math.isinf(v) for v in values[_REQUIRED_IN_ROW:]):
        return None
    segment_text = cells[1]
    if not segment_text.isdigit() or len(segment_text) > 18:
        return None
    kind = _KIND_CODE_BYTES.get(cells[2])
    if kind is None:
        return None
    return t, int(segment_text), kind, values


def _checked_row(raw: bytes, lineno: int, path: str | None) -> _Row:
    """Parse one row checking every cell; raise SessionFormatError naming the first problem."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise _fail("line is not valid UTF-8 text", lineno, path) from None
    cells = text.split(",")
    if len(cells) != _N_COLS:
        what = "empty line" if not text.strip(_PAD) else f"{len(cells)} fields"
        raise _fail(f"wrong number of fields: {what}, expected {_N_COLS}", lineno, path)
    parsed: list[float] = []
    for column, cell in zip(COLUMNS, cells, strict=True):
        if column in ("segment", "kind"):
            continue
        cell = cell.strip(_PAD)
        if not cell:
            if column not in _EMPTY_OK:
                raise _fail(f"empty value in column '{column}' (only temp and ref_* may be empty)", lineno, path)
            parsed.append(_NAN)
            continue
        if not _NUMBER.fullmatch(cell):
            if cell.lower().lstrip("+-") in _NONFINITE_WORDS:
                raise _fail(f"NaN or infinite value {_show(cell, 40)} in column '{column}'", lineno, path)
            raise _fail(f"non-numeric value {_show(cell, 40)} in column '{column}'", lineno, path)
        value = float(cell)
        if not math.isfinite(value):
            raise _fail(f"infinite value {_show(cell, 40)} (out of range) in column '{column}'", lineno, path)
        parsed.append(value)
    cell = cells[1].strip(_PAD)
    m = _SEGMENT.fullmatch(cell)
    if m is None:
        if _DIGITS.fullmatch(cell):
            raise _fail(f"segment {_show(cell, 40)} is too large", lineno, path)
        raise _fail(f"segment must be a non-negative integer, found {_show(cell, 40)}", lineno, path)
    segment = int(m.group(1))
    if segment > _INT64_MAX:
        raise _fail(f"segment {_show(cell, 40)[1:-1]} is too large", lineno, path)
    cell = cells[2].strip(_PAD)
    kind = _KIND_CODE.get(cell)
    if kind is None:
        raise _fail(f"unknown kind {_show(cell, 40)} (expected one of {', '.join(KIND_LABELS)})", lineno, path)
    return parsed[0], segment, kind, parsed[1:]


def _parse_body_stream(source: LineSource, first_line: int, path: str | None, max_rows: int) -> dict[str, np.ndarray]:
    """The data rows, one block of whole lines (about one read) at a time: the fast parser, else the blocks of
    :func:`_parse_body_blocks`. Returns the Session's fields (:class:`_Fields`)."""
    fields = _Fields()
    previous_t = -math.inf
    line = first_line
    rows = 0
    while True:
        try:
            block = source.block()
        except LineTooLong as exc:
            raise _fail(_long_line(exc.head), line, path) from None
        if block is None:
            break
        if b"\r" in block:  # accept CRLF line ends; a lone CR is caught as a bad cell later
            block = block.replace(b"\r\n", b"\n")
        ends = np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == ord("\n"))
        _check_line_lengths(block, ends, line, path)
        n_rows = len(ends) + (0 if block.endswith(b"\n") else 1)
        if rows + n_rows > max_rows:
            raise SessionLimitError(f"more than {max_rows:,} data rows, the reader's limit (set {MAX_ROWS_ENV} to "
                                    "read longer recordings)", line=first_line + max_rows, path=path)
        try:
            arrays = _parse_body_fast(block, newlines=len(ends))
        except Exception:  # any failure, including pandas/numpy internals: let the reference parser decide
            arrays = None
        if arrays is None or not arrays["t"][0] > previous_t:
            arrays = _parse_body_blocks(block, line, path, previous_t=previous_t)
        previous_t = float(arrays["t"][-1])
        fields.append(arrays)
        rows += n_rows
        line += len(ends)
    return fields.arrays()


def _check_line_lengths(block: bytes, ends: np.ndarray, first_line: int, path: str | None) -> None:
    """Refuse a line longer than the line limit (its line number), as the line source does across reads."""
    lengths = np.diff(ends, prepend=-1) - 1
    if lengths.size and int(lengths.max()) > MAX_LINE_BYTES:
        i = int(np.argmax(lengths > MAX_LINE_BYTES))
        start = int(ends[i - 1]) + 1 if i else 0
        raise _fail(_long_line(block[start:start + 200]), first_line + i, path)
    last = len(block) - (int(ends[-1]) + 1 if ends.size else 0)
    if last > MAX_LINE_BYTES:
        raise _fail(_long_line(block[len(block) - last:][:200]), first_line + len(ends), path)


#: The Session's array fields: (field, file columns), columns stacked into (n, 3) where there are three.
_FIELDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("t_s", ("t",)), ("segment", ("segment",)), ("kind", ("kind",)),
    ("accel_mps2", ("ax", "ay", "az")), ("gyro_radps", ("gx", "gy", "gz")), ("temp_degc", ("temp",)),
    ("ref_accel_mps2", ("ref_ax", "ref_ay", "ref_az")), ("ref_gyro_radps", ("ref_gx", "ref_gy", "ref_gz")),
)
_DEGREE_FIELDS = frozenset(("gyro_radps", "ref_gyro_radps"))


class _Fields:
    """The Session's arrays, grown block by block in place.

    Each array is resized (``realloc``, which moves a large allocation's pages without copying them) and the
    block written into its new end, gyro columns converted from deg/s to rad/s there: the peak is the arrays
    plus one block, not the blocks kept and then joined (twice the arrays). The arrays are handed over read-only
    and owning their memory, which the Session takes without a copy.
    """

    def __init__(self) -> None:
        self._n = 0
        self._arrays: dict[str, np.ndarray] = {}
        for field, columns in _FIELDS:
            dtype = np.int64 if field == "segment" else np.int8 if field == "kind" else np.float64
            self._arrays[field] = np.empty((0, 3) if len(columns) == 3 else (0,), dtype=dtype)

    def append(self, block: _Arrays) -> None:
        k = len(block["t"])
        lo, hi = self._n, self._n + k
        for field, columns in _FIELDS:
            a = self._arrays[field]
            a.resize((hi, *a.shape[1:]), refcheck=False)
            if len(columns) == 1:
                a[lo:hi] = block[columns[0]]
                continue
            for j, column in enumerate(columns):
                a[lo:hi, j] = block[column]
            if field in _DEGREE_FIELDS:
                np.deg2rad(a[lo:hi], out=a[lo:hi])
        self._n = hi

    def arrays(self) -> dict[str, np.ndarray]:
        for a in self._arrays.values():
            a.flags.writeable = False
        return self._arrays


def _build_session(metadata: dict[str, str], angles: dict[int, tuple[float, float, float]],
                   fields: dict[str, np.ndarray]) -> Session:
    return Session(metadata=metadata, angles_deg=angles, **fields)


# --------------------------------------------------------------------------- writing


def format_session(session: Session) -> str:
    """The CSV v1 text of a session: deterministic, ``\\n`` line ends, gyro columns in deg/s."""
    return _format_preamble(session) + _format_body(session)


def write_session(session: Session, path_or_stream: str | os.PathLike[str] | IO[str] | IO[bytes]) -> None:
    """Write a session as CSV v1 (UTF-8) to a file path (replaced atomically) or a text/binary stream."""
    text = format_session(session)
    if hasattr(path_or_stream, "write"):
        stream = path_or_stream
        if isinstance(stream, io.TextIOBase):
            stream.write(text)
        elif isinstance(stream, io.BufferedIOBase | io.RawIOBase):
            stream.write(text.encode("utf-8"))
        else:
            try:  # a stream of unknown kind: text first, then bytes
                cast(IO[str], stream).write(text)
            except TypeError:
                cast(IO[bytes], stream).write(text.encode("utf-8"))
        return
    target = Path(os.fspath(path_or_stream))
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(text.encode("utf-8"))
        os.chmod(tmp_name, 0o644)  # mkstemp creates 0600; a recording is an ordinary shared file
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


def _format_preamble(session: Session) -> str:
    metadata: Mapping[str, str] = session.metadata
    for key in NUMERIC_KEYS:
        problem = _metadata_number_problem(str(metadata[key]).strip())
        if problem:
            raise SessionFormatError(f"cannot write metadata {key}: {problem}")
    keys = [*REQUIRED_KEYS, *(k for k in metadata if k not in REQUIRED_KEYS)]
    lines = [f"# {VERSION_KEY}: {FORMAT_VERSION}"]
    for key in keys:
        value = str(metadata[key]).strip()
        _check_writable_metadata(key, value)
        lines.append(f"# {key}: {value}".rstrip())
    for index in sorted(session.angles_deg):
        if index < 0:
            raise SessionFormatError(f"cannot write angle.{index}: segment index must be >= 0")
        angle = session.angles_deg[index]
        if not all(math.isfinite(a) for a in angle):
            raise SessionFormatError(f"cannot write angle.{index}: non-finite angle {angle}")
        lines.append(f"# angle.{index}: " + ",".join(repr(float(a)) for a in angle))
    lines.append(HEADER)
    return "\n".join(lines) + "\n"


def _check_writable_metadata(key: str, value: str) -> None:
    bad = (
        not key
        or key != key.strip()
        or ":" in key
        or any(c in key or c in value for c in "\n\r")
        or key == VERSION_KEY
        or _ANGLE_KEY.fullmatch(key) is not None
    )
    if bad:
        raise SessionFormatError(f"metadata {key!r}: {value!r} cannot be written as a '# key: value' line")


def _file_columns(session: Session) -> dict[str, np.ndarray]:
    """The float columns in file units (gyro deg/s), keyed by column name."""
    values: dict[str, np.ndarray] = {"t": np.asarray(session.t_s, dtype=np.float64)}
    for prefix, block, in_degrees in (
        ("a", session.accel_mps2, False),
        ("g", session.gyro_radps, True),
        ("ref_a", session.ref_accel_mps2, False),
        ("ref_g", session.ref_gyro_radps, True),
    ):
        data = np.rad2deg(block) if in_degrees else np.asarray(block, dtype=np.float64)
        for axis, column in zip("xyz", data.T, strict=True):
            values[f"{prefix}{axis}"] = column
    values["temp"] = np.asarray(session.temp_degc, dtype=np.float64)
    return values


def _format_body(session: Session) -> str:
    if len(session) == 0:
        raise SessionFormatError("cannot write a session without samples")
    values = _file_columns(session)
    scaled = {c: np.rint(values[c] * 10.0 ** _DECIMALS[c]) for c in _FLOAT_COLUMNS}  # NaN stays NaN
    _check_writable(session, values, scaled)
    if all(np.nanmax(np.abs(k), initial=0.0) < _EXACT_LIMIT for k in scaled.values()):
        return _format_body_vectorized(session, scaled)
    return _format_body_python(session, values, scaled)


def _check_writable(session: Session, values: dict[str, np.ndarray], scaled: dict[str, np.ndarray]) -> None:
    """Refuse sessions whose file the reader would refuse (the model itself does not enforce these)."""
    for column, data in values.items():
        bad = np.isinf(data) if column in _EMPTY_OK else ~np.isfinite(data)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise SessionFormatError(f"cannot write sample {i}: column '{column}' is {data[i]!r}")
    not_increasing = np.flatnonzero(np.diff(scaled["t"]) <= 0)
    if not_increasing.size:
        i = int(not_increasing[0]) + 1
        raise SessionFormatError(
            f"cannot write sample {i}: t = {values['t'][i]!r} s does not increase at "
            f"{_DECIMALS['t']} decimals (previous {values['t'][i - 1]!r} s)"
        )
    segment = np.asarray(session.segment)
    if (segment < 0).any():
        i = int(np.flatnonzero(segment < 0)[0])
        raise SessionFormatError(f"cannot write sample {i}: negative segment {int(segment[i])}")
    kind = np.asarray(session.kind)
    bad_kind = (kind < 0) | (kind >= len(KIND_LABELS))
    if bad_kind.any():
        i = int(np.flatnonzero(bad_kind)[0])
        raise SessionFormatError(f"cannot write sample {i}: unknown kind code {int(kind[i])}")


# Below this magnitude x * 10**decimals, rounded, is an exact integer in float64 and int64.
_EXACT_LIMIT = 2.0**52
_PAD_BYTE = 0  # filler in the fixed-width text matrix, removed before returning
_KIND_TEXT = np.array(  # one column per kind code, padded with filler to the longest label
    [list(label.encode("ascii").ljust(max(map(len, KIND_LABELS)), bytes((_PAD_BYTE,)))) for label in KIND_LABELS],
    dtype=np.uint8,
).T.copy()


def _format_body_vectorized(session: Session, scaled: dict[str, np.ndarray]) -> str:
    """All rows at once: a fixed-width byte matrix with filler bytes, then the filler removed.

    The matrix is built transposed (one contiguous row of bytes per character position) so every
    write is contiguous; ``tobytes`` of its transpose yields the rows in file order.
    """
    n = len(session)
    plans: list[tuple[str, np.ndarray, int, int]] = []  # (column, integer values, decimals, whole-part digits)
    width = 0
    for column in COLUMNS:
        if column == "kind":
            plans.append((column, np.asarray(session.kind, dtype=np.intp), 0, 0))
            width += _KIND_TEXT.shape[0] + 1
            continue
        if column == "segment":
            k = np.asarray(session.segment, dtype=np.int64)
            decimals = 0
        else:
            k = np.nan_to_num(scaled[column], nan=0.0).astype(np.int64)
            decimals = _DECIMALS[column]
        digits = len(str(int(np.abs(k).max()) // 10**decimals))
        plans.append((column, k, decimals, digits))
        width += 1 + digits + (1 + decimals if decimals else 0) + 1
    matrix = np.empty((width, n), dtype=np.uint8)
    offset = 0
    for column, k, decimals, digits in plans:
        if column == "kind":
            cell_width = _KIND_TEXT.shape[0]
            matrix[offset : offset + cell_width] = np.take(_KIND_TEXT, k, axis=1)
        else:
            cell_width = 1 + digits + (1 + decimals if decimals else 0)
            empty = np.isnan(scaled[column]) if column in scaled else None
            _fill_number(matrix[offset : offset + cell_width], k, decimals, digits, empty)
        offset += cell_width
        matrix[offset] = ord("\n") if offset == width - 1 else ord(",")
        offset += 1
    return matrix.T.tobytes().translate(None, bytes((_PAD_BYTE,))).decode("ascii")


# "000" .. "999" as bytes, one column per number: three digits per lookup instead of a division per digit.
_DIGITS3 = np.array([list(f"{i:03d}".encode("ascii")) for i in range(1000)], dtype=np.uint8).T.copy()


def _fill_digits(target: np.ndarray, values: np.ndarray) -> None:
    """Write the zero-padded decimal digits of non-negative integer ``values`` into the (d, n) byte view."""
    right = target.shape[0]
    rest = values
    while right > 0:
        rest, low = np.divmod(rest, 1000)
        left = max(0, right - 3)
        target[left:right] = np.take(_DIGITS3, low, axis=1)[3 - (right - left) :]
        right = left


def _fill_number(target: np.ndarray, k: np.ndarray, decimals: int, digits: int, empty: np.ndarray | None) -> None:
    """Text of k / 10**decimals with exactly ``decimals`` digits after the point into a (w, n) byte view.

    Leading zeros, the '+' sign and cells marked ``empty`` become filler. Zero is never '-0'.
    """
    magnitude = np.abs(k)
    whole, fraction = np.divmod(magnitude, 10**decimals)
    # 32-bit division is about twice as fast; the fraction always fits, the whole part usually.
    whole = whole.astype(np.uint32) if digits <= 9 else whole.astype(np.uint64)
    target[0] = np.where(k < 0, ord("-"), _PAD_BYTE)
    _fill_digits(target[1 : 1 + digits], whole)
    for j in range(digits - 1):  # leading zeros of the whole part become filler; the units digit stays
        target[1 + j][whole < 10 ** (digits - 1 - j)] = _PAD_BYTE
    if decimals:
        target[1 + digits] = ord(".")
        _fill_digits(target[2 + digits :], fraction.astype(np.uint32))
    if empty is not None and empty.any():
        target[:, empty] = _PAD_BYTE


def _format_body_python(session: Session, values: dict[str, np.ndarray], scaled: dict[str, np.ndarray]) -> str:
    """Row-by-row formatting for sessions with huge values (beyond exact float64 integers).

    Gives the same text as the vectorized path wherever both apply.
    """
    columns: list[list[object]] = []
    for column in COLUMNS:
        if column == "segment":
            columns.append(np.asarray(session.segment, dtype=np.int64).tolist())
        elif column == "kind":
            columns.append([KIND_LABELS[int(k)] for k in session.kind])
        else:
            decimals = _DECIMALS[column]
            k = scaled[column]
            exact = np.abs(k) < _EXACT_LIMIT
            # Within the exact range print the rounded value (identical digits to the vectorized path);
            # "+ 0.0" turns -0.0 into 0.0. NaN prints as '' below.
            rounded = np.where(exact, k / 10.0**decimals + 0.0, values[column])
            columns.append(["" if math.isnan(v) else f"{v:.{decimals}f}" for v in rounded.tolist()])
    return "".join(",".join(map(str, row)) + "\n" for row in zip(*columns, strict=True))
