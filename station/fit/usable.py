"""Is a parameter set usable by Algorithm 1? The checks a firmware image and ``station correct`` share.

A parameter set read from a file can hold anything JSON can: these checks refuse, with one line
(:class:`~station.kernel.errors.FormatError`), what the corrector cannot run or what no sensor
has: non-finite values, a misalignment matrix that is singular or far from the identity (a scale
outside :data:`SCALE_RANGE`, a cross-axis term beyond :data:`MAX_CROSS_AXIS`), biases beyond any
MEMS sensor's range, a non-positive correlation time, a sample period outside
:data:`SAMPLE_PERIOD_RANGE_S`, a moving-average length the corrector cannot hold (1..
:data:`MAX_MOVING_AVERAGE`, the EEPROM field's 16 bits).
"""

from __future__ import annotations

import math

import numpy as np

from station.fit.params import ParameterSet, TriadParams
from station.kernel.errors import FormatError

#: diagonal of M (scale factor) a sensor can have
SCALE_RANGE = (0.5, 2.0)
#: largest |off-diagonal| of M (cross-axis sensitivity, ~30 deg)
MAX_CROSS_AXIS = 0.5
#: largest condition number of M
MAX_CONDITION = 1e3
#: largest |bias| (static plus drifting): accelerometer m/s^2 (~10 g), gyroscope rad/s (~570 deg/s)
MAX_BIAS = {"accel": 100.0, "gyro": 10.0}
#: sample period T_sampl (s): 100 kHz .. 0.1 Hz
SAMPLE_PERIOD_RANGE_S = (1e-5, 10.0)
#: moving-average length n of eq. (6) the corrector holds (the EEPROM image's 16-bit field)
MAX_MOVING_AVERAGE = 0xFFFF


def _triad(t: TriadParams, name: str) -> None:
    m = np.asarray(t.misalignment, dtype=np.float64)
    if not np.isfinite(m).all():
        raise FormatError(f"parameter set: {name} misalignment matrix has non-finite entries")
    diag = np.diag(m)
    lo, hi = SCALE_RANGE
    if np.any((diag < lo) | (diag > hi)):
        raise FormatError(f"parameter set: {name} scale factors {diag.tolist()} are outside {lo:g}..{hi:g}")
    cross = np.abs(m - np.diag(diag)).max()
    if cross > MAX_CROSS_AXIS:
        raise FormatError(f"parameter set: {name} cross-axis term {cross:.3g} exceeds {MAX_CROSS_AXIS:g}")
    cond = float(np.linalg.cond(m))
    if not math.isfinite(cond) or cond > MAX_CONDITION:
        raise FormatError(f"parameter set: {name} misalignment matrix is near singular (condition {cond:.3g})")
    limit = MAX_BIAS[name]
    for field in ("bias_static", "bias_drift"):
        v = np.asarray(getattr(t, field), dtype=np.float64)
        if not np.isfinite(v).all():
            raise FormatError(f"parameter set: {name} {field} has non-finite entries")
        if np.abs(v).max() > limit:
            raise FormatError(f"parameter set: {name} {field} {v.tolist()} exceeds {limit:g} in magnitude")
    tc = np.asarray(t.correlation_time_s, dtype=np.float64)
    if np.any(np.isinf(tc)) or np.any(tc[~np.isnan(tc)] <= 0):
        raise FormatError(f"parameter set: {name} correlation time must be positive or null, got {tc.tolist()}")


def check_usable(params: ParameterSet) -> None:
    """Refuse a parameter set Algorithm 1 cannot run with (see the module docstring)."""
    ts = params.sample_period_s
    lo, hi = SAMPLE_PERIOD_RANGE_S
    if not (isinstance(ts, float) and math.isfinite(ts) and lo <= ts <= hi):
        raise FormatError(f"parameter set: sample period {ts!r} s is outside {lo:g}..{hi:g} s")
    n = params.moving_average_length
    if not 1 <= n <= MAX_MOVING_AVERAGE:
        raise FormatError(f"parameter set: moving-average length {n} is outside 1..{MAX_MOVING_AVERAGE}")
    _triad(params.accel, "accel")
    _triad(params.gyro, "gyro")
