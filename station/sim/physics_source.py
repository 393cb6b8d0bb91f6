"""The sensor physics of a simulated unit mounted on the simulated rig.

:class:`PhysicsSource` is a :class:`~station.sim.sensor_core.SampleSource`: the
simulated sensor asks it for samples at sensor times (s since power-on), it asks
the rig what the sensor frame did at the matching rig times and renders the
unit's raw output with :class:`~station.physics.imu.ImuModel` (eq. 1 with the
Gauss-Markov drift of eq. 3, plus any optional effects). This binds a simulated
sensor to the simulated rig it sits on: whatever the rig does, whoever commands
it, the sensor feels.

Time: sensor time ``t`` is rig (clock) time ``t_power_on + t``; with a
``time_offset`` effect the sample stamped ``t`` was taken at rig time
``t_power_on + t - time_offset``. :meth:`PhysicsSource.power_on` restarts the
physics (a fresh model: g(0) = 1 of eq. 3, self-heating from ambient); the noise of
each power cycle comes from its own seeded stream, so runs are reproducible per
boot count. Units: m/s^2, rad/s, degC, s.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

import numpy as np

from station.kernel.clock import Clock
from station.kernel.geometry import Kinematics
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.effects import Effects, EffectTruth
from station.physics.imu import Environment, ImuModel
from station.physics.unit import UnitTruth


class KinematicsProvider(Protocol):
    """Anything that says what a sensor mounted on it does at clock times (s), e.g. a SimulatedRig."""

    def kinematics(self, t_s: np.ndarray) -> Kinematics: ...


class PhysicsSource:
    """Renders one unit's raw output for whatever ``rig`` does (a SampleSource).

    Args:
        rig: the rig the unit sits on (``SimulatedRig`` or ``RigModel``), evaluated at clock time.
        clock: the clock shared with the rig and the simulated sensor (s).
        truth: the unit's true parameters (:func:`station.physics.unit.draw_unit`).
        sensor_class: used to draw the room environment when ``environment`` is None.
        effects: optional physics beyond eq. (1); default none.
        seed: seeds the noise; power cycle ``k`` (1 = first boot) uses child stream ``k``.
        gravity_mps2: local gravity (m/s^2).
        latitude_deg, heading_deg: the site, for the ``earth_rotation`` effect (deg).
        environment: the room; drawn per power cycle from the seed when None.
        temperature_degc: the temperature of the unit's case (degC) at clock times (s), e.g. the load
            of a simulated climate chamber; the sensor's self-heating (the unit's ``self_heating_k``,
            ``self_heating_tau_s``, counted from its first power-on: a quick power cycle does not cool
            it) is added on top. The temperature effects then act about ``reference_degc``.
        reference_degc: the temperature at which the unit's temperature effects are zero (degC).
        mount: the rotation from the sensor frame to its nest's frame (3x3; None: mounted exactly), e.g. a
            nest's mounting error: what the rig moves is the nest, what the sensor measures is in its own frame.
        effect_change: applied to the SI coefficients ``effects`` realize for the unit, e.g. to give it physics no
            :class:`Effects` magnitude has (the IEEE 952 polynomial's ``gyro_quadratic``); None: as realized.
    """

    def __init__(
        self,
        rig: KinematicsProvider,
        clock: Clock,
        truth: UnitTruth,
        *,
        sensor_class: SensorClass = TABLE1,
        effects: Effects | None = None,
        seed: int = 0,
        gravity_mps2: float = 9.80665,
        latitude_deg: float = 0.0,
        heading_deg: float = 0.0,
        environment: Environment | None = None,
        temperature_degc: Callable[[np.ndarray], np.ndarray] | None = None,
        reference_degc: float = 25.0,
        mount: np.ndarray | None = None,
        effect_change: Callable[[EffectTruth], EffectTruth] | None = None,
    ) -> None:
        self.rig = rig
        self.effect_change = effect_change
        self.mount = None if mount is None else np.asarray(mount, dtype=float).reshape(3, 3)
        self.clock = clock
        self.truth = truth
        self.sensor_class = sensor_class
        self.effects = effects if effects is not None else Effects()
        self.seed = int(seed)
        self.gravity_mps2 = float(gravity_mps2)
        self.latitude_deg = float(latitude_deg)
        self.heading_deg = float(heading_deg)
        self.environment = environment
        self.temperature_degc = temperature_degc
        self.reference_degc = float(reference_degc)
        self.t_first_power_on_s: float | None = None
        self.boots = 0
        self.t_power_on_s = 0.0
        self.model: ImuModel | None = None
        self._lock = threading.Lock()

    def unit_temperature(self, t_clock_s: np.ndarray) -> np.ndarray:
        """True sensor temperature (degC) at clock times ``t_clock_s`` when a case temperature is given:
        the case plus the self-heating since the first power-on."""
        if self.temperature_degc is None:
            raise RuntimeError("no case temperature course given")
        t = np.asarray(t_clock_s, dtype=float)
        first = self.t_first_power_on_s if self.t_first_power_on_s is not None else math.inf
        on = np.maximum(t - first, 0.0)
        heat = self.truth.self_heating_k * -np.expm1(-on / self.truth.self_heating_tau_s)
        return np.asarray(self.temperature_degc(t), dtype=float) + heat

    def _new_model(self) -> ImuModel:
        ss = np.random.SeedSequence(self.seed, spawn_key=(self.boots,))
        effect_truth = None
        if self.effect_change is not None:
            effect_truth = self.effect_change(self.effects.realize(
                self.truth.shapes, latitude_deg=self.latitude_deg, heading_deg=self.heading_deg))
        if self.temperature_degc is not None:
            t_on = self.t_power_on_s
            env = Environment(ambient_degc=self.reference_degc)
            return ImuModel(
                self.truth, self.sensor_class, self.effects, ss, latitude_deg=self.latitude_deg,
                heading_deg=self.heading_deg, environment=env, effect_truth=effect_truth,
                temperature_degc=lambda t: self.unit_temperature(t_on + np.asarray(t, dtype=float)),
            )
        return ImuModel(
            self.truth,
            self.sensor_class,
            self.effects,
            ss,
            latitude_deg=self.latitude_deg,
            heading_deg=self.heading_deg,
            environment=self.environment,
            effect_truth=effect_truth,
        )

    def power_on(self) -> None:
        """Restart the physics: time base at the current clock time, drift state g(0) = 1 (eq. 3)."""
        with self._lock:
            self.boots += 1
            self.t_power_on_s = self.clock.now()
            if self.t_first_power_on_s is None:
                self.t_first_power_on_s = self.t_power_on_s
            self.model = self._new_model()

    def rig_time(self, t_s: np.ndarray) -> np.ndarray:
        """Rig (clock) times (s) at which the samples stamped with sensor times ``t_s`` were taken."""
        model = self.model
        offset = model.time_offset_s if model is not None else 0.0
        return self.t_power_on_s + np.asarray(t_s, dtype=float) - offset

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw (accel m/s^2 (n, 3), gyro rad/s (n, 3), temperature degC (n,)) at sensor times ``t_s`` (s)."""
        with self._lock:
            if self.model is None:
                raise RuntimeError("PhysicsSource.render before power_on")
            t = np.asarray(t_s, dtype=float)
            kin = self.rig.kinematics(self.rig_time(t))
            if self.mount is not None:  # the unit sits in its nest rotated by ``mount`` (sensor to nest frame)
                kin = replace(kin, rotation=kin.rotation @ self.mount, omega_radps=kin.omega_radps @ self.mount,
                              alpha_radps2=kin.alpha_radps2 @ self.mount)
            raw = self.model.render(replace(kin, t_s=t), self.gravity_mps2)
            return raw.accel_mps2, raw.gyro_radps, raw.temp_degc
