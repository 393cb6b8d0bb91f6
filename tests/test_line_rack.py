"""The soak rack: relay board (Modbus, simulated peer on 127.0.0.1), logging units from power-on over
ptys, recordings in the database found by serial, and the rig role's plan choice."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from sqlalchemy import Engine, create_engine, update
from sqlalchemy.orm import Session as DbSession
from sqlalchemy.pool import StaticPool

from station.fit.calibrate import FitOptions
from station.kernel.errors import HardwareError
from station.line.recordings import DatabaseArchive, RackRecordingError, latest_rack_recording, save_rack_recording
from station.line.rigrole import FULL, LINE, choose_plan, fit_line_unit
from station.line.soak import SoakRack
from station.rack.board import RelayBoard, RelayBoardError
from station.sensor import open_sensor
from station.sensor.protocol import Sensor
from station.sim.line_sim import simulate_line
from station.sim.rack_sim import SimRack
from station.sim.relay_server import SimulatedRelayBoard
from station.store.models import Base, RackRecording


@pytest.fixture
def engine() -> Iterator[Engine]:
    eng = create_engine("sqlite://", poolclass=StaticPool)
    Base.metadata.create_all(eng)  # the rack_recordings table alone is what these tests use
    yield eng
    eng.dispose()


@pytest.fixture
def db(engine: Engine) -> Iterator[DbSession]:
    with DbSession(engine) as session:
        yield session


def test_relay_board_switches_confirms_and_counts_its_own_power_loss() -> None:
    switched: list[tuple[int, bool]] = []
    with SimulatedRelayBoard(16, on_switch=lambda k, on: switched.append((k, on))) as sim, \
            RelayBoard(sim.url) as board:
        assert board.channels == 16
        board.power(5, True)
        assert board.relays()[5] and sum(board.relays()) == 1
        board.power_all(True)
        assert all(board.relays())
        board.power(5, False)
        assert not board.relays()[5]
        assert switched[0] == (5, True) and switched[-1] == (5, False)
        with pytest.raises(RelayBoardError, match="slot 16 does not exist"):
            board.power(16, True)
        before = board.state().power_on_count
        sim.model.power_loss()
        state = board.state()
        assert state.power_on_count == before + 1 and not any(state.relays)
        sim.faults.exception_replies = 4
        with pytest.raises(RelayBoardError, match="exception 4"):
            board.power(1, True)


def test_the_rack_logs_each_unit_from_power_on_and_the_rig_role_finds_it_by_serial(
    db: DbSession, engine: Engine
) -> None:
    archive = DatabaseArchive(lambda: DbSession(engine))
    with SimRack(3, scale=30.0, seed=11) as rack:  # 9000 frames per wall second in all
        board = RelayBoard(rack.board_url)
        sensors = [open_sensor(u, rack.clock) for u in rack.sensor_urls]
        try:
            soaked = SoakRack(board, sensors, rack.clock, station="rack-1").soak([0, 1, 2], 60.0)
            assert [u.error for u in soaked] == ["", "", ""], [u.error for u in soaked]
            assert [u.serial for u in soaked] == [t.serial for t in rack.truths]
            for u in soaked:
                s = u.session
                assert s is not None
                assert np.all(np.isnan(s.ref_accel_mps2)) and np.all(np.isnan(s.ref_gyro_radps))
                assert 59.9 <= s.duration_s <= 60.0 and 0.0 < s.t_s[0] < 60.0  # sensor time since its power-on
                # at rest in the slot: gravity in an unknown direction, raw (Table 1: scale to 2 %, bias to 0.17 m/s^2)
                assert np.linalg.norm(s.accel_mps2.mean(axis=0)) == pytest.approx(9.80665, abs=0.4)
                save_rack_recording(db, s, station="rack-1", slot=u.slot)
            db.commit()
            unit = soaked[1]
            stored = latest_rack_recording(db, unit.serial)
            assert stored is not None and stored.slot == 1 and stored.station == "rack-1"
            assert np.allclose(stored.session.accel_mps2, unit.session.accel_mps2, atol=1e-6)
            assert np.allclose(stored.session.t_s, unit.session.t_s, atol=1e-6)

            # still powered: the rig role gives it the line's short plan
            rack.clock.sleep(30.0)
            status = sensors[1].status()
            # (the slack of a clock at scale 30: round trips take 30x longer in its seconds, as in the demo)
            decision = choose_plan(archive, unit.serial, boot_count=status.boot_count, uptime_s=status.uptime_s,
                                   clock_now_s=rack.clock.now(), clock_slack_s=8.0)
            assert decision.plan == LINE and decision.reason == ""
            # power lost on the way: the full plan, and the record says why
            board.power(1, False)
            board.power(1, True)
            rack.clock.sleep(2.0)
            status = sensors[1].status()
            decision = choose_plan(archive, unit.serial, boot_count=status.boot_count, uptime_s=status.uptime_s,
                                   clock_now_s=rack.clock.now())
            assert decision.plan == FULL and "power-on counter changed" in decision.reason
            decision = choose_plan(archive, unit.serial, boot_count=None, uptime_s=status.uptime_s,
                                   clock_now_s=rack.clock.now(), on_interruption="back to rack")
            assert decision.plan == "back to rack" and "sensor time restarted" in decision.reason
            assert choose_plan(archive, "NOT-SOAKED", boot_count=1, uptime_s=10.0, clock_now_s=0.0).plan == FULL
        finally:
            for s in sensors:
                s.close()
            board.close()


def test_a_stored_recording_whose_bytes_changed_is_refused(db: DbSession) -> None:
    line = simulate_line(2005)
    save_rack_recording(db, line.rack, station="rack", slot=0)
    db.commit()
    row = db.query(RackRecording).one()
    data = bytearray(row.data)
    import gzip
    csv = bytearray(gzip.decompress(bytes(data)))
    csv[-10] = ord("7") if csv[-10] != ord("7") else ord("8")
    db.execute(update(RackRecording).values(data=gzip.compress(bytes(csv), mtime=0)))
    db.commit()
    with pytest.raises(RackRecordingError, match="SHA-256"):
        latest_rack_recording(db, line.rack.serial)


def test_the_joint_fit_from_the_database_matches_the_fit_from_memory(db: DbSession) -> None:
    line = simulate_line(2006)
    save_rack_recording(db, line.rack, station="rack", slot=3)
    db.commit()
    stored = latest_rack_recording(db, line.rig.serial)
    assert stored is not None
    opts = FitOptions(tc_range_s={"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)})
    a = fit_line_unit(stored.session, line.rig, opts)
    b = fit_line_unit(line.rack, line.rig, opts)
    for name in ("accel", "gyro"):
        ta, tb = getattr(a, name), getattr(b, name)
        np.testing.assert_allclose(ta.misalignment, tb.misalignment, atol=3 * np.max(tb.misalignment_std) * 1e-2)
        np.testing.assert_allclose(ta.bias_static, tb.bias_static, atol=np.max(tb.bias_static_std) * 1e-1)
        np.testing.assert_allclose(ta.correlation_time_s, tb.correlation_time_s,
                                   atol=np.nanmax(tb.correlation_time_s_std) * 1e-1)
    assert a.source["line"]["transfer_s"] == pytest.approx(60.0, abs=0.02)


class _StopFails:
    """A sensor client whose stream cannot be stopped once the rest was read (the link died at the end)."""

    def __init__(self, inner: Sensor) -> None:
        self.inner = inner

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def stop_stream(self) -> None:
        raise HardwareError("STOP_STREAM: no reply after 3 attempts")


def test_a_soak_whose_stream_cannot_be_stopped_keeps_its_recording() -> None:
    """Nothing lost: the rest is logged whole before the stop fails; the slot keeps it, with the fault noted."""
    with SimRack(2, scale=30.0, seed=12) as rack:
        board = RelayBoard(rack.board_url)
        sensors = [open_sensor(u, rack.clock) for u in rack.sensor_urls]
        try:
            flaky = [sensors[0], _StopFails(sensors[1])]
            soaked = SoakRack(board, flaky, rack.clock, station="rack-1").soak([0, 1], 30.0)  # type: ignore[arg-type]
            assert [u.error for u in soaked] == ["", ""]
            assert soaked[0].note == ""
            assert "STOP_STREAM: no reply" in soaked[1].note and "recording kept" in soaked[1].note
            for u in soaked:
                assert u.session is not None and 29.9 <= u.session.duration_s <= 30.0
            assert soaked[1].serial == rack.truths[1].serial
        finally:
            for s in sensors:
                s.close()
            board.close()
