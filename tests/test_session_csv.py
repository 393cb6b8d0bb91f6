"""CSV v1 session reader/writer (spec: shared/spec/session-csv-v1.md)."""

from __future__ import annotations

import io
import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from station.kernel.errors import SessionFormatError, UnsupportedVersionError
from station.session import Kind, Session, format_session, parse_session, read_session, write_session
from station.session.csv_v1 import (
    _DECIMALS,
    _FLOAT_COLUMNS,
    COLUMNS,
    HEADER,
    UnsupportedSessionVersionError,
    _file_columns,
    _format_body_python,
    _format_body_vectorized,
    _parse_body_blocks,
    _parse_body_fast,
    _parse_body_slow,
)

# --------------------------------------------------------------------------- fixtures

HEADER_LINE = 7
FIRST_DATA_LINE = 8


def valid_lines() -> list[str]:
    """A small valid file; line numbers are fixed (header on line 7, data from line 8)."""
    return [
        "# imu-session: 1",  # 1
        "# serial: SN-000123",  # 2
        "# sample_rate_hz: 100",  # 3
        "# gravity_mps2: 9.8128",  # 4
        "# latitude_deg: 52.61",  # 5
        "# angle.2: 0,0,90",  # 6
        HEADER,  # 7
        "0.00,0,rest,0.1,0.2,9.9,1.0,-1.0,2.5,23.0,0.0,0.0,9.8128,0.0,0.0,0.0",  # 8
        "0.01,0,rest,0.1,0.2,9.8,1.0,-1.0,2.5,23.1,0.0,0.0,9.8128,0.0,0.0,0.0",  # 9
        "0.02,1,pose,9.8,0.1,0.2,0.5,0.5,0.5,,9.8128,0.0,0.0,0.0,0.0,0.0",  # 10: temp empty
        "0.03,2,move,3.0,4.0,5.0,10.0,20.0,90.0,23.2,,,,,,",  # 11: references unknown
        "0.04,3,rate,0.0,0.0,9.8,0.0,0.0,180.0,23.3,0.0,0.0,9.8128,0.0,0.0,180.0",  # 12
    ]


def text_of(lines: list[str]) -> str:
    return "\n".join(lines) + "\n"


def with_cell(lines: list[str], lineno: int, column: str, value: str) -> list[str]:
    out = list(lines)
    cells = out[lineno - 1].split(",")
    cells[COLUMNS.index(column)] = value
    out[lineno - 1] = ",".join(cells)
    return out


def refused(text: str | bytes, line: int | None, *fragments: str) -> SessionFormatError:
    with pytest.raises(SessionFormatError) as info:
        parse_session(text)
    err = info.value
    assert err.line == line, str(err)
    if line is not None:
        assert f"line {line}:" in str(err)
    for fragment in fragments:
        assert fragment.lower() in str(err).lower(), str(err)
    return err


def synthetic_session(n: int = 500, seed: int = 7) -> Session:
    rng = np.random.default_rng(seed)
    t = 0.25 + np.arange(n) / 100.0
    segment = np.arange(n) // 50
    kind = np.array([Kind.REST, Kind.POSE, Kind.MOVE, Kind.RATE], dtype=np.int8)[segment % 4]
    accel = rng.normal(0.0, 6.0, (n, 3))
    accel[:5] = [[1e-9, -1e-9, -0.0]] * 5  # tiny values must not print as '-0.000000'
    gyro = rng.normal(0.0, 2.0, (n, 3))  # rad/s
    temp = 25.0 + rng.normal(0.0, 0.5, n)
    temp[::7] = np.nan
    ref_accel = np.where((kind == Kind.MOVE)[:, None], np.nan, rng.normal(0.0, 9.8, (n, 3)))
    ref_gyro = np.where((kind == Kind.MOVE)[:, None], np.nan, rng.normal(0.0, 1.0, (n, 3)))
    return Session(
        metadata={
            "serial": "SN-42",
            "sample_rate_hz": "100",
            "gravity_mps2": "9.8128",
            "zeta": "last-but-first",
            "latitude_deg": "52.61",
            "station": "Köln line 3",
        },
        t_s=t,
        segment=segment,
        kind=kind,
        accel_mps2=accel,
        gyro_radps=gyro,
        temp_degc=temp,
        ref_accel_mps2=ref_accel,
        ref_gyro_radps=ref_gyro,
        angles_deg={6: (0.0, 0.0, -360.0), 2: (90.0, 0.5, -1.25)},
    )


# --------------------------------------------------------------------------- reading valid files


def test_valid_file_values_and_units() -> None:
    s = parse_session(text_of(valid_lines()))
    assert len(s) == 5
    np.testing.assert_array_equal(s.t_s, [0.0, 0.01, 0.02, 0.03, 0.04])
    np.testing.assert_array_equal(s.segment, [0, 0, 1, 2, 3])
    np.testing.assert_array_equal(s.kind, [Kind.REST, Kind.REST, Kind.POSE, Kind.MOVE, Kind.RATE])
    np.testing.assert_array_equal(s.accel_mps2[3], [3.0, 4.0, 5.0])
    # gyro: deg/s in the file, rad/s in the Session
    np.testing.assert_allclose(s.gyro_radps[3], np.deg2rad([10.0, 20.0, 90.0]), rtol=0, atol=1e-15)
    assert s.gyro_radps[4, 2] == pytest.approx(math.pi, abs=1e-15)
    assert s.ref_gyro_radps[4, 2] == pytest.approx(math.pi, abs=1e-15)
    assert s.ref_accel_mps2[2, 0] == 9.8128


def test_empty_temp_and_reference_cells_become_nan() -> None:
    s = parse_session(text_of(valid_lines()))
    assert math.isnan(s.temp_degc[2]) and s.temp_degc[3] == 23.2
    assert np.isnan(s.ref_accel_mps2[3]).all() and np.isnan(s.ref_gyro_radps[3]).all()
    assert np.isfinite(s.ref_accel_mps2[[0, 1, 2, 4]]).all()


def test_metadata_required_and_unknown_keys_kept() -> None:
    lines = valid_lines()
    lines.insert(5, "# rig: turntable-7 (spare): v2")  # value may itself hold ':'
    lines.insert(5, "# firmware:")  # empty value
    s = parse_session(text_of(lines))
    assert s.serial == "SN-000123" and s.sample_rate_hz == 100.0 and s.gravity_mps2 == 9.8128
    assert s.metadata["latitude_deg"] == "52.61"
    assert s.metadata["rig"] == "turntable-7 (spare): v2"
    assert s.metadata["firmware"] == ""
    assert "imu-session" not in s.metadata and "angle.2" not in s.metadata


def test_angle_lines_parsed() -> None:
    lines = valid_lines()
    lines.insert(5, "# angle.0: -360, 0.5 ,1e1")
    lines.insert(5, "# angle.17: +1.5,-2,.25")
    s = parse_session(text_of(lines))
    assert dict(s.angles_deg) == {2: (0.0, 0.0, 90.0), 0: (-360.0, 0.5, 10.0), 17: (1.5, -2.0, 0.25)}


def test_read_session_from_path_and_streams(tmp_path: Path) -> None:
    text = text_of(valid_lines())
    path = tmp_path / "s.csv"
    path.write_text(text, encoding="utf-8")
    expected = format_session(parse_session(text))
    assert format_session(read_session(path)) == expected
    assert format_session(read_session(str(path))) == expected
    assert format_session(parse_session(io.StringIO(text))) == expected
    assert format_session(parse_session(io.BytesIO(text.encode()))) == expected
    assert format_session(parse_session(text.encode())) == expected


def test_crlf_bom_and_padded_cells_are_read_like_the_plain_file() -> None:
    plain = parse_session(text_of(valid_lines()))
    crlf = parse_session(text_of(valid_lines()).replace("\n", "\r\n"))
    bom = parse_session("\ufeff" + text_of(valid_lines()))
    padded_lines = valid_lines()
    padded_lines[FIRST_DATA_LINE - 1] = " 0.00 , 0,rest\t,0.1 ,0.2,9.9,1.0,-1.0,2.5,23.0,0.0,0.0,9.8128,0.0,0.0,0.0"
    padded = parse_session(text_of(padded_lines))
    for other in (crlf, bom, padded):
        assert format_session(other) == format_session(plain)


def test_last_line_without_newline() -> None:
    s = parse_session(text_of(valid_lines()).rstrip("\n"))
    assert len(s) == 5


def test_alternative_number_spellings() -> None:
    lines = with_cell(valid_lines(), 8, "ax", "1e-1")
    lines = with_cell(lines, 8, "ay", "+.2")
    lines = with_cell(lines, 8, "az", "9.")
    lines = with_cell(lines, 9, "segment", "+0")
    lines = with_cell(lines, 10, "segment", "001")
    s = parse_session(text_of(lines))
    np.testing.assert_array_equal(s.accel_mps2[0], [0.1, 0.2, 9.0])
    np.testing.assert_array_equal(s.segment[:3], [0, 0, 1])


# --------------------------------------------------------------------------- refusals


def test_empty_file() -> None:
    refused("", 1, "empty file")
    refused("\n\n  \n", 1, "empty file")


def test_missing_version() -> None:
    lines = valid_lines()[1:]
    refused(text_of(lines), 1, "imu-session")


def test_missing_version_file_starts_with_header() -> None:
    refused(text_of(valid_lines()[6:]), 1, "imu-session")


def test_version_not_first() -> None:
    lines = valid_lines()
    lines[0], lines[1] = lines[1], lines[0]
    refused(text_of(lines), 2, "first line")


def test_unknown_version() -> None:
    lines = valid_lines()
    lines[0] = "# imu-session: 2"
    err = refused(text_of(lines), 1, "version", "'2'")
    assert isinstance(err, UnsupportedSessionVersionError)
    assert isinstance(err, UnsupportedVersionError)


def test_duplicate_version_line() -> None:
    lines = valid_lines()
    lines.insert(3, "# imu-session: 1")
    refused(text_of(lines), 4, "imu-session")


@pytest.mark.parametrize("key", ["serial", "sample_rate_hz", "gravity_mps2"])
def test_missing_required_key(key: str) -> None:
    lines = [line for line in valid_lines() if not line.startswith(f"# {key}:")]
    refused(text_of(lines), HEADER_LINE - 1, "missing required", key)


@pytest.mark.parametrize("value", ["abc", "nan", "inf", "-1", "0", "", "1,5"])
@pytest.mark.parametrize(("key", "line"), [("sample_rate_hz", 3), ("gravity_mps2", 4)])
def test_required_numeric_metadata_must_be_finite_positive(key: str, line: int, value: str) -> None:
    lines = valid_lines()
    lines[line - 1] = f"# {key}: {value}"
    refused(text_of(lines), line, key)


def test_metadata_line_without_colon() -> None:
    lines = valid_lines()
    lines.insert(4, "# just a comment")
    refused(text_of(lines), 5, "key: value")


def test_duplicate_metadata_key() -> None:
    lines = valid_lines()
    lines.insert(4, "# serial: other")
    refused(text_of(lines), 5, "duplicate", "serial")


@pytest.mark.parametrize(
    ("value", "fragment"),
    [("1,2", "three"), ("a,0,0", "not a number"), ("nan,0,0", "nan"), ("0,inf,0", "infinite"), ("1e999,0,0", "finite")],
)
def test_bad_angle_value(value: str, fragment: str) -> None:
    lines = valid_lines()
    lines[5] = f"# angle.2: {value}"
    refused(text_of(lines), 6, fragment)


@pytest.mark.parametrize("key", ["angle.x", "angle.", "angle.-1", "angle.1.5"])
def test_bad_angle_key(key: str) -> None:
    lines = valid_lines()
    lines[5] = f"# {key}: 0,0,90"
    refused(text_of(lines), 6, "angle")


def test_duplicate_angle() -> None:
    lines = valid_lines()
    lines.insert(6, "# angle.2: 0,0,45")
    refused(text_of(lines), 7, "duplicate")


def test_end_of_file_before_header() -> None:
    refused(text_of(valid_lines()[:5]), 6, "header")


@pytest.mark.parametrize(
    ("header", "fragment"),
    [
        (HEADER.replace("ax,ay", "ay,ax"), "reordered"),
        (HEADER.replace(",temp", ""), "missing temp"),
        (HEADER + ",extra", "unknown 'extra'"),
        (HEADER.replace("gz", "gyro_z", 1), "unknown 'gyro_z'"),
        (HEADER.upper(), "wrong header"),
        (HEADER.replace("ref_gx", "ref_gy"), "duplicate"),
    ],
)
def test_wrong_or_reordered_header(header: str, fragment: str) -> None:
    lines = valid_lines()
    lines[HEADER_LINE - 1] = header
    refused(text_of(lines), HEADER_LINE, fragment)


def test_no_data_rows() -> None:
    refused(text_of(valid_lines()[:HEADER_LINE]), FIRST_DATA_LINE, "no data rows")
    refused(text_of(valid_lines()[:HEADER_LINE]).rstrip("\n"), FIRST_DATA_LINE, "no data rows")


@pytest.mark.parametrize("column", ["t", "ax", "gz", "temp", "ref_ax", "ref_gz"])
def test_non_numeric_value_names_the_column(column: str) -> None:
    lines = with_cell(valid_lines(), 10, column, "1.2.3")
    refused(text_of(lines), 10, "non-numeric", f"'{column}'")


def test_non_numeric_value_decimal_comma_and_quotes() -> None:
    refused(text_of(with_cell(valid_lines(), 9, "ay", '"0.2"')), 9, "non-numeric", "'ay'")
    refused(text_of(with_cell(valid_lines(), 11, "gx", "0x10")), 11, "non-numeric", "'gx'")


@pytest.mark.parametrize("column", ["t", "segment", "kind", "ax", "ay", "az", "gx", "gy", "gz"])
def test_empty_where_not_allowed(column: str) -> None:
    lines = with_cell(valid_lines(), 12, column, "")
    fragment = "empty value" if column not in ("segment", "kind") else column
    refused(text_of(lines), 12, fragment)


@pytest.mark.parametrize("token", ["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "INF"])
@pytest.mark.parametrize("column", ["ax", "gy", "temp", "ref_az", "ref_gx"])
def test_nan_and_infinite_tokens_refused_even_where_empty_is_allowed(token: str, column: str) -> None:
    lines = with_cell(valid_lines(), 9, column, token)
    refused(text_of(lines), 9, "nan or infinite", f"'{column}'")


@pytest.mark.parametrize("column", ["t", "az", "temp", "ref_gz"])
def test_overflowing_number_is_infinite(column: str) -> None:
    lines = with_cell(valid_lines(), 11, column, "1e999")
    refused(text_of(lines), 11, "infinite", f"'{column}'")


@pytest.mark.parametrize(("row", "fields"), [(["0.05,3,rate"], 3), (["0.05"] + ["1"] * 16, 17)])
def test_wrong_number_of_fields(row: list[str], fields: int) -> None:
    lines = [*valid_lines(), ",".join(row)]
    refused(text_of(lines), 13, "number of fields", f"{fields} fields")


def test_one_field_short_in_optional_column_is_still_refused() -> None:
    lines = valid_lines()
    lines[10 - 1] = lines[10 - 1].rsplit(",", 1)[0]  # drop ref_gz: 15 fields
    refused(text_of(lines), 10, "15 fields")


def test_blank_line_in_data() -> None:
    lines = valid_lines()
    lines.insert(9, "")
    refused(text_of(lines), 10, "empty line")
    refused(text_of(valid_lines()) + "\n", 13, "empty line")


@pytest.mark.parametrize("kind", ["spin", "Rest", "REST", "", "0"])
def test_unknown_kind(kind: str) -> None:
    lines = with_cell(valid_lines(), 11, "kind", kind)
    refused(text_of(lines), 11, "kind")


@pytest.mark.parametrize(("value", "line"), [("0.01", 10), ("0.005", 10), ("0.00", 9)])
def test_t_not_strictly_increasing(value: str, line: int) -> None:
    lines = with_cell(valid_lines(), line, "t", value)
    err = refused(text_of(lines), line, "does not increase", f"line {line - 1}")
    assert err.reason.startswith("t does not increase")


@pytest.mark.parametrize("value", ["-1", "1.5", "3.0", "3e0", "x", "99999999999999999999"])
def test_segment_must_be_a_non_negative_integer(value: str) -> None:
    lines = with_cell(valid_lines(), 12, "segment", value)
    refused(text_of(lines), 12, "segment")


def test_invalid_utf8_in_data_and_in_metadata() -> None:
    data = text_of(valid_lines()).encode()
    refused(data.replace(b",rate,", b",r\xffte,"), 12, "utf-8")
    refused(data.replace(b"SN-000123", b"SN-\xff"), 2, "utf-8")


def test_lone_carriage_return_is_refused() -> None:
    lines = valid_lines()
    lines[9 - 1] = lines[9 - 1].replace(",23.1,", ",23.1\r,")
    refused(text_of(lines), 9, "'temp'")


def test_comment_after_header_is_a_bad_row() -> None:
    lines = valid_lines()
    lines.insert(9, "# note: operator sneezed")
    refused(text_of(lines), 10, "fields")


def test_error_on_last_line_of_a_large_file_names_that_line() -> None:
    s = synthetic_session(n=3000)
    lines = format_session(s).splitlines()
    lines[-1] = lines[-1].replace(",pose,", ",spin,").replace(",move,", ",spin,").replace(",rate,", ",spin,")
    lines[-1] = lines[-1].replace(",rest,", ",spin,")
    refused("\n".join(lines) + "\n", len(lines), "unknown kind")


@pytest.mark.parametrize("bad_line", [0, 1, 2, 3, 4, 9, 10, 11])
def test_block_parser_matches_reference_across_block_boundaries(bad_line: int) -> None:
    all_lines = format_session(synthetic_session(n=12)).splitlines()
    body_lines = all_lines[all_lines.index(HEADER) + 1 :]
    body_lines[5] = " " + body_lines[5].replace(",", " ,", 3)  # padded: the fast path refuses, still valid
    if bad_line == 10:
        body_lines[bad_line] = body_lines[bad_line - 1]  # t repeats across a block boundary
    elif bad_line:
        body_lines[bad_line] = body_lines[bad_line].replace(",", ",x", 1)
    body = ("\n".join(body_lines) + "\n").encode()
    outcomes = []
    for parse in (
        lambda: _parse_body_slow(body, 20, None),
        lambda: _parse_body_blocks(body, 20, None, block_lines=2),
        lambda: _parse_body_blocks(body, 20, None, block_lines=5),
    ):
        try:
            arrays = parse()
            outcomes.append(tuple(arrays[c].tobytes() for c in COLUMNS))
        except SessionFormatError as err:
            outcomes.append(str(err))
    assert outcomes[0] == outcomes[1] == outcomes[2]
    if bad_line:
        assert outcomes[0].startswith(f"line {20 + bad_line}: ")


def test_read_session_errors_name_the_path(tmp_path: Path) -> None:
    path = tmp_path / "broken.csv"
    path.write_text(text_of(with_cell(valid_lines(), 9, "ax", "oops")))
    with pytest.raises(SessionFormatError) as info:
        read_session(path)
    assert info.value.path == str(path) and info.value.line == 9
    assert str(info.value).startswith(f"{path}:line 9: ")
    with pytest.raises(SessionFormatError, match="cannot read"):
        read_session(tmp_path / "missing.csv")


# --------------------------------------------------------------------------- writing


def test_round_trip_is_byte_stable_and_keeps_values_to_written_precision() -> None:
    s = synthetic_session()
    text = format_session(s)
    back = parse_session(text)
    assert format_session(back) == text
    assert dict(back.metadata) == dict(s.metadata)
    assert dict(back.angles_deg) == dict(s.angles_deg)
    np.testing.assert_array_equal(back.segment, s.segment)
    np.testing.assert_array_equal(back.kind, s.kind)
    np.testing.assert_allclose(back.t_s, s.t_s, rtol=0, atol=5.1e-7)
    np.testing.assert_allclose(back.accel_mps2, s.accel_mps2, rtol=0, atol=5.1e-7)
    np.testing.assert_allclose(np.rad2deg(back.gyro_radps), np.rad2deg(s.gyro_radps), rtol=0, atol=5.1e-7)
    np.testing.assert_allclose(back.temp_degc, s.temp_degc, rtol=0, atol=5.1e-4)
    np.testing.assert_allclose(back.ref_accel_mps2, s.ref_accel_mps2, rtol=0, atol=5.1e-7)
    np.testing.assert_allclose(np.rad2deg(back.ref_gyro_radps), np.rad2deg(s.ref_gyro_radps), rtol=0, atol=5.1e-7)
    np.testing.assert_array_equal(np.isnan(back.temp_degc), np.isnan(s.temp_degc))
    np.testing.assert_array_equal(np.isnan(back.ref_gyro_radps), np.isnan(s.ref_gyro_radps))


def test_format_is_deterministic_with_stable_metadata_order() -> None:
    s = synthetic_session()
    text = format_session(s)
    assert text == format_session(synthetic_session())
    assert "\r" not in text and text.endswith("\n")
    head = text.split("\n")[:10]
    assert head == [
        "# imu-session: 1",
        "# serial: SN-42",
        "# sample_rate_hz: 100",
        "# gravity_mps2: 9.8128",
        "# zeta: last-but-first",
        "# latitude_deg: 52.61",
        "# station: Köln line 3",
        "# angle.2: 90.0,0.5,-1.25",
        "# angle.6: 0.0,0.0,-360.0",
        HEADER,
    ]
    assert "-0.000000" not in text and "nan" not in text.lower()


def test_exact_bytes_of_a_small_session() -> None:
    s = Session(
        metadata={"gravity_mps2": "9.81", "serial": "A1", "sample_rate_hz": "1000", "rig": "r"},
        t_s=[0.0, 0.001, 0.0020000004],
        segment=[0, 0, 12],
        kind=[Kind.REST, Kind.REST, Kind.MOVE],
        accel_mps2=[[0.1, -0.0, 9.81], [1e-7, -4e-7, 123.4567896], [-1234.5, 0.5e-6, -6e-7]],
        gyro_radps=[[0.0, math.pi, -math.pi / 2], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
        temp_degc=[21.5, np.nan, -0.0004],
        ref_accel_mps2=[[0.0, 0.0, 9.81], [0.0, 0.0, 9.81], [np.nan] * 3],
        ref_gyro_radps=[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [np.nan] * 3],
        angles_deg={12: (0.0, 0.0, 90.0)},
    )
    assert format_session(s) == (
        "# imu-session: 1\n"
        "# serial: A1\n"
        "# sample_rate_hz: 1000\n"
        "# gravity_mps2: 9.81\n"
        "# rig: r\n"
        "# angle.12: 0.0,0.0,90.0\n"
        f"{HEADER}\n"
        "0.000000,0,rest,0.100000,0.000000,9.810000,0.000000,180.000000,-90.000000,21.500,"
        "0.000000,0.000000,9.810000,0.000000,0.000000,0.000000\n"
        "0.001000,0,rest,0.000000,0.000000,123.456790,0.000000,0.000000,0.000000,,"
        "0.000000,0.000000,9.810000,0.000000,0.000000,0.000000\n"
        "0.002000,12,move,-1234.500000,0.000000,-0.000001,57.295780,0.000000,0.000000,0.000,,,,,,\n"
    )


def test_write_session_to_path_and_streams(tmp_path: Path) -> None:
    s = synthetic_session(n=120)
    expected = format_session(s)
    path = tmp_path / "out.csv"
    write_session(s, path)
    assert path.read_bytes() == expected.encode("utf-8")
    write_session(s, str(path))  # replaces the file
    assert format_session(read_session(path)) == expected
    text_stream = io.StringIO()
    write_session(s, text_stream)
    assert text_stream.getvalue() == expected
    byte_stream = io.BytesIO()
    write_session(s, byte_stream)
    assert byte_stream.getvalue() == expected.encode("utf-8")
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]  # no temporary left behind


def test_gyro_written_in_deg_per_s() -> None:
    s = parse_session(text_of(valid_lines()))
    s2 = s.replace(gyro_radps=np.tile([math.pi, -math.pi / 4, 0.0], (len(s), 1)))
    row = format_session(s2).split("\n")[FIRST_DATA_LINE - 1].split(",")
    assert row[COLUMNS.index("gx") : COLUMNS.index("gz") + 1] == ["180.000000", "-45.000000", "0.000000"]


def test_writer_refuses_what_the_reader_would_refuse() -> None:
    s = synthetic_session(n=20)
    bad_accel = s.accel_mps2.copy()
    bad_accel[3, 1] = np.nan
    with pytest.raises(SessionFormatError, match=r"sample 3.*'ay'"):
        format_session(s.replace(accel_mps2=bad_accel))
    bad_temp = s.temp_degc.copy()
    bad_temp[5] = np.inf
    with pytest.raises(SessionFormatError, match=r"sample 5.*'temp'"):
        format_session(s.replace(temp_degc=bad_temp))
    t = s.t_s.copy()
    t[8] = t[7] + 1e-8  # distinct, but equal at 6 decimals
    with pytest.raises(SessionFormatError, match=r"sample 8.*does not increase"):
        format_session(s.replace(t_s=t))
    with pytest.raises(SessionFormatError, match="sample_rate_hz"):
        format_session(s.replace(metadata={**s.metadata, "sample_rate_hz": "fast"}))
    with pytest.raises(SessionFormatError, match="cannot be written"):
        format_session(s.replace(metadata={**s.metadata, "bad\nkey": "x"}))
    with pytest.raises(SessionFormatError, match="cannot be written"):
        format_session(s.replace(metadata={**s.metadata, "angle.3": "1,2,3"}))
    with pytest.raises(SessionFormatError, match="angle"):
        format_session(s.replace(angles_deg={1: (np.nan, 0.0, 0.0)}))
    with pytest.raises(SessionFormatError, match="negative segment"):
        format_session(s.replace(segment=np.full(len(s), -1)))


def test_huge_values_use_the_exact_fallback_and_still_round_trip() -> None:
    s = synthetic_session(n=30)
    accel = s.accel_mps2.copy()
    accel[4, 0] = 3.0e12
    accel[5, 2] = -7.25e15
    big = s.replace(accel_mps2=accel)
    text = format_session(big)
    assert ",3000000000000.000000," in text and ",-7250000000000000.000000," in text
    back = parse_session(text)
    assert back.accel_mps2[5, 2] == -7.25e15
    assert format_session(back) == text


def test_vectorized_and_row_formatters_agree() -> None:
    s = synthetic_session(n=400, seed=3)
    accel = s.accel_mps2.copy()
    accel[10:20, 0] = [999999.9999995, -1e6, 123456789.0, -5e-7, 5e-7, 4.9999e-7, -0.0, 1e-12, 7.0, -7.0]
    s = s.replace(accel_mps2=accel, segment=s.segment * 1000003)
    values = _file_columns(s)
    scaled = {c: np.rint(values[c] * 10.0 ** _DECIMALS[c]) for c in _FLOAT_COLUMNS}
    assert _format_body_vectorized(s, scaled) == _format_body_python(s, values, scaled)


def test_large_synthetic_file_fast_and_slow_parsers_agree() -> None:
    text = format_session(synthetic_session(n=5000, seed=11)).encode()
    body = text[text.index(HEADER.encode()) + len(HEADER) + 1 :]
    fast = _parse_body_fast(body)
    assert fast is not None
    slow = _parse_body_slow(body, FIRST_DATA_LINE, None)
    for column in COLUMNS:
        np.testing.assert_array_equal(fast[column], slow[column])


# --------------------------------------------------------------------------- property tests

_GARBAGE = st.one_of(
    st.text(max_size=40),
    st.text(alphabet="0123456789.,+-eE restposamvnaif#:\t\"'", max_size=60),
    st.lists(
        st.sampled_from(["", "0", "1.5", "-2", "nan", "inf", "rest", "move", "1e999", " ", "x", "+.5", "3."]),
        min_size=1,
        max_size=18,
    ).map(",".join),
)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_garbage_never_raises_anything_but_session_format_error(data: st.DataObject) -> None:
    lines = valid_lines()
    for _ in range(data.draw(st.integers(1, 3))):
        action = data.draw(st.sampled_from(["insert", "replace", "mutate"]))
        index = data.draw(st.integers(0, len(lines) if action == "insert" else len(lines) - 1))
        if action == "insert":
            lines.insert(index, data.draw(_GARBAGE))
        elif action == "replace":
            lines[index] = data.draw(_GARBAGE)
        else:
            line = lines[index]
            pos = data.draw(st.integers(0, len(line)))
            lines[index] = line[:pos] + data.draw(st.text(max_size=3)) + line[pos + 1 :]
    text = text_of(lines)
    try:
        session = parse_session(text)
    except SessionFormatError as err:
        assert err.line is not None and 1 <= err.line <= len(text.split("\n")) + 1
        assert re.search(r"line \d+: ", str(err))
        return
    assert len(session) >= 1 and np.all(np.diff(session.t_s) > 0)


def fast_or_none(body: bytes) -> dict[str, np.ndarray] | None:
    """The fast path as the reader uses it: any exception means 'ask the reference parser'."""
    try:
        return _parse_body_fast(body)
    except Exception:
        return None


_CELL = st.one_of(
    st.sampled_from(["", "0", "1", "-1", "+1", "1.", ".5", "1e3", "1E-3", "1e999", "nan", "inf", "-0", "007"]),
    st.sampled_from(["rest", "pose", "rate", "move", "e", "-", ".", "1e", "1.2.3", "--1", "mover", " 1"]),
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr),
    st.integers(-3, 10**20).map(str),
)


@settings(max_examples=200, deadline=None)
@given(rows=st.lists(st.lists(_CELL, min_size=14, max_size=18), min_size=1, max_size=6), base=st.integers(0, 4))
def test_fast_path_never_accepts_what_the_reference_parser_refuses(rows: list[list[str]], base: int) -> None:
    valid = valid_lines()[HEADER_LINE:]
    lines = list(valid)
    for i, cells in enumerate(rows):
        lines[(base + i) % len(lines)] = ",".join(cells)
    body = text_of(lines).encode("utf-8")
    fast = fast_or_none(body)
    try:
        slow = _parse_body_slow(body, FIRST_DATA_LINE, None)
    except SessionFormatError as err:
        assert fast is None
        with pytest.raises(SessionFormatError) as blocks_err:
            _parse_body_blocks(body, FIRST_DATA_LINE, None, block_lines=2)
        assert str(blocks_err.value) == str(err)
        return
    blocks = _parse_body_blocks(body, FIRST_DATA_LINE, None, block_lines=2)
    for column in COLUMNS:
        np.testing.assert_array_equal(blocks[column], slow[column])
        if fast is not None:
            np.testing.assert_array_equal(fast[column], slow[column])
