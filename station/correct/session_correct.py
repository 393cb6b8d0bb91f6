"""Algorithm 1 applied to a recorded :class:`~station.session.model.Session`, and its
post-processed (two-sided) counterpart the paper compares the online output with.

Units: SI throughout (specific force m/s^2, angular rate rad/s, time s).
"""

from __future__ import annotations

import math

import numpy as np

from station.correct.batch import correct_batch
from station.correct.streaming import CorrectionConstants, compensate_extended
from station.kernel.errors import FormatError
from station.kernel.parameters import ParameterSet
from station.session.model import Session

# relative mismatch between the session's sample rate and 1 / T_sampl that we accept
_RATE_TOLERANCE = 1e-3


def _check_rate(session: Session, params: ParameterSet) -> None:
    rate = session.sample_rate_hz
    expected = 1.0 / params.sample_period_s
    if not math.isfinite(rate) or abs(rate - expected) > _RATE_TOLERANCE * expected:
        raise FormatError(
            f"session {session.serial} is sampled at {rate:g} Hz but parameter set {params.serial} "
            f"has T_sampl = {params.sample_period_s:g} s ({expected:g} Hz)"
        )


def _temperature(session: Session, params: ParameterSet) -> np.ndarray | None:
    """The session's temperature column when the set compensates temperature (refused if it has none)."""
    if not params.compensates_temperature:
        return None
    if not session.has_temperature or not np.all(np.isfinite(session.temp_degc)):
        raise FormatError(
            f"parameter set {params.serial} compensates temperature, but session {session.serial} has no "
            "temperature in every sample"
        )
    return session.temp_degc


def remove_g_sensitivity(accel: np.ndarray, gyro: np.ndarray, params: ParameterSet) -> np.ndarray:
    """The gyro's g-sensitivity G out of Algorithm 1's output, as the firmware does: ``w - M_w^-1 G a`` with the
    corrected specific force ``a``; ``gyro`` itself when G is zero."""
    g = np.asarray(params.gyro.g_sensitivity, dtype=np.float64)
    if not np.any(g != 0):
        return gyro
    return gyro - accel @ np.linalg.solve(np.asarray(params.gyro.misalignment, dtype=np.float64), g).T


def start_index_of(session: Session, params: ParameterSet) -> int:
    """Samples since power-on of the session's first row: round(t_s[0] / T_sampl)."""
    if len(session) == 0:
        return 0
    k = round(float(session.t_s[0]) / params.sample_period_s)
    if k < 0:
        raise FormatError(f"session {session.serial} starts before power-on (t = {session.t_s[0]:g} s)")
    return k


def correct_session(session: Session, params: ParameterSet) -> Session:
    """Run Algorithm 1 (online, one-sided) over a session.

    Returns a Session with the same metadata plus ``corrected: algorithm1`` and
    ``params_serial``, whose measurement columns (``accel_mps2``, ``gyro_radps``) hold the
    corrected values; time, segments, temperature and reference columns are unchanged.
    The corrector is taken to have run since power-on: it starts at sample index
    round(t_s[0] / T_sampl) with an empty moving-average buffer.

    A ``station-params/2`` set with temperature terms corrects each sample at the session's
    temperature column (line 6' of :mod:`station.correct.streaming`); a fitted g-sensitivity is
    removed from the rate as the firmware does (:func:`remove_g_sensitivity`).

    Raises:
        FormatError: the parameter set cannot be used (singular M, non-finite b_stat, ...),
            its sample period does not match the session's sample rate, or it compensates
            temperature and the session has no temperature in every sample.
    """
    _check_rate(session, params)
    temp = _temperature(session, params)
    # two outputs that own their memory, made read-only below: the Session takes them without copying
    accel, gyro = correct_batch(session.accel_mps2, session.gyro_radps, params, start_index_of(session, params),
                                temp_degc=temp, out=(np.empty((len(session), 3)), np.empty((len(session), 3))))
    gyro = remove_g_sensitivity(accel, gyro, params)
    for column in (accel, gyro):
        column.flags.writeable = False
    metadata = {**session.metadata, "corrected": "algorithm1", "params_serial": params.serial}
    return session.replace(metadata=metadata, accel_mps2=accel, gyro_radps=gyro)


def _centred_moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Two-sided moving average of length n along axis 0 (rows i - n//2 .. i + (n-1)//2).

    Symmetric for odd n; for even n one more sample before than after. Near the ends it
    averages the samples available. Computed from prefix sums in float64 (reference only).
    """
    total = x.shape[0]
    c = np.zeros((total + 1, x.shape[1]))
    np.cumsum(x, axis=0, out=c[1:])
    i = np.arange(total)
    lo = np.clip(i - n // 2, 0, total)
    hi = np.clip(i + (n - 1) // 2 + 1, 0, total)
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def two_sided_reference(
    accel_mps2: np.ndarray, gyro_radps: np.ndarray, t_s: np.ndarray, params: ParameterSet,
    temp_degc: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Post-processed counterpart of Algorithm 1 over a whole record.

    Same bias removal as Algorithm 1 but with the exact drift shape g(t) = exp(-t / T_c)
    (eq. 3 without noise) instead of the Euler recursion, a centred (two-sided) moving
    average of the same length n, then the solve M x = x_MA per triad. Channels whose
    T_c is NaN or b_drift is 0 get no drift removal, as in Algorithm 1.

    Args:
        accel_mps2: raw specific force (n, 3), m/s^2.
        gyro_radps: raw angular rate (n, 3), rad/s.
        t_s: sample times since power-on (n,), s.
        params: the parameter set.

    Returns:
        (specific force (n, 3) in m/s^2, angular rate (n, 3) in rad/s).
    """
    c = CorrectionConstants.from_params(params)
    raw = np.hstack([np.asarray(accel_mps2, dtype=np.float64), np.asarray(gyro_radps, dtype=np.float64)])
    t = np.asarray(t_s, dtype=np.float64)
    if raw.shape != (t.shape[0], 6):
        raise ValueError(f"expected (n, 3), (n, 3), (n,) inputs, got raw {raw.shape}, t {t.shape}")
    if params.time_offset_s != 0.0 and len(t):  # the time offset, two-sided: linear interpolation at i + tau/T
        pos = np.arange(len(t)) + params.time_offset_s / params.sample_period_s
        raw = np.column_stack([np.interp(pos, np.arange(len(t)), raw[:, j]) for j in range(6)])
    tc = np.concatenate([params.accel.correlation_time_s, params.gyro.correlation_time_s])
    active = c.bias_drift != 0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        g = np.exp(-t[:, None] / np.where(active, tc, np.inf))  # exact solution of eq. (3), w_g = 0
    x_temp = raw - c.bias_static - c.bias_drift * g
    if c.extended:
        x_temp = compensate_extended(c, x_temp, temp_degc)
    x_ma = _centred_moving_average(x_temp, c.ma_length)
    return x_ma[:, :3] @ c.accel_inverse.T, x_ma[:, 3:] @ c.gyro_inverse.T


def reference_session(session: Session, params: ParameterSet) -> Session:
    """:func:`two_sided_reference` over a session (metadata ``corrected: two_sided_reference``)."""
    _check_rate(session, params)
    accel, gyro = two_sided_reference(session.accel_mps2, session.gyro_radps, session.t_s, params,
                                      _temperature(session, params))
    metadata = {**session.metadata, "corrected": "two_sided_reference", "params_serial": params.serial}
    return session.replace(metadata=metadata, accel_mps2=accel, gyro_radps=gyro)


def cross_correlation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Zero-lag normalised cross-correlation (Pearson) per column of two (n, k) records.

    The figure the paper quotes (>= 0.98) between online and post-processed output.
    Rows where either record is non-finite are ignored; NaN for a constant column.
    """
    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2:
        raise ValueError(f"expected two (n, k) arrays of the same shape, got {x.shape} and {y.shape}")
    out = np.full(x.shape[1], np.nan)
    for j in range(x.shape[1]):
        ok = np.isfinite(x[:, j]) & np.isfinite(y[:, j])
        if np.count_nonzero(ok) < 2:
            continue
        xj = x[ok, j] - x[ok, j].mean()
        yj = y[ok, j] - y[ok, j].mean()
        den = math.sqrt(float(xj @ xj) * float(yj @ yj))
        if den > 0:
            out[j] = float(xj @ yj) / den
    return out
