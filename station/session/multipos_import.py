"""Importers of hand-held multi-position recordings (no rig, gravity the only reference).

* :func:`import_openaxes`: an OpenAXES IMU log (``log_imu*.csv``, semicolon-separated, columns
  ``MAC;IMU;TIME;INDEX;QUATERNION_0..3;ACCEL_ADXL355_0..2;ACCEL_BMI160_0..2;GYRO_0..2;GYRO_ECC_0..2``):
  accelerometers in m/s^2 (uncalibrated), gyroscope in rad/s, ``TIME`` the host clock in us,
  ``INDEX`` a 16-bit sample counter. One accelerometer (``adxl355`` or ``bmi160``) goes into the
  session with the gyroscope. The host clock jitters (packets arrive in bursts), the counter does
  not: sample times are ``(INDEX unwrapped) / rate`` with the rate from the host clock over the whole
  recording (first to last sample), so a lost sample shows as a gap, not as a shifted time base.
* :func:`import_imu_tk`: imu_tk's text format, one file per sensor (accelerometer, gyroscope), rows of
  whitespace-separated ``time_s x y z`` in raw counts. Counts become SI as ``(raw - offset_lsb) /
  lsb_per_unit`` (nominal sensitivity; the fit finds the true scale and offset).

Both label rest, pose and move segments with the still detector (:mod:`station.session.still`)
and write the local gravity (m/s^2) into ``gravity_mps2``. Poses carry no reference (empty
``ref_*``): the fit is the rig-free one (:mod:`station.fit.rigfree_fit`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from station.kernel.errors import FormatError
from station.session.model import Session
from station.session.still import StillOptions, detect_still, label_segments

__all__ = ["OPENAXES_ACCELS", "OPENAXES_GRAVITY_MPS2", "import_imu_tk", "import_openaxes", "normal_gravity_mps2"]

#: local gravity where the OpenAXES recordings were made (Hannover), m/s^2
OPENAXES_GRAVITY_MPS2 = 9.8128
OPENAXES_ACCELS = ("adxl355", "bmi160")
_OPENAXES_COLUMNS = ("TIME", "INDEX", "GYRO_0", "GYRO_1", "GYRO_2")
#: plausible magnitudes: a gyroscope beyond this (rad/s) is in other units (deg/s, counts)
MAX_PLAUSIBLE_RATE_RADPS = 70.0  # ~4000 deg/s, twice the largest common full scale


def normal_gravity_mps2(latitude_deg: float, height_m: float = 0.0) -> float:
    """Local gravity (m/s^2) from the site: WGS 84 normal gravity on the ellipsoid (Somigliana's closed formula)
    with the free-air correction -3.086e-6 m/s^2 per metre of height. Within about 1e-3 m/s^2 of a measured
    value in open country; a gravimeter or a national gravity model is better where that matters."""
    if not (np.isfinite(latitude_deg) and -90.0 <= latitude_deg <= 90.0):
        raise FormatError(f"latitude {latitude_deg!r} deg is outside -90..90")
    if not (np.isfinite(height_m) and -500.0 <= height_m <= 9000.0):
        raise FormatError(f"height {height_m!r} m is outside -500..9000")
    s2 = np.sin(np.radians(latitude_deg)) ** 2
    gamma = 9.7803253359 * (1 + 0.00193185265241 * s2) / np.sqrt(1 - 0.00669437999013 * s2)
    return float(gamma - 3.086e-6 * height_m)


def _positive(name: str, value: float) -> float:
    number = float(value)
    if not (np.isfinite(number) and number > 0):
        raise FormatError(f"{name} must be a positive number, got {value!r}")
    return number


def _number_text(value: float) -> str:
    return repr(float(value))


def _build(
    t_s: np.ndarray, accel: np.ndarray, gyro: np.ndarray, metadata: dict[str, str], sample_rate_hz: float,
    still: StillOptions | None, source: str,
) -> Session:
    if not (np.isfinite(accel).all() and np.isfinite(gyro).all()):
        raise FormatError(f"{source}: non-finite sensor values")
    peak = float(np.abs(gyro).max())
    if peak > MAX_PLAUSIBLE_RATE_RADPS:
        raise FormatError(f"{source}: gyroscope reaches {peak:.4g} rad/s ({np.degrees(peak):.4g} deg/s): not rad/s "
                          "(deg/s or counts? give the sensitivity)")
    opt = still or StillOptions()
    intervals = detect_still(accel, sample_rate_hz, opt, gyro)
    segment, kind = label_segments(len(t_s), intervals)
    n = len(t_s)
    metadata = {
        **metadata,
        "sample_rate_hz": _number_text(sample_rate_hz),
        "still_detector": opt.describe(),
        "still_reference_mps2": f"{intervals.reference_mps2:.6g}",
    }
    return Session(
        metadata=metadata, t_s=t_s, segment=segment, kind=kind, accel_mps2=accel, gyro_radps=gyro,
        temp_degc=np.full(n, np.nan), ref_accel_mps2=np.full((n, 3), np.nan), ref_gyro_radps=np.full((n, 3), np.nan),
    )


def import_openaxes(
    csv_path: str | os.PathLike[str],
    *,
    accel: str = "adxl355",
    gravity_mps2: float = OPENAXES_GRAVITY_MPS2,
    serial: str | None = None,
    still: StillOptions | None = None,
) -> Session:
    """Import an OpenAXES log with one of its accelerometers (see the module docstring)."""
    name = os.fspath(csv_path)
    if accel not in OPENAXES_ACCELS:
        raise FormatError(f"--accel {accel!r}: OpenAXES logs hold {' and '.join(OPENAXES_ACCELS)}")
    gravity = _positive("gravity", gravity_mps2)
    columns = [f"ACCEL_{accel.upper()}_{k}" for k in range(3)]
    try:
        frame = pd.read_csv(name, sep=";")
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise FormatError(f"{name}: cannot read OpenAXES log: {exc}") from exc
    missing = [c for c in (*_OPENAXES_COLUMNS, *columns) if c not in frame.columns]
    if missing:
        raise FormatError(f"{name}: not an OpenAXES log, missing column(s) {', '.join(missing)}")
    if len(frame) < 100:
        raise FormatError(f"{name}: only {len(frame)} samples")
    for c in (*_OPENAXES_COLUMNS, *columns):
        if not pd.api.types.is_numeric_dtype(frame[c]) or not np.isfinite(frame[c].to_numpy(float)).all():
            raise FormatError(f"{name}: column {c!r} must hold finite numbers")
    index = frame["INDEX"].to_numpy(np.int64)
    step = np.diff(index) % 65536  # 16-bit counter
    if (step == 0).any():
        raise FormatError(f"{name}: sample counter repeats at row {int(np.flatnonzero(step == 0)[0]) + 2}")
    counter = np.concatenate(([0], np.cumsum(step)))
    host_s = frame["TIME"].to_numpy(np.float64) * 1e-6
    span = host_s[-1] - host_s[0]
    if not span > 0:
        raise FormatError(f"{name}: TIME does not advance")
    rate = float(counter[-1] / span)
    t_s = counter / rate
    acc = frame[columns].to_numpy(np.float64)
    gyro = frame[["GYRO_0", "GYRO_1", "GYRO_2"]].to_numpy(np.float64)
    mac = str(frame["MAC"].iloc[0]) if "MAC" in frame.columns else "openaxes"
    imu = str(frame["IMU"].iloc[0]) if "IMU" in frame.columns else ""
    metadata = {
        "serial": serial or f"{imu or 'openaxes'}-{mac.replace(':', '')}-{accel}",
        "gravity_mps2": _number_text(gravity),
        "source": "openaxes",
        "source_file": Path(name).name,
        "source_accel": accel,
        "lost_samples": str(int(counter[-1] + 1 - len(counter))),
    }
    return _build(t_s, acc, gyro, metadata, rate, still, name)


def _read_imu_tk(path: str) -> np.ndarray:
    try:
        data = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as exc:
        raise FormatError(f"{path}: cannot read imu_tk file (rows of 'time x y z'): {exc}") from exc
    if data.shape[1] != 4:
        raise FormatError(f"{path}: imu_tk rows have 4 columns (time x y z), found {data.shape[1]}")
    if len(data) < 100:
        raise FormatError(f"{path}: only {len(data)} samples")
    if not np.isfinite(data).all():
        raise FormatError(f"{path}: non-finite values")
    if (np.diff(data[:, 0]) <= 0).any():
        row = int(np.flatnonzero(np.diff(data[:, 0]) <= 0)[0]) + 2
        raise FormatError(f"{path}: time does not increase at row {row}")
    return data


def _per_axis(name: str, value: float | tuple[float, float, float]) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).copy()
    if not np.isfinite(arr).all():
        raise FormatError(f"{name} must be finite")
    return arr


def import_imu_tk(
    accel_path: str | os.PathLike[str],
    gyro_path: str | os.PathLike[str],
    *,
    accel_lsb_per_mps2: float = 1.0,
    gyro_lsb_per_radps: float = 1.0,
    accel_offset_lsb: float | tuple[float, float, float] = 0.0,
    gyro_offset_lsb: float | tuple[float, float, float] = 0.0,
    gravity_mps2: float = 9.80665,
    serial: str = "imu-tk",
    still: StillOptions | None = None,
) -> Session:
    """Import imu_tk's two text files (see the module docstring); the gyroscope's times must be the
    accelerometer's (within a tenth of a sample)."""
    a_name, g_name = os.fspath(accel_path), os.fspath(gyro_path)
    a_sens = _positive("--accel-lsb-per-mps2", accel_lsb_per_mps2)
    g_sens = _positive("--gyro-lsb-per-radps", gyro_lsb_per_radps)
    gravity = _positive("gravity", gravity_mps2)
    a_off, g_off = _per_axis("accel offset", accel_offset_lsb), _per_axis("gyro offset", gyro_offset_lsb)
    acc, gyr = _read_imu_tk(a_name), _read_imu_tk(g_name)
    dt = float(np.median(np.diff(acc[:, 0])))
    if len(acc) != len(gyr) or np.abs(acc[:, 0] - gyr[:, 0]).max() > 0.1 * dt:
        raise FormatError(f"{g_name}: the gyroscope's sample times are not the accelerometer's ({len(gyr)} vs "
                          f"{len(acc)} rows); resample both to one time base first")
    t_s = acc[:, 0] - acc[0, 0]
    rate = float((len(t_s) - 1) / t_s[-1])
    metadata = {
        "serial": serial,
        "gravity_mps2": _number_text(gravity),
        "source": "imu_tk",
        "source_file": Path(a_name).name,
        "source_gyro_file": Path(g_name).name,
        "accel_lsb_per_mps2": _number_text(a_sens),
        "gyro_lsb_per_radps": _number_text(g_sens),
        "accel_offset_lsb": ",".join(f"{v:g}" for v in a_off),
        "gyro_offset_lsb": ",".join(f"{v:g}" for v in g_off),
    }
    accel = (acc[:, 1:] - a_off) / a_sens
    gyro = (gyr[:, 1:] - g_off) / g_sens
    return _build(t_s, accel, gyro, metadata, rate, still, a_name)
