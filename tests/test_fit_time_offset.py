"""The time offset tau (the sensor's lag behind the rig) estimated by the fit on the transitions, kept in
``station-params/3``, written in the EEPROM image and applied by Algorithm 1 (streaming, batch, simulated firmware).

Seeds: development used 101-104; these tests use 310-316.
"""

from __future__ import annotations

import dataclasses
import json
from datetime import UTC, datetime

import numpy as np
import pytest

from station.correct import StreamingCorrector, correct_batch
from station.eeprom.image import (
    IMAGE_SIZE_2,
    IMAGE_SIZE_3,
    CalibrationImage,
    decode_image,
    encode_image,
    image_problems,
)
from station.fit.calibrate import FitOptions, fit_session
from station.kernel.clock import ManualClock
from station.kernel.errors import UnsupportedVersionError
from station.kernel.parameters import ParameterSet
from station.kernel.sensor_class import TABLE1
from station.physics.effects import Effects
from station.physics.unit import draw_unit
from station.session.model import Kind
from station.sim.eeprom import Eeprom
from station.sim.firmware import CalibrationFirmware
from station.sim.session_sim import simulate_session

PRIOR = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}
AUTO = FitOptions(time_offset="auto", tc_range_s=PRIOR)
T0 = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)


@pytest.mark.parametrize(("seed", "tau_ms"), [(310, 3.0), (311, -6.5), (312, 0.4)])
def test_time_offset_is_recovered_within_its_uncertainty(seed: int, tau_ms: float) -> None:
    sim = simulate_session(seed, effects=Effects(time_offset=tau_ms))
    params = fit_session(sim.session, AUTO)
    note = params.quality.time_offset
    assert note is not None and note.status == "fitted", note
    assert note.transitions >= 3 and note.std_s > 0
    assert abs(params.time_offset_s - tau_ms * 1e-3) < 3.0 * params.time_offset_std_s, note
    assert params.format == "station-params/3"
    back = ParameterSet.from_json(params.to_json())
    assert back.time_offset_s == params.time_offset_s and back.time_offset_std_s == params.time_offset_std_s
    assert back.quality.time_offset == note


def test_no_time_offset_is_not_kept() -> None:
    params = fit_session(simulate_session(313).session, AUTO)
    note = params.quality.time_offset
    assert note is not None and note.status == "not_significant", note
    assert params.time_offset_s == 0.0 and params.format == "station-params/2"


def test_without_transitions_it_is_not_determined() -> None:
    session = simulate_session(314, effects=Effects(time_offset=3.0)).session
    moving = np.isin(session.kind, [Kind.MOVE])
    blind = session.replace(ref_gyro_radps=np.where(moving[:, None], np.nan, session.ref_gyro_radps))
    params = fit_session(blind, AUTO)
    note = params.quality.time_offset
    assert note is not None and note.status == "not_determined" and "transitions" in note.reason, note
    assert np.isnan(note.estimate_s) and params.time_offset_s == 0.0
    assert fit_session(session, FitOptions(tc_range_s=PRIOR)).quality.time_offset is None  # off by default
    with pytest.raises(ValueError, match="time_offset"):
        FitOptions(time_offset="on")


def test_station_params_2_still_loads_and_unknown_is_refused() -> None:
    plain = draw_unit(TABLE1, np.random.default_rng(1), serial="U-1").as_parameter_set(0.01)
    doc = json.loads(plain.to_json())
    assert doc["format"] == "station-params/2" and "scale_quadratic" not in doc["gyro"]
    old = ParameterSet.from_dict(doc)
    assert not old.has_polynomial and old.time_offset_s == 0.0
    with pytest.raises(UnsupportedVersionError):
        ParameterSet.from_dict({**doc, "format": "station-params/4"})
    three = dataclasses.replace(plain, time_offset_s=0.002, time_offset_std_s=1e-5,
                                gyro=dataclasses.replace(plain.gyro, scale_quadratic=np.array([1e-4, 0.0, -2e-4])))
    d3 = json.loads(three.to_json())
    assert d3["format"] == "station-params/3" and d3["gyro"]["scale_quadratic"] == [1e-4, 0.0, -2e-4]
    with pytest.raises(Exception, match="time_offset_std_s"):
        ParameterSet.from_dict({k: v for k, v in d3.items() if k != "time_offset_std_s"})


def _terms(seed: int = 1) -> ParameterSet:
    p = draw_unit(TABLE1, np.random.default_rng(seed), serial="UNIT-0001").as_parameter_set(0.01)
    return dataclasses.replace(
        p, time_offset_s=-0.0123, time_offset_std_s=1e-5,
        gyro=dataclasses.replace(p.gyro, scale_quadratic=np.array([2e-4, -1e-4, 3e-4]),
                                 scale_cubic=np.array([-5e-5, 4e-5, 1e-5])))


def test_layout3_round_trip_and_layout2_for_the_time_offset_alone() -> None:
    p = _terms()
    img = CalibrationImage.from_params(p, "ST-01", T0)
    data = encode_image(img)
    assert img.layout_version == 3 and len(data) == IMAGE_SIZE_3 == 940 and data[4:6] == b"\x03\x00"
    back = decode_image(data)
    assert back.same_as(img) and encode_image(back) == data
    q = back.to_params()
    np.testing.assert_array_equal(q.gyro.scale_quadratic, p.gyro.scale_quadratic)
    np.testing.assert_array_equal(q.gyro.scale_cubic, p.gyro.scale_cubic)
    assert q.time_offset_s == p.time_offset_s
    only_tau = dataclasses.replace(p, gyro=dataclasses.replace(p.gyro, scale_quadratic=np.zeros(3),
                                                               scale_cubic=np.zeros(3)))
    d2 = encode_image(CalibrationImage.from_params(only_tau, "ST-01", T0))
    assert len(d2) == IMAGE_SIZE_2 and decode_image(d2).to_params().time_offset_s == -0.0123
    assert image_problems(img) == []
    late = CalibrationImage.from_params(dataclasses.replace(p, time_offset_s=0.05), "ST-01", T0)  # 5 samples of lag
    assert any("time offset" in m for m in image_problems(late))


@pytest.mark.parametrize("tau_s", [-0.0123, 0.0031])
def test_firmware_streaming_and_batch_equal_station_correct(tau_s: float) -> None:
    p = dataclasses.replace(_terms(), time_offset_s=tau_s)
    img = CalibrationImage.from_params(p, "ST-01", T0)
    data = encode_image(img)
    raw = bytearray([0xFF]) * 4096
    raw[0x800:0x800 + len(data)] = data  # slot A2
    rng = np.random.default_rng(2)
    n = 700
    t = np.arange(n) * p.sample_period_s
    acc = rng.normal(0, 0.02, (n, 3)) + np.array([0.0, 0.0, 9.81])
    gyr = rng.normal(0, 2e-4, (n, 3)) + np.column_stack([3.0 * np.sin(t), -2.0 * np.sin(0.7 * t), 0.5 + 0 * t])
    ref_a, ref_w = correct_batch(acc, gyr, p)
    sa, sw = StreamingCorrector(p).run(acc, gyr)
    assert np.max(np.abs(sa - ref_a)) < 1e-9 and np.max(np.abs(sw - ref_w)) < 1e-9
    for engine in ("streaming", "batch"):
        clock = ManualClock()
        fw = CalibrationFirmware(Eeprom(clock=clock, image=bytes(raw)), clock, serial="UNIT-0001",
                                 engine=engine)  # type: ignore[arg-type]
        assert fw.loaded and fw.image is not None and fw.image.layout_version == 3
        outs_a, outs_w, pos = [], [], 0
        for size in (1, 39, 40, 41, 200, 379):
            clock.advance((pos + size - 1) * p.sample_period_s - clock.now())  # the chunk's newest sample is due
            a, w = fw(acc[pos:pos + size], gyr[pos:pos + size])
            outs_a.append(a)
            outs_w.append(w)
            pos += size
        assert np.max(np.abs(np.concatenate(outs_a) - ref_a)) < 1e-9
        assert np.max(np.abs(np.concatenate(outs_w) - ref_w)) < 1e-9
