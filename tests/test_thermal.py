"""The thermal terms from the fit through the parameter set, Algorithm 1, the EEPROM
(layout 2) and the simulated firmware; and the simulated temperature plateaus they are fitted on."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from datetime import UTC, datetime

import numpy as np
import pytest

from station.correct import StreamingCorrector, correct_batch, correct_session
from station.eeprom.image import (
    IMAGE_SIZE,
    IMAGE_SIZE_2,
    WIDE_SLOTS,
    CalibrationImage,
    decode_image,
    encode_image,
    read_all_slots,
    select_image,
)
from station.eeprom.provision import read_current_image, write_image
from station.fit.calibrate import FitOptions, fit_session
from station.fit.compensation import COMPENSATION, compensated_by
from station.kernel.clock import ManualClock
from station.kernel.errors import FitError, HardwareError, UnsupportedVersionError
from station.kernel.parameters import ParameterSet
from station.kernel.plan import RigPlan
from station.kernel.sensor_class import TABLE1
from station.physics.effects import Effects
from station.physics.unit import draw_unit
from station.sensor import Sensor, open_sensor
from station.session.csv_v1 import format_session
from station.session.model import Kind
from station.sim.eeprom import Eeprom
from station.sim.fakes import FakeSensorDevice, publish
from station.sim.firmware import CalibrationFirmware, install_firmware
from station.sim.session_sim import simulate_session

SERIAL = "UNIT-0001"
T0 = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
#: A short plan per plateau (tests; the benchmark runs the default plan).
PLAN = RigPlan(rest_s=120.0, pose_hold_s=20.0, rate_hold_s=8.0,
               rate_steps=tuple((a, s * 150.0) for a in "xyz" for s in (1.0, -1.0)))
PLATEAUS = (25.0, 45.0, 5.0, 25.0)
AUTO = FitOptions(thermal="auto")
EFFECTS = Effects(temperature_bias=0.004, temperature_scale=200.0)  # 0.2-0.4 mg/K, 0.01-0.02 deg/s/K, 100-200 ppm/K


def _thermal_params(seed: int = 1, serial: str = SERIAL) -> ParameterSet:
    """A unit's truth with temperature terms up to order 3 and a scale nonlinearity."""
    p = draw_unit(TABLE1, np.random.default_rng(seed), serial=serial).as_parameter_set(0.01)
    rng = np.random.default_rng(seed + 100)
    accel = dataclasses.replace(p.accel, temp_bias_coeff=rng.normal(size=(3, 3)) * [3e-3, 2e-5, 1e-7],
                                temp_scale_coeff=rng.normal(size=(3, 3)) * [2e-4, 1e-6, 1e-8],
                                scale_nonlinearity=rng.normal(size=3) * 1e-3)
    gyro = dataclasses.replace(p.gyro, temp_bias_coeff=rng.normal(size=(3, 3)) * [3e-4, 2e-6, 1e-8],
                               temp_scale_coeff=rng.normal(size=(3, 3)) * [2e-4, 1e-6, 1e-8])
    return dataclasses.replace(p, accel=accel, gyro=gyro, reference_temperature_degc=25.0)


# --- parameter set ---------------------------------------------------------------------------------


def test_parameter_set_v2_round_trip_and_v1_still_loads() -> None:
    p = _thermal_params()
    doc = json.loads(p.to_json())
    assert doc["format"] == "station-params/2" and doc["reference_temperature_degc"] == 25.0
    q = ParameterSet.from_json(p.to_json())
    assert q.to_json() == p.to_json() and q.compensates_temperature and q.has_nonlinearity
    np.testing.assert_array_equal(q.gyro.temp_scale_coeff, p.gyro.temp_scale_coeff)
    # a station-params/1 file: the new fields absent, they load as zero / none
    v1 = {k: v for k, v in doc.items() if k not in ("reference_temperature_degc", "time_offset_s", "thermal")}
    v1["format"] = "station-params/1"
    for tri in ("accel", "gyro"):
        for name in ("temp_bias_coeff", "temp_bias_coeff_std", "temp_scale_coeff", "temp_scale_coeff_std",
                     "scale_nonlinearity", "scale_nonlinearity_std"):
            del v1[tri][name]
    old = ParameterSet.from_dict(v1)
    assert not old.compensates_temperature and old.thermal.status == "absent"
    assert not np.any(old.accel.temp_bias_coeff) and np.isnan(old.reference_temperature_degc)
    np.testing.assert_array_equal(old.accel.misalignment, p.accel.misalignment)
    with pytest.raises(UnsupportedVersionError, match="station-params/4"):
        ParameterSet.from_dict({**doc, "format": "station-params/4"})


# --- Algorithm 1 ------------------------------------------------------------------------------------


def test_batch_equals_streaming_with_temperature_terms() -> None:
    p = _thermal_params(seed=2)
    rng = np.random.default_rng(0)
    n = 3000
    temp = 25.0 + 20.0 * np.sin(np.arange(n) / 400.0)
    acc = rng.normal(0, 0.02, (n, 3)) + np.array([0.0, 0.0, 9.81])
    gyr = rng.normal(0, 2e-4, (n, 3)) + np.array([0.01, -0.02, 3.0])
    for start in (0, 1234):
        ba, bw = correct_batch(acc, gyr, p, start, temp_degc=temp, chunk_rows=256)
        sa, sw = StreamingCorrector(p, start).run(acc, gyr, temp)
        assert np.max(np.abs(ba - sa)) < 1e-9 and np.max(np.abs(bw - sw)) < 1e-9
    with pytest.raises(ValueError, match="temp"):
        correct_batch(acc, gyr, p)
    # the terms act: the same record without them differs by about c dT
    plain = dataclasses.replace(p, reference_temperature_degc=float("nan"),
                                accel=dataclasses.replace(p.accel, temp_bias_coeff=np.zeros((3, 3)),
                                                          temp_scale_coeff=np.zeros((3, 3))),
                                gyro=dataclasses.replace(p.gyro, temp_bias_coeff=np.zeros((3, 3)),
                                                         temp_scale_coeff=np.zeros((3, 3))))
    pa, _ = correct_batch(acc, gyr, plain)
    assert np.max(np.abs(pa - ba)) > 1e-2


def test_correction_inverts_the_model() -> None:
    """Noise-free raw output of the eq. (1) model with temperature terms and nonlinearity is corrected to the truth."""
    p = _thermal_params(seed=3)
    n = 400
    temp = np.linspace(5.0, 45.0, n)
    dt = (temp - 25.0)[:, None]
    x_true = np.array([[0.3, -0.4, 9.8], [0.5, -0.2, 1.5]])  # constant specific force and rate
    raws = []
    for k, tri in enumerate((p.accel, p.gyro)):
        u = (tri.misalignment @ x_true[k])[None, :] * (1 + sum(tri.temp_scale_coeff[:, j] * dt ** (j + 1)
                                                              for j in range(3)))
        u = u + tri.scale_nonlinearity * u * np.abs(u)
        raws.append(u + tri.bias_static + sum(tri.temp_bias_coeff[:, j] * dt ** (j + 1) for j in range(3)))
    p0 = dataclasses.replace(p, accel=dataclasses.replace(p.accel, bias_drift=np.zeros(3)),
                             gyro=dataclasses.replace(p.gyro, bias_drift=np.zeros(3)))
    a, w = correct_batch(raws[0], raws[1], p0, temp_degc=temp)
    np.testing.assert_allclose(a, np.tile(x_true[0], (n, 1)), atol=1e-12)
    np.testing.assert_allclose(w, np.tile(x_true[1], (n, 1)), atol=1e-12)


# --- EEPROM layout 2 ----------------------------------------------------------------------------------


def test_layout2_round_trip_and_layout1_unchanged() -> None:
    p = _thermal_params()
    img = CalibrationImage.from_params(p, "ST-01", T0)
    data = encode_image(img)
    assert img.layout_version == 2 and len(data) == IMAGE_SIZE_2 == 844 and data[4:6] == b"\x02\x00"
    back = decode_image(data)
    assert back.same_as(img) and encode_image(back) == data
    q = back.to_params()
    np.testing.assert_array_equal(q.gyro.temp_bias_coeff, p.gyro.temp_bias_coeff)
    np.testing.assert_array_equal(q.accel.scale_nonlinearity, p.accel.scale_nonlinearity)
    assert q.reference_temperature_degc == 25.0 and q.compensates_temperature
    # a set without the effects still gives the layout-1 image, byte for byte the old size
    plain = draw_unit(TABLE1, np.random.default_rng(1), serial=SERIAL).as_parameter_set(0.01)
    d1 = encode_image(CalibrationImage.from_params(plain, "ST-01", T0))
    assert len(d1) == IMAGE_SIZE == 492 and d1[4:6] == b"\x01\x00" and decode_image(d1).effects is None
    # a damaged layout-2 image is refused like a layout-1 one
    with pytest.raises(Exception, match="CRC"):
        decode_image(data[:600] + bytes([data[600] ^ 1]) + data[601:])


class _ModelSource:
    def __init__(self) -> None:
        pass

    def power_on(self) -> None:
        pass

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = np.asarray(t_s).shape[0]
        return np.tile([0.0, 0.0, 9.81], (n, 1)), np.zeros((n, 3)), np.full(n, 30.0)


@pytest.fixture()
def unit() -> Iterator[tuple[FakeSensorDevice, Sensor, CalibrationFirmware]]:
    clock = ManualClock()
    sensor = FakeSensorDevice(_ModelSource(), clock, url="fake-sensor://thermal/0", serial=SERIAL,
                              eeprom=Eeprom(clock=clock))
    publish(sensor)
    fw = install_firmware(sensor, clock)
    client = open_sensor(sensor.url, clock, command_timeout_s=0.25, attempts=1)
    try:
        yield sensor, client, fw
    finally:
        client.close()
        sensor.close()


def _image(params: ParameterSet, station: str) -> CalibrationImage:
    return CalibrationImage.from_params(params, station, T0)


def _power_loss_round(sensor: FakeSensorDevice, client: Sensor, fw: CalibrationFirmware, new: CalibrationImage) -> int:
    """A power loss at every page of one write: the old image stays current; then the write completes."""
    before = read_all_slots(sensor.eeprom.image())
    old = select_image(before)
    assert old is not None and old.image is not None
    old_bytes = encode_image(old.image)
    new_bytes = encode_image(new.with_update_count(old.image.update_count + 1))
    known = {encode_image(b.image) for b in before if b.image is not None} | {old_bytes, new_bytes}
    pages = -(-len(new_bytes) // 32)
    for k in range(pages):
        sensor.eeprom.power_loss_after(n_bytes=(5 * k) % 11, pages_before=k)  # < the shortest page (12 bytes)
        with pytest.raises(HardwareError):
            write_image(client, new)
        sensor.power_on()
        slots = read_all_slots(sensor.eeprom.image())
        assert all(encode_image(s.image) in known for s in slots if s.image is not None)  # never a mix
        cur = select_image(slots)
        assert cur is not None and cur.image is not None and encode_image(cur.image) == old_bytes
        assert fw.loaded and fw.image is not None and fw.image.update_count == old.image.update_count
    sensor.eeprom.disarm()
    report = write_image(client, new)
    cur = select_image(read_all_slots(sensor.eeprom.image()))
    assert cur is not None and cur.image is not None and encode_image(cur.image) == new_bytes
    assert report.update_count == old.image.update_count + 1
    return pages


def test_layout2_power_loss_at_every_page_keeps_old_image(unit: tuple) -> None:
    sensor, client, fw = unit
    plain = draw_unit(TABLE1, np.random.default_rng(1), serial=SERIAL).as_parameter_set(0.01)
    write_image(client, _image(plain, "OLD"))  # a layout-1 image in slot A
    sensor.power_cycle()
    assert fw.loaded and fw.image is not None and fw.image.layout_version == 1
    thermal = _thermal_params(seed=4)
    assert _power_loss_round(sensor, client, fw, _image(thermal, "NEW")) == 27  # layout 1 -> 2 (slot A2)
    assert _power_loss_round(sensor, client, fw, _image(_thermal_params(seed=5), "NEWER")) == 27  # slot B2
    assert _power_loss_round(sensor, client, fw, _image(plain, "BACK")) == 16  # 2 -> 1 (slot B)
    cur = read_current_image(client)
    assert cur is not None and cur.layout_version == 1 and cur.station_id == "BACK"


def test_firmware_applies_layout2_terms_like_station_correct(unit: tuple) -> None:
    sensor, client, _fw = unit
    p = _thermal_params(seed=6)
    report = write_image(client, _image(p, "ST-01"))
    assert report.slot == "A2" and report.address == WIDE_SLOTS.base and report.length == IMAGE_SIZE_2
    clock = _Clock()
    ee = Eeprom(clock=clock, image=sensor.eeprom.image())
    rng = np.random.default_rng(1)
    n = 700
    acc = rng.normal(0, 0.02, (n, 3)) + np.array([0.0, 0.0, 9.81])
    gyr = rng.normal(0, 2e-4, (n, 3)) + np.array([0.01, -0.02, 0.5])
    temp = 10.0 + 0.05 * np.arange(n)
    ref_a, ref_w = correct_batch(acc, gyr, p, temp_degc=temp)
    for engine in ("streaming", "batch"):
        fw = CalibrationFirmware(ee, clock, serial=SERIAL, engine=engine)  # type: ignore[arg-type]
        assert fw.loaded and fw.image is not None and fw.image.layout_version == 2
        outs_a, outs_w, pos = [], [], 0
        for size in (1, 39, 40, 41, 200, 379):
            clock.t = (pos + size - 1) * p.sample_period_s  # the newest sample of the chunk is due now
            a, w = fw(acc[pos:pos + size], gyr[pos:pos + size], temp[pos:pos + size])
            outs_a.append(a)
            outs_w.append(w)
            pos += size
        assert np.max(np.abs(np.concatenate(outs_a) - ref_a)) < 1e-9
        assert np.max(np.abs(np.concatenate(outs_w) - ref_w)) < 1e-9
        clock.t = 0.0


class _Clock:
    scale = 1.0

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


# --- simulation and fit -------------------------------------------------------------------------------


def test_plateau_session_is_deterministic_and_moves_the_temperature() -> None:
    a = simulate_session(5, plan=PLAN, effects=EFFECTS, temperature_plateaus_degc=PLATEAUS, soak_s=300.0)
    b = simulate_session(5, plan=PLAN, effects=EFFECTS, temperature_plateaus_degc=PLATEAUS, soak_s=300.0)
    assert format_session(a.session) == format_session(b.session)
    s = a.session
    assert abs(s.temp_degc[0] - 25.0) < 0.3 and a.environment.ambient_degc == 25.0
    rests = [seg for seg in s.segments() if seg.kind.label == "rest"]
    assert len(rests) == 4
    course = a.temperature
    assert course is not None
    previous = PLATEAUS[0]
    for seg, target in zip(rests[1:], PLATEAUS[1:], strict=True):
        t_end = s.t_s[seg.stop - 100:seg.stop]
        measured = float(np.mean(s.temp_degc[seg.stop - 100:seg.stop]))
        assert abs(measured - float(np.mean(course(t_end)))) < 0.05  # the channel reads the course
        lagged = float(course.chamber_lagged(t_end[-1:])[0])
        # a 300 s soak is two lags of 150 s: at most exp(-2) (+ what the previous soak left) of the step remains
        assert abs(lagged - target) < 0.2 * abs(target - previous) + 1.0
        previous = target


@pytest.fixture(scope="module")
def plateau_fit() -> tuple:
    res = simulate_session(21, plan=PLAN, effects=EFFECTS, temperature_plateaus_degc=PLATEAUS, soak_s=300.0)
    return res, fit_session(res.session, AUTO)


def test_fit_recovers_temperature_coefficients(plateau_fit: tuple) -> None:
    res, p = plateau_fit
    assert p.thermal.status == "fitted" and p.thermal.span_k > 30.0
    assert p.reference_temperature_degc == pytest.approx(25.0, abs=0.2)
    et = res.effect_truth
    for tri, bias, scale in ((p.accel, et.accel_temp_bias, et.accel_temp_scale),
                             (p.gyro, et.gyro_temp_bias, et.gyro_temp_scale)):
        for est, std, true in ((tri.temp_bias_coeff, tri.temp_bias_coeff_std, bias),
                               (tri.temp_scale_coeff, tri.temp_scale_coeff_std, scale)):
            assert np.all(std[:, 0] > 0)
            assert np.all(np.abs(est[:, 0] - true) < 4.0 * std[:, 0] + 1e-12), (est[:, 0], true, std[:, 0])
            assert np.all(std[:, 0] < 0.05 * np.abs(true))  # resolved to better than 5 % of the coefficient
    assert p.quality.passed
    # the orders are stated; a linear truth rarely needs more
    assert sum(sum(o) for t in p.thermal.orders.values() for o in t.values()) <= 14


def test_plateau_correction_matches_unit_without_temperature_effects(plateau_fit: tuple) -> None:
    res, p = plateau_fit
    out = correct_session(res.session, p)
    off = fit_session(res.session, FitOptions(thermal="off"))
    out_off = correct_session(res.session, off)
    err, err_off = _worst_errors(res.session, out), _worst_errors(res.session, out_off)
    assert err[0] < 0.01 and err[1] < 0.02  # m/s^2 per pose; deg/s per rate step
    assert err_off[0] > 5 * err[0] and err_off[1] > 5 * err[1]


def _worst_errors(raw: object, corrected: object) -> tuple[float, float]:
    """Largest |mean corrected - reference| of pose segments (m/s^2) and rate segments (deg/s), last half of each."""
    s = corrected
    worst = [0.0, 0.0]
    for seg in s.segments():  # type: ignore[attr-defined]
        if seg.kind.label not in ("pose", "rate"):
            continue
        a = seg.start + (seg.stop - seg.start) // 2
        if seg.kind.label == "pose":
            e = np.abs(s.accel_mps2[a:seg.stop].mean(0) - s.ref_accel_mps2[a:seg.stop].mean(0)).max()  # type: ignore
            worst[0] = max(worst[0], float(e))
        else:
            e = np.abs(s.gyro_radps[a:seg.stop].mean(0) - s.ref_gyro_radps[a:seg.stop].mean(0)).max()  # type: ignore
            worst[1] = max(worst[1], float(np.degrees(e)))
    return worst[0], worst[1]


def test_no_thermal_fit_without_a_temperature_course() -> None:
    res = simulate_session(3, plan=PLAN, effects=EFFECTS)  # self-heating only: warm-up shaped
    p = fit_session(res.session, AUTO)
    assert p.thermal.status == "not_separable" and "warm-up" in p.thermal.reason
    assert not p.compensates_temperature and not np.any(p.gyro.temp_bias_coeff)
    base = fit_session(res.session)  # the library default: off
    assert base.thermal.status == "disabled"
    np.testing.assert_array_equal(base.gyro.misalignment, p.gyro.misalignment)  # the same fit as before
    with pytest.raises(FitError, match="temperature terms required"):
        fit_session(res.session, FitOptions(thermal="require"))


def test_compensation_mapping_names_parameter_fields() -> None:
    assert COMPENSATION["temperature_bias"] == ("accel.temp_bias_coeff", "gyro.temp_bias_coeff")
    p = _thermal_params()
    assert compensated_by(p, "temperature_bias") and compensated_by(p, "temperature_scale")
    assert compensated_by(p, "scale_nonlinearity") and not compensated_by(p, "g_sensitivity")
    assert not compensated_by(p, "lever_arm") and not compensated_by(p, "no_such_effect")


def test_sensor_streams_layout2_corrected_output_at_its_temperature(unit: tuple) -> None:
    """The sensor core hands the firmware each chunk's temperature column (CORRECTED output of a layout-2 unit)."""
    _sensor, client, fw = unit
    p = _thermal_params(seed=8)
    write_image(client, _image(p, "ST-01"))
    client.power_cycle()
    assert fw.loaded and fw.image is not None and fw.image.layout_version == 2
    client.set_output("corrected")
    client.start_stream()
    block = client.read_samples(200)
    client.stop_stream()
    assert len(block) == 200 and block.corrected.all()
    n = len(block)
    raw_a, raw_w = np.tile([0.0, 0.0, 9.81], (n, 1)), np.zeros((n, 3))
    k0 = round(float(block.t_s[0]) / p.sample_period_s)
    exp_a, exp_w = correct_batch(raw_a, raw_w, p, k0, temp_degc=np.full(n, 30.0))
    # float32 on the wire; the moving average restarts at the first corrected chunk, so compare its full windows
    np.testing.assert_allclose(block.accel_mps2[40:], exp_a[40:], atol=2e-5)
    np.testing.assert_allclose(block.gyro_radps[40:], exp_w[40:], atol=2e-6)
    plain = ParameterSet.from_json(p.to_json().replace('"reference_temperature_degc": 25.0',
                                                       '"reference_temperature_degc": null'))
    with pytest.raises(Exception, match="reference temperature"):
        correct_batch(raw_a, raw_w, plain)


def test_thermal_limits_in_the_limits_file(plateau_fit: tuple) -> None:
    from station.kernel.limits_file import load_limits, parse_limits
    from station.sequence.limits import check_limits

    lim = load_limits()
    t = lim.product.thermal
    assert t is not None and t.gyro_temp_bias_radps_per_k[1] == pytest.approx(np.radians(0.075))
    assert t.accel_temp_scale_per_k == pytest.approx((-450e-6, 450e-6))
    text = lim.path.read_text()  # type: ignore[union-attr]
    without = text[:text.index("[thermal]")] + text[text.index("# Post-calibration verification"):]
    assert parse_limits(without).product.thermal is None  # a /2 file without the table: nothing checked
    with pytest.raises(Exception, match="unknown key"):
        parse_limits(text.replace("[thermal]\n", "[thermal]\nsurprise = 1\n"))
    _, p = plateau_fit
    checks = {m.name: m for m in check_limits(p, lim.product)}
    assert checks["gyro.temp_bias_coeff.x"].passed and checks["fit.accel.temp_scale_coeff_std.z"].passed
    assert len([n for n in checks if "temp_" in n]) == 24  # 2 triads x 2 terms x 3 axes, value and std
    res = simulate_session(3, plan=PLAN)
    plain = fit_session(res.session, AUTO)
    assert not [m for m in check_limits(plain, lim.product) if "temp_" in m.name]  # not fitted: not checked


def test_station_correct_removes_g_sensitivity_like_the_firmware() -> None:
    res = simulate_session(9, plan=PLAN, effects=Effects(g_sensitivity=0.05))  # 0.025-0.05 deg/s per g
    p = fit_session(res.session, FitOptions(g_sensitivity=True))
    assert np.any(p.gyro.g_sensitivity != 0)
    out = correct_session(res.session, p)
    a, w = correct_batch(res.session.accel_mps2, res.session.gyro_radps, p)
    np.testing.assert_allclose(out.gyro_radps, w - a @ np.linalg.solve(p.gyro.misalignment, p.gyro.g_sensitivity).T,
                               rtol=0, atol=1e-15)
    poses = res.session.segments_of(Kind.POSE)  # true rate 0 (no Earth rate simulated), +-g along each axis

    def worst(x: np.ndarray) -> float:
        return max(float(np.abs(x[s.start + (s.stop - s.start) // 2:s.stop].mean(0)).max()) for s in poses)

    assert worst(out.gyro_radps) < 0.5 * worst(w)


def test_order_chosen_by_the_data(plateau_fit: tuple) -> None:
    """A quadratic temperature bias added to one gyro axis (and a cubic to one accel axis) is found at its order."""
    res, _ = plateau_fit
    s = res.session
    dt = s.temp_degc - 25.0
    c2 = np.radians(4e-4)  # deg/s/K^2: 0.16 deg/s at 20 K
    c3 = 2e-6  # m/s^2/K^3: 0.016 m/s^2 at 20 K
    gyro = s.gyro_radps.copy()
    gyro[:, 1] += c2 * dt**2
    accel = s.accel_mps2.copy()
    accel[:, 2] += c3 * dt**3
    p = fit_session(s.replace(gyro_radps=gyro, accel_mps2=accel), AUTO)
    assert p.thermal.orders["gyro"]["bias"][1] == 2 and p.thermal.orders["accel"]["bias"][2] == 3
    assert abs(p.gyro.temp_bias_coeff[1, 1] - c2) < 4 * p.gyro.temp_bias_coeff_std[1, 1]
    assert abs(p.accel.temp_bias_coeff[2, 2] - c3) < 4 * p.accel.temp_bias_coeff_std[2, 2]
    assert "Wald" in p.thermal.rule


def test_temperature_levels_and_order_caps() -> None:
    """The polynomial order is capped by the temperature levels the data hold (two plateaus: order 1)."""
    from station.fit.temperature_terms import temperature_levels

    two_plateaus = np.concatenate([10.0 + np.linspace(0, 2.5, 50), 40.0 + np.linspace(0, 4.0, 50)])
    assert temperature_levels(two_plateaus) == 2
    assert temperature_levels(np.linspace(5.0, 45.0, 200)) == 9  # a ramp: 1 + 40 // 5
    assert temperature_levels(np.array([5.0, 15.0, 25.0, 45.0])) == 4
    assert temperature_levels(np.array([np.nan])) == 0
