"""Algorithm 1 of Kolhoff & Kemper, sample by sample, as the unit's firmware runs it.

Per time step i and per channel j of six (ax, ay, az in m/s^2, gx, gy, gz in rad/s):

    line 4:  g_ij = (1 - T_sampl / T_c,j) * g_(i-1),j        forward Euler of eq. (3), w_g neglected
    line 5:  x_drift,ij = g_ij * b_drift,j
    line 6:  x_temp,j = x~_ij - x_drift,ij - b_stat,j
    line 7:  x_MA,j = one-sided moving average of the last n values of x_temp,j, eq. (6)
    line 8:  solve M x_i = x_MA per triad (accelerometer, gyroscope)

With a ``station-params/2`` set that carries them, line 6 also removes the compensable effects beyond
eq. (1), per channel, with dT = T_i - T_ref the unit's temperature at the sample minus the set's
reference (see :mod:`station.kernel.parameters`):

    line 6':  v = x~_ij - x_drift,ij - b_stat,j - (c_1 dT + c_2 dT^2 + c_3 dT^3)     temperature bias
              u = 2 v / (1 + sqrt(1 + 4 k |v|))                                       inverse of u + k u|u|
              x_temp,j = u / (1 + s_1 dT + s_2 dT^2 + s_3 dT^3)                       temperature scale

With the IEEE Std 952 polynomial ``y = u + k u|u| + k2 u^2 + k3 u^3`` (``station-params/3``: k2, k3 non-zero)
the inverse is three Newton steps from u = v (:func:`invert_scale`; for |k u|, |k2 u|, |k3 u^2| < 0.1 the error
after them is below 1e-12 u): the same operations, in the same order, in the streaming and the batch code.

Line 0 (``station-params/3`` with a time offset tau, the sensor's lag behind the rig in samples s = tau/T_sampl):
the raw input is moved onto the rig's time, ``z_i = x~ at sample position i + s``, by a straight line through
two raw samples (:func:`shift_taps`):

    lead (s < 0):  linear interpolation between the two samples that bracket i + s, both in the past: a
                   delay line of d = ceil(-s) + ... samples, causal;
    lag  (s > 0):  the future is not available to a causal corrector: linear extrapolation along the line
                   through x~_(i-1) and x~_i, z_i = x~_i + s (x~_i - x~_(i-1)); its noise is averaged by line 7
                   (the variance of eq. 6's output grows by (2 s^2 + 2 s) / n^2 only). At most
                   :data:`MAX_LAG_SAMPLES` samples of lag are applied; a set with more is refused.

A sample the line needs from before the corrector's first sample is that first sample (held). Lines 4-8 then
run on z. A set without a time offset skips line 0.

A set without them (every coefficient zero) runs the plain lines 4-8, bit for bit as before.

Conventions (shared with :mod:`station.correct.batch`):

* Sample index i counts samples since power-on; the power-on sample i = 0 has g = 1, so
  sample i sees g_i = (1 - T_sampl/T_c)^i. A corrector started later (``start_index`` = k)
  begins with g = (1 - T_sampl/T_c)^k and an empty moving-average buffer.
* During the first n - 1 samples the moving average is over the samples available.
* Where T_c is NaN (unresolved) or b_drift is 0 or NaN, the drift term is 0. T_c = inf
  keeps the drift constant. For 0 < T_c <= T_sampl the Euler factor would be <= 0
  (unstable); it is clamped to 0, i.e. the drift is removed at the power-on sample only.
* A non-finite input makes the n outputs whose averaging window holds it non-finite;
  the corrector recovers once it has left the window.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from station.kernel.errors import FormatError
from station.kernel.parameters import MAX_LAG_SAMPLES, MAX_LEAD_SAMPLES, ParameterSet, TriadParams

CHANNELS: tuple[str, ...] = ("ax", "ay", "az", "gx", "gy", "gz")

# A misalignment matrix whose condition number exceeds this cannot be inverted usefully.
_MAX_CONDITION = 1e10
#: Newton steps of the polynomial's inverse (line 6').
NEWTON_STEPS = 3


def shift_taps(time_offset_s: float, sample_period_s: float) -> tuple[int, float, float]:
    """Line 0's two taps for the time offset: ``z_i = a x_(i-d) + b x_(i-d+1)``; returns (d, a, b), with d = 0
    for no shift. Raises :class:`FormatError` for an offset beyond :data:`MAX_LAG_SAMPLES` /
    :data:`MAX_LEAD_SAMPLES`."""
    s = float(time_offset_s) / float(sample_period_s)
    if not math.isfinite(s):
        raise FormatError(f"parameter set: time offset {time_offset_s!r} s is not finite; cannot correct")
    if s == 0.0:
        return 0, 0.0, 1.0
    if s > MAX_LAG_SAMPLES or s < -MAX_LEAD_SAMPLES:
        raise FormatError(f"parameter set: time offset {time_offset_s:g} s ({s:.3g} samples) is beyond what "
                          f"Algorithm 1 applies ({MAX_LAG_SAMPLES:g} samples of lag, {MAX_LEAD_SAMPLES:g} of lead)")
    if s > 0.0:  # lag: extrapolate along x_(i-1) -> x_i
        return 1, -s, 1.0 + s
    m = math.floor(s)  # lead: interpolate between x_(i+m) and x_(i+m+1), both in the past
    f = s - m
    return -m, 1.0 - f, f


def invert_scale(v: float, k: float, k2: float, k3: float) -> float:
    """u with ``u + k u|u| + k2 u^2 + k3 u^3 = v``: :data:`NEWTON_STEPS` Newton steps from u = v."""
    u = v
    for _ in range(NEWTON_STEPS):
        au = abs(u)
        f = u + k * u * au + k2 * u * u + k3 * u * u * u - v
        d = 1.0 + 2.0 * k * au + 2.0 * k2 * u + 3.0 * k3 * u * u
        u = u - f / d
    return u


def invert_scale_array(v: np.ndarray, k: np.ndarray, k2: np.ndarray, k3: np.ndarray) -> np.ndarray:
    """:func:`invert_scale` over a block (n, 6), elementwise, the same operations in the same order."""
    u = v
    for _ in range(NEWTON_STEPS):
        au = np.abs(u)
        f = u + k * u * au + k2 * u * u + k3 * u * u * u - v
        d = 1.0 + 2.0 * k * au + 2.0 * k2 * u + 3.0 * k3 * u * u
        u = u - f / d
    return u


def _triad_inverse(triad: TriadParams, name: str) -> np.ndarray:
    """Inverse of the misalignment matrix M (dimensionless), checked."""
    m = np.asarray(triad.misalignment, dtype=np.float64)
    if not np.isfinite(m).all():
        raise FormatError(f"parameter set: {name} misalignment matrix has non-finite entries")
    cond = np.linalg.cond(m)
    if not np.isfinite(cond) or cond > _MAX_CONDITION:
        raise FormatError(f"parameter set: {name} misalignment matrix is singular (condition {cond:.3g})")
    return np.linalg.inv(m)


def _channel_drift(triad: TriadParams, sample_period_s: float, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis Euler factor rho = 1 - T_sampl/T_c and the effective b_drift (0 where unused)."""
    tc = np.asarray(triad.correlation_time_s, dtype=np.float64)
    bd = np.asarray(triad.bias_drift, dtype=np.float64)
    if np.any(tc <= 0):
        raise FormatError(f"parameter set: {name} correlation time must be positive, got {tc.tolist()}")
    active = np.isfinite(bd) & (bd != 0) & ~np.isnan(tc)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(active, 1.0 - sample_period_s / np.where(active, tc, 1.0), 1.0)
    rho = np.maximum(rho, 0.0)
    return rho, np.where(active, bd, 0.0)


@dataclass(frozen=True, eq=False)
class CorrectionConstants:
    """What the firmware computes once when it loads a parameter set.

    Attributes:
        sample_period_s: T_sampl (s).
        ma_length: n of the moving average, eq. (6).
        rho: Euler factor 1 - T_sampl/T_c per channel (ax..gz), shape (6,); 1 where unused.
        bias_drift: b_drift per channel (m/s^2 for ax..az, rad/s for gx..gz), 0 where the
            drift term is dropped, shape (6,).
        bias_static: b_stat per channel (same units), shape (6,).
        accel_inverse: M_a^-1, shape (3, 3).
        gyro_inverse: M_w^-1, shape (3, 3).
        reference_temperature_degc: T_ref (degC) of the temperature terms; NaN without them.
        temp_bias: c_1..c_3 per channel, (6, 3) (m/s^2/K^j, rad/s/K^j); temp_scale: s_1..s_3 (1/K^j), (6, 3).
        nonlinearity: k of ``u + k u|u|`` per channel (1/U), (6,).
        quadratic, cubic: k2 (1/U), k3 (1/U^2) of the IEEE 952 polynomial per channel, (6,).
        shift: line 0's taps (d, a, b) for the time offset (:func:`shift_taps`); d = 0: no shift.
        extended: line 6' is active (a temperature term or a nonlinearity is non-zero).
    """

    sample_period_s: float
    ma_length: int
    rho: np.ndarray
    bias_drift: np.ndarray
    bias_static: np.ndarray
    accel_inverse: np.ndarray
    gyro_inverse: np.ndarray
    reference_temperature_degc: float = math.nan
    temp_bias: np.ndarray = field(default_factory=lambda: np.zeros((6, 3)))
    temp_scale: np.ndarray = field(default_factory=lambda: np.zeros((6, 3)))
    nonlinearity: np.ndarray = field(default_factory=lambda: np.zeros(6))
    quadratic: np.ndarray = field(default_factory=lambda: np.zeros(6))
    cubic: np.ndarray = field(default_factory=lambda: np.zeros(6))
    shift: tuple[int, float, float] = (0, 0.0, 1.0)

    @property
    def extended(self) -> bool:
        return self.uses_temperature or bool(np.any(self.nonlinearity != 0)) or self.polynomial

    @property
    def polynomial(self) -> bool:
        """The IEEE 952 polynomial (k2 or k3 non-zero): line 6' inverts by Newton steps."""
        return bool(np.any(self.quadratic != 0) or np.any(self.cubic != 0))

    @property
    def uses_temperature(self) -> bool:
        return math.isfinite(self.reference_temperature_degc) and bool(
            np.any(self.temp_bias != 0) or np.any(self.temp_scale != 0)
        )

    @classmethod
    def from_params(cls, params: ParameterSet) -> CorrectionConstants:
        ts = float(params.sample_period_s)
        if not (math.isfinite(ts) and ts > 0):
            raise FormatError(f"parameter set: sample period must be a positive number of seconds, got {ts}")
        n = int(params.moving_average_length)
        if n < 1:
            raise FormatError(f"parameter set: moving average length must be >= 1, got {n}")
        bias = np.concatenate([params.accel.bias_static, params.gyro.bias_static]).astype(np.float64)
        if not np.isfinite(bias).all():
            raise FormatError("parameter set: static bias has non-finite entries; cannot correct")
        rho_a, bd_a = _channel_drift(params.accel, ts, "accel")
        rho_g, bd_g = _channel_drift(params.gyro, ts, "gyro")
        t_ref = float(params.reference_temperature_degc)
        temp_bias = np.vstack([params.accel.temp_bias_coeff, params.gyro.temp_bias_coeff]).astype(np.float64)
        temp_scale = np.vstack([params.accel.temp_scale_coeff, params.gyro.temp_scale_coeff]).astype(np.float64)
        nonlin = np.concatenate([params.accel.scale_nonlinearity, params.gyro.scale_nonlinearity]).astype(np.float64)
        quad = np.concatenate([params.accel.scale_quadratic, params.gyro.scale_quadratic]).astype(np.float64)
        cubic = np.concatenate([params.accel.scale_cubic, params.gyro.scale_cubic]).astype(np.float64)
        if not (np.isfinite(temp_bias).all() and np.isfinite(temp_scale).all() and np.isfinite(nonlin).all()
                and np.isfinite(quad).all() and np.isfinite(cubic).all()):
            raise FormatError("parameter set: temperature or nonlinearity terms have non-finite entries; "
                              "cannot correct")
        if (np.any(temp_bias != 0) or np.any(temp_scale != 0)) and not math.isfinite(t_ref):
            raise FormatError("parameter set: temperature terms without a reference temperature; cannot correct")
        out = cls(
            sample_period_s=ts,
            ma_length=n,
            rho=np.concatenate([rho_a, rho_g]),
            bias_drift=np.concatenate([bd_a, bd_g]),
            bias_static=bias,
            accel_inverse=_triad_inverse(params.accel, "accel"),
            gyro_inverse=_triad_inverse(params.gyro, "gyro"),
            reference_temperature_degc=t_ref,
            temp_bias=temp_bias,
            temp_scale=temp_scale,
            nonlinearity=nonlin,
            quadratic=quad,
            cubic=cubic,
            shift=shift_taps(params.time_offset_s, ts),
        )
        for name in ("rho", "bias_drift", "bias_static", "accel_inverse", "gyro_inverse", "temp_bias", "temp_scale",
                     "nonlinearity", "quadratic", "cubic"):
            getattr(out, name).flags.writeable = False
        return out


def compensate_extended(c: CorrectionConstants, v: np.ndarray, temp_degc: np.ndarray | None) -> np.ndarray:
    """Line 6' over a block: ``v`` (n, 6) = x~ - x_drift - b_stat; returns x_temp (n, 6) (a new array).

    ``temp_degc`` (n,) is the unit's temperature per sample (degC); required when ``c`` has temperature terms.
    """
    out = np.array(v, dtype=np.float64)
    dt = None
    if c.uses_temperature:
        if temp_degc is None:
            raise ValueError("the parameter set compensates temperature: a temperature per sample is needed")
        dt = (np.asarray(temp_degc, dtype=np.float64) - c.reference_temperature_degc)[:, None]
        b = c.temp_bias
        out -= ((b[:, 2] * dt + b[:, 1]) * dt + b[:, 0]) * dt
    k = c.nonlinearity
    if c.polynomial:
        out = invert_scale_array(out, k, c.quadratic, c.cubic)
    elif np.any(k != 0):
        out = 2.0 * out / (1.0 + np.sqrt(np.maximum(1.0 + 4.0 * k * np.abs(out), 0.0)))
    if dt is not None:
        sc = c.temp_scale
        out /= 1.0 + ((sc[:, 2] * dt + sc[:, 1]) * dt + sc[:, 0]) * dt
    return out


def shift_block(c: CorrectionConstants, x: np.ndarray) -> np.ndarray:
    """Line 0 over a block (n, k) whose first row is the corrector's first sample: ``a x_(i-d) + b x_(i-d+1)``,
    rows before the first held at it; ``x`` itself without a shift."""
    d, a, b = c.shift
    if d == 0 or len(x) == 0:
        return x
    idx = np.arange(len(x))
    older = x[np.maximum(idx - d, 0)]
    newer = x[np.maximum(idx - d + 1, 0)]
    return a * older + b * newer


Vec3 = tuple[float, float, float]


class StreamingCorrector:
    """Algorithm 1, one 6-channel sample per :meth:`step`, in plain floating point.

    Args:
        params: the unit's parameter set (SI: accel m/s^2, gyro rad/s, times s).
        start_index: samples elapsed since power-on before the first :meth:`step`
            (0 when the corrector runs from power-on).
    """

    def __init__(self, params: ParameterSet, start_index: int = 0) -> None:
        c = CorrectionConstants.from_params(params)
        # Loading: everything the loop needs as plain floats (firmware would keep them in RAM).
        self._n = c.ma_length
        self._rho = [float(v) for v in c.rho]
        self._b_drift = [float(v) for v in c.bias_drift]
        self._b_stat = [float(v) for v in c.bias_static]
        self._ainv = [float(v) for v in c.accel_inverse.ravel()]
        self._ginv = [float(v) for v in c.gyro_inverse.ravel()]
        self._extended = c.extended
        self.uses_temperature = c.uses_temperature
        self._t_ref = float(c.reference_temperature_degc)
        self._tb = [[float(x) for x in row] for row in c.temp_bias]
        self._ts = [[float(x) for x in row] for row in c.temp_scale]
        self._k = [float(v) for v in c.nonlinearity]
        self._k2 = [float(v) for v in c.quadratic]
        self._k3 = [float(v) for v in c.cubic]
        self._poly = c.polynomial
        self._shift_d, self._shift_a, self._shift_b = c.shift
        self.reset(start_index)

    def reset(self, start_index: int = 0) -> None:
        """Restart as if ``start_index`` samples had passed since power-on (empty MA buffer)."""
        if int(start_index) != start_index or start_index < 0:
            raise ValueError(f"start_index must be a non-negative integer, got {start_index!r}")
        k = int(start_index)
        self._index = k
        self._g = [rho**k for rho in self._rho]  # g_k = (1 - T_sampl/T_c)^k, g_0 = 1 at power-on
        self._buf = [[0.0] * self._n for _ in range(6)]  # ring buffers of x_temp, eq. (6)
        self._slot = 0
        self._count = 0
        self._delay: list[tuple[float, ...]] = []  # line 0: the last d raw samples, oldest first

    @property
    def index(self) -> int:
        """Samples since power-on of the next sample :meth:`step` will process."""
        return self._index

    def step(
        self, accel_mps2: Sequence[float], gyro_radps: Sequence[float], temp_degc: float | None = None
    ) -> tuple[Vec3, Vec3]:
        """Correct one sample.

        Args:
            accel_mps2: raw specific force (ax, ay, az) in m/s^2.
            gyro_radps: raw angular rate (gx, gy, gz) in rad/s.
            temp_degc: the unit's temperature at the sample (degC); required when the set compensates
                temperature (:attr:`uses_temperature`), ignored otherwise.

        Returns:
            (corrected specific force in m/s^2, corrected angular rate in rad/s), each a 3-tuple.
        """
        raw = (*accel_mps2, *gyro_radps)
        if len(raw) != 6:
            raise ValueError("step() needs three accelerometer and three gyroscope values")
        d = self._shift_d
        if d:  # line 0: the raw input moved onto the rig's time (a delay line, first sample held)
            line = self._delay
            if not line:
                line.extend([tuple(raw)] * d)
            older, newer = line[0], (line[1] if d > 1 else raw)
            sa, sb = self._shift_a, self._shift_b
            line.append(tuple(raw))
            del line[0]
            raw = tuple(sa * older[j] + sb * newer[j] for j in range(6))
        slot = self._slot
        count = self._count + 1 if self._count < self._n else self._n
        x_ma = [0.0] * 6
        dt = 0.0
        if self.uses_temperature:
            if temp_degc is None:
                raise ValueError("the parameter set compensates temperature: step() needs temp_degc")
            dt = float(temp_degc) - self._t_ref
        for j in range(6):
            g = self._g[j]  # line 4 (g of this sample)
            x_drift = g * self._b_drift[j]  # line 5
            x_temp = raw[j] - x_drift - self._b_stat[j]  # line 6
            if self._extended:  # line 6': temperature bias, nonlinearity, temperature scale
                b, sc, k = self._tb[j], self._ts[j], self._k[j]
                x_temp -= ((b[2] * dt + b[1]) * dt + b[0]) * dt
                if self._poly:
                    x_temp = invert_scale(x_temp, k, self._k2[j], self._k3[j])
                elif k != 0.0:
                    x_temp = 2.0 * x_temp / (1.0 + math.sqrt(max(1.0 + 4.0 * k * abs(x_temp), 0.0)))
                x_temp /= 1.0 + ((sc[2] * dt + sc[1]) * dt + sc[0]) * dt
            buf = self._buf[j]
            buf[slot] = x_temp  # line 7: drop the oldest value, add the new one, eq. (6)
            x_ma[j] = sum(buf) / count  # unfilled slots hold 0 during the first n - 1 samples
            self._g[j] = self._rho[j] * g  # line 4 for the next sample
        self._slot = slot + 1 if slot + 1 < self._n else 0
        self._count = count
        self._index += 1
        # line 8: M x = x_MA per triad, with the inverse precomputed at load time
        a, w = self._ainv, self._ginv
        m0, m1, m2, m3, m4, m5 = x_ma
        accel = (
            a[0] * m0 + a[1] * m1 + a[2] * m2,
            a[3] * m0 + a[4] * m1 + a[5] * m2,
            a[6] * m0 + a[7] * m1 + a[8] * m2,
        )
        gyro = (
            w[0] * m3 + w[1] * m4 + w[2] * m5,
            w[3] * m3 + w[4] * m4 + w[5] * m5,
            w[6] * m3 + w[7] * m4 + w[8] * m5,
        )
        return accel, gyro

    def run(
        self, accel_mps2: np.ndarray, gyro_radps: np.ndarray, temp_degc: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Feed a whole record through :meth:`step`; arrays (n, 3) in m/s^2 and rad/s, temperature (n,) degC."""
        a = np.asarray(accel_mps2, dtype=np.float64)
        w = np.asarray(gyro_radps, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 3 or w.shape != a.shape:
            raise ValueError(f"expected two (n, 3) arrays, got {a.shape} and {w.shape}")
        temps: list[float | None]
        if temp_degc is None:
            temps = [None] * a.shape[0]
        else:
            t = np.asarray(temp_degc, dtype=np.float64)
            if t.shape != (a.shape[0],):
                raise ValueError(f"temp_degc must have shape ({a.shape[0]},), got {t.shape}")
            temps = t.tolist()
        out_a = np.empty_like(a)
        out_w = np.empty_like(w)
        step = self.step
        for i, (ra, rw, tt) in enumerate(zip(a.tolist(), w.tolist(), temps, strict=True)):
            out_a[i], out_w[i] = step(ra, rw, tt)
        return out_a, out_w
