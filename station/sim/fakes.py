"""In-process fakes of the rig and the sensors, on the simulator's own physics: no Modbus, no pty, no frames.

The fakes run the same code as the simulated peers and the station's clients, minus the wire:

* :class:`FakeRig` is the station's :class:`~station.rig.mapped.RegisterRig` (the Rig protocol over
  the register map: commands, acknowledgements, readback checks, waits) whose register transport
  calls a :class:`~station.sim.rig_server.RigModel` directly instead of a Modbus server.
* :class:`FakeSensor` is the station's :class:`~station.sensor.base.ProtocolSensor` (commands and
  their replies, retries and refusals, power cycling, the sample buffer) whose transport calls the
  simulated firmware (:class:`~station.sim.sensor_core.SensorCore` in a :class:`FakeSensorDevice`)
  directly instead of a pty. Samples are rendered when asked for, for every sample time that has
  come on the clock, and pass the SAMPLE payload's float32 as on the wire.

Both are selected by URL like any device, through the scheme registries this module extends on
import: ``fake-rig://NAME`` and ``fake-sensor://NAME/SLOT``, where NAME is a :class:`FakeStation`
(or anything :func:`publish`-ed) in this process. A :class:`FakeStation` is a
:class:`~station.sim.station_sim.SimulatedStation`: the same seeded units on the same physics as
:class:`~station.sim.station_sim.SimStation`; on a :class:`~station.kernel.clock.ManualClock` a
seed gives the same samples on every run.

Fault switches: the rig model's (:class:`~station.sim.rig_server.RigFaults`: ``fault_code``,
``estop``, ``stuck_in_position``, ``local_mode``, ``nan_angle``, ``alive_stalled``, and
``drop_connection_mid_motion``, which counts as a re-established link), the sensor's ``go_silent``
and its EEPROM's (write protect, power loss mid-write). Wire faults (bit errors, dropped frames, a
rig that does not answer) exist only on the wire peers. The fake rig does not beat its heartbeat
unless opened with ``heartbeat=True``: there is no link to supervise, so the rig's watchdog stays
unarmed.
"""

from __future__ import annotations

import itertools
import threading
from typing import Any

import numpy as np

from station.kernel.clock import Clock
from station.kernel.errors import StationError
from station.kernel.urls import split_url
from station.physics.unit import UnitTruth
from station.rig import RIGS
from station.rig.mapped import RegisterRig, start_rig
from station.rig.protocol import RigProtocolError
from station.rig.rig_url import RigUrlError
from station.sensor import SENSORS
from station.sensor.base import ProtocolSensor
from station.sensor.commands import BootEvent, BootReason, Command, Reply
from station.sensor.frames import ParserStats, SequenceTracker
from station.sensor.protocol import SampleBlock
from station.sensor.serial_url import SensorUrlError
from station.sim.eeprom import Eeprom
from station.sim.physics_source import PhysicsSource
from station.sim.rig_server import RigModel, RigModelView
from station.sim.sensor_core import Answer, SampleSource, SensorCore, SensorUnit
from station.sim.sensor_peer import PeerStats
from station.sim.station_sim import SimulatedStation

RIG_SCHEME = "fake-rig"
SENSOR_SCHEME = "fake-sensor"

# --- the process-local table of fake devices -----------------------------------------------------------

_lock = threading.Lock()
_rigs: dict[str, FakeRigDevice] = {}
_sensors: dict[str, FakeSensorDevice] = {}


def _key(url: str, scheme: str, error: type[StationError]) -> str:
    parts = split_url(url, scheme, error)
    if parts.scheme.lower() != scheme or not parts.netloc:
        raise error(f"URL {url!r}: expected {scheme}://NAME")
    return f"{parts.netloc}{parts.path}".rstrip("/")


def publish(device: FakeRigDevice | FakeSensorDevice) -> None:
    """Make ``device`` reachable at its URL in this process."""
    with _lock:
        if isinstance(device, FakeRigDevice):
            _rigs[_key(device.url, RIG_SCHEME, RigUrlError)] = device
        else:
            _sensors[_key(device.url, SENSOR_SCHEME, SensorUrlError)] = device


def withdraw(device: FakeRigDevice | FakeSensorDevice) -> None:
    """Forget ``device``'s URL (idempotent)."""
    with _lock:
        table: dict[str, Any] = _rigs if isinstance(device, FakeRigDevice) else _sensors
        for key in [k for k, v in table.items() if v is device]:
            del table[key]


def _lookup(url: str, table: dict[str, Any], scheme: str, error: type[StationError]) -> Any:
    key = _key(url, scheme, error)
    with _lock:
        try:
            return table[key]
        except KeyError:
            raise error(f"no fake device at {url!r} in this process (known: {sorted(table)})") from None


# --- the rig -----------------------------------------------------------------------------------------------


class FakeRigDevice(RigModelView):
    """A simulated rig without a server: a :class:`RigModel` reachable at ``fake-rig://NAME``."""

    def __init__(self, model: RigModel, name: str) -> None:
        self.model = model
        self.url = f"{RIG_SCHEME}://{name}"
        self.connections_dropped = 0

    def stop(self) -> None:
        withdraw(self)


class FakeRig(RegisterRig):
    """The station's rig client with the simulated rig's model as its register transport.

    Args:
        device: the rig (see :func:`open_fake_rig` to reach one by URL).
        clock: the clock of waits and polls (default: the model's); must be the model's clock.
        options: the motion and supervision settings of :class:`~station.rig.mapped.RegisterRig`.
    """

    def __init__(self, device: FakeRigDevice, clock: Clock | None = None, **options: Any) -> None:
        super().__init__(clock if clock is not None else device.model.clock, **options)
        self.device = device
        self.url = device.url

    def _accessed(self) -> None:
        if self.device.model.take_drop_request():  # the link dropped and was re-established
            self.device.connections_dropped += 1
            self.reconnects += 1

    def _read_input(self, address: int, count: int, what: str) -> list[int]:
        registers = self.device.model.input_registers()
        self._accessed()
        return [registers.get(a, 0) for a in range(address, address + count)]

    def _write(self, address: int, values: list[int], what: str, retries: int | None = None) -> None:
        code = self.device.model.write_holding(address, [int(v) for v in values])
        self._accessed()
        if code is not None:
            raise RigProtocolError(f"rig {what}: Modbus exception {int(code)} ({code.name})", exception_code=int(code))

    def _close_link(self) -> None:
        pass


def open_fake_rig(
    url: str, clock: Clock | None = None, *, heartbeat: bool = False, watchdog_s: float | None = None, **options: Any
) -> FakeRig:
    """Open the fake rig at ``fake-rig://NAME`` (the opener of :data:`station.rig.RIGS` for the scheme).

    Like :func:`station.rig.modbus.open_rig`: identify it, write ``watchdog_s`` if given, and beat the
    heartbeat only when ``heartbeat`` is true (default off, see the module doc).
    """
    device = _lookup(url, _rigs, RIG_SCHEME, RigUrlError)
    return start_rig(FakeRig(device, clock, **options), heartbeat=heartbeat, watchdog_s=watchdog_s)


# --- the sensor --------------------------------------------------------------------------------------------


class FakeSensorDevice(SensorUnit):
    """A simulated IMU without a wire: the firmware core, its power switches, ``go_silent``.

    Takes the arguments of :class:`~station.sim.sensor_core.SensorCore` (``identity`` keywords:
    serial, firmware, rates, EEPROM, corrector, ranges) and the ``url`` it is reached at. What it
    sends (sample records and BOOT events) waits in an outbox until the client collects it.
    """

    def __init__(self, source: SampleSource, clock: Clock | None = None, *, url: str, **identity: Any) -> None:
        super().__init__(SensorCore(source, clock, **identity))
        self.url = url
        self._stats = dict.fromkeys(PeerStats.__dataclass_fields__, 0)
        self._outbox: list[np.ndarray | BootEvent] = []
        with self._lock:
            self._boot(BootReason.POWER_ON)

    def stats(self) -> PeerStats:
        """The sensor-side counters (nothing is dropped, flipped or overrun without a wire)."""
        with self._lock:
            return PeerStats(**{**self._stats, "tx_overruns": self.core.tx_overruns})

    def close(self) -> None:
        withdraw(self)

    def _generate(self) -> None:
        records = self.core.due_samples()
        if records is None:
            return
        self._stats["sample_frames"] += records.shape[0]
        if self.go_silent:
            self._stats["frames_silenced"] += records.shape[0]
            return
        self._outbox.append(records)

    def _power_off(self) -> None:
        self._generate()  # what was due before the power went is sent
        super()._power_off()

    def _boot(self, reason: BootReason) -> BootEvent:
        self._stats["boots"] += 1
        event = super()._boot(reason)
        if not self.go_silent:
            self._outbox.append(event)
        return event

    def exchange(self, code: int, args: bytes) -> Answer | None:
        """Run one command (the samples due before it go out first); None: no answer (off, silent)."""
        with self._lock:
            self._generate()
            if not self.core.powered or self.go_silent:
                return None
            self._stats["commands"] += 1
            answer = self.core.execute(code, args)
            if not self.core.powered:
                self._power_off()  # the power failed while executing
                return None
            if code == Command.RESET and answer is not None:
                self._boot(BootReason.RESET_COMMAND)
            return answer

    def collect(self) -> list[np.ndarray | BootEvent]:
        """Everything sent since the last call, in order: sample records and BOOT events."""
        with self._lock:
            self._generate()
            out, self._outbox = self._outbox, []
            return out


class FakeSensor(ProtocolSensor):
    """The station's sensor client with the simulated firmware as its transport.

    Args:
        device: the sensor (see :func:`open_fake_sensor` to reach one by URL).
        clock: the station clock (default: the device's); must be the device's clock.
        url: the URL it was opened by (default: the device's).
        options: ``command_timeout_s``, ``attempts``, ``max_buffered_samples`` as for
            :class:`~station.sensor.client.SerialSensor` (an unanswered command fails at once);
            ``crc_window_frames`` and ``crc_error_threshold`` are accepted and ignored (nothing is
            corrupted in process).
    """

    def __init__(self, device: FakeSensorDevice, clock: Clock | None = None, *, url: str | None = None,
                 **options: Any) -> None:
        for ignored in ("crc_window_frames", "crc_error_threshold"):
            options.pop(ignored, None)
        url = url if url is not None else device.url
        super().__init__(clock if clock is not None else device.core.clock, url, url, **options)
        self._device = device
        self._pump_lock = threading.Lock()  # what was collected first is buffered first
        self._frames = 0
        self._sequence = SequenceTracker()
        device.collect()  # what waited before the open is discarded, as on a port

    def _pump(self) -> None:
        """Take in what the device sent."""
        with self._pump_lock:
            for item in self._device.collect():
                if isinstance(item, BootEvent):
                    self._frames += 1
                    self._sequence.boot()
                    self._received_boot()
                else:
                    self._frames += item.shape[0]
                    self._sequence.feed_records(item)
                    self._received_samples(SampleBlock.from_records(item))

    def _exchange(self, command: Command, args: bytes, attempt: int) -> tuple[Reply | None, int]:
        self._check_fault()
        answer = self._device.exchange(int(command), args)
        if answer is None:  # every remaining attempt goes unanswered
            self._counts["retries"] += self.attempts - attempt - (0 if attempt else 1)
            self._pump()
            return None, self.attempts
        while answer.due_s is not None and answer.due_s > self._clock.now():  # the EEPROM's write cycle
            self._clock.sleep(answer.due_s - self._clock.now())
        self._frames += 1
        self._pump()
        return Reply(0, int(command), answer.ok, answer.data, answer.error), attempt + 1

    def _read(self, n: int | None, duration_s: float | None, timeout_s: float) -> SampleBlock:
        deadline = self._clock.now() + timeout_s
        while True:
            now = self._clock.now()  # before pumping: what is due by now is in the buffer then
            self._pump()
            with self._cond:
                self._check_fault()
                block = self._buffer.take(n, duration_s)
                if block is not None:
                    return block
                missing_s = self._buffer.shortfall_s(n, duration_s, self._rate_hz or 10)
            if now >= deadline:
                raise self._samples_timeout(timeout_s)
            self._clock.sleep(min(max(missing_s, 1e-6), deadline - now))

    def drain(self) -> SampleBlock:
        self._pump()
        return super().drain()

    def _parser_stats(self) -> ParserStats:
        s = self._sequence
        return ParserStats(frames=self._frames, gaps=s.gaps, lost_frames=s.lost, duplicates=s.duplicates,
                           restarts=s.restarts)

    def close(self) -> None:
        """Close the client (idempotent); the device stays."""
        self._link_error = f"sensor {self.url} is closed"

    def __enter__(self) -> FakeSensor:
        return self


def open_fake_sensor(url: str, clock: Clock | None = None, **options: Any) -> FakeSensor:
    """Open the fake sensor at ``fake-sensor://NAME/SLOT`` (the opener of :data:`station.sensor.SENSORS`).

    ``options`` are those of :class:`FakeSensor` (the same as :func:`station.sensor.client.open_sensor`'s).
    """
    return FakeSensor(_lookup(url, _sensors, SENSOR_SCHEME, SensorUrlError), clock, url=url, **options)


RIGS.register(RIG_SCHEME, open_fake_rig)
SENSORS.register(SENSOR_SCHEME, open_fake_sensor)


# --- a whole station ------------------------------------------------------------------------------------------

_names = itertools.count(1)


class FakeStation(SimulatedStation):
    """A simulated rig and ``units`` simulated sensors in this process, reached by fake URLs.

    The units, their physics and seeds are :class:`~station.sim.station_sim.SimStation`'s; the rig
    is ``fake-rig://NAME``, the sensors ``fake-sensor://NAME/0`` ... Arguments are those of
    :class:`~station.sim.station_sim.SimulatedStation` (pass ``clock=VirtualClock()`` for runs
    that repeat bit for bit, the sequence's threads included), plus ``name`` (default: a new one per station).
    """

    def __init__(self, units: int = 4, scale: float = 30.0, seed: int = 0, *, name: str | None = None,
                 **kwargs: Any) -> None:
        super().__init__(units, scale, seed, **kwargs)
        self.name = name if name is not None else f"station{next(_names)}"

    def _start_rig(self, options: dict[str, Any]) -> FakeRigDevice:
        device = FakeRigDevice(RigModel(self.clock, **options), self.name)
        publish(device)
        return device

    def _start_sensor(self, source: PhysicsSource, truth: UnitTruth, rate_hz: int, seed: int) -> FakeSensorDevice:
        url = f"{SENSOR_SCHEME}://{self.name}/{len(self.units)}"
        device = FakeSensorDevice(source, self.clock, url=url, serial=truth.serial, default_rate_hz=rate_hz,
                                  eeprom=Eeprom(clock=self.clock))
        publish(device)
        return device

    def _stop_rig(self) -> None:
        self.rig.stop()


__all__ = [
    "FakeRig",
    "FakeRigDevice",
    "FakeSensor",
    "FakeSensorDevice",
    "FakeStation",
    "open_fake_rig",
    "open_fake_sensor",
    "publish",
    "withdraw",
]
