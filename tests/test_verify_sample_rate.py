"""The on-rig verification of a written image at the unit's sample rate: the firmware's moving average (eq. 6) spans
n samples, 0.4 s at 100 Hz but 4 s at 10 Hz, and the capture window must not start before it holds only samples
taken after the rig confirmed the step. Real peers: the simulated rig on Modbus/TCP (127.0.0.1), the sensor on a
pty, the firmware loading the unit's true parameters as its image, on the virtual clock."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest

from station.eeprom.image import CalibrationImage
from station.eeprom.provision import write_image
from station.kernel.clock import Clock
from station.kernel.plan import RigPlan
from station.kernel.virtual_clock import VirtualClock, acting
from station.rig import open_rig
from station.sensor import open_sensor
from station.sequence.options import SequenceOptions
from station.sequence.steps import Step, drive_rig
from station.sequence.verify import RigVerifier, VerificationLimits, settle_before_window
from station.session.model import Kind
from station.sim.firmware import install_firmware
from station.sim.station_sim import SimStation


def _verify(rate_hz: int, seed: int) -> dict[str, float]:
    clock: Clock = VirtualClock()
    plan = RigPlan(sample_rate_hz=float(rate_hz))
    with acting(clock, name="test"), SimStation(1, 1.0, seed, plan=plan, clock=clock) as sim:
        su = sim.units[0]
        install_firmware(su.sensor, sim.clock)
        params = su.truth.as_parameter_set(1.0 / rate_hz)  # the true parameters: only noise remains
        image = CalibrationImage.from_params(params, "ST-01", datetime(2026, 1, 2, tzinfo=UTC))
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        sensor = open_sensor(sim.sensor_urls[0], sim.clock)
        try:
            write_image(sensor, image)
            sensor.power_cycle(2.0)
            # the rig starts upside down, so the verification's pose check (+z) follows a tumble
            drive_rig(rig, Step(0, "start", Kind.POSE, "-z", 0.0, 1.0), SequenceOptions())
            verifier = RigVerifier(rig, sim.clock, VerificationLimits(), gravity_mps2=plan.gravity_mps2,
                                   sample_rate_hz=rate_hz)
            res = verifier.verify(sensor, image)
        finally:
            sensor.close()
            rig.close()
    assert res.uncorrected_samples == 0 and res.samples == 2 * round(VerificationLimits().hold_s * rate_hz)
    return {c.name: c.value for c in res.checks}


@pytest.mark.parametrize("rate_hz", [10, 100])
def test_a_true_image_verifies_at_the_units_rate(rate_hz: int) -> None:
    values = _verify(rate_hz, seed=21)
    # the true parameters leave the noise of a 5 s window mean and Earth's rate (7.3e-5 rad/s): far inside the
    # limits (0.05 m/s^2, 8.7e-4 rad/s, 3.5e-3 rad/s). With the 1 s settle of the limits file at 10 Hz the window
    # averaged the tumble and the spin-up: 0.4 m/s^2, 0.06 rad/s and -0.08 rad/s (-9 % of 50 deg/s).
    assert values["verify.pose.accel_error"] < 0.01
    assert values["verify.pose.gyro_error"] < 3e-4
    assert abs(values["verify.rate.rate_error"]) < 1e-3
    assert values["verify.rate.accel_error"] < 0.01


def test_the_window_waits_for_the_moving_average() -> None:
    lim = VerificationLimits()  # settle 1 s
    assert settle_before_window(lim, moving_average_length=40, sample_rate_hz=100) == lim.settle_s
    assert settle_before_window(lim, moving_average_length=40, sample_rate_hz=10) == pytest.approx(4.0)
    assert settle_before_window(lim, moving_average_length=40, sample_rate_hz=25) == pytest.approx(1.6)
