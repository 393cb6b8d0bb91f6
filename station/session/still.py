"""Still-interval detector: labels a recording without segments as rest, pose and move.

A hand-held multi-position recording (Tedaldi et al. 2014, the method imu_tk implements) is a
still interval after power-on, then the unit held still in many orientations with hand moves in
between. Nothing in the file says where the still intervals are; this detector finds them from the
accelerometer alone, as imu_tk does:

1. **window** (``window_s``, default 1 s): the moving standard deviation of each accelerometer axis
   over a centred window; its Euclidean norm over the three axes is the *activity* (m/s^2).
2. **initial still** (``initial_still_s``, default 10 s): the recording must start still for at
   least this long (imu_tk's "init interval"). The median activity over it is the sensor's noise
   level at rest, the reference of the threshold.
3. **threshold** (``threshold``, default 3): a sample is still when its activity is below
   ``threshold`` times the reference (and below ``max_activity_mps2`` in any case).
4. **gyroscope** (when the recording has one): a turn about the vertical leaves the accelerometer
   unchanged, so a sample is also not still when the gyro's rate over the window (its windowed mean
   minus the initial still's mean, plus its windowed standard deviation, norms over the axes) exceeds
   ``threshold`` times its initial-still level or ``still_rate_dps`` (default 1 deg/s), whichever is
   larger (the floor keeps a slowly drifting gyro bias from ending a still interval).
5. **minimum length** (``min_still_s``, default 1.5 s): a sample is still in steps 3-4 only when its
   whole centred window is, so a run of still samples is the quiet interval less half a window at
   each end; runs whose quiet interval (the run plus one window) is shorter than this belong to the
   move around them. The run's edges stay where they are (half a window inside the quiet interval),
   so the moves keep their slow beginnings and ends.

The first still run, when it starts within one window of the recording's start and is at least
``initial_still_s`` long, is the ``rest`` segment (the initial still: gyro bias, eq. 3 warm-up);
every other still run is a ``pose``; everything between is a ``move``. Segments are numbered
0, 1, 2, ... in time order.

The user overrides the detector by its options (``station import ... --still-window ...``) or by
editing the ``segment``/``kind`` columns of the written session CSV, which the fit uses as given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from station.kernel.errors import FormatError
from station.session.model import Kind

__all__ = ["StillIntervals", "StillOptions", "detect_still", "label_segments"]


@dataclass(frozen=True)
class StillOptions:
    """The detector's knobs (see the module docstring). Times in s, activity in m/s^2."""

    window_s: float = 1.0
    threshold: float = 3.0
    min_still_s: float = 1.5
    initial_still_s: float = 10.0
    max_activity_mps2: float = 0.5
    still_rate_dps: float = 1.0

    def __post_init__(self) -> None:
        for name in ("window_s", "threshold", "min_still_s", "initial_still_s", "max_activity_mps2", "still_rate_dps"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise FormatError(f"still detector: {name} must be a positive number, got {value!r}")

    def describe(self) -> str:
        return (f"window {self.window_s:g} s, threshold {self.threshold:g} x initial-still activity, "
                f"min still {self.min_still_s:g} s, initial still {self.initial_still_s:g} s, gyro floor "
                f"{self.still_rate_dps:g} deg/s")


@dataclass(frozen=True, eq=False)
class StillIntervals:
    """Detected still runs ``[start, stop)`` (sample indices), in time order.

    Attributes:
        starts, stops: run bounds, (k,) each.
        rest: whether the first run is the initial still (rest).
        reference_mps2: the activity at rest the threshold is relative to (m/s^2).
        activity_mps2: the activity per sample (m/s^2), (n,).
    """

    starts: np.ndarray
    stops: np.ndarray
    rest: bool
    reference_mps2: float
    activity_mps2: np.ndarray

    def __len__(self) -> int:
        return int(self.starts.shape[0])


def _activity(accel: np.ndarray, window: int) -> np.ndarray:
    mean = uniform_filter1d(accel, window, axis=0, mode="nearest")
    mean_sq = uniform_filter1d(accel * accel, window, axis=0, mode="nearest")
    return np.sqrt(np.clip(mean_sq - mean * mean, 0.0, None).sum(axis=1))


def detect_still(
    accel_mps2: np.ndarray, sample_rate_hz: float, options: StillOptions | None = None,
    gyro_radps: np.ndarray | None = None,
) -> StillIntervals:
    """Find the still intervals of a recording from its accelerometer (m/s^2, (n, 3)) and gyroscope (rad/s)."""
    opt = options or StillOptions()
    accel = np.asarray(accel_mps2, dtype=np.float64)
    n = accel.shape[0]
    fs = float(sample_rate_hz)
    window = max(3, round(opt.window_s * fs) | 1)
    n_init = round(opt.initial_still_s * fs)
    if n < n_init + window:
        raise FormatError(f"recording of {n / fs:.1f} s is shorter than the initial still ({opt.initial_still_s:g} s) "
                          "and one window")
    activity = _activity(accel, window)
    reference = float(np.median(activity[:n_init]))
    level = min(opt.threshold * max(reference, 1e-9), opt.max_activity_mps2)
    if np.quantile(activity[:n_init], 0.9) > level:
        raise FormatError(f"the recording does not start still: over the first {opt.initial_still_s:g} s the "
                          f"accelerometer's activity reaches {np.quantile(activity[:n_init], 0.9):.3g} m/s^2 "
                          f"(threshold {level:.3g}); give --initial-still for a shorter initial still")
    still = activity < level
    if gyro_radps is not None:
        gyro = np.asarray(gyro_radps, dtype=np.float64)
        g_mean = uniform_filter1d(gyro, window, axis=0, mode="nearest")
        g_act = np.linalg.norm(g_mean - np.median(gyro[:n_init], axis=0), axis=1) + _activity(gyro, window)
        g_level = max(opt.threshold * float(np.median(g_act[:n_init])), np.radians(opt.still_rate_dps))
        still &= g_act < g_level
    edges = np.diff(np.concatenate(([0], still.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    # step 5: the quiet interval is the run plus half a window each side (the windows' erosion)
    keep = (stops - starts) >= max(2, round(opt.min_still_s * fs) - (window - 1))
    starts, stops = starts[keep], stops[keep]
    rest = bool(len(starts) and starts[0] <= window and stops[0] - starts[0] >= n_init)
    return StillIntervals(starts=starts, stops=stops, rest=rest, reference_mps2=reference, activity_mps2=activity)


def label_segments(n: int, intervals: StillIntervals) -> tuple[np.ndarray, np.ndarray]:
    """The ``segment`` and ``kind`` columns for ``n`` samples: rest / pose for the still runs, move between."""
    segment = np.empty(n, dtype=np.int64)
    kind = np.empty(n, dtype=np.int8)
    index, cursor = -1, 0
    for i, (a, b) in enumerate(zip(intervals.starts.tolist(), intervals.stops.tolist(), strict=True)):
        if a > cursor:
            index += 1
            segment[cursor:a], kind[cursor:a] = index, Kind.MOVE
        index += 1
        segment[a:b] = index
        kind[a:b] = Kind.REST if (i == 0 and intervals.rest) else Kind.POSE
        cursor = b
    if cursor < n:
        index += 1
        segment[cursor:], kind[cursor:] = index, Kind.MOVE
    return segment, kind
