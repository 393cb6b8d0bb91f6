"""The soak rack role: power units through the relay board and log their rest from power-on.

:meth:`SoakRack.soak` switches every requested slot on (one coil each, confirmed from the readback;
the unit boots), streams each unit from just after its power-on for ``rack_s`` of sensor time (one
thread per unit, the same serial clients as the rig's), checks that nothing lost power while it
logged (the unit's ``boot_count`` before and after, the board's own power-on counter), and stores each
rest in the line's database (:mod:`station.line.recordings`) for the rig role to find by serial. The
units stay powered: the rig role must receive them without a power interruption
(:func:`station.fit.joint.check_power`), or the unit goes back to the rack or gets the full rig plan.

A station fault on one slot (a silent sensor, a reboot during the soak) ends that slot only, with its
reason; a relay-board fault ends the soak (every slot), as a rig fault ends a run.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from station.kernel.clock import Clock
from station.kernel.errors import HardwareError
from station.kernel.virtual_clock import ActorPool, wait_futures
from station.rack.board import RelayBoard
from station.sensor.protocol import Sensor
from station.session.model import Kind, Session


@dataclass(frozen=True, eq=False)
class SoakedUnit:
    """One slot's soak.

    Attributes:
        slot: rack slot (relay) index.
        serial: the unit's serial ('' when it never answered).
        session: its rest from power-on, references NaN; None after a fault.
        error: why the slot has no recording ('' when it has one).
        note: what could not be done after the rest was logged ('' when nothing): the stream's stop or the
            status after the soak failed. The recording is kept; a reboot during the soak it could not rule
            out is caught later, by the sample counter's time base (a jump back) and the rig role's
            power-on check.
    """

    slot: int
    serial: str
    session: Session | None
    error: str = ""
    note: str = ""


def _number(x: float) -> str:
    return repr(float(x))


class SoakRack:
    """Soak-rack units through ``board`` (relay k powers ``sensors[k]``), on the station ``clock``.

    Args:
        board: the relay board.
        sensors: per slot the unit's sensor client (None: no unit in that slot).
        clock: station clock (s); the rack's ``wall_clock_at_start_s`` and the rig's must be on one clock.
        sample_rate_hz: the rate the units log at (Hz).
        gravity_mps2: local gravity (m/s^2), written into the recordings.
        station: this rack's name in the recordings.
        boot_wait_s: how long a unit may take to answer after its slot is switched on (station s).
    """

    def __init__(self, board: RelayBoard, sensors: Sequence[Sensor | None], clock: Clock, *,
                 sample_rate_hz: int = 100, gravity_mps2: float = 9.80665, station: str = "rack",
                 boot_wait_s: float = 2.0) -> None:
        self.board = board
        self.sensors = list(sensors)
        self.clock = clock
        self.sample_rate_hz = int(sample_rate_hz)
        self.gravity_mps2 = float(gravity_mps2)
        self.station = station
        self.boot_wait_s = float(boot_wait_s)

    def soak(self, slots: Sequence[int], rack_s: float,
             on_unit: Callable[[SoakedUnit], None] | None = None) -> list[SoakedUnit]:
        """Power ``slots`` on, log ``rack_s`` of rest each, return (and hand to ``on_unit``) every slot's result."""
        if not rack_s > 0:
            raise ValueError(f"rack_s must be > 0, got {rack_s!r}")
        board0 = self.board.state().power_on_count
        for slot in slots:
            if not 0 <= slot < len(self.sensors) or self.sensors[slot] is None:
                raise ValueError(f"slot {slot}: no unit")
            self.board.power(slot, True)
        self.clock.sleep(self.boot_wait_s)
        results: list[SoakedUnit] = []
        lock = threading.Lock()

        def one(slot: int) -> None:
            result = self._log(slot, rack_s)
            with lock:
                results.append(result)

        # on a virtual clock each slot's logger is an actor and this thread waits for them through the clock
        # (a plain ``fut.result()`` would hold time while they wait on it: ClockStalled)
        pool = ActorPool(self.clock, max_workers=max(1, len(slots)), thread_name_prefix="rack")
        try:
            futures = [pool.submit(one, s) for s in slots]
            wait_futures(self.clock, futures)
        except BaseException:
            # interrupted (Ctrl-C, SIGTERM): the loggers may be waiting on the clock, and joining them here would
            # hold time for good; they end on their own once this thread stops holding it (or their link closes)
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()
        for fut in futures:
            fut.result()
        board1 = self.board.state().power_on_count
        if board1 != board0:
            why = f"the relay board lost power during the soak (its power-on counter {board0} -> {board1})"
            results = [SoakedUnit(r.slot, r.serial, None, why) for r in results]
        results.sort(key=lambda r: r.slot)
        for r in results:
            if on_unit is not None:
                on_unit(r)
        return results

    def _log(self, slot: int, rack_s: float) -> SoakedUnit:
        sensor = self.sensors[slot]
        assert sensor is not None
        serial = ""
        try:
            serial = sensor.identify().serial
            t_a = self.clock.now()
            before = sensor.status()
            t_b = self.clock.now()
            power_on_clock = 0.5 * (t_a + t_b) - before.uptime_s  # station clock at the unit's power-on
            sensor.start_stream(self.sample_rate_hz)
            block = sensor.read_samples(duration_s=rack_s, timeout_s=rack_s + 30.0)
        except HardwareError as exc:
            return SoakedUnit(slot, serial, None, f"station fault: {exc}")
        # the rest is logged: a fault from here on is noted, and the recording is not thrown away with it
        note = ""
        after = None
        try:
            sensor.stop_stream()
            after = sensor.status()
        except HardwareError as exc:
            note = (f"after the soak: {exc} (recording kept; its boot count after the soak not read, a reboot is "
                    "caught by the time base and the rig's power-on check)")
        if after is not None and after.boot_count != before.boot_count:
            return SoakedUnit(slot, serial, None, f"the unit rebooted during the soak (boot count "
                                                  f"{before.boot_count} -> {after.boot_count})")
        if len(block) < 2:
            return SoakedUnit(slot, serial, None, "no samples")
        n = len(block)
        nan = np.full((n, 3), math.nan)
        session = Session(
            metadata={
                "serial": serial,
                "sample_rate_hz": str(self.sample_rate_hz),
                "gravity_mps2": _number(self.gravity_mps2),
                "station": self.station,
                "rack_slot": str(slot),
                "boot_count": str(before.boot_count),
                "wall_clock_at_start_s": _number(power_on_clock + float(block.t_s[0])),
            },
            t_s=block.t_s,
            segment=np.zeros(n, dtype=np.int64),
            kind=np.full(n, int(Kind.REST)),
            accel_mps2=block.accel_mps2,
            gyro_radps=block.gyro_radps,
            temp_degc=block.temp_degc,
            ref_accel_mps2=nan,
            ref_gyro_radps=nan,
        )
        return SoakedUnit(slot, serial, session, note=note)


__all__ = ["SoakRack", "SoakedUnit"]
