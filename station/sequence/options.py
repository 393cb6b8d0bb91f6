"""Knobs of the calibration sequence: timeouts, settle guard, capture quality gates.

Times are seconds of the station clock (rig seconds: real seconds on hardware,
simulated seconds on a :class:`~station.kernel.clock.SimClock`) unless the name says
``wall``. Angles in the rig's degrees, rates deg/s for rig tolerances; gate
thresholds are SI (m/s^2, rad/s) or fractions (1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace


@dataclass(frozen=True)
class SequenceOptions:
    """How the sequence drives the rig and judges each capture.

    Rig:
        move_timeout_s: a tumble must be confirmed in position within this (s).
        spin_timeout_s: a table rate change must be confirmed settled within this (s).
        rest_timeout_s: teardown waits this long for the rig to report rest (s).
        settle_guard_s: samples of the first ``settle_guard_s`` after the rig confirmed a
            pose or rate are not captured (s); covers the sensor clock sync error.
        supervise_period_s: rig status polling period while capturing (s).
        rate_tol_dps, angle_tol_deg: rig readback tolerances while capturing (deg/s, deg).
        rig_reconnect_is_error: a rig link that dropped and had to be re-established during
            the run makes the run a station ERROR (the rig went unsupervised for a while).

    Sensors:
        sync_tries: GET_STATUS round trips per clock sync; the shortest wins.
        silence_timeout_s: no sample for this long while capturing is a sensor timeout (s);
            at least ``silence_floor_wall_s`` wall seconds.

    Quality gates (per unit and captured step):
        min_sample_fraction: received / expected samples in a window, at least this (1).
        max_dropped_fraction: frames lost to sequence gaps in a window, at most this (1).
        stillness_gyro_radps, stillness_accel_mps2: during rest and poses, the largest
            per-axis std of the linearly detrended samples (rad/s, m/s^2).
        gravity_tolerance: rest/pose ``| |mean a| / g - 1 |`` at most this (1).
        rate_tolerance, rate_offset_radps: rate steps: the mean gyro rate about the
            commanded axis within ``rate_tolerance * |commanded| + rate_offset_radps`` of it.
        rate_steadiness_radps: rate steps: detrended std about the commanded axis (rad/s).

    Station timing gates (a failure is the station's, ERROR):
        max_clock_rate_error: station seconds per sensor second within ``1 +-`` this (1), beyond what the
            clock syncs resolve. Quartz clocks agree to 1e-4; 1 % still keeps a window placed from a sync at
            the step's start within 0.3 s over a 30 s hold.
        clock_check_min_s: the clock rate is judged once two syncs are this far apart in sensor time (s).
        max_frame_lateness_s: the stream may run this far behind the station clock (s), on top of the
            station's polling period.
    """

    move_timeout_s: float = 60.0
    spin_timeout_s: float = 60.0
    rest_timeout_s: float = 60.0
    settle_guard_s: float = 0.5
    supervise_period_s: float = 1.0
    rate_tol_dps: float = 0.05
    angle_tol_deg: float = 0.05
    rig_reconnect_is_error: bool = True
    sync_tries: int = 3
    silence_timeout_s: float = 2.0
    silence_floor_wall_s: float = 1.0
    min_sample_fraction: float = 0.99
    max_dropped_fraction: float = 0.001
    stillness_gyro_radps: float = math.radians(0.2)
    stillness_accel_mps2: float = 0.15
    gravity_tolerance: float = 0.06
    rate_tolerance: float = 0.05
    rate_offset_radps: float = math.radians(5.0)
    rate_steadiness_radps: float = math.radians(0.3)
    max_clock_rate_error: float = 0.01
    clock_check_min_s: float = 5.0
    max_frame_lateness_s: float = 5.0

    def for_scale(self, scale: float) -> SequenceOptions:
        """The same options with polling slowed down for a fast simulated clock (``scale`` sim s per wall s).

        Keeps the rig supervision at no more than ~20 polls per wall second.
        """
        return replace(self, supervise_period_s=max(self.supervise_period_s, 0.05 * scale))
