"""A simulated unit in a climate chamber: its temperature is the chamber's load temperature plus its own
self-heating since the first power-on (a quick power cycle does not cool it), and its temperature effects
act on that temperature about the reference temperature, exactly as the effect truth says."""

from __future__ import annotations

import numpy as np
import pytest

from station.kernel.sensor_class import TABLE1
from station.physics.effects import Effects
from station.physics.unit import draw_unit
from station.sim.chamber_server import ChamberModel
from station.sim.physics_source import PhysicsSource
from station.sim.rig_server import RigModel


class ManualClock:
    scale = 1.0

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(seconds, 0.0)


def _case(t: np.ndarray) -> np.ndarray:
    return np.where(np.asarray(t) < 1000.0, 10.0, 40.0)


def _source(clock: ManualClock, effects: Effects) -> PhysicsSource:
    truth = draw_unit(TABLE1, np.random.default_rng(42))
    return PhysicsSource(RigModel(clock), clock, truth, effects=effects, seed=7, temperature_degc=_case,
                         reference_degc=25.0)


def test_unit_temperature_is_case_plus_self_heating_from_first_power_on() -> None:
    clock = ManualClock()
    src = _source(clock, Effects())
    src.power_on()
    clock.t = 1500.0
    src.power_on()  # a reboot: the self-heating goes on from the first power-on
    t = np.array([0.0, 500.0, 1500.0, 3000.0])
    tr = src.truth
    heat = tr.self_heating_k * (1.0 - np.exp(-t / tr.self_heating_tau_s))
    assert src.unit_temperature(t) == pytest.approx(_case(t) + heat)
    _, _, temp = src.render(np.arange(100.0, 110.0, 0.02))  # sensor time since the reboot at 1500 s
    expected = 40.0 + tr.self_heating_k * (1.0 - np.exp(-1605.0 / tr.self_heating_tau_s))
    assert temp.mean() == pytest.approx(expected, abs=0.01)


def test_temperature_effects_act_about_the_reference_temperature() -> None:
    effects = Effects(temperature_bias=0.005)
    clock_a, clock_b = ManualClock(), ManualClock()
    hot, plain = _source(clock_a, effects), _source(clock_b, Effects())
    hot.power_on()
    plain.power_on()
    for t0 in (900.0, 1900.0):
        clock_a.t = clock_b.t = t0 + 20.0
        t = np.arange(t0, t0 + 20.0, 0.01)
        a1, g1, temp = hot.render(t)
        a0, g0, _ = plain.render(t)
        truth = effects.realize(hot.truth.shapes)
        d_temp = hot.unit_temperature(t).mean() - 25.0
        # the same noise streams: the difference is the temperature effect (to the ADC's resolution)
        assert (a1 - a0).mean(axis=0) == pytest.approx(truth.accel_temp_bias * d_temp, abs=2 * hot.truth.accel.lsb)
        assert (g1 - g0).mean(axis=0) == pytest.approx(truth.gyro_temp_bias * d_temp, abs=2 * hot.truth.gyro.lsb)
        assert abs(temp.mean() - 25.0 - d_temp) < 0.05


def test_chamber_load_drives_the_unit() -> None:
    clock = ManualClock()
    chamber = ChamberModel(clock, ambient_degc=23.0)
    truth = draw_unit(TABLE1, np.random.default_rng(1))
    src = PhysicsSource(RigModel(clock), clock, truth, temperature_degc=chamber.load_temperature)
    src.power_on()
    clock.t = 5000.0
    t = np.array([100.0, 4000.0])
    heat = truth.self_heating_k * (1.0 - np.exp(-t / truth.self_heating_tau_s))
    assert src.unit_temperature(t) == pytest.approx(23.0 + heat)
