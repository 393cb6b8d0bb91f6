"""The regressors of the candidate effects the base model (eq. 1 + eq. 3) leaves out.

The candidates themselves (names, units, simulator and compensation mappings, identifiability) are
:mod:`station.diagnose.effect_registry`; this module holds their regressors. Each *mean* candidate is a set
of regressors built from the session's references and metadata: per sample an array ``Z`` of shape
(n, 3, p) such that the effect adds ``Z[i, k] @ theta`` to output axis k of sample i (theta: p
parameters in SI). They are
block-averaged by :mod:`station.diagnose.residuals` and fitted jointly with the base
model's linear terms by :mod:`station.diagnose.selection`. The selection asks for them a piece of samples
at a time (:class:`Rows`, the ``*_rows`` functions): a long recording's (n, 3, p) arrays are never held whole
there; each candidate's whole array is still there for a caller that wants it (the function of its name).
Two candidates are not mean terms: ``bias_random_walk`` changes the block covariance and ``outliers`` is a count.

Units: ``u = M ref`` in m/s^2 (accelerometer) or rad/s (gyroscope), temperature rise in K,
time in s. :func:`station.diagnose.effect_registry.engineering` converts fitted SI parameters to the units the
report uses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from station.diagnose.residuals import Baseline, SensorData
from station.kernel.geometry import POSE_ANGLES_DEG, rotation_matrices, up_vector
from station.physics.effects import EARTH_RATE_RADPS

#: Largest time offset (s) the exact-delay candidate searches.
MAX_DELAY_S = 0.05

_DEG = math.pi / 180.0


@dataclass(frozen=True)
class Rows:
    """A candidate's per-sample regressors a piece at a time: ``of(lo, hi)`` is rows lo:hi of the (n, 3, p)
    array (the same numbers as the whole array's rows), so that block means and fitted signals are summed a piece
    of samples at a time (:meth:`station.diagnose.residuals.SensorData.block_mean_of`)."""

    n: int
    of: Callable[[int, int], np.ndarray]

    def whole(self) -> np.ndarray:
        """The whole (n, 3, p) array."""
        return self.of(0, self.n)


def rows_of(z: np.ndarray) -> Rows:
    """The rows of an array already made."""
    return Rows(len(z), lambda lo, hi: z[lo:hi])


Builder = Callable[[Baseline, SensorData], np.ndarray | None]
RowsBuilder = Callable[[Baseline, SensorData], Rows | None]


def whole(rows: RowsBuilder) -> Builder:
    """The builder of the whole (n, 3, p) array of a candidate given by its rows (:func:`rows_builder` finds the
    rows again from it)."""

    def build(b: Baseline, s: SensorData) -> np.ndarray | None:
        r = rows(b, s)
        return None if r is None else r.whole()

    name = rows.__name__
    build.__name__ = build.__qualname__ = name[:-5] if name.endswith("_rows") else "build"
    build.__doc__ = rows.__doc__
    _ROWS_OF[build] = rows
    return build


def rows_builder(build: Builder) -> RowsBuilder | None:
    """The rows of a builder made by :func:`whole` (None for another)."""
    return _ROWS_OF.get(build)


_ROWS_OF: dict[Builder, RowsBuilder] = {}


def _diag(values: np.ndarray) -> np.ndarray:
    """(n, 3) per-axis regressors -> (n, 3, 3) with axis k's regressor in parameter k."""
    z = np.zeros((values.shape[0], 3, 3))
    for k in range(3):
        z[:, k, k] = values[:, k]
    return z


def _diag_rows(b: Baseline, s: SensorData, values: Callable[[slice], np.ndarray]) -> Rows:
    """Rows of the per-axis regressors ``values(rows)`` (elementwise in the samples), diagonal as :func:`_diag`."""
    return Rows(len(s.ref), lambda lo, hi: _diag(values(slice(lo, hi))))


def temperature_bias_rows(b: Baseline, s: SensorData) -> Rows | None:
    if not np.any(b.d_temp):
        return None
    return _diag_rows(b, s, lambda r: np.repeat(b.d_temp[r, None], 3, axis=1))


def temperature_scale_rows(b: Baseline, s: SensorData) -> Rows | None:
    if not np.any(b.d_temp):
        return None
    return _diag_rows(b, s, lambda r: s.u_rows(r.start, r.stop) * b.d_temp[r, None])


def g_sensitivity_rows(b: Baseline, s: SensorData) -> Rows:
    ref = b.session.ref_accel_mps2

    def of(lo: int, hi: int) -> np.ndarray:
        f = np.nan_to_num(ref[lo:hi])
        z = np.zeros((len(f), 3, 9))
        for k in range(3):
            z[:, k, 3 * k:3 * k + 3] = f
        return z

    return Rows(len(ref), of)


def nonlinearity_rows(b: Baseline, s: SensorData) -> Rows:
    return _diag_rows(b, s, lambda r: (u := s.u_rows(r.start, r.stop)) * np.abs(u))


def poly_even_rows(b: Baseline, s: SensorData) -> Rows:
    """IEEE scale polynomial, even term: ``k2 u^2`` per axis, k2 relative at the reference input (1/U)."""
    return _diag_rows(b, s, lambda r: s.u_rows(r.start, r.stop) ** 2)


def poly_odd_rows(b: Baseline, s: SensorData) -> Rows:
    """IEEE scale polynomial, odd term: ``k3 u^3`` per axis (1/U^2)."""
    return _diag_rows(b, s, lambda r: s.u_rows(r.start, r.stop) ** 3)


def asymmetry_rows(b: Baseline, s: SensorData) -> Rows:
    return _diag_rows(b, s, lambda r: 0.5 * np.abs(s.u_rows(r.start, r.stop)))


temperature_bias = whole(temperature_bias_rows)
temperature_scale = whole(temperature_scale_rows)
g_sensitivity = whole(g_sensitivity_rows)
nonlinearity = whole(nonlinearity_rows)
poly_even = whole(poly_even_rows)
poly_odd = whole(poly_odd_rows)
asymmetry = whole(asymmetry_rows)


def _gradient_rows(values: np.ndarray, t: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Rows lo:hi of ``np.gradient(values, t, axis=0)``, from those rows and one neighbour on each side
    (second-order central differences inside, first-order one-sided at the recording's ends, as numpy's)."""
    a, b = max(lo - 1, 0), min(hi + 1, len(t))
    if b - a < 2:
        return np.gradient(values[a:b], axis=0) if b - a > 1 else np.zeros((b - a, *values.shape[1:]))
    return np.gradient(values[a:b], t[a:b], axis=0)[lo - a:hi - a]


def lever_arm_rows(b: Baseline, s: SensorData) -> Rows | None:
    rate, t = b.session.ref_gyro_radps, b.session.t_s
    if not any(np.any(np.nan_to_num(rate[lo:lo + _PIECE])) for lo in range(0, len(rate), _PIECE)):
        return None
    m = np.nan_to_num(s.params.misalignment)

    def of(lo: int, hi: int) -> np.ndarray:
        a, c = max(lo - 1, 0), min(hi + 1, len(t))
        w_near = np.nan_to_num(rate[a:c])
        wp, ap = w_near[lo - a:hi - a], _gradient_rows(w_near, t[a:c], lo - a, hi - a)
        z = np.zeros((hi - lo, 3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = 1.0
            extra = np.cross(wp, np.cross(wp, e)) + np.cross(ap, e)  # w x (w x r) + alpha x r per unit r_j
            z[:, :, j] = extra @ m.T
        return z

    return Rows(len(t), of)


lever_arm = whole(lever_arm_rows)


def earth_rate_world(latitude_deg: float, heading_deg: float) -> np.ndarray:
    """Earth rate (rad/s) in the rig's world frame (x, y horizontal, y at ``heading_deg`` from north, z up)."""
    lat, head = math.radians(latitude_deg), math.radians(heading_deg)
    north = np.array([-math.sin(head), math.cos(head), 0.0])
    return EARTH_RATE_RADPS * (math.cos(lat) * north + np.array([0.0, 0.0, math.sin(lat)]))


def _quat_mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton products ``p q`` of quaternions (n, 4), scalar last (the rotation q, then p); written out per
    component (``np.cross`` on (n, 3) took half the time of the attitude scan)."""
    px, py, pz, pw = p.T
    qx, qy, qz, qw = q.T
    out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    out[:, 0] = pw * qx + qw * px + py * qz - pz * qy  # pw qv + qw pv + pv x qv
    out[:, 1] = pw * qy + qw * py + pz * qx - px * qz
    out[:, 2] = pw * qz + qw * pz + px * qy - py * qx
    out[:, 3] = pw * qw - (px * qx + py * qy + pz * qz)
    return out


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of quaternions (n, 4), scalar last (normalized here)."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)


def attitude_rows(b: Baseline) -> Callable[[int, int], np.ndarray] | None:
    """Rows lo:hi of :func:`attitude` as ``rows(lo, hi)`` -> (hi - lo, 3, 3), from the scanned quaternions kept
    (n, 4); None when the first segment's pose is not one of the rig's six poses."""
    session = b.session
    f0 = np.nan_to_num(session.ref_accel_mps2[0])
    if not np.any(f0):
        return None
    up0 = f0 / np.linalg.norm(f0)
    start = [p for p in POSE_ANGLES_DEG if up0 @ up_vector(p) > 0.999]
    if not start:
        return None
    roll, pitch = POSE_ANGLES_DEG[start[0]]
    r0 = rotation_matrices(np.array(roll * _DEG), np.array(pitch * _DEG), np.array(0.0)).reshape(3, 3)
    quat = _increments(session.t_s, session.ref_gyro_radps)
    _prefix_products(quat)
    return lambda lo, hi: np.einsum("ij,njk->nik", r0, _quat_matrix(quat[lo:hi]))


def attitude(b: Baseline) -> np.ndarray | None:
    """Sensor-to-world rotations (n, 3, 3) of the station's rig, from the rest pose (yaw 0) and the
    integrated rate reference; None when the first segment's pose is not one of the rig's six poses.

    The product of the per-sample body-frame increments ``exp([w dt]x)`` (quaternions) is formed
    by a parallel prefix scan (log2 n vectorized steps).
    """
    rows = attitude_rows(b)
    if rows is None:
        return None
    n = len(b.session)
    out = np.empty((n, 3, 3))
    for lo in range(0, n, _PIECE):  # elementwise per sample: the same numbers a piece at a time
        out[lo:lo + _PIECE] = rows(lo, min(lo + _PIECE, n))
    return out


def _prefix_products(quat: np.ndarray) -> None:
    """Replace the quaternions (n, 4) by their prefix products in place, ``q_0 ... q_i`` in row i: a parallel
    prefix scan (log2 n vectorized steps, row i taking row i - d's product at step d). Each step runs from the
    last rows down, a piece at a time, so that every piece still reads the step's inputs: no copy of the whole."""
    n = len(quat)
    d = 1
    while d < n:
        for hi in range(n, d, -_PIECE):
            lo = max(hi - _PIECE, d)
            quat[lo:hi] = _quat_mul(quat[lo - d:hi - d], quat[lo:hi])
        d *= 2


#: Samples per piece of :func:`attitude`'s rotation matrices and the scan of its quaternions.
_PIECE = 1 << 16


def _increments(t_s: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Per-sample body-frame rotation increments ``exp([w dt]x)`` (n, 4), scalar last, of the rate reference
    (rad/s, NaN -> 0; trapezoid rate over each interval), made a piece at a time (each with the sample before)."""
    n = len(t_s)
    out = np.empty((n, 4))
    for lo in range(0, n, _PIECE):
        hi, a = min(lo + _PIECE, n), max(lo - 1, 0)
        t = t_s[a:hi]
        w = np.nan_to_num(rate[a:hi])
        dt = np.diff(t, prepend=t[0])
        wm = w.copy()
        wm[1:] = 0.5 * (w[1:] + w[:-1])  # trapezoid rate over each interval
        rotvec = wm * dt[:, None]
        angle = np.linalg.norm(rotvec, axis=1, keepdims=True)
        # sin(a/2)/a, with its limit 1/2 - a^2/48 for small a
        half = np.where(angle > 1e-6, np.sin(0.5 * angle) / np.where(angle > 1e-6, angle, 1.0),
                        0.5 - angle**2 / 48.0)
        out[lo:hi] = np.concatenate([rotvec * half, np.cos(0.5 * angle)], axis=1)[lo - a:]
    return out


def earth_rotation_rows(b: Baseline, s: SensorData) -> Rows | None:
    session = b.session
    lat = session.meta_float("latitude_deg")
    if lat is None:
        return None
    head = session.meta_float("heading_deg") or 0.0
    e = earth_rate_world(lat, head)
    m = np.nan_to_num(s.params.misalignment)
    rot = attitude_rows(b)
    ref = session.ref_accel_mps2

    def of(lo: int, hi: int) -> np.ndarray:
        if rot is not None:
            seen = np.einsum("nij,i->nj", rot(lo, hi), e)  # R^T e
        else:  # only the vertical part: along 'up' whatever the yaw
            f = np.nan_to_num(ref[lo:hi])
            norm = np.linalg.norm(f, axis=1)
            seen = np.where(norm[:, None] > 0, f / np.where(norm > 0, norm, 1.0)[:, None], 0.0) * e[2]
        return (seen @ m.T)[:, :, None]

    return Rows(len(ref), of)


earth_rotation = whole(earth_rotation_rows)


def time_offset_rows(b: Baseline, s: SensorData) -> Rows | None:
    t = b.session.t_s

    def of(lo: int, hi: int) -> np.ndarray:
        # y(t) = u(t - delta) ~ u(t) - delta du/dt (first order: the start of the search)
        a, c = max(lo - 1, 0), min(hi + 1, len(t))
        return -_gradient_rows(s.u_rows(a, c), t[a:c], lo - a, hi - a)[:, :, None]

    if not any(np.any(of(lo, min(lo + _PIECE, len(t)))) for lo in range(0, len(t), _PIECE)):
        return None
    return Rows(len(t), of)


time_offset = whole(time_offset_rows)


def delay_rows(b: Baseline, s: SensorData, tau_s: float) -> Rows:
    """Rows of :func:`delay_regressor`: the reference of rows lo:hi interpolated at ``t - tau`` from the rows
    around them (np.interp on the table's rows that bracket every query: the same numbers as on the whole)."""
    if abs(tau_s) < 1e-6:
        first = time_offset_rows(b, s)
        return first if first is not None else Rows(len(s.ref), lambda lo, hi: np.zeros((hi - lo, 3, 1)))
    t = b.session.t_s

    def of(lo: int, hi: int) -> np.ndarray:
        q = t[lo:hi] - tau_s
        a = min(max(int(np.searchsorted(t, q.min(), side="right")) - 1, 0), lo)  # the table holds rows lo:hi too
        c = max(min(int(np.searchsorted(t, q.max(), side="left")) + 1, len(t)), hi)
        table = s.u_rows(a, c)
        u = table[lo - a:hi - a]
        shifted = np.stack([np.interp(q, t[a:c], table[:, k]) for k in range(3)], axis=1)
        return ((shifted - u) / tau_s)[:, :, None]

    return Rows(len(t), of)


def delay_regressor(b: Baseline, s: SensorData, tau_s: float) -> np.ndarray:
    """The exact delay as a regressor at ``tau_s`` (s): ``(u(t - tau) - u(t)) / tau`` (n, 3, 1), the reference
    interpolated at ``t - tau``, so that the coefficient is the delay itself when it equals ``tau_s``
    (``y(t) = u(t - tau)``, eq. 1 with the motion late); the first-order regressor ``-du/dt`` at ``tau -> 0``."""
    return delay_rows(b, s, tau_s).whole()


__all__ = [
    "MAX_DELAY_S",
    "Rows",
    "asymmetry",
    "asymmetry_rows",
    "attitude",
    "delay_regressor",
    "delay_rows",
    "earth_rate_world",
    "earth_rotation",
    "earth_rotation_rows",
    "g_sensitivity",
    "g_sensitivity_rows",
    "lever_arm",
    "lever_arm_rows",
    "nonlinearity",
    "nonlinearity_rows",
    "poly_even",
    "poly_even_rows",
    "poly_odd",
    "poly_odd_rows",
    "rows_builder",
    "rows_of",
    "temperature_bias",
    "temperature_bias_rows",
    "temperature_scale",
    "temperature_scale_rows",
    "time_offset",
    "time_offset_rows",
    "whole",
]
