"""The EEPROM calibration image: round trip, the documented layout, refusals, A/B slot selection."""

from __future__ import annotations

import json
import math
import struct
import zlib
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from station.commands.eeprom import eeprom_app
from station.eeprom.image import (
    BODY_SIZE,
    DEFAULT_SLOTS,
    IMAGE_SIZE,
    MAGIC,
    CalibrationImage,
    ImageContentError,
    ImageCrcError,
    ImageError,
    ImageLengthError,
    ImageMagicError,
    ImageVersionError,
    SlotLayout,
    decode_image,
    decode_slot,
    encode_image,
    next_write,
    params_id,
    read_slots,
    select_image,
)
from station.kernel.errors import FormatError, UnsupportedVersionError
from station.kernel.parameters import ParameterSet
from station.kernel.sensor_class import TABLE1
from station.physics.unit import draw_unit

T0 = datetime(2026, 3, 4, 5, 6, 7, 890123, tzinfo=UTC)


def _params(seed: int = 0, serial: str | None = None, nan_tc: bool = False) -> ParameterSet:
    p = draw_unit(TABLE1, np.random.default_rng(seed), serial=serial).as_parameter_set(0.01)
    if nan_tc:
        d = p.to_dict()
        d["gyro"]["correlation_time_s"] = [None, 2000.0, None]
        p = ParameterSet.from_dict(d)
    return p


IMG = CalibrationImage.from_params(_params(nan_tc=True), "ST-01", T0, update_count=7)
DATA = encode_image(IMG)


def test_round_trip_is_exact() -> None:
    assert len(DATA) == IMAGE_SIZE == 492
    back = decode_image(DATA)
    assert back.same_as(IMG)
    assert back.calibration_time == T0 and back.update_count == 7 and back.station_id == "ST-01"
    assert math.isnan(back.gyro.correlation_time_s[0]) and back.gyro.correlation_time_s[1] == 2000.0
    p = _params(nan_tc=True)
    q = back.to_params()
    for tri in ("accel", "gyro"):
        for f in ("misalignment", "bias_static", "bias_drift", "correlation_time_s", "noise_std"):
            assert np.array_equal(getattr(getattr(p, tri), f), getattr(getattr(q, tri), f), equal_nan=True)
    assert q.serial == p.serial and q.sample_period_s == 0.01 and q.moving_average_length == 40
    assert encode_image(back) == DATA  # deterministic bytes


def test_layout_offsets_match_layout_md() -> None:
    assert DATA[0:4] == MAGIC == b"SCAL"
    assert struct.unpack_from("<HHI", DATA, 4) == (1, IMAGE_SIZE, 7)
    assert DATA[12:28].rstrip(b"\0").decode() == IMG.serial
    assert DATA[28:44] == params_id(_params(nan_tc=True))
    assert DATA[44:60].rstrip(b"\0") == b"ST-01"
    assert struct.unpack_from("<q", DATA, 60)[0] == int((T0 - datetime(1970, 1, 1, tzinfo=UTC)).total_seconds() * 1e6)
    assert struct.unpack_from("<dHH", DATA, 68) == (0.01, 40, 0)
    assert struct.unpack_from("<9d", DATA, 80) == tuple(IMG.accel.misalignment.ravel())
    assert struct.unpack_from("<3d", DATA, 80 + 72) == tuple(IMG.accel.bias_static)
    assert struct.unpack_from("<3d", DATA, 248 + 72 + 48) == pytest.approx(tuple(IMG.gyro.correlation_time_s),
                                                                          nan_ok=True)
    assert struct.unpack_from("<9d", DATA, 416) == tuple(IMG.g_sensitivity.ravel())
    assert BODY_SIZE == 488 and struct.unpack_from("<I", DATA, 488)[0] == zlib.crc32(DATA[:488])


def _recrc(b: bytearray) -> bytes:
    struct.pack_into("<I", b, BODY_SIZE, zlib.crc32(bytes(b[:BODY_SIZE])))
    return bytes(b)


def test_refusals_name_the_reason() -> None:
    with pytest.raises(ImageVersionError, match="version 4") as info:  # layouts 2 and 3 exist
        decode_image(DATA[:4] + struct.pack("<H", 4) + DATA[6:])
    assert isinstance(info.value, UnsupportedVersionError) and isinstance(info.value, FormatError)
    with pytest.raises(ImageLengthError, match="491 bytes"):
        decode_image(DATA[:-1])
    with pytest.raises(ImageLengthError, match="493 bytes"):
        decode_image(DATA + b"\0")
    with pytest.raises(ImageLengthError, match="length field says 500"):
        decode_image(DATA[:6] + struct.pack("<H", 500) + DATA[8:])
    with pytest.raises(ImageCrcError):
        decode_image(DATA[:100] + bytes([DATA[100] ^ 0x40]) + DATA[101:])
    with pytest.raises(ImageMagicError):
        decode_image(b"\xff" * IMAGE_SIZE)  # erased EEPROM
    with pytest.raises(ImageLengthError, match="too few"):
        decode_image(b"SCA")
    b = bytearray(DATA)
    struct.pack_into("<H", b, 78, 1)  # reserved
    with pytest.raises(ImageContentError, match="reserved"):
        decode_image(_recrc(b))
    b = bytearray(DATA)
    struct.pack_into("<d", b, 68, -0.01)  # sample period
    with pytest.raises(ImageContentError, match="sample period"):
        decode_image(_recrc(b))
    b = bytearray(DATA)
    b[12:28] = b"\x00" * 16  # empty serial
    with pytest.raises(ImageContentError, match="serial"):
        decode_image(_recrc(b))


def test_encode_refuses_bad_content() -> None:
    with pytest.raises(ImageContentError, match="serial"):
        encode_image(CalibrationImage.from_params(_params(serial="X" * 17), "ST", T0))
    with pytest.raises(ImageContentError, match="station id"):
        encode_image(CalibrationImage.from_params(_params(), "Stätion", T0))
    with pytest.raises(ImageContentError, match="update count"):
        encode_image(IMG.with_update_count(0))
    with pytest.raises(ImageContentError, match="timezone"):
        CalibrationImage.from_params(_params(), "ST", datetime(2026, 1, 1))


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=0, max_size=600))
def test_random_bytes_are_refused(data: bytes) -> None:
    with pytest.raises(ImageError):
        decode_image(data)


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=IMAGE_SIZE - 8, max_size=IMAGE_SIZE - 8))
def test_random_body_behind_a_valid_header_is_refused(body: bytes) -> None:
    with pytest.raises(ImageError):
        decode_image(DATA[:8] + body)


@settings(max_examples=500, deadline=None)
@given(st.lists(st.integers(0, IMAGE_SIZE * 8 - 1), min_size=1, max_size=3, unique=True))
def test_bit_flips_are_refused(bits: list[int]) -> None:
    """CRC-32 has Hamming distance >= 4 at this length: every 1-3 bit error is detected."""
    b = bytearray(DATA)
    for bit in bits:
        b[bit // 8] ^= 1 << (bit % 8)
    with pytest.raises(ImageError):
        decode_image(bytes(b))


@settings(max_examples=300, deadline=None)
@given(st.integers(0, IMAGE_SIZE - 4), st.binary(min_size=1, max_size=4))
def test_bursts_are_refused(offset: int, junk: bytes) -> None:
    """Any change confined to 4 bytes (a burst of <= 32 bits) is detected by CRC-32."""
    b = bytearray(DATA)
    new = bytes(x ^ (y or 0x01) for x, y in zip(b[offset : offset + len(junk)], junk, strict=True))
    b[offset : offset + len(junk)] = new
    with pytest.raises(ImageError):
        decode_image(bytes(b))


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.integers(0, 2**32 - 1),
    st.integers(1, 2**32 - 1),
    st.integers(-(2**62), 2**62),
    st.floats(1e-6, 10.0),
    st.integers(1, 65535),
)
def test_round_trip_property(seed: int, count: int, t_us: int, period: float, n: int) -> None:
    p = _params(seed % 1000)
    img = CalibrationImage.from_params(p, "S", T0, update_count=count)
    img = replace(img, calibration_time_us=t_us, sample_period_s=period, ma_length=n)
    assert decode_image(encode_image(img)).same_as(img)


def _dump(slot_a: bytes | None, slot_b: bytes | None, layout: SlotLayout = DEFAULT_SLOTS) -> bytes:
    mem = bytearray(b"\xff" * 4096)
    for k, data in enumerate((slot_a, slot_b)):
        if data is not None:
            a = layout.address(k)
            mem[a : a + len(data)] = data
    return bytes(mem)


def test_slot_selection() -> None:
    one = encode_image(IMG.with_update_count(1))
    two = encode_image(IMG.with_update_count(2))
    assert next_write(read_slots(_dump(None, None))) == (0, 1)
    slots = read_slots(_dump(one, None))
    assert select_image(slots).slot == 0 and next_write(slots) == (1, 2)  # type: ignore[union-attr]
    assert "magic" in slots[1].error
    slots = read_slots(_dump(one, two))
    assert select_image(slots).slot == 1 and next_write(slots) == (0, 3)  # type: ignore[union-attr]
    torn = two[:200] + b"\xff" * 32 + two[232:]  # a page of the newer image never programmed
    slots = read_slots(_dump(one, torn))
    assert select_image(slots).slot == 0 and "CRC" in slots[1].error  # type: ignore[union-attr]
    assert select_image(read_slots(_dump(one, two)), serial="nobody") is None
    assert decode_slot(0, one + b"\x00" * 20).image is not None  # trailing slot bytes are ignored
    with pytest.raises(ImageLengthError):
        read_slots(b"\xff" * 1000)


# --- the `station eeprom` commands ------------------------------------------------------------------


def test_cli_image_decode_kalibr(tmp_path: Path) -> None:
    params = _params(seed=5, serial="CLI-1")
    pj = tmp_path / "p.json"
    pj.write_text(params.to_json())
    img = tmp_path / "image.bin"
    runner = CliRunner()
    res = runner.invoke(eeprom_app, ["image", "CLI-1", "--params", str(pj), "-o", str(img), "--station", "ST-7"])
    assert res.exit_code == 0, res.output
    decoded = decode_image(img.read_bytes())
    assert decoded.serial == "CLI-1" and decoded.station_id == "ST-7" and decoded.update_count == 1
    assert np.array_equal(decoded.accel.misalignment, params.accel.misalignment)
    res = runner.invoke(eeprom_app, ["decode", str(img)])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["serial"] == "CLI-1" and out["gyro_radps"]["bias_static"] == params.gyro.bias_static.tolist()
    bad = tmp_path / "bad.bin"
    bad.write_bytes(img.read_bytes()[:-1] + b"\x00")
    res = runner.invoke(eeprom_app, ["decode", str(bad)])
    assert res.exit_code == 2 and "CRC-32" in res.output
    res = runner.invoke(eeprom_app, ["image", "OTHER", "--params", str(pj), "-o", str(img)])
    assert res.exit_code == 2 and "not 'OTHER'" in res.output
    dump = tmp_path / "dump.bin"
    dump.write_bytes(_dump(img.read_bytes(), None))
    res = runner.invoke(eeprom_app, ["decode", "--dump", str(dump)])
    assert res.exit_code == 0 and json.loads(res.output)["current"] == "A"
    res = runner.invoke(eeprom_app, ["kalibr", "--params", str(pj)])
    assert res.exit_code == 0, res.output
    values = dict(line.split("#")[0].split(":", 1) for line in res.output.splitlines() if not line.startswith("#"))
    ts = params.sample_period_s
    # truth params have no Allan figures: density sigma sqrt(T_s), random walk sigma_gm sqrt(2 / T_c)
    assert float(values["accelerometer_noise_density"]) == pytest.approx(params.accel.noise_std.max() * ts**0.5,
                                                                         rel=1e-6)
    walk = params.gyro.drift_noise * np.sqrt(2.0 / params.gyro.correlation_time_s)
    assert float(values["gyroscope_random_walk"]) == pytest.approx(walk.max(), rel=1e-6)
    assert float(values["update_rate"]) == 100.0 and values["rostopic"].strip() == "/imu0"
