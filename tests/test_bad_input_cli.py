"""Every command refuses bad input with one line and exit 1 or 2; hypothesis for every loader."""

from __future__ import annotations

import contextlib
import json
import re
import sqlite3
import struct
import zlib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from station.cli import app
from station.eeprom.image import ImageError, decode_image
from station.fit.calibrate import fit_session
from station.kernel.errors import FormatError, StationError
from station.kernel.limits_file import DEFAULT_LIMITS_PATH, parse_limits
from station.kernel.parameters import ParameterSet
from station.session import parse_session, write_session
from station.session.csv_v1 import format_session
from station.sim.session_sim import simulate_session
from station.store.db import StoreError, open_database

RUN = CliRunner()


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    w = tmp_path_factory.mktemp("bad")
    session = simulate_session(5).session
    csv = w / "good.csv"
    write_session(session, csv)
    params = fit_session(session)
    pj = w / "good.json"
    pj.write_text(params.to_json())
    return {"dir": w, "csv": csv, "params": pj}


def refused(args: list[str], codes: tuple[int, ...] = (1, 2)) -> str:
    result = RUN.invoke(app, args)
    text = result.stderr + result.stdout
    assert result.exit_code in codes, (result.exit_code, text)
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in text
    if "Usage:" not in result.stderr:
        lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return result.stderr


def _params(files: dict[str, Path], name: str, change: object = None, raw: bytes | None = None) -> Path:
    path = files["dir"] / f"{name}.json"
    if raw is not None:
        path.write_bytes(raw)
    else:
        d = json.loads(files["params"].read_text())
        change(d)  # type: ignore[operator]
        path.write_text(json.dumps(d))
    return path


def _set(*keys: str, value: object):
    def f(d: dict) -> None:
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value
    return f


@pytest.mark.parametrize(("name", "change", "raw", "fragment"), [
    ("period0", _set("sample_period_s", value=0), None, "sample period"),
    ("drift1e300", _set("accel", "bias_drift", value=[1e300, 0, 0]), None, "bias_drift"),
    ("allanlist", _set("accel", "allan", value=[1, 2]), None, "allan"),
    ("ma1e12", _set("moving_average_length", value=10**12), None, "moving-average length"),
    ("ma5000", _set("moving_average_length", value=5000), None, "moving-average length"),
    ("singular", _set("accel", "misalignment", value=[[1, 0, 0], [1, 0, 0], [0, 0, 1]]), None, "accel M"),
    ("utf8", None, b'{"format": "\xff"}', "not UTF-8"),
    ("deep", None, b"[" * 100000 + b"]" * 100000, "nested too deeply"),
    ("period_mismatch", _set("sample_period_s", value=0.001), None, "the unit samples at 100 Hz"),
])
def test_correct_refuses_bad_parameters(files: dict[str, Path], name: str, change: object, raw: bytes | None,
                                        fragment: str) -> None:
    out = files["dir"] / f"{name}.csv"
    err = refused(["correct", str(files["csv"]), "--params", str(_params(files, name, change, raw)), "-o", str(out)])
    assert fragment in err and not out.exists()


def test_correct_refuses_another_serial_unless_forced(files: dict[str, Path]) -> None:
    other = _params(files, "other", _set("serial", value="SOMEONE-ELSE"))
    out = files["dir"] / "forced.csv"
    assert "SOMEONE-ELSE" in refused(["correct", str(files["csv"]), "--params", str(other), "-o", str(out)])
    assert not out.exists()
    forced = RUN.invoke(app, ["correct", str(files["csv"]), "--params", str(other), "-o", str(out), "--force"])
    assert forced.exit_code == 0


def test_correct_refuses_to_overwrite_its_input(files: dict[str, Path]) -> None:
    before = files["csv"].read_bytes()
    same = files["dir"] / ".." / files["dir"].name / files["csv"].name
    for target in (files["csv"], same, files["params"]):
        assert "is the input" in refused(["correct", str(files["csv"]), "--params", str(files["params"]),
                                          "-o", str(target)])
    assert files["csv"].read_bytes() == before


@pytest.mark.parametrize("args", [
    ["import", "imucal", "IN", "-o", "/nonexistent/x.csv"],
    ["import", "imucal", "IN", "-o", "DIR"],
    ["simulate", "-o", "/nonexistent/x.csv"],
    ["simulate", "-o", "DIR"],
    ["diagnose", "IN", "--plot", "/nonexistent/d.png"],
    ["diagnose", "IN", "--plot", "DIR/d.txt"],
    ["diagnose", "IN", "--plot", "DIR/v"],
    ["simulate", "-o", "DIR/x.csv", "--seed", "-1"],
    ["demo", "--seed", "-1"],
    ["sim", "--seed", "-1"],
    ["sim", "--port", "99999"],
])
def test_output_paths_and_options_are_checked_first(files: dict[str, Path], args: list[str]) -> None:
    args = [a.replace("DIR", str(files["dir"])).replace("IN", str(files["csv"])) for a in args]
    refused(args)


@pytest.mark.parametrize("t_us", [2**63 - 1, -(2**63)])
def test_eeprom_time_beyond_a_date_is_refused(files: dict[str, Path], t_us: int) -> None:
    image = files["dir"] / "good.bin"
    serial = json.loads(files["params"].read_text())["serial"]
    made = RUN.invoke(app, ["eeprom", "image", serial, "--params", str(files["params"]), "-o", str(image)])
    assert made.exit_code == 0
    b = bytearray(image.read_bytes())
    struct.pack_into("<q", b, 60, t_us)
    struct.pack_into("<I", b, len(b) - 4, zlib.crc32(bytes(b[:-4])))
    bad = files["dir"] / f"t{t_us & 0xFF}.bin"
    bad.write_bytes(bytes(b))
    assert "calibration time" in refused(["eeprom", "decode", str(bad)])


def _newer(path: Path) -> None:
    open_database(f"sqlite:///{path}").close()
    with sqlite3.connect(path) as c:
        c.execute("UPDATE alembic_version SET version_num = '9999_future'")


def test_databases_are_refused_before_anything_is_written(tmp_path: Path) -> None:
    newer = tmp_path / "newer.sqlite"
    _newer(newer)
    foreign = tmp_path / "foreign.sqlite"
    with sqlite3.connect(foreign) as c:
        c.execute("CREATE TABLE customers (id INTEGER)")
    corrupt = tmp_path / "corrupt.sqlite"
    open_database(f"sqlite:///{corrupt}").close()
    data = bytearray(corrupt.read_bytes())
    for i in range(200, len(data), 7):
        data[i] = 0xA5
    corrupt.write_bytes(bytes(data))
    cases = {
        f"sqlite:///{newer}": "schema revision 9999_future is newer than this program (it knows revisions up to",
        f"sqlite:///{foreign}": "not a station database",
        f"sqlite:///{corrupt}": "corrupt",
        f"sqlite:///{tmp_path}": "is a directory",
        "mysql://u@localhost/db": "scheme 'mysql' is not supported",
    }
    for url, fragment in cases.items():
        before = {p: p.read_bytes() for p in (newer, foreign, corrupt)}
        with pytest.raises(StoreError, match=re.escape(fragment)):
            open_database(url)
        for command in (["units", "list"], ["units", "show", "X"], ["units", "disposition", "X", "scrap"]):
            assert fragment.split(" (")[0] in refused([*command, "--db", url])
        assert {p: p.read_bytes() for p in before} == before


# --------------------------------------------------------------------------- properties

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                       HealthCheck.function_scoped_fixture])
GOOD_TEXT = format_session(simulate_session(6).session)[:6000].rsplit("\n", 1)[0] + "\n"


@FAST
@given(st.integers(0, len(GOOD_TEXT) - 1), st.text(min_size=1, max_size=8))
def test_session_reader_refuses_or_reads_any_edit(pos: int, junk: str) -> None:
    with contextlib.suppress(StationError):
        parse_session(GOOD_TEXT[:pos] + junk + GOOD_TEXT[pos + 1:])


@FAST
@given(st.sampled_from(["latitude_deg", "heading_deg", "angle_std_deg", "sample_rate_hz", "gravity_mps2"]),
       st.one_of(st.text(max_size=12), st.floats(allow_nan=True, allow_infinity=True).map(repr)))
def test_metadata_values_are_numbers_in_range_or_refused(key: str, value: str) -> None:
    value = value.replace("\n", " ").replace("\r", " ")
    lines = GOOD_TEXT.split("\n")
    lines = [ln for ln in lines if not ln.startswith(f"# {key}:")]
    lines.insert(1, f"# {key}: {value}")
    try:
        s = parse_session("\n".join(lines))
    except StationError:
        return
    if key in ("latitude_deg", "heading_deg", "angle_std_deg") and value.strip():
        assert s.meta_float(key) is not None


json_values = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
                           lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=5), c, max_size=4),
                           max_leaves=12)
PARAMS = json.loads(ParameterSet.from_json(
    json.dumps(json.loads(fit_session(simulate_session(7).session).to_json()))).to_json())


@FAST
@given(st.lists(st.sampled_from(["serial", "sample_period_s", "moving_average_length", "accel", "gyro", "format",
                                 "quality"]), min_size=1, max_size=2), json_values)
def test_parameter_json_loads_or_refuses(keys: list[str], value: object) -> None:
    d = json.loads(json.dumps(PARAMS))
    for k in keys:
        d[k] = value
    try:
        params = ParameterSet.from_json(json.dumps(d))
    except FormatError:
        return
    from datetime import UTC, datetime

    from station.eeprom.image import CalibrationImage, image_problems

    with contextlib.suppress(FormatError):  # the image's own checks: a list of problems, never an exception
        assert isinstance(image_problems(CalibrationImage.from_params(params, "S", datetime(2026, 1, 1, tzinfo=UTC))),
                          list)


IMAGE_FIELDS = [(12, "<16s"), (28, "<16s"), (44, "<16s"), (60, "<q"), (68, "<d"), (76, "<H"), (78, "<H"),
                *((80 + 8 * i, "<d") for i in range(63))]


@FAST
@given(st.sampled_from(IMAGE_FIELDS), st.binary(min_size=16, max_size=16))
def test_eeprom_every_field_decodes_or_refuses_with_valid_crc(field: tuple[int, str], raw: bytes) -> None:
    from station.commands.eeprom import image_summary
    from station.eeprom.image import CalibrationImage, encode_image

    params = ParameterSet.from_dict(PARAMS)
    from datetime import UTC, datetime

    b = bytearray(encode_image(CalibrationImage.from_params(params, "S", datetime(2026, 1, 1, tzinfo=UTC))))
    offset, fmt = field
    size = struct.calcsize(fmt)
    b[offset:offset + size] = raw[:size]
    struct.pack_into("<I", b, len(b) - 4, zlib.crc32(bytes(b[:-4])))
    with contextlib.suppress(ImageError):
        image_summary(decode_image(bytes(b)))


LIMITS = DEFAULT_LIMITS_PATH.read_text()


@FAST
@given(st.integers(0, len(LIMITS) - 1), st.sampled_from(["[", "]", "=", '"', "9" * 400, "-1", "nan", "\n", "x"]))
def test_limits_file_loads_or_refuses(pos: int, junk: str) -> None:
    with contextlib.suppress(StationError):
        parse_limits(LIMITS[:pos] + junk + LIMITS[pos:])


@FAST
@given(json_values)
def test_imucal_section_list_imports_or_refuses(tmp_path: Path, sections: object) -> None:
    from station.session.imucal_import import import_imucal_ferraris

    csv = tmp_path / "f.csv"
    rows = ["n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z", *(f"{i},0.1,0.2,0.3,0,0,9.81" for i in range(50))]
    csv.write_text("\n".join(rows) + "\n")
    js = tmp_path / "s.json"
    js.write_text(json.dumps(sections))
    with contextlib.suppress(StationError):
        import_imucal_ferraris(csv, js)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(st.sampled_from(["fit", "diagnose", "correct", "import", "decode", "limits"]), st.binary(max_size=300))
def test_cli_fuzz_every_command_refuses_garbage(files: dict[str, Path], command: str, data: bytes) -> None:
    bad = files["dir"] / "fuzz.bin"
    bad.write_bytes(data)
    out = files["dir"] / "fuzz-out.csv"
    args = {
        "fit": ["fit", str(bad)],
        "diagnose": ["diagnose", str(bad)],
        "correct": ["correct", str(files["csv"]), "--params", str(bad), "-o", str(out)],
        "import": ["import", "imucal", str(bad), "-o", str(out)],
        "decode": ["eeprom", "decode", str(bad)],
        "limits": ["diagnose", str(files["csv"]), "--limits", str(bad)],
    }[command]
    refused(args)
