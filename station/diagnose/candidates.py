"""The regressors of the candidate effects the base model (eq. 1 + eq. 3) leaves out.

The candidates themselves (names, units, simulator and compensation mappings, identifiability) are
:mod:`station.diagnose.effect_registry`; this module holds their regressors. Each *mean* candidate is a set
of regressors built from the session's references and metadata: per sample an array ``Z`` of shape
(n, 3, p) such that the effect adds ``Z[i, k] @ theta`` to output axis k of sample i (theta: p
parameters in SI). They are
block-averaged by :mod:`station.diagnose.residuals` and fitted jointly with the base
model's linear terms by :mod:`station.diagnose.selection`. Two candidates are not mean
terms: ``bias_random_walk`` changes the block covariance and ``outliers`` is a count.

Units: ``u = M ref`` in m/s^2 (accelerometer) or rad/s (gyroscope), temperature rise in K,
time in s. :func:`station.diagnose.effect_registry.engineering` converts fitted SI parameters to the units the
report uses.
"""

from __future__ import annotations

import math

import numpy as np

from station.diagnose.residuals import Baseline, SensorData
from station.kernel.geometry import POSE_ANGLES_DEG, rotation_matrices, up_vector
from station.physics.effects import EARTH_RATE_RADPS

#: Largest time offset (s) the exact-delay candidate searches.
MAX_DELAY_S = 0.05

_DEG = math.pi / 180.0


def _diag(values: np.ndarray) -> np.ndarray:
    """(n, 3) per-axis regressors -> (n, 3, 3) with axis k's regressor in parameter k."""
    z = np.zeros((values.shape[0], 3, 3))
    for k in range(3):
        z[:, k, k] = values[:, k]
    return z


def temperature_bias(b: Baseline, s: SensorData) -> np.ndarray | None:
    if not np.any(b.d_temp):
        return None
    return _diag(np.repeat(b.d_temp[:, None], 3, axis=1))


def temperature_scale(b: Baseline, s: SensorData) -> np.ndarray | None:
    if not np.any(b.d_temp):
        return None
    return _diag(s.u * b.d_temp[:, None])


def g_sensitivity(b: Baseline, s: SensorData) -> np.ndarray:
    f = np.nan_to_num(b.session.ref_accel_mps2)
    z = np.zeros((len(f), 3, 9))
    for k in range(3):
        z[:, k, 3 * k:3 * k + 3] = f
    return z


def nonlinearity(b: Baseline, s: SensorData) -> np.ndarray:
    return _diag(s.u * np.abs(s.u))


def poly_even(b: Baseline, s: SensorData) -> np.ndarray:
    """IEEE scale polynomial, even term: ``k2 u^2`` per axis, k2 relative at the reference input (1/U)."""
    return _diag(s.u**2)


def poly_odd(b: Baseline, s: SensorData) -> np.ndarray:
    """IEEE scale polynomial, odd term: ``k3 u^3`` per axis (1/U^2)."""
    return _diag(s.u**3)


def asymmetry(b: Baseline, s: SensorData) -> np.ndarray:
    return _diag(0.5 * np.abs(s.u))


def _angular(b: Baseline) -> tuple[np.ndarray, np.ndarray]:
    """Rig body rate (rad/s) and angular acceleration (rad/s^2) from the rate reference."""
    w = np.nan_to_num(b.session.ref_gyro_radps)
    alpha = np.gradient(w, b.session.t_s, axis=0)
    return w, alpha


def lever_arm(b: Baseline, s: SensorData) -> np.ndarray | None:
    w, alpha = _angular(b)
    if not np.any(w):
        return None
    m = np.nan_to_num(s.params.misalignment)
    z = np.zeros((len(w), 3, 3))
    for lo in range(0, len(w), _PIECE):  # a piece at a time: no (n, 3) temporaries (the same numbers)
        wp, ap = w[lo:lo + _PIECE], alpha[lo:lo + _PIECE]
        for j in range(3):
            e = np.zeros(3)
            e[j] = 1.0
            extra = np.cross(wp, np.cross(wp, e)) + np.cross(ap, e)  # w x (w x r) + alpha x r per unit r_j
            z[lo:lo + _PIECE, :, j] = extra @ m.T
    return z


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


def attitude(b: Baseline) -> np.ndarray | None:
    """Sensor-to-world rotations (n, 3, 3) of the station's rig, from the rest pose (yaw 0) and the
    integrated rate reference; None when the first segment's pose is not one of the rig's six poses.

    The product of the per-sample body-frame increments ``exp([w dt]x)`` (quaternions) is formed
    by a parallel prefix scan (log2 n vectorized steps).
    """
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
    d = 1
    n = len(quat)
    while d < n:
        quat = np.concatenate([quat[:d], _quat_mul(quat[:-d], quat[d:])])
        d *= 2
    # the (n, 3, 3) result filled a piece at a time: the matrices of the whole record and their temporaries
    # held it several times over (elementwise per sample: the same numbers)
    out = np.empty((n, 3, 3))
    for lo in range(0, n, _PIECE):
        out[lo:lo + _PIECE] = np.einsum("ij,njk->nik", r0, _quat_matrix(quat[lo:lo + _PIECE]))
    return out


#: Samples per piece of :func:`attitude`'s rotation matrices.
_PIECE = 1 << 16


def _increments(t_s: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Per-sample body-frame rotation increments ``exp([w dt]x)`` (n, 4), scalar last, of the rate reference
    (rad/s, NaN -> 0; trapezoid rate over each interval)."""
    w = np.nan_to_num(rate)
    dt = np.diff(t_s, prepend=t_s[0])
    wm = w.copy()
    wm[1:] = 0.5 * (w[1:] + w[:-1])  # trapezoid rate over each interval
    rotvec = wm * dt[:, None]
    angle = np.linalg.norm(rotvec, axis=1, keepdims=True)
    # sin(a/2)/a, with its limit 1/2 - a^2/48 for small a
    half = np.where(angle > 1e-6, np.sin(0.5 * angle) / np.where(angle > 1e-6, angle, 1.0), 0.5 - angle**2 / 48.0)
    return np.concatenate([rotvec * half, np.cos(0.5 * angle)], axis=1)


def earth_rotation(b: Baseline, s: SensorData) -> np.ndarray | None:
    session = b.session
    lat = session.meta_float("latitude_deg")
    if lat is None:
        return None
    head = session.meta_float("heading_deg") or 0.0
    e = earth_rate_world(lat, head)
    rot = attitude(b)
    if rot is not None:
        seen = np.einsum("nij,i->nj", rot, e)  # R^T e
    else:  # only the vertical part: along 'up' whatever the yaw
        f = np.nan_to_num(session.ref_accel_mps2)
        norm = np.linalg.norm(f, axis=1)
        seen = np.where(norm[:, None] > 0, f / np.where(norm > 0, norm, 1.0)[:, None], 0.0) * e[2]
    return (seen @ np.nan_to_num(s.params.misalignment).T)[:, :, None]


def time_offset(b: Baseline, s: SensorData) -> np.ndarray | None:
    du = np.gradient(s.u, b.session.t_s, axis=0)
    if not np.any(du):
        return None
    return -du[:, :, None]  # y(t) = u(t - delta) ~ u(t) - delta du/dt (first order: the start of the search)


def delay_regressor(b: Baseline, s: SensorData, tau_s: float) -> np.ndarray:
    """The exact delay as a regressor at ``tau_s`` (s): ``(u(t - tau) - u(t)) / tau`` (n, 3, 1), the reference
    interpolated at ``t - tau``, so that the coefficient is the delay itself when it equals ``tau_s``
    (``y(t) = u(t - tau)``, eq. 1 with the motion late); the first-order regressor ``-du/dt`` at ``tau -> 0``."""
    if abs(tau_s) < 1e-6:
        out = time_offset(b, s)
        return np.zeros((len(s.u), 3, 1)) if out is None else out
    t = b.session.t_s
    shifted = np.stack([np.interp(t - tau_s, t, s.u[:, k]) for k in range(3)], axis=1)
    return ((shifted - s.u) / tau_s)[:, :, None]


__all__ = [
    "MAX_DELAY_S", "asymmetry", "attitude", "delay_regressor", "earth_rate_world", "earth_rotation", "g_sensitivity",
    "lever_arm", "nonlinearity", "poly_even", "poly_odd", "temperature_bias", "temperature_scale", "time_offset",
]
