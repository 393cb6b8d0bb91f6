"""A simulated calibration line on its real transports: a soak rack and a rig sharing one set of units.

:class:`SimLine` holds a :class:`~station.sim.station_sim.SimStation` (the Modbus rig and the units' sensors on
ptys, one clock) and a simulated relay board (:class:`~station.sim.relay_server.SimulatedRelayBoard`) whose
coils power the units. :meth:`SimLine.soak` is the rack role (:class:`~station.line.soak.SoakRack`: slots
switched on, each unit logged still in its own slot orientation from power-on, the recordings stored in an
archive); :meth:`SimLine.to_rig` carries units, still powered, onto the rig's fixture (optionally losing power
on the way); :meth:`SimLine.rig_config` is the rig role's station configuration for those units
(:class:`station.compose.StationConfig` with the line plan). ``station demo`` and ``benchmarks/bench_line.py``'s
throughput part use it.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Self

import numpy as np

from station.compose import StationConfig
from station.kernel.clock import Clock
from station.kernel.geometry import POSE_ANGLES_DEG
from station.kernel.line_plan import ANY_ORIENTATION, LinePlanFile
from station.kernel.plan import RigPlan
from station.line.recordings import RackArchive
from station.line.soak import SoakedUnit, SoakRack
from station.rack.board import RelayBoard
from station.sensor import open_sensor
from station.sim.firmware import install_firmware
from station.sim.rack_sim import StaticMount
from station.sim.relay_server import SimulatedRelayBoard
from station.sim.station_sim import SimStation


@dataclass(frozen=True)
class SoakReport:
    """One rack soak: its units' results and when it ran on the line's clock (s)."""

    units: tuple[SoakedUnit, ...]
    started_s: float
    ended_s: float


class SimLine:
    """``units`` simulated units, a rack with a slot for each, one rig (see the module docstring).

    Args:
        units: units (and rack slots).
        scale: clock scale.
        seed: the same seed gives the same units and slot orientations.
        plan: the rig plan the simulated rig is built for (its sample rate is the units' rate).
        clock: the line's one clock (default ``SimClock(scale)``). On a
            :class:`~station.kernel.virtual_clock.VirtualClock` (scale 1) the thread that enters, soaks, carries
            and runs the rig role must be its actor (``acting(clock, name=...)``): then the line repeats bit for
            bit (docs/simulation.md).
        rack_orientation: the line plan's (:class:`~station.kernel.line_plan.LinePlan`): ``"any"``, each slot
            within 20 deg per angle of +z up; a pose, every slot that way up within 2 deg per angle.
        station: further keyword arguments of :class:`~station.sim.station_sim.SimStation` (e.g. ``effects``,
            ``effect_change``: the units' physics).
    """

    def __init__(self, units: int, scale: float, seed: int, plan: RigPlan, *, clock: Clock | None = None,
                 rack_orientation: str = ANY_ORIENTATION, **station: Any) -> None:
        if clock is not None:
            scale = clock.scale
        self.n, self.scale, self.seed, self.plan = units, scale, seed, plan
        self.rack_orientation = rack_orientation
        self.sim = SimStation(units, scale, seed, plan=plan, clock=clock, **station)
        self.board_sim: SimulatedRelayBoard | None = None

    def __enter__(self) -> Self:
        self.sim.__enter__()
        try:
            rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(10_000,)))
            for u in self.sim.units:
                install_firmware(u.sensor, self.sim.clock)
                u.sensor.power_off()  # the rack's relay powers it
                if self.rack_orientation == ANY_ORIENTATION:
                    tilt = np.radians(rng.uniform(-20.0, 20.0, size=3))
                    u.source.rig = StaticMount(*tilt)  # still in its rack slot, an orientation nobody measured
                else:  # the slots hold their units that way up, within 2 deg per angle
                    roll, pitch = POSE_ANGLES_DEG[self.rack_orientation]
                    tilt = np.radians(rng.uniform(-2.0, 2.0, size=3))
                    u.source.rig = StaticMount(math.radians(roll) + tilt[0], math.radians(pitch) + tilt[1], tilt[2])

            def switch(slot: int, on: bool) -> None:
                sensor = self.sim.units[slot].sensor
                sensor.power_on() if on else sensor.power_off()

            self.board_sim = SimulatedRelayBoard(self.n, on_switch=switch).__enter__()
        except BaseException:
            self.sim.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        try:
            if self.board_sim is not None:
                self.board_sim.__exit__(et, ev, tb)
        finally:
            self.sim.__exit__(et, ev, tb)

    @property
    def clock(self) -> Clock:
        return self.sim.clock

    @property
    def board_url(self) -> str:
        assert self.board_sim is not None
        return str(self.board_sim.url)

    def serial(self, slot: int) -> str:
        return str(self.sim.units[slot].truth.serial)

    def sensor_client_options(self) -> dict[str, Any]:
        """:func:`~station.sensor.open_sensor` keyword arguments for this line's simulated sensors.

        The simulated station's (:meth:`~station.sim.station_sim.SimulatedStation.sensor_client_options`: 5 s per
        attempt), grown with the rack: these sensors answer from threads of this process, two per unit (its peer
        and the station's reader) besides the loggers, which take the interpreter in turns of
        ``sys.getswitchinterval()`` (5 ms): with 64 units one round of them alone is 0.64 s, more than the
        client's 0.5 s default per attempt, and a loaded host stretches it further. With 0.5 s the soak lost
        recordings on "did not answer IDENTIFY / GET_STATUS / STOP_STREAM" (15 and 32 of 64 in two runs on a
        starved host, the first on a scaled clock, the second on the virtual clock). The wall timeout per
        attempt is ten such rounds, at least the station's: a peer that died is still found, and on the
        virtual clock the wait costs no simulated time.
        """
        base = self.sim.sensor_client_options()
        timeout = max(float(base.get("command_timeout_s", 0.5)), 10.0 * 2 * self.n * sys.getswitchinterval())
        # pyserial's write timeout also counts the writer's wait for the interpreter after its bytes went out: a
        # command to a unit of batch 1 of 64 failed so ("Write timeout") on a host at a load average of 35
        return {**base, "command_timeout_s": timeout, "write_timeout_s": max(2.0, 3 * timeout)}

    def soak(self, slots: Sequence[int], rack_s: float, archive: RackArchive, station: str = "sim-rack") -> SoakReport:
        """The rack role: power ``slots`` on and log each unit's rest for ``rack_s``; store each recording."""
        sensors = [open_sensor(url, self.clock, **self.sensor_client_options()) for url in self.sim.sensor_urls]
        t0 = self.clock.now()
        try:
            with RelayBoard(self.board_url) as board:
                rack = SoakRack(board, list(sensors), self.clock, sample_rate_hz=int(self.plan.sample_rate_hz),
                                gravity_mps2=self.plan.gravity_mps2, station=station)
                soaked = rack.soak(list(slots), rack_s)
        finally:
            for s in sensors:
                s.close()
        for r in soaked:
            if r.session is not None:
                archive.save(r.session, station=station, slot=r.slot)
        return SoakReport(tuple(soaked), t0, self.clock.now())

    def to_rig(self, slots: Sequence[int], transfer_s: float, interrupt: Sequence[int] = ()) -> None:
        """Carry ``slots``' units to the rig, still powered, taking ``transfer_s``; those in ``interrupt`` lose
        power on the way (and come back on)."""
        for slot in interrupt:
            self.sim.units[slot].sensor.power_off()
        self.clock.sleep(transfer_s)
        for slot in interrupt:
            self.sim.units[slot].sensor.power_on()
        for slot in slots:
            self.sim.units[slot].source.rig = self.sim.rig

    def rig_config(self, slots: Sequence[int], line: LinePlanFile, *, db_url: str | None,
                   out_dir: Path | None = None, **kwargs: Any) -> StationConfig:
        """The rig role's station for ``slots``' units (the line plan's rig part, recorded at ``db_url``)."""
        urls = tuple(self.sim.sensor_urls[k] for k in slots)
        kwargs.setdefault("sensor_options", self.sensor_client_options())
        return StationConfig(self.sim.rig_url, urls, db_url=db_url, out_dir=out_dir, clock_scale=self.scale,
                             provision=True, rig_options=self.sim.rig_client_options(), line=line, **kwargs)


__all__ = ["SimLine", "SoakReport"]
