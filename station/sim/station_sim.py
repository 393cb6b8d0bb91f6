"""A whole simulated station: one simulated rig and N simulated sensors on one clock.

:class:`SimulatedStation` draws the units and binds their physics to the rig; :class:`SimStation`
serves them over the real transports, :class:`station.sim.fakes.FakeStation` in process.
:class:`SimStation` starts a :class:`~station.sim.rig_server.SimulatedRig` (a real
pymodbus server) and N :class:`~station.sim.sensor_peer.SimulatedSensor` (each on
its own pty), all on one :class:`~station.kernel.clock.SimClock`. Each sensor's
physics is a :class:`~station.sim.physics_source.PhysicsSource` bound to the rig,
so all units feel whatever the rig is commanded to do. The station code talks to
them only through :attr:`SimStation.rig_url` and :attr:`SimStation.sensor_urls`,
exactly as it would to hardware. Used by ``station sim``, ``station demo`` and the
tests; a context manager.

Seeds: unit ``k`` of ``seed`` is drawn from ``SeedSequence(seed, spawn_key=(k,))``:
the same seed gives the same units (truth, serial numbers) and the same noise per
power cycle.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Self

import numpy as np

from station.kernel.clock import Clock, SimClock
from station.kernel.plan import RigPlan, default_plan
from station.kernel.sensor_class import TABLE1, SensorClass
from station.kernel.virtual_clock import is_virtual
from station.physics.effects import Effects, EffectTruth
from station.physics.unit import UnitTruth, draw_unit
from station.rig import rig_client_options
from station.sim.chamber_server import SimulatedChamber
from station.sim.eeprom import Eeprom
from station.sim.physics_source import PhysicsSource
from station.sim.rig_server import SimulatedRig
from station.sim.sensor_peer import SimulatedSensor


@dataclass(frozen=True, eq=False)
class SimUnit:
    """One simulated unit in the fixture.

    Attributes:
        slot: fixture slot (0-based).
        truth: its true parameters (SI).
        source: its physics, bound to the rig.
        sensor: the simulated firmware (``sensor.url``, ``sensor.eeprom``, fault switches): a
            :class:`~station.sim.sensor_peer.SimulatedSensor` on a pty, or the in-process
            :class:`~station.sim.fakes.FakeSensorDevice`.
    """

    slot: int
    truth: UnitTruth
    source: PhysicsSource
    sensor: Any


#: Wall seconds the station waits for each answer of a simulated sensor (see ``sensor_client_options``).
SIM_COMMAND_TIMEOUT_S = 5.0


class SimulatedStation:
    """A simulated rig + ``units`` simulated sensors on one clock; subclasses say how they are reached.

    Args:
        units: number of sensors in the fixture.
        scale: simulated seconds per wall second of the default clock.
        seed: seeds the units and their noise.
        plan: site values (gravity, latitude, heading) and the sensors' power-on sample rate.
        sensor_class: distribution the units are drawn from (default: the paper's Table 1).
        effects: optional physics for every unit.
        rig_options: extra keyword arguments of the rig model (motion limits, settle time).
        clock: the clock everything lives by (default ``SimClock(scale)``); a
            :class:`~station.kernel.virtual_clock.VirtualClock` makes runs repeat bit for bit (``docs/simulation.md``).
        chamber: start a simulated climate chamber (:class:`~station.sim.chamber_server.SimulatedChamber`,
            a Modbus/TCP server on 127.0.0.1) with these model options (``{}``: the defaults); the units'
            temperature then follows its load, their self-heating on top. None: no chamber.
        unit_effects: per slot, effects replacing ``effects`` (None entries keep ``effects``), e.g. a
            reference unit without temperature effects next to units with them.
        reference_degc: with a chamber, the temperature at which the units' temperature effects vanish.
        unit_keys: per slot, which unit of ``seed`` sits there (default: unit k in slot k), so that the same
            unit (the same truth and serial) can be measured again in another nest.
        noise_index: which noise and fault streams the units use (0: the default streams; another index gives
            the same units fresh noise, as a repeat measurement does).
        nest_errors_deg: the rig's configuration: per nest, its mounting error as a small rotation vector
            (deg, about the nest's x, y, z) from the sensor frame to the nest frame; None: perfect nests.
        truth_change: ``(slot, truth) -> truth`` applied to every drawn unit, e.g. a unit that has aged.
        effect_change: ``(slot, effect truth) -> effect truth`` applied to every unit's realized effects, e.g. a
            planted gyro k2 (:class:`~station.sim.physics_source.PhysicsSource`'s ``effect_change``).
    """

    def __init__(
        self,
        units: int = 4,
        scale: float = 30.0,
        seed: int = 0,
        *,
        plan: RigPlan | None = None,
        sensor_class: SensorClass = TABLE1,
        effects: Effects | None = None,
        rig_options: dict[str, Any] | None = None,
        clock: Clock | None = None,
        chamber: dict[str, Any] | None = None,
        unit_effects: Sequence[Effects | None] | None = None,
        reference_degc: float = 25.0,
        unit_keys: Sequence[int] | None = None,
        noise_index: int = 0,
        nest_errors_deg: Sequence[Sequence[float]] | None = None,
        truth_change: Callable[[int, UnitTruth], UnitTruth] | None = None,
        effect_change: Callable[[int, EffectTruth], EffectTruth] | None = None,
    ) -> None:
        if units < 1:
            raise ValueError("a simulated station needs at least one unit")
        self.n_units = int(units)
        self.seed = int(seed)
        self.plan = plan if plan is not None else default_plan()
        self.sensor_class = sensor_class
        self.effects = effects
        self.clock: Clock = clock if clock is not None else SimClock(scale)
        self._rig_options = dict(rig_options or {})
        self.rig: Any = None
        self.units: list[SimUnit] = []
        self._chamber_options = dict(chamber) if chamber is not None else None
        self.chamber: SimulatedChamber | None = None
        self.unit_effects = list(unit_effects or [])
        self.reference_degc = float(reference_degc)
        self.unit_keys = [int(k) for k in unit_keys] if unit_keys is not None else list(range(self.n_units))
        if len(self.unit_keys) != self.n_units:
            raise ValueError(f"unit_keys names {len(self.unit_keys)} units for {self.n_units} slots")
        self.noise_index = int(noise_index)
        self.truth_change = truth_change
        self.effect_change = effect_change
        self.nest_errors_deg = [tuple(float(v) for v in e) for e in nest_errors_deg] if nest_errors_deg else []

    @property
    def scale(self) -> float:
        return self.clock.scale

    # --- what a subclass provides --------------------------------------------------------------

    def _start_rig(self, options: dict[str, Any]) -> Any:
        """Start the rig (a :class:`~station.sim.rig_server.RigModelView` with a ``url``) with model ``options``."""
        raise NotImplementedError

    def _start_sensor(self, source: PhysicsSource, truth: UnitTruth, rate_hz: int, seed: int) -> Any:
        """Start one unit's simulated sensor on ``source`` (``seed``: its fault generators)."""
        raise NotImplementedError

    def _stop_rig(self) -> None:
        raise NotImplementedError

    # --- lifetime ---------------------------------------------------------------------------------

    def start(self) -> Self:
        """Start the rig and the sensors; returns self."""
        if self.rig is not None:
            return self
        try:
            opts = {"watchdog_s": rig_client_options(self.scale)["watchdog_s"], **self._rig_options}
            self.rig = self._start_rig(opts)
            if self._chamber_options is not None:
                self.chamber = SimulatedChamber(self.clock, **self._chamber_options).start()
            rate = int(self.plan.sample_rate_hz)
            for k in range(self.n_units):
                key = self.unit_keys[k]
                unit_ss, imu_ss, fault_ss = np.random.SeedSequence(self.seed, spawn_key=(key,)).spawn(3)
                if self.noise_index:
                    _, imu_ss, fault_ss = np.random.SeedSequence(self.seed, spawn_key=(key, self.noise_index)).spawn(3)
                truth = draw_unit(self.sensor_class, np.random.default_rng(unit_ss))
                if self.truth_change is not None:
                    truth = self.truth_change(k, truth)
                effects = self.effects
                if k < len(self.unit_effects) and self.unit_effects[k] is not None:
                    effects = self.unit_effects[k]
                source = PhysicsSource(
                    self.rig,
                    self.clock,
                    truth,
                    sensor_class=self.sensor_class,
                    effects=effects,
                    seed=int(imu_ss.generate_state(1)[0]),
                    gravity_mps2=self.plan.gravity_mps2,
                    latitude_deg=self.plan.latitude_deg,
                    heading_deg=self.plan.heading_deg,
                    temperature_degc=self.chamber.load_temperature if self.chamber is not None else None,
                    reference_degc=self.reference_degc,
                    mount=self.nest_mount(k),
                    effect_change=(None if self.effect_change is None
                                   else functools.partial(self.effect_change, k)),
                )
                sensor = self._start_sensor(source, truth, rate, int(fault_ss.generate_state(1)[0]))
                self.units.append(SimUnit(k, truth, source, sensor))
        except BaseException:
            self.stop()
            raise
        return self

    def nest_mount(self, slot: int) -> np.ndarray | None:
        """The rotation from a unit's sensor frame to nest ``slot``'s frame (None: a perfect nest)."""
        if slot >= len(self.nest_errors_deg):
            return None
        from scipy.spatial.transform import Rotation

        return np.asarray(Rotation.from_rotvec(np.radians(self.nest_errors_deg[slot])).as_matrix())

    def stop(self) -> None:
        """Stop the sensors and the rig (idempotent)."""
        for unit in self.units:
            unit.sensor.close()
        self.units = []
        if self.rig is not None:
            self._stop_rig()
            self.rig = None
        if self.chamber is not None:
            self.chamber.stop()
            self.chamber = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def rig_url(self) -> str:
        """The rig's URL for :func:`station.rig.open_rig`."""
        if self.rig is None:
            raise RuntimeError("the simulated station is not started")
        return str(self.rig.url)

    @property
    def chamber_url(self) -> str:
        """The simulated chamber's URL for :func:`station.chamber.open_chamber`."""
        if self.chamber is None:
            raise RuntimeError("the simulated station has no chamber")
        return self.chamber.url

    @property
    def sensor_urls(self) -> list[str]:
        """The sensors' URLs for :func:`station.sensor.open_sensor`, in slot order."""
        return [u.sensor.url for u in self.units]

    def rig_client_options(self) -> dict[str, Any]:
        """:func:`station.rig.open_rig` keyword arguments suited to this station's clock scale."""
        return rig_client_options(self.scale)

    def sensor_client_options(self) -> dict[str, Any]:
        """:func:`station.sensor.open_sensor` keyword arguments for these simulated sensors.

        A real sensor answers a command within milliseconds, so the station waits 0.5 wall seconds per attempt.
        A simulated sensor is a thread of a process that also fits units and serves a rig: on a loaded machine
        its answer can wait behind them for seconds (a line demo at load 28 on 2 cores lost IDENTIFY three times
        in 0.5 s), which would make a run's verdict depend on the machine's load. It gets 5 s per attempt: a dead
        link is still found, in 15 s.
        """
        return {"command_timeout_s": SIM_COMMAND_TIMEOUT_S}


class SimStation(SimulatedStation):
    """Simulated rig + ``units`` simulated sensors sharing one ``SimClock(scale)``, over real transports.

    The rig is a Modbus server (:class:`~station.sim.rig_server.SimulatedRig`), each sensor a
    :class:`~station.sim.sensor_peer.SimulatedSensor` on its own pty. Arguments are those of
    :class:`SimulatedStation`, plus:

    Args:
        host, port: where the rig's Modbus/TCP server listens (port 0: a free port).
        rig_transport: 'tcp' or 'rtu' (RTU over a pty pair).
        rig_options: extra keyword arguments of :class:`SimulatedRig` (motion limits, settle time).
    """

    def __init__(
        self,
        units: int = 4,
        scale: float = 30.0,
        seed: int = 0,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        rig_transport: str = "tcp",
        **kwargs: Any,
    ) -> None:
        super().__init__(units, scale, seed, **kwargs)
        self._host, self._port, self._transport = host, port, rig_transport

    def _start_rig(self, options: dict[str, Any]) -> SimulatedRig:
        return SimulatedRig(self.clock, self._host, self._port, transport=self._transport, **options).start()

    def _start_sensor(self, source: PhysicsSource, truth: UnitTruth, rate_hz: int, seed: int) -> SimulatedSensor:
        # On a virtual clock time is frozen while the station waits on I/O for the EEPROM's answer, so a
        # write cycle that must pass before the answer could never end: it takes no time there.
        eeprom = Eeprom(clock=self.clock, write_cycle_s=0.0) if is_virtual(self.clock) else Eeprom(clock=self.clock)
        return SimulatedSensor(source, self.clock, serial=truth.serial, default_rate_hz=rate_hz, eeprom=eeprom,
                               seed=seed)

    def _stop_rig(self) -> None:
        self.rig.stop()
