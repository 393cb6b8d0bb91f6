"""A simulated soak rack: a relay board on Modbus/TCP and one simulated sensor per slot on its own pty.

Each slot holds its unit still in a fixed orientation (slot k: the k-th of the six poses, and a tilt
drawn from the seed; the station does not know either). Relay k switches unit k's supply: on, it boots
(sensor time and sample counter from 0, eq. 3's warm-up from g(0) = 1); off, it goes dark. Units are
drawn as :class:`~station.sim.station_sim.SimulatedStation` draws them (``SeedSequence(seed,
spawn_key=(k,))``), so a rack and a rig simulated with the same seed hold the same units.
"""

from __future__ import annotations

from typing import Self

import numpy as np

from station.kernel.clock import Clock, SimClock
from station.kernel.geometry import POSE_ANGLES_DEG, Kinematics, kinematics_from_angles
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.unit import UnitTruth, draw_unit
from station.sim.eeprom import Eeprom
from station.sim.physics_source import PhysicsSource
from station.sim.relay_server import SimulatedRelayBoard
from station.sim.sensor_peer import SimulatedSensor

_POSES = tuple(POSE_ANGLES_DEG)


class StaticMount:
    """A slot that holds its unit still: constant roll, pitch, yaw (rad)."""

    def __init__(self, roll_rad: float, pitch_rad: float, yaw_rad: float = 0.0) -> None:
        self.angles = np.array([roll_rad, pitch_rad, yaw_rad])

    def kinematics(self, t_s: np.ndarray) -> Kinematics:
        t = np.asarray(t_s, dtype=float)
        zero = np.zeros((t.shape[0], 3))
        return kinematics_from_angles(t, np.broadcast_to(self.angles, (t.shape[0], 3)).copy(), zero, zero)


class SimRack:
    """``slots`` simulated units behind a simulated relay board, on one clock; a context manager."""

    def __init__(self, slots: int = 4, scale: float = 100.0, seed: int = 0, *, clock: Clock | None = None,
                 sensor_class: SensorClass = TABLE1, sample_rate_hz: int = 100, gravity_mps2: float = 9.80665,
                 channels: int | None = None) -> None:
        self.n_slots = int(slots)
        self.seed = int(seed)
        self.clock: Clock = clock if clock is not None else SimClock(scale)
        self.sensor_class = sensor_class
        self.sample_rate_hz = int(sample_rate_hz)
        self.gravity_mps2 = float(gravity_mps2)
        self.channels = int(channels if channels is not None else max(slots, 1))
        self.board: SimulatedRelayBoard | None = None
        self.sensors: list[SimulatedSensor] = []
        self.truths: list[UnitTruth] = []
        self.mounts: list[StaticMount] = []

    def _switch(self, slot: int, on: bool) -> None:
        if slot < len(self.sensors):
            if on:
                self.sensors[slot].power_on()
            else:
                self.sensors[slot].power_off()

    def start(self) -> Self:
        try:
            rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(10_000,)))
            for k in range(self.n_slots):
                unit_ss, imu_ss, fault_ss = np.random.SeedSequence(self.seed, spawn_key=(k,)).spawn(3)
                truth = draw_unit(self.sensor_class, np.random.default_rng(unit_ss))
                roll, pitch = POSE_ANGLES_DEG[_POSES[k % len(_POSES)]]
                tilt = np.radians(rng.uniform(-3.0, 3.0, size=3))
                mount = StaticMount(np.radians(roll) + tilt[0], np.radians(pitch) + tilt[1], tilt[2])
                source = PhysicsSource(mount, self.clock, truth, sensor_class=self.sensor_class,
                                       seed=int(imu_ss.generate_state(1)[0]), gravity_mps2=self.gravity_mps2)
                sensor = SimulatedSensor(source, self.clock, serial=truth.serial, default_rate_hz=self.sample_rate_hz,
                                         eeprom=Eeprom(clock=self.clock), seed=int(fault_ss.generate_state(1)[0]))
                sensor.power_off()  # the relay powers it
                self.sensors.append(sensor)
                self.truths.append(truth)
                self.mounts.append(mount)
            self.board = SimulatedRelayBoard(self.channels, on_switch=self._switch).start()
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self) -> None:
        if self.board is not None:
            self.board.stop()
            self.board = None
        for s in self.sensors:
            s.close()
        self.sensors = []

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def board_url(self) -> str:
        if self.board is None:
            raise RuntimeError("the simulated rack is not started")
        return self.board.url

    @property
    def sensor_urls(self) -> list[str]:
        return [s.url for s in self.sensors]


__all__ = ["SimRack", "StaticMount"]
