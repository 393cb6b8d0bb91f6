"""Injected faults during the sequence: the outcome is ERROR (never PASS), the rig ends at rest, no EEPROM write.

Each test starts a fresh simulated station with two sensors: faults of the wire (a rig that does
not answer or answers with exceptions, a dropped connection, bit errors, dropped frames, the
watchdog of an unsupervised link) on the real peers (Modbus/TCP rig on 127.0.0.1, sensors on
ptys: the ``sim`` fixture); faults of the devices themselves, operator aborts, limits and
verification on the in-process fakes (``fake``: the same simulated rig and firmware, no port, no
pty). It injects one fault when a chosen step starts (through a record subscriber,
the way an operator display would see the run), and runs a short sequence on a fast
clock. A provisioner that writes the EEPROM of every PASS unit is installed, so "no
write" is a real check: a faulted unit, or every unit when the rig faulted, must keep
its EEPROM untouched. Rig faults end every unit with ERROR; a sensor fault ends its own
unit with ERROR, the other unit is measured to the end.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from station.kernel.limits import table1_limits
from station.kernel.measurement import Measurement
from station.kernel.plan import RigPlan
from station.rig import open_rig
from station.rig.registers import FaultCode, Status
from station.sensor import Sensor, open_sensor
from station.sequence import (
    Measured,
    Outcome,
    Record,
    RunFinished,
    RunResult,
    SequenceOptions,
    SequenceRunner,
    StepFinished,
    StepStarted,
    UnitResult,
)
from station.sim.eeprom import ERASED
from station.sim.fakes import FakeStation
from station.sim.station_sim import SimStation, SimulatedStation

SCALE = 100.0  # the wire peers'
FAKE_SCALE = 400.0  # the fakes have no link to keep up with
PLAN = RigPlan(
    sample_rate_hz=50.0,
    rest_s=20.0,
    pose_hold_s=2.0,
    rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)),
    rate_hold_s=2.0,
)
OPTIONS = SequenceOptions(move_timeout_s=30.0, spin_timeout_s=30.0, rest_timeout_s=60.0)  # .for_scale(station's)
RIG_QUERY = "&timeout=0.2&retries=1"  # fail fast when the rig does not answer (wall seconds)
SENSOR_OPTIONS = {"command_timeout_s": 0.2, "attempts": 2}


class EepromWriter:
    """Writes one page into the EEPROM of every PASS unit."""

    def __init__(self) -> None:
        self.calls: list[int] = []

    verifies = False

    def intend(self, unit: UnitResult, sensor: Sensor, run_started_at: object = None) -> UnitResult:
        return unit

    def write(self, unit: UnitResult, sensor: Sensor) -> UnitResult:
        self.calls.append(unit.slot)
        sensor.eeprom_write_page(0, b"CAL:" + unit.serial.encode())
        return unit

    def verify(self, written: UnitResult, sensor: Sensor) -> None:
        return None

    def complete(self, written: UnitResult, result: object, fault: str = "") -> None:
        return None


def at_step(name: str, action: Callable[[], None]) -> Callable[[Record], None]:
    """A subscriber that runs ``action`` once, when step ``name`` starts."""
    fired = []

    def subscriber(record: Record) -> None:
        if isinstance(record, StepStarted) and record.name == name and not fired:
            fired.append(True)
            action()

    return subscriber


@pytest.fixture
def sim() -> Iterator[SimStation]:
    with SimStation(2, SCALE, seed=3, plan=PLAN) as station:
        yield station


@pytest.fixture
def fake() -> Iterator[FakeStation]:
    with FakeStation(2, FAKE_SCALE, seed=3, plan=PLAN) as station:
        yield station


def rig_url(sim: SimulatedStation) -> str:
    return sim.rig_url + RIG_QUERY if isinstance(sim, SimStation) else sim.rig_url


def run(
    sim: SimulatedStation,
    *subscribers: Callable[[Record], None],
    out_dir: Path | None = None,
    limits: object = None,
    plan: RigPlan = PLAN,
) -> tuple[RunResult, EepromWriter]:
    writer = EepromWriter()
    rig = open_rig(rig_url(sim), sim.clock, **sim.rig_client_options())
    sensors = [open_sensor(url, sim.clock, **SENSOR_OPTIONS) for url in sim.sensor_urls]  # type: ignore[arg-type]
    try:
        runner = SequenceRunner(
            rig, sensors, sim.clock, plan=plan, options=OPTIONS.for_scale(sim.scale), provisioner=writer,
            out_dir=out_dir, subscribers=list(subscribers), limits=limits or table1_limits(),  # type: ignore[arg-type]
        )
        result = runner.run()
    finally:
        for s in sensors:
            s.close()
        rig.close()
    return result, writer


def rig_comes_to_rest(sim: SimulatedStation, wall_timeout_s: float = 10.0) -> bool:
    """The simulated rig reports rest (all axes still) within the wall timeout (its watchdog may do it)."""
    assert sim.rig is not None
    deadline = time.monotonic() + wall_timeout_s
    while time.monotonic() < deadline:
        _, _, _, rate, status = sim.rig.readback()
        if status & Status.AT_REST and rate == 0.0:
            return True
        time.sleep(0.05)
    return False


def assert_no_eeprom_write(sim: SimulatedStation, slots: tuple[int, ...] = (0, 1)) -> None:
    for k in slots:
        eeprom = sim.units[k].sensor.eeprom
        assert eeprom.page_writes == 0, f"slot {k}: {eeprom.page_writes} EEPROM page writes"
        assert eeprom.image() == bytes([ERASED]) * eeprom.size


def assert_rig_fault_outcome(result: RunResult, writer: EepromWriter, *words: str) -> None:
    print(f"run {result.outcome.value}: {result.message}")
    assert result.outcome == Outcome.ERROR
    assert [u.outcome for u in result.units] == [Outcome.ERROR, Outcome.ERROR]
    assert writer.calls == []
    finished = result.records[-1]
    assert isinstance(finished, RunFinished) and finished.outcome == Outcome.ERROR
    for word in words:
        assert word in result.message, result.message


# --- rig faults ------------------------------------------------------------------------------------


@pytest.mark.integration
def test_rig_no_answer_while_spinning(sim: SimStation) -> None:
    assert sim.rig is not None
    faults = sim.rig.faults
    result, writer = run(sim, at_step("rate y +100", lambda: setattr(faults, "no_answer", True)))
    assert_rig_fault_outcome(result, writer, "no answer")
    assert not result.rig_at_rest  # the station could not confirm it ...
    assert rig_comes_to_rest(sim)  # ... the rig's watchdog stopped the spinning table
    assert sim.rig.model.fault_code == FaultCode.WATCHDOG
    assert_no_eeprom_write(sim)


@pytest.mark.integration
def test_rig_exception_replies(sim: SimStation) -> None:
    assert sim.rig is not None
    faults = sim.rig.faults
    result, writer = run(sim, at_step("rate y +100", lambda: setattr(faults, "exception_replies", 4)))
    assert_rig_fault_outcome(result, writer, "Modbus exception 4")
    assert rig_comes_to_rest(sim)
    assert_no_eeprom_write(sim)


def test_rig_stuck_in_position(fake: FakeStation) -> None:
    assert fake.rig is not None
    faults = fake.rig.faults
    result, writer = run(fake, at_step("pose -z", lambda: setattr(faults, "stuck_in_position", True)))
    assert_rig_fault_outcome(result, writer, "not in position")
    assert result.rig_at_rest and rig_comes_to_rest(fake, 0.5)
    assert_no_eeprom_write(fake)


def test_rig_fault_bit_during_rate_step(fake: FakeStation) -> None:
    assert fake.rig is not None
    faults = fake.rig.faults
    result, writer = run(fake, at_step("rate y +100", lambda: setattr(faults, "fault_code", int(FaultCode.DRIVE_YAW))))
    assert_rig_fault_outcome(result, writer, "DRIVE_YAW", "5")
    assert result.rig_at_rest and rig_comes_to_rest(fake, 0.5)
    assert_no_eeprom_write(fake)


@pytest.mark.integration
def test_rig_connection_dropped_mid_motion(sim: SimStation) -> None:
    assert sim.rig is not None
    faults = sim.rig.faults
    result, writer = run(sim, at_step("pose -z", lambda: setattr(faults, "drop_connection_mid_motion", True)))
    assert sim.rig.connections_dropped >= 1
    assert_rig_fault_outcome(result, writer, "rig link dropped")
    assert result.rig_at_rest and rig_comes_to_rest(sim, 0.5)
    assert_no_eeprom_write(sim)


# --- sensor faults (slot 1); slot 0 is measured to the end ------------------------------------------------


def assert_sensor_fault_outcome(result: RunResult, *words: str) -> None:
    print(f"slot 1 {result.units[1].outcome.value}: {result.units[1].message}; slot 0 {result.units[0].outcome.value}")
    assert result.outcome == Outcome.ERROR
    bad, good = result.units[1], result.units[0]
    assert bad.outcome == Outcome.ERROR
    assert any(w in bad.message for w in words), bad.message
    assert good.outcome in (Outcome.PASS, Outcome.FAIL) and good.params is not None, good.message
    assert result.rig_at_rest and result.message == ""


def when_streaming(sim: SimulatedStation, slot: int, action: Callable[[], None], delay_wall_s: float = 0.0) -> None:
    """Run ``action`` from a thread once slot's sensor has sent its first sample frame (plus a delay)."""
    peer = sim.units[slot].sensor

    def wait_then_act() -> None:
        while peer.stats().sample_frames == 0:
            time.sleep(0.001)
        time.sleep(delay_wall_s)
        action()

    threading.Thread(target=wait_then_act, daemon=True).start()


@pytest.mark.integration
def test_sensor_bit_errors_crc_storm(sim: SimStation) -> None:
    peer = sim.units[1].sensor

    def once_streaming() -> None:  # bit errors from the first sample frame of the rest on
        when_streaming(sim, 1, lambda: setattr(peer, "bit_error_rate", 2e-3))

    result, _ = run(sim, at_step("rest", once_streaming))
    assert_sensor_fault_outcome(result, "CRC storm", "dropped_fraction")
    assert "CrcStormError" in result.units[1].message
    assert rig_comes_to_rest(sim, 0.5)
    assert_no_eeprom_write(sim, (1,))


@pytest.mark.integration
def test_sensor_dropped_frames(sim: SimStation) -> None:
    peer = sim.units[1].sensor
    result, _ = run(sim, at_step("pose -z", lambda: setattr(peer, "drop_frame_rate", 0.05)))
    assert_sensor_fault_outcome(result, "dropped_fraction")
    # detected in the step the drops started in or a later one (a loaded machine may deliver
    # most of a short step's frames before the drops take effect), never before
    names = [r.name for r in result.records if isinstance(r, StepStarted)]
    detected = next(n for n in names if f"step '{n}'" in result.units[1].message)
    assert names.index(detected) >= names.index("pose -z"), result.units[1].message
    assert rig_comes_to_rest(sim, 0.5)
    assert_no_eeprom_write(sim, (1,))


def test_sensor_going_silent() -> None:
    with FakeStation(2, SCALE, seed=3, plan=PLAN) as fake:  # the wire's scale: the rest lasts 0.2 s wall
        peer = fake.units[1].sensor

        def mid_rest() -> None:  # ~5 s of rig time into the 20 s rest: silence while capturing
            when_streaming(fake, 1, lambda: setattr(peer, "go_silent", True), delay_wall_s=0.05)

        result, _ = run(fake, at_step("rest", mid_rest))
        # "went silent": no samples while capturing; "did not answer": the clock sync got no reply
        assert_sensor_fault_outcome(result, "went silent", "did not answer")
        assert "SensorTimeout" in result.units[1].message and "step 'rest'" in result.units[1].message
        assert rig_comes_to_rest(fake, 0.5)
        assert_no_eeprom_write(fake, (1,))


# --- operator abort and out-of-limits units ----------------------------------------------------------------


def test_ctrl_c_aborts_brings_rig_to_rest_and_writes_nothing(fake: FakeStation, tmp_path: Path) -> None:
    def ctrl_c() -> None:
        raise KeyboardInterrupt

    result, writer = run(fake, at_step("rate x +100", ctrl_c), out_dir=tmp_path)
    assert result.outcome == Outcome.ABORTED
    assert [u.outcome for u in result.units] == [Outcome.ABORTED, Outcome.ABORTED]
    assert result.rig_at_rest and rig_comes_to_rest(fake, 0.5)
    assert writer.calls == []
    assert_no_eeprom_write(fake)
    # what was captured before the abort is kept for diagnosis
    assert all(u.session_path is not None and u.session_path.exists() for u in result.units)
    assert all(u.params is None for u in result.units)


def test_unit_out_of_limits_is_fail_and_writes_nothing(fake: FakeStation) -> None:
    lim = table1_limits()
    tight = replace(lim, name="too-tight", gyro=replace(lim.gyro, noise_std=(0.0, 1e-9)))
    result, writer = run(fake, limits=tight)
    assert result.outcome == Outcome.FAIL
    for unit in result.units:
        assert unit.outcome == Outcome.FAIL and "gyro.noise_std" in unit.message
    assert writer.calls == [] and result.rig_at_rest
    assert_no_eeprom_write(fake)


@pytest.mark.integration
def test_next_run_clears_the_watchdog_fault_the_last_one_left(sim: SimStation) -> None:
    """Closing the station stops the heartbeat, so the rig latches WATCHDOG; the next run resets it."""
    assert sim.rig is not None
    short = RigPlan(sample_rate_hz=50.0, rest_s=2.0, poses=("+z",), pose_hold_s=1.0, rate_steps=())
    first, _ = run(sim, plan=short)
    deadline = time.monotonic() + 5.0
    while sim.rig.model.fault_code != FaultCode.WATCHDOG and time.monotonic() < deadline:
        sim.rig.readback()  # the model applies the watchdog when it is looked at
        time.sleep(0.05)
    assert sim.rig.model.fault_code == FaultCode.WATCHDOG
    second, _ = run(sim, plan=short)
    for result in (first, second):
        assert [s.ok for s in result.records if isinstance(s, StepFinished)] == [True, True]
        assert result.rig_at_rest and result.message == ""


def run_with_verification(sim: SimulatedStation, limits: object = None) -> tuple[RunResult, list[Record]]:
    """A run whose PASS units are written to EEPROM by the real provisioner and verified on the rig,
    with the simulated sensors running the calibration firmware (Algorithm 1 from their EEPROM)."""
    from station.sequence.provision import EepromProvisioner
    from station.sequence.verify import RigVerifier
    from station.sim.firmware import install_firmware

    for u in sim.units:
        install_firmware(u.sensor, sim.clock)
    records: list[Record] = []
    rig = open_rig(rig_url(sim), sim.clock, **sim.rig_client_options())
    sensors = [open_sensor(url, sim.clock, **SENSOR_OPTIONS) for url in sim.sensor_urls]  # type: ignore[arg-type]
    try:
        verifier = RigVerifier(rig, sim.clock, limits, gravity_mps2=PLAN.gravity_mps2,  # type: ignore[arg-type]
                               sample_rate_hz=int(PLAN.sample_rate_hz), options=OPTIONS.for_scale(sim.scale))
        runner = SequenceRunner(
            rig, sensors, sim.clock, plan=PLAN, options=OPTIONS.for_scale(sim.scale), limits=table1_limits(),
            provisioner=EepromProvisioner("test", verifier=verifier), subscribers=[records.append],
        )
        result = runner.run()
    finally:
        for s in sensors:
            s.close()
        rig.close()
    return result, records


def verify_measurements(records: list[Record]) -> list[tuple[int, Measurement]]:
    """(slot, measurement) of every 'verify' measurement."""
    return [(r.slot, r.measurement) for r in records if isinstance(r, Measured) and r.step == "verify"]


def test_failed_verification_is_fail_with_the_residuals_recorded(fake: FakeStation) -> None:
    """The EEPROM is written and the firmware corrects, but the corrected output misses a limit: FAIL, not ERROR."""
    from station.kernel.limits_file import VerificationLimits

    result, records = run_with_verification(fake, VerificationLimits(accel_mps2=1e-9))  # no residual is that small
    assert [u.outcome for u in result.units] == [Outcome.FAIL, Outcome.FAIL]
    assert result.outcome == Outcome.FAIL and result.rig_at_rest
    verify = verify_measurements(records)
    assert {slot for slot, _ in verify} == {0, 1}
    assert any(not m.passed and "accel" in m.name for _, m in verify)
    assert all(u.sensor.eeprom.page_writes > 0 for u in fake.units)  # written, then verified


def test_passed_verification_records_its_residuals(fake: FakeStation) -> None:
    """A unit that passes verification gets its residuals recorded as 'verify' measurements, all passed."""
    result, records = run_with_verification(fake)
    assert [u.outcome for u in result.units] == [Outcome.PASS, Outcome.PASS]
    verify = verify_measurements(records)
    assert {slot for slot, _ in verify} == {0, 1} and all(m.passed for _, m in verify)
    assert {m.name for _, m in verify} >= {"verify.rate.rate_error"}
