"""Post-calibration verification: the unit's own corrected output, checked on the rig.

After the image is written and the sensor power-cycled (its firmware loads the image
and runs Algorithm 1 of Kolhoff & Kemper), :class:`RigVerifier` switches the sensor to
CORRECTED output and repeats a short check on the rig:

* a static pose (default ``+z`` up): the mean corrected specific force must equal
  ``g * up`` of the pose (m/s^2) and the mean corrected rate must be ~0 (rad/s; the
  Earth rate, <= 7.3e-5 rad/s, is inside the limit's margin);
* a constant table rate about the vertical sensor axis: the mean corrected rate about
  that axis must equal the commanded rate (rad/s).

Each window starts after the rig confirmed the step and the firmware's moving average (eq. 6, n samples) has
filled with samples taken after it (:func:`settle_before_window`: n / f, 4 s at 10 Hz, at least the limits file's
``settle_s``). Each residual (the largest per-axis error of the window mean) is checked against
:class:`~station.kernel.limits_file.VerificationLimits` (the ``[verification]`` table
of the limits file); every sample must carry the CORRECTED flag. This is the
paper's online (on-sensor, Algorithm 1) versus post-processed comparison, run on
every unit. The rig is brought back to rest and the sensor back to RAW output afterwards.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from station.eeprom.image import CalibrationImage
from station.kernel.clock import Clock
from station.kernel.errors import StationError
from station.kernel.geometry import AXIS_INDEX, up_vector
from station.kernel.limits_file import VerificationLimits
from station.kernel.measurement import Measurement
from station.kernel.nest_frames import NestCalibration
from station.kernel.virtual_clock import ActorPool, wait_futures
from station.rig.protocol import Rig
from station.sensor.protocol import Sensor
from station.sequence.options import SequenceOptions
from station.sequence.steps import Step, bring_to_rest, check_rig_holding, drive_rig
from station.session.model import Kind

_DEG = math.pi / 180.0


@dataclass(frozen=True)
class VerificationResult:
    """All checks of one unit, plus how many samples were (not) corrected."""

    serial: str
    checks: tuple[Measurement, ...]
    samples: int
    uncorrected_samples: int
    notes: tuple[str, ...] = field(default=())

    @property
    def passed(self) -> bool:
        return self.uncorrected_samples == 0 and self.samples > 0 and all(c.passed for c in self.checks)

    def describe(self) -> str:
        bad = [f"{c.name}={c.value:.3g} {c.unit} (limit {c.high:.3g})" for c in self.checks if not c.passed]
        if self.uncorrected_samples:
            bad.append(f"{self.uncorrected_samples} of {self.samples} samples not corrected")
        if self.samples == 0:
            bad.append("no samples")
        return "; ".join(bad) if bad else "all residuals within limits"


def settle_before_window(limits: VerificationLimits, *, moving_average_length: int, sample_rate_hz: float) -> float:
    """Sensor seconds to skip after the rig confirmed a step, before the capture window (s).

    The firmware's output is the one-sided moving average of the last n samples (eq. 6), so a sample of the window
    is the specific force or rate of the step only when all n lie after the confirmation: at least n samples, n / f
    seconds (0.4 s for the paper's n = 40 at 100 Hz, 4 s at 10 Hz), and never less than the limits file's
    ``settle_s`` (which covers it at 100 Hz).
    """
    return max(float(limits.settle_s), int(moving_average_length) / float(sample_rate_hz))


class RigVerifier:
    """Runs the verification of one unit on the rig (implements ``provision.Verifier``).

    Args:
        rig: the open rig; clock: the station clock.
        limits: residual limits and the short plan.
        gravity_mps2: local gravity (m/s^2).
        sample_rate_hz: sensor rate during the check (Hz).
        options: rig timeouts and tolerances (the sequence's).
        nests, sensors: the rig's nest calibration and the fixture's sensors in slot order: a unit's expected
            output is the rig's reference taken into its sensor frame (the calibration's datum), as its fit was.
    """

    def __init__(
        self,
        rig: Rig,
        clock: Clock,
        limits: VerificationLimits | None = None,
        *,
        gravity_mps2: float = 9.80665,
        sample_rate_hz: int = 100,
        options: SequenceOptions | None = None,
        nests: NestCalibration | None = None,
        sensors: Sequence[Sensor] = (),
    ) -> None:
        self.rig = rig
        self.nests = nests
        self._sensors = list(sensors)
        self.clock = clock
        self.limits = limits if limits is not None else VerificationLimits()
        self.gravity_mps2 = float(gravity_mps2)
        self.sample_rate_hz = int(sample_rate_hz)
        self.options = options if options is not None else SequenceOptions()

    def _capture(self, sensor: Sensor, step: Step, settle_s: float) -> tuple[np.ndarray, np.ndarray, int, int]:
        """(mean accel m/s^2, mean gyro rad/s, samples, uncorrected samples) of a settled window."""
        out = self._window(sensor, settle_s)
        check_rig_holding(self.rig.state(), step, self.options)
        return out

    def _window(self, sensor: Sensor, settle_s: float) -> tuple[np.ndarray, np.ndarray, int, int]:
        """:meth:`_capture` without the rig check (one sensor of a shared hold)."""
        lim = self.limits
        sensor.drain()
        sensor.read_samples(duration_s=settle_s)  # moving-average window and settle guard
        block = sensor.read_samples(duration_s=lim.hold_s)
        n = len(block)
        if n == 0:
            return np.full(3, np.nan), np.full(3, np.nan), 0, 0
        return block.accel_mps2.mean(axis=0), block.gyro_radps.mean(axis=0), n, int(n - block.corrected.sum())

    def _expected(self, sensor: Sensor, ref_nest: np.ndarray) -> np.ndarray:
        """A reference in the nest's frame as the unit's sensor frame sees it (unchanged without nests)."""
        slot = next((k for k, s in enumerate(self._sensors) if s is sensor), None)
        if self.nests is None or slot is None:
            return ref_nest
        return self.nests.to_sensor_frame(slot, ref_nest[None, :])[0]

    def _steps(self) -> tuple[Step, Step]:
        lim = self.limits
        axis = lim.rate_pose[1]
        sign = 1.0 if lim.rate_pose[0] == "+" else -1.0
        pose_step = Step(0, f"verify pose {lim.pose}", Kind.POSE, lim.pose, 0.0, lim.hold_s)
        rate_step = Step(1, f"verify rate {axis}", Kind.RATE, lim.rate_pose, sign * lim.rate_dps, lim.hold_s, axis,
                         lim.rate_dps)
        return pose_step, rate_step

    def _pose_checks(self, sensor: Sensor, a: np.ndarray, w: np.ndarray) -> list[Measurement]:
        lim, check = self.limits, Measurement.at_most_abs
        da = a - self._expected(sensor, self.gravity_mps2 * up_vector(lim.pose))
        return [check("verify.pose.accel_error", float(np.max(np.abs(da))), lim.accel_mps2, "m/s^2"),
                check("verify.pose.gyro_error", float(np.max(np.abs(w))), lim.gyro_static_radps, "rad/s")]

    def _rate_checks(self, sensor: Sensor, a: np.ndarray, w: np.ndarray) -> list[Measurement]:
        lim, check = self.limits, Measurement.at_most_abs
        k = AXIS_INDEX[lim.rate_pose[1]]
        sign = 1.0 if lim.rate_pose[0] == "+" else -1.0
        rate = self._expected(sensor, sign * lim.rate_dps * _DEG * np.eye(3)[k])
        da = a - self._expected(sensor, self.gravity_mps2 * up_vector(lim.rate_pose))
        return [check("verify.rate.rate_error", float(w[k] - abs(rate[k])), lim.rate_radps, "rad/s"),
                check("verify.rate.accel_error", float(np.max(np.abs(da))), lim.accel_mps2, "m/s^2")]

    def verify_many(self, units: Sequence[tuple[Sensor, CalibrationImage]]) -> list[VerificationResult | StationError]:
        """Every written unit of the fixture in the same two holds: one pose, one rate step, each unit's own
        window of each hold read at once (one thread per unit); the rig time is one unit's, whatever N.

        Per unit its result, or the :class:`StationError` its link raised (that unit is the station's fault,
        the others are still judged). A rig fault (the rig did not reach or hold a step) raises: every unit's
        verification is void then. The rig is brought back to rest and every sensor back to RAW output.
        """
        pose_step, rate_step = self._steps()
        settles = [settle_before_window(self.limits, moving_average_length=image.ma_length,
                                        sample_rate_hz=self.sample_rate_hz) for _, image in units]
        state: list[VerificationResult | StationError | None] = [None] * len(units)
        checks: list[list[Measurement]] = [[] for _ in units]
        counts = np.zeros((len(units), 2), dtype=int)
        with ActorPool(self.clock, max_workers=max(1, len(units)), thread_name_prefix="verify") as pool:
            def each(fn: Callable[[int], None], keys: Sequence[int] | None = None) -> None:
                live = [k for k in range(len(units)) if state[k] is None] if keys is None else list(keys)
                futures = [(k, pool.submit(fn, k)) for k in live]
                wait_futures(self.clock, [f for _, f in futures])  # on a virtual clock time passes meanwhile
                for k, fut in futures:
                    err = fut.exception()
                    if isinstance(err, StationError):
                        state[k] = state[k] or err
                    elif err is not None:
                        raise err

            def start(k: int) -> None:
                units[k][0].set_output("corrected")
                units[k][0].start_stream(self.sample_rate_hz)

            def hold(step: Step) -> None:
                def one(k: int) -> None:
                    sensor = units[k][0]
                    a, w, n, u = self._window(sensor, settles[k])
                    counts[k] += (n, u)
                    checks[k].extend(self._pose_checks(sensor, a, w) if step is pose_step
                                     else self._rate_checks(sensor, a, w))
                drive_rig(self.rig, step, self.options)
                each(one)
                check_rig_holding(self.rig.state(), step, self.options)

            def stop(k: int) -> None:
                try:
                    units[k][0].stop_stream()
                finally:
                    units[k][0].set_output("raw")

            try:
                each(start)
                hold(pose_step)
                hold(rate_step)
            finally:
                try:
                    each(stop, range(len(units)))
                finally:
                    bring_to_rest(self.rig, self.options.rest_timeout_s)
        return [s if s is not None else
                VerificationResult(img.serial, tuple(checks[k]), int(counts[k, 0]), int(counts[k, 1]))
                for k, ((_, img), s) in enumerate(zip(units, state, strict=True))]

    def verify(self, sensor: Sensor, image: CalibrationImage) -> VerificationResult:
        """Switch to corrected output, run the pose and rate checks, restore RAW and rest."""
        pose_step, rate_step = self._steps()
        checks: list[Measurement] = []
        samples = uncorrected = 0
        settle = settle_before_window(self.limits, moving_average_length=image.ma_length,
                                      sample_rate_hz=self.sample_rate_hz)
        sensor.set_output("corrected")
        try:
            sensor.start_stream(self.sample_rate_hz)
            drive_rig(self.rig, pose_step, self.options)
            a, w, n, u = self._capture(sensor, pose_step, settle)
            samples, uncorrected = samples + n, uncorrected + u
            checks.extend(self._pose_checks(sensor, a, w))
            drive_rig(self.rig, rate_step, self.options)
            a, w, n, u = self._capture(sensor, rate_step, settle)
            samples, uncorrected = samples + n, uncorrected + u
            checks.extend(self._rate_checks(sensor, a, w))
        finally:
            try:
                sensor.stop_stream()
                sensor.set_output("raw")
            finally:
                bring_to_rest(self.rig, self.options.rest_timeout_s)
        return VerificationResult(image.serial, tuple(checks), samples, uncorrected)
