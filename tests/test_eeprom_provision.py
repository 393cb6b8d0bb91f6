"""EEPROM provisioning through the sensor protocol, the simulated firmware, and verification on the rig.

Provisioning logic runs on the in-process fakes (:mod:`station.sim.fakes`: the same firmware and
client code without a pty or a port); the wire itself is covered by tests/test_sensor_pty.py and by
the device contract (tests/test_device_contract.py), which runs both.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from station.commands.eeprom import eeprom_app
from station.correct import correct_batch
from station.eeprom.image import (
    IMAGE_SIZE,
    CalibrationImage,
    decode_image,
    encode_image,
    read_slots,
    select_image,
)
from station.eeprom.provision import (
    EepromUnusableError,
    ReadbackMismatchError,
    SerialMismatchError,
    read_current_image,
    write_image,
)
from station.kernel.clock import ManualClock
from station.kernel.errors import HardwareError, UnitRejected
from station.kernel.parameters import ParameterSet
from station.kernel.sensor_class import TABLE1
from station.physics.unit import draw_unit
from station.rig import open_rig
from station.sensor import Sensor, open_sensor
from station.sequence.provision import EepromProvisioner
from station.sequence.records import Outcome
from station.sequence.runner import UnitResult
from station.sequence.verify import RigVerifier, VerificationLimits
from station.sim.eeprom import Eeprom
from station.sim.fakes import FakeSensorDevice, FakeStation, publish
from station.sim.firmware import CalibrationFirmware, install_firmware

GRAVITY = 9.80665
SERIAL = "UNIT-0001"
F_TRUE = np.array([0.0, 0.0, GRAVITY])  # m/s^2, +z up
W_TRUE = np.array([0.01, -0.02, 0.5])  # rad/s
T0 = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)


def _params(seed: int = 1, serial: str = SERIAL, period: float = 0.01) -> ParameterSet:
    truth = draw_unit(TABLE1, np.random.default_rng(seed), serial=serial)
    return truth.as_parameter_set(period)


class ModelSource:
    """Noiseless eq. (1) raw output of constant true (f, w): ``M x + b_stat + b_drift exp(-t/T_c)``."""

    def __init__(self, params: ParameterSet) -> None:
        self.p = params

    def power_on(self) -> None:
        pass

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t_s, dtype=float)[:, None]
        out = []
        for tri, x in ((self.p.accel, F_TRUE), (self.p.gyro, W_TRUE)):
            drift = tri.bias_drift * np.exp(-t / tri.correlation_time_s)
            out.append(np.asarray(tri.misalignment) @ x + tri.bias_static + drift)
        return out[0], out[1], np.zeros(t.shape[0])


@pytest.fixture()
def unit() -> Iterator[tuple[FakeSensorDevice, Sensor, CalibrationFirmware, ParameterSet]]:
    params = _params()
    clock = ManualClock()
    sensor = FakeSensorDevice(ModelSource(params), clock, url="fake-sensor://provision/0", serial=SERIAL,
                              eeprom=Eeprom(clock=clock))
    publish(sensor)
    fw = install_firmware(sensor, clock)
    client = open_sensor(sensor.url, clock, command_timeout_s=0.25, attempts=1)
    try:
        yield sensor, client, fw, params
    finally:
        client.close()
        sensor.close()


def _image(params: ParameterSet, station: str = "ST-01") -> CalibrationImage:
    return CalibrationImage.from_params(params, station, T0)


def test_write_read_back_and_firmware_loads(unit: tuple) -> None:
    sensor, client, fw, params = unit
    assert not fw.loaded and read_current_image(client) is None
    r1 = write_image(client, _image(params))
    assert (r1.slot, r1.update_count, r1.previous_count, r1.attempts, r1.length) == ("A", 1, 0, 1, IMAGE_SIZE)
    r2 = write_image(client, _image(params))
    assert (r2.slot, r2.update_count, r2.previous_count) == ("B", 2, 1)
    r3 = write_image(client, _image(params))
    assert (r3.slot, r3.update_count) == ("A", 3)
    raw = sensor.eeprom.image()
    assert raw[: IMAGE_SIZE] == encode_image(r3.image)
    cur = read_current_image(client)
    assert cur is not None and cur.same_as(r3.image)
    assert not fw.loaded  # the firmware reads its image at power-on only
    client.power_cycle(2.0)
    assert fw.loaded and fw.image is not None and fw.image.update_count == 3


def test_firmware_corrected_output_is_algorithm1(unit: tuple) -> None:
    _sensor, client, fw, params = unit
    client.start_stream(100)
    raw = client.read_samples(200)
    client.stop_stream()
    client.drain()  # samples sent before the STOP answer
    assert not raw.corrected.any()
    client.set_output("corrected")
    client.start_stream(100)
    before = client.read_samples(50)  # no image: corrected mode passes raw values through
    client.stop_stream()
    client.drain()
    assert before.corrected.all()
    assert np.abs(before.accel_mps2.mean(axis=0) - F_TRUE).max() > 0.01
    write_image(client, _image(params))
    client.power_cycle(2.0)
    assert fw.loaded
    client.set_output("corrected")
    client.start_stream(100)
    block = client.read_samples(400)
    client.stop_stream()
    assert block.corrected.all()
    settled = slice(params.moving_average_length, None)  # the moving average has filled
    # float32 on the wire (~1e-6 relative), forward-Euler drift vs exp (<1e-6 m/s^2 here)
    np.testing.assert_allclose(block.accel_mps2[settled], np.broadcast_to(F_TRUE, (360, 3)), atol=2e-5)
    np.testing.assert_allclose(block.gyro_radps[settled], np.broadcast_to(W_TRUE, (360, 3)), atol=2e-6)
    # raw output of the same unit is off by its bias and scale
    assert np.abs(raw.gyro_radps.mean(axis=0) - W_TRUE).max() > 1e-3


class FakeClock:
    scale = 1.0

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def test_firmware_engines_agree_chunk_by_chunk() -> None:
    params = _params(seed=3)
    clock = FakeClock()
    ee = Eeprom(clock=clock)
    ee_img = encode_image(_image(params))
    for a in range(0, IMAGE_SIZE, 32):
        ee.write_page(a, ee_img[a : a + 32])
        ee.power_reset()
    rng = np.random.default_rng(0)
    n = 1000
    acc = rng.normal(0, 0.02, (n, 3)) + F_TRUE
    gyr = rng.normal(0, 2e-4, (n, 3)) + W_TRUE
    ref_a, ref_w = correct_batch(acc, gyr, params)
    for engine in ("streaming", "batch"):
        fw = CalibrationFirmware(ee, clock, serial=SERIAL, engine=engine)  # type: ignore[arg-type]
        assert fw.loaded
        outs_a, outs_w = [], []
        pos = 0
        for size in [1, 7, 50, 3, 200, 39, 40, 41, 619]:
            clock.t = (pos + size - 1) * params.sample_period_s  # the newest sample of the chunk is due now
            a, w = fw(acc[pos : pos + size], gyr[pos : pos + size])
            outs_a.append(a)
            outs_w.append(w)
            pos += size
        assert pos == n
        np.testing.assert_allclose(np.concatenate(outs_a), ref_a, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.concatenate(outs_w), ref_w, rtol=0, atol=1e-12)
        clock.t = 0.0


def test_firmware_ignores_image_of_another_serial() -> None:
    clock = FakeClock()
    ee = Eeprom(clock=clock)
    data = encode_image(_image(_params(serial="OTHER")))
    for a in range(0, IMAGE_SIZE, 32):
        ee.write_page(a, data[a : a + 32])
        ee.power_reset()
    fw = CalibrationFirmware(ee, clock, serial=SERIAL)
    assert not fw.loaded and "other serial" in fw.load_error
    a = np.ones((3, 3))
    out_a, _ = fw(a, a)
    assert out_a is a


def _power_loss_round(sensor: FakeSensorDevice, client: Sensor, fw: CalibrationFirmware,
                      new: CalibrationImage) -> tuple[int, int]:
    """Arm a power loss at every page of one write; returns (cases, new image seen complete)."""
    before = read_slots(sensor.eeprom.image())
    old = select_image(before)
    assert old is not None and old.image is not None
    old_bytes = encode_image(old.image)
    new_count = old.image.update_count + 1
    new_bytes = encode_image(new.with_update_count(new_count))
    pages = -(-IMAGE_SIZE // 32)
    cases = 0
    for k in range(pages):
        sensor.eeprom.power_loss_after(n_bytes=(5 * k) % 32, pages_before=k)
        with pytest.raises(HardwareError):
            write_image(client, new)
        assert not sensor.powered
        sensor.power_on()
        slots = read_slots(sensor.eeprom.image())
        for s in slots:  # whatever decodes is exactly a real image, never a mix
            if s.image is not None:
                assert encode_image(s.image) in (old_bytes, new_bytes, *[encode_image(b.image) for b in before if
                                                                          b.image is not None])
        cur = select_image(slots)
        assert cur is not None and cur.image is not None
        assert encode_image(cur.image) == old_bytes  # the header page goes last: the new image never completes
        assert fw.loaded and fw.image is not None and fw.image.update_count == old.image.update_count
        cases += 1
    sensor.eeprom.disarm()
    report = write_image(client, new)  # power stays on: the new image becomes current
    assert report.update_count == new_count
    cur = select_image(read_slots(sensor.eeprom.image()))
    assert cur is not None and cur.image is not None and encode_image(cur.image) == new_bytes
    return cases, 1


def test_power_loss_at_every_page_keeps_old_image(unit: tuple) -> None:
    sensor, client, fw, params = unit
    write_image(client, _image(params, "OLD"))
    sensor.power_cycle()
    assert fw.loaded
    other = _params(seed=7, serial=SERIAL)
    cases1, _ = _power_loss_round(sensor, client, fw, _image(other, "NEW"))  # target: slot B, A holds #1
    cases2, _ = _power_loss_round(sensor, client, fw, _image(params, "NEWER"))  # target: slot A, B holds #2
    assert cases1 == cases2 == 16


def test_readback_mismatch_retries_then_fails(unit: tuple, monkeypatch: pytest.MonkeyPatch) -> None:
    sensor, client, _fw, params = unit
    ee = sensor.eeprom
    original = ee.read
    bad_reads = {"left": 1}

    def flaky(addr: int, n: int) -> bytes:
        data = original(addr, n)
        if addr in (256, 768) and n == IMAGE_SIZE - 256 and bad_reads["left"] > 0:  # 2nd read-back chunk of a slot
            bad_reads["left"] -= 1
            data = bytes([data[0] ^ 0x01]) + data[1:]
        return data

    monkeypatch.setattr(ee, "read", flaky)
    report = write_image(client, _image(params), max_attempts=3)
    assert report.attempts == 2 and report.update_count == 1
    bad_reads["left"] = 10**6
    writes0 = ee.page_writes
    with pytest.raises(ReadbackMismatchError, match="after 3 write attempts"):
        write_image(client, _image(params), max_attempts=3)
    assert ee.page_writes - writes0 == 3 * 16
    assert isinstance(ReadbackMismatchError("x"), HardwareError)
    monkeypatch.setattr(ee, "read", original)
    cur = select_image(read_slots(ee.image()))
    assert cur is not None and cur.image is not None and cur.image.update_count in (1, 2)


def test_other_serial_is_refused(unit: tuple) -> None:
    sensor, client, _fw, params = unit
    writes0 = sensor.eeprom.page_writes
    with pytest.raises(SerialMismatchError, match="UNIT-0002"):
        write_image(client, _image(_params(serial="UNIT-0002")))
    assert sensor.eeprom.page_writes == writes0
    sensor.eeprom.write_protect = True
    with pytest.raises(EepromUnusableError, match="write protected"):
        write_image(client, _image(params))
    sensor.eeprom.write_protect = False


def test_provisioner_writes_pass_unit_and_power_cycles(unit: tuple) -> None:
    sensor, client, fw, params = unit
    seen = []
    prov = EepromProvisioner("ST-01", now=lambda: T0, on_record=seen.append)
    result = UnitResult(0, sensor.url, SERIAL, Outcome.PASS, "", params=params)
    prov.provision(result, client)
    assert fw.loaded and fw.image is not None and fw.image.station_id == "ST-01"
    assert fw.image.calibration_time == T0
    rec = prov.records[SERIAL]
    assert seen == [rec] and rec.write.update_count == 1 and rec.verification is None
    assert decode_image(sensor.eeprom.image()[:IMAGE_SIZE]).same_as(rec.write.image)
    wrong = UnitResult(0, sensor.url, "UNIT-0009", Outcome.PASS, "", params=params)
    with pytest.raises(SerialMismatchError):
        prov.provision(wrong, client)


@pytest.mark.parametrize("good", [True, False])
def test_verification_on_the_rig(good: bool) -> None:
    with FakeStation(1, 30.0, seed=4) as sim:
        su = sim.units[0]
        install_firmware(su.sensor, sim.clock)
        params = su.truth.as_parameter_set(0.01)
        if not good:  # a wrong calibration: the gyro bias not removed
            d = params.to_dict()
            d["gyro"]["bias_static"] = [0.0, 0.0, 0.0]
            params = ParameterSet.from_dict(d)
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        client = open_sensor(sim.sensor_urls[0], sim.clock)
        try:
            verifier = RigVerifier(rig, sim.clock, VerificationLimits(hold_s=4.0), gravity_mps2=sim.plan.gravity_mps2,
                                    sample_rate_hz=100)
            prov = EepromProvisioner("ST-01", verifier=verifier, now=lambda: T0)
            unit_result = UnitResult(0, su.sensor.url, su.truth.serial, Outcome.PASS, "", params=params)
            if good:
                prov.provision(unit_result, client)
            else:
                with pytest.raises(UnitRejected, match="verification"):
                    prov.provision(unit_result, client)
            res = prov.records[su.truth.serial].verification
            assert res is not None and res.samples >= 790 and res.uncorrected_samples == 0
            values = {c.name: c.value for c in res.checks}
            print(values)
            assert res.passed is good
            if good:
                assert values["verify.pose.accel_error"] < 0.003
                assert values["verify.pose.gyro_error"] < 2e-4
                assert abs(values["verify.rate.rate_error"]) < 1e-3
            else:
                assert values["verify.pose.gyro_error"] > 1e-3
            assert not client.status().streaming and client.status().output == 0
        finally:
            client.close()
            rig.close()


def test_cli_write_and_read(unit: tuple, tmp_path: Path) -> None:
    sensor, client, fw, params = unit
    client.close()  # the command opens the port itself
    pj = tmp_path / "p.json"
    pj.write_text(params.to_json())
    runner = CliRunner()
    db_url = f"sqlite:///{tmp_path / 'station.sqlite'}"
    res = runner.invoke(eeprom_app, ["write", SERIAL, "--sensor", sensor.url, "--params", str(pj), "--station", "CLI",
                                     "--db", db_url])
    assert res.exit_code == 0, res.output
    assert "image #1 to slot A" in res.output
    from station.store.db import open_database
    from station.store.queries import show_unit

    with open_database(db_url) as db:  # the write is recorded in the unit store
        writes = show_unit(db, SERIAL).to_dict()["eeprom_writes"]
    assert len(writes) == 1 and writes[0]["attempts"] == 1 and len(writes[0]["image_sha256"]) == 64
    assert fw.loaded and fw.image is not None and fw.image.station_id == "CLI"  # power-cycled: firmware loaded it
    res = runner.invoke(eeprom_app, ["read", "--sensor", sensor.url])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["serial"] == SERIAL and out["current"] == "A" and "magic" in out["slots"]["B"]["error"]
    res = runner.invoke(eeprom_app, ["write", "UNIT-0002", "--sensor", sensor.url, "--params", str(pj), "--db", db_url])
    assert res.exit_code == 2 and "not 'UNIT-0002'" in res.output


def test_firmware_removes_g_sensitivity() -> None:
    g = np.array([[1e-4, 0, 0], [0, -2e-4, 0], [0, 3e-5, 5e-5]])  # rad/s per m/s^2
    truth = draw_unit(TABLE1, np.random.default_rng(11), serial=SERIAL)
    params = truth.as_parameter_set(0.01, g_sensitivity=g)
    clock = FakeClock()
    ee = Eeprom(clock=clock)
    data = encode_image(_image(params))
    for a in range(0, IMAGE_SIZE, 32):
        ee.write_page(a, data[a : a + 32])
        ee.power_reset()
    fw = CalibrationFirmware(ee, clock, serial=SERIAL)
    n = 100
    m_a, m_w = params.accel.misalignment, params.gyro.misalignment
    acc = np.tile(m_a @ F_TRUE + params.accel.bias_static + params.accel.bias_drift, (n, 1))
    gyr = np.tile(m_w @ W_TRUE + g @ F_TRUE + params.gyro.bias_static + params.gyro.bias_drift, (n, 1))
    clock.t = (n - 1) * 0.01
    out_a, out_w = fw(acc, gyr)
    # the drift decays by (1 - T_s/T_c)^i: a few 1e-6 over 1 s; the g-sensitivity term (~1e-3 rad/s) is gone
    np.testing.assert_allclose(out_a, np.tile(F_TRUE, (n, 1)), atol=2e-4)
    np.testing.assert_allclose(out_w, np.tile(W_TRUE, (n, 1)), atol=2e-5)


@contextlib.contextmanager
def _two_written_units(
    seed: int, params_for: Callable[[int, ParameterSet], ParameterSet] = lambda _k, p: p,
) -> Iterator[tuple[FakeStation, EepromProvisioner, list[Any], list[Any]]]:
    """Two simulated units running the firmware, each image written (``params_for`` may spoil one), ready to verify
    together: (station, provisioner, written images, sensor clients); the clients and the rig closed after."""
    with FakeStation(2, 30.0, seed=seed) as sim:
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        clients = [open_sensor(url, sim.clock) for url in sim.sensor_urls]
        try:
            verifier = RigVerifier(rig, sim.clock, VerificationLimits(hold_s=4.0), gravity_mps2=sim.plan.gravity_mps2,
                                   sample_rate_hz=100)
            prov = EepromProvisioner("ST-01", verifier=verifier, now=lambda: T0)
            written = []
            for k, su in enumerate(sim.units):
                install_firmware(su.sensor, sim.clock)
                params = params_for(k, su.truth.as_parameter_set(0.01))
                unit_result = UnitResult(k, su.sensor.url, su.truth.serial, Outcome.PASS, "", params=params)
                written.append(prov.write(prov.intend(unit_result, clients[k]), clients[k]))
            yield sim, prov, written, clients
        finally:
            for c in clients:
                c.close()
            rig.close()


def test_units_are_verified_together_in_the_same_two_holds(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two written units, one with a wrong calibration: one pose and one rate step for both, each judged alone."""
    import station.sequence.verify as verify_module

    moves: list[str] = []
    drive = verify_module.drive_rig

    def counted(rig: object, step: object, options: object) -> None:
        moves.append(step.name)  # type: ignore[attr-defined]
        drive(rig, step, options)  # type: ignore[arg-type]

    def wrong_gyro_bias(k: int, params: ParameterSet) -> ParameterSet:
        if k != 1:
            return params
        d = params.to_dict()  # a wrong calibration: the gyro bias not removed
        d["gyro"]["bias_static"] = [0.0, 0.0, 0.0]
        return ParameterSet.from_dict(d)

    monkeypatch.setattr(verify_module, "drive_rig", counted)
    with _two_written_units(4, wrong_gyro_bias) as (sim, prov, written, clients):
        results = prov.verify_many(list(zip(written, clients, strict=True)))
        assert results is not None and len(results) == 2
        good, bad = results
        assert not isinstance(good, Exception) and not isinstance(bad, Exception)
        assert moves == ["verify pose +z", "verify rate z"], moves  # the holds are shared, not one pair per unit
        assert good.passed and good.samples >= 790 and good.uncorrected_samples == 0
        assert not bad.passed and {c.name: c.value for c in bad.checks}["verify.pose.gyro_error"] > 1e-3
        assert good.serial == sim.units[0].truth.serial and bad.serial == sim.units[1].truth.serial
        for c in clients:
            assert not c.status().streaming and c.status().output == 0


def test_a_link_fault_in_shared_holds_is_that_units_alone() -> None:
    """One unit's link fails during the shared verification: it gets its fault, the other unit is still judged."""
    from station.sensor.protocol import SensorTimeout

    with _two_written_units(5) as (_, prov, written, clients):
        def broken(*_: object, **__: object) -> None:
            raise SensorTimeout("unit 1 stopped answering")

        clients[1].read_samples = broken  # type: ignore[method-assign]
        results = prov.verify_many(list(zip(written, clients, strict=True)))
        assert results is not None
        good, bad = results
        assert isinstance(bad, SensorTimeout)
        assert not isinstance(good, Exception) and good.passed and good.samples >= 790
        assert not clients[0].status().streaming and clients[0].status().output == 0
