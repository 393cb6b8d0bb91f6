"""The calibration image stored in the unit's EEPROM: a versioned binary layout with CRC-32.

The byte table is in ``station/eeprom/layout.md``. Everything is little-endian; every
physical quantity is an IEEE-754 float64 in SI units (m/s^2 for the accelerometer,
rad/s for the gyroscope, s for times), so a parameter set survives the round trip
bit for bit. The image holds what Algorithm 1 of Kolhoff & Kemper needs per triad:
the misalignment M (eq. 1), b_stat and b_drift (eq. 2), the correlation time T_c of
the Gauss-Markov drift (eq. 3; NaN when the fit could not resolve it), plus the
moving-average length n (eq. 6), the sample period T_sampl, the white-noise std and
the gyro's g-sensitivity.

:func:`decode_image` refuses, with a :class:`ImageError` subclass, anything that is
not exactly one image of a known layout version: wrong magic, unknown version, a
length field that does not match the version or the bytes given, a bad CRC-32, or
fields outside their domain.

Two-slot (A/B) scheme (:class:`SlotLayout`): the EEPROM holds two slots; each write
goes to the slot that does *not* hold the newest valid image, with an update count
one above the newest. A power loss during the write leaves that slot with a bad CRC
(or an older image with a lower count), so :func:`select_image` still returns the old
image; after a complete write it returns the new one.
"""

from __future__ import annotations

import hashlib
import math
import struct
import zlib
from dataclasses import dataclass, replace
from dataclasses import field as dc_field
from datetime import UTC, datetime
from typing import ClassVar, cast

import numpy as np

from station.kernel.errors import FormatError, UnsupportedVersionError
from station.kernel.parameters import (
    MAX_LAG_SAMPLES,
    MAX_LEAD_SAMPLES,
    AllanCoefficients,
    ParameterSet,
    ThermalFit,
    TriadParams,
)

MAGIC = b"SCAL"
LAYOUT_VERSION = 1  # the layout of an image without the effects of layout 2 (byte for byte as before)
LAYOUT_VERSION_2 = 2  # adds the compensable effects (temperature terms, nonlinearity, time offset)
LAYOUT_VERSION_3 = 3  # adds the IEEE 952 scale polynomial (k2, k3 per triad and axis)
LAYOUT_VERSIONS = (LAYOUT_VERSION, LAYOUT_VERSION_2, LAYOUT_VERSION_3)
TEXT_FIELD = 16  # bytes of serial / station id, ASCII, NUL padded
ID_FIELD = 16  # bytes of the parameter-set id

_HEADER = struct.Struct("<4sHHI16s16s16sqdHH")  # magic .. reserved: 80 bytes
_TRIAD = struct.Struct("<21d")  # M (9, row-major), b_stat, b_drift, T_c, noise_std (3 each): 168 bytes
_GSENS = struct.Struct("<9d")  # gyro g-sensitivity (3, 3) row-major: 72 bytes
_CRC = struct.Struct("<I")
BODY_SIZE = _HEADER.size + 2 * _TRIAD.size + _GSENS.size
IMAGE_SIZE = BODY_SIZE + _CRC.size  # 492 bytes for layout version 1
# layout 2 appends T_ref, the time offset and per triad: temperature bias (3x3), temperature scale (3x3),
# nonlinearity (3), all float64
_EFFECTS_HEAD = struct.Struct("<2d")  # reference temperature (degC; NaN = none), time offset (s): 16 bytes
_EFFECTS_TRIAD = struct.Struct("<21d")  # c (3x3 axis-major, orders 1..3), s (3x3), k (3): 168 bytes
BODY_SIZE_2 = BODY_SIZE + _EFFECTS_HEAD.size + 2 * _EFFECTS_TRIAD.size
IMAGE_SIZE_2 = BODY_SIZE_2 + _CRC.size  # 844 bytes for layout version 2
# layout 3 appends per triad the polynomial's k2 (3) and k3 (3), float64
_POLY_TRIAD = struct.Struct("<6d")  # k2 (3), k3 (3): 48 bytes
BODY_SIZE_3 = BODY_SIZE_2 + 2 * _POLY_TRIAD.size
IMAGE_SIZE_3 = BODY_SIZE_3 + _CRC.size  # 940 bytes for layout version 3 (fits the 1024-byte A2/B2 slots)
_SIZES = {LAYOUT_VERSION: IMAGE_SIZE, LAYOUT_VERSION_2: IMAGE_SIZE_2, LAYOUT_VERSION_3: IMAGE_SIZE_3}
MIN_HEADER = 8  # magic, version, length: enough to know what the rest must be


class ImageError(FormatError):
    """Bytes that are not a valid calibration image."""


class ImageMagicError(ImageError):
    """The bytes do not start with the image magic (erased, foreign or shifted data)."""


class ImageVersionError(ImageError, UnsupportedVersionError):
    """The image has a layout version this software does not read."""


class ImageLengthError(ImageError):
    """The length field does not match the layout version or the number of bytes given."""


class ImageCrcError(ImageError):
    """The CRC-32 does not match the content (partly written or corrupted image)."""


class ImageContentError(ImageError):
    """A field is outside its domain (bad text, non-positive sample period, reserved bits set, ...)."""


@dataclass(frozen=True, eq=False)
class TriadImage:
    """One triad's Algorithm 1 parameters as stored (unit U = m/s^2 or rad/s).

    Attributes:
        misalignment: M, (3, 3), 1.
        bias_static: b_stat (U), (3,).
        bias_drift: b_drift at power-on (U), (3,).
        correlation_time_s: T_c (s), (3,); NaN = not resolved (Algorithm 1 drops the drift term).
        noise_std: white-noise std per sample (U), (3,).
    """

    misalignment: np.ndarray
    bias_static: np.ndarray
    bias_drift: np.ndarray
    correlation_time_s: np.ndarray
    noise_std: np.ndarray

    def __post_init__(self) -> None:
        for name in ("misalignment", "bias_static", "bias_drift", "correlation_time_s", "noise_std"):
            shape = (3, 3) if name == "misalignment" else (3,)
            a = np.array(getattr(self, name), dtype=np.float64)
            if a.shape != shape:
                raise ImageContentError(f"triad field {name} must have shape {shape}, got {a.shape}")
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @classmethod
    def from_triad(cls, t: TriadParams) -> TriadImage:
        return cls(t.misalignment, t.bias_static, t.bias_drift, t.correlation_time_s, t.noise_std)

    def values(self) -> list[float]:
        return [
            *self.misalignment.ravel().tolist(),
            *self.bias_static.tolist(),
            *self.bias_drift.tolist(),
            *self.correlation_time_s.tolist(),
            *self.noise_std.tolist(),
        ]

    @classmethod
    def from_values(cls, v: tuple[float, ...]) -> TriadImage:
        a = np.asarray(v, dtype=float)
        return cls(np.reshape(a[0:9], (3, 3)), a[9:12], a[12:15], a[15:18], a[18:21])

    def same_as(self, other: TriadImage) -> bool:
        """Bitwise equal (NaN equals NaN)."""
        return all(
            np.array_equal(getattr(self, n), getattr(other, n), equal_nan=True)
            for n in ("misalignment", "bias_static", "bias_drift", "correlation_time_s", "noise_std")
        )


@dataclass(frozen=True, eq=False)
class EffectsImage:
    """What layout 2 adds: the compensable effects beyond eq. (1) (see :mod:`station.kernel.parameters`).

    Attributes:
        reference_temperature_degc: T_ref of the temperature terms (degC); NaN when they are all zero.
        time_offset_s: tau, the unit's lag behind the rig (s); Algorithm 1's line 0 moves the input by it.
        temp_bias: c per triad (accel, gyro), output axis and order 1..3, (2, 3, 3) (U/K^j).
        temp_scale: s likewise, (2, 3, 3) (1/K^j).
        nonlinearity: k of ``u + k u|u|`` per triad and axis, (2, 3) (1/U).
        quadratic, cubic: k2 (1/U) and k3 (1/U^2) of the IEEE 952 polynomial per triad and axis, (2, 3);
            non-zero only in a layout-3 image.
    """

    reference_temperature_degc: float
    time_offset_s: float
    temp_bias: np.ndarray
    temp_scale: np.ndarray
    nonlinearity: np.ndarray
    quadratic: np.ndarray = dc_field(default_factory=lambda: np.zeros((2, 3)))
    cubic: np.ndarray = dc_field(default_factory=lambda: np.zeros((2, 3)))

    _SHAPES: ClassVar[dict[str, tuple[int, ...]]] = {"temp_bias": (2, 3, 3), "temp_scale": (2, 3, 3),
                                                     "nonlinearity": (2, 3), "quadratic": (2, 3),
                                                     "cubic": (2, 3)}

    @property
    def polynomial(self) -> bool:
        """A non-zero k2 or k3: the image needs layout 3."""
        return bool(np.any(self.quadratic != 0) or np.any(self.cubic != 0))

    def __post_init__(self) -> None:
        object.__setattr__(self, "reference_temperature_degc", float(self.reference_temperature_degc))
        object.__setattr__(self, "time_offset_s", float(self.time_offset_s))
        for name, shape in self._SHAPES.items():
            a = np.array(getattr(self, name), dtype=np.float64)
            if a.shape != shape:
                raise ImageContentError(f"effects field {name} must have shape {shape}, got {a.shape}")
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @classmethod
    def from_params(cls, params: ParameterSet) -> EffectsImage | None:
        """The effects of ``params``, or None when it has none (its image is then layout 1)."""
        if not (params.compensates_temperature or params.has_nonlinearity or params.time_offset_s != 0.0):
            return None
        return cls(
            reference_temperature_degc=(
                params.reference_temperature_degc if params.compensates_temperature else math.nan),
            time_offset_s=params.time_offset_s,
            temp_bias=np.stack([params.accel.temp_bias_coeff, params.gyro.temp_bias_coeff]),
            temp_scale=np.stack([params.accel.temp_scale_coeff, params.gyro.temp_scale_coeff]),
            nonlinearity=np.stack([params.accel.scale_nonlinearity, params.gyro.scale_nonlinearity]),
            quadratic=np.stack([params.accel.scale_quadratic, params.gyro.scale_quadratic]),
            cubic=np.stack([params.accel.scale_cubic, params.gyro.scale_cubic]),
        )

    def poly_values(self, t: int) -> list[float]:
        return [*self.quadratic[t].tolist(), *self.cubic[t].tolist()]

    def triad_values(self, t: int) -> list[float]:
        return [*self.temp_bias[t].ravel().tolist(), *self.temp_scale[t].ravel().tolist(),
                *self.nonlinearity[t].tolist()]

    def problems(self) -> list[str]:
        out = []
        for name in ("temp_bias", "temp_scale", "nonlinearity", "quadratic", "cubic"):
            if not np.isfinite(getattr(self, name)).all():
                out.append(f"effects {name} has non-finite entries")
        if not math.isfinite(self.time_offset_s):
            out.append("time offset is not finite")
        has_temp = bool(np.any(self.temp_bias != 0) or np.any(self.temp_scale != 0))
        t_ref = self.reference_temperature_degc
        if has_temp and not (math.isfinite(t_ref) and -100.0 <= t_ref <= 200.0):
            out.append(f"reference temperature {t_ref!r} degC: temperature terms need one in -100..200 degC")
        if not has_temp and not (math.isnan(t_ref) or math.isfinite(t_ref)):
            out.append(f"reference temperature {t_ref!r} must be finite or NaN")
        return out

    def same_as(self, other: EffectsImage | None) -> bool:
        return other is not None and _same_float(self.reference_temperature_degc, other.reference_temperature_degc) \
            and _same_float(self.time_offset_s, other.time_offset_s) and all(
                np.array_equal(getattr(self, n), getattr(other, n), equal_nan=True) for n in self._SHAPES)


def _text(value: str, what: str) -> bytes:
    try:
        raw = value.encode("ascii")
    except UnicodeEncodeError as exc:
        raise ImageContentError(f"{what} {value!r} is not ASCII") from exc
    if len(raw) > TEXT_FIELD or b"\x00" in raw or not raw:
        raise ImageContentError(f"{what} {value!r} must be 1..{TEXT_FIELD} ASCII characters without NUL")
    return raw.ljust(TEXT_FIELD, b"\x00")


def _untext(raw: bytes, what: str) -> str:
    body = raw.rstrip(b"\x00")
    if not body or b"\x00" in body:
        raise ImageContentError(f"{what} field is empty or has embedded NUL bytes")
    try:
        text = body.decode("ascii")
    except UnicodeDecodeError as exc:
        raise ImageContentError(f"{what} field is not ASCII") from exc
    if not text.isprintable():
        raise ImageContentError(f"{what} field has non-printable characters")
    return text


def params_id(params: ParameterSet) -> bytes:
    """A 16-byte content id of a parameter set: the first 16 bytes of SHA-256 of its compact JSON."""
    return hashlib.sha256(params.to_json(indent=None).encode("utf-8")).digest()[:ID_FIELD]


@dataclass(frozen=True, eq=False)
class CalibrationImage:
    """The decoded content of one EEPROM image (layout version 1).

    Attributes:
        serial: the unit's serial number (ASCII, 1..16 characters).
        params_id: 16-byte id of the parameter set (see :func:`params_id`; the store may use its own).
        station_id: the calibrating station (ASCII, 1..16 characters).
        calibration_time_us: calibration time, µs since the Unix epoch, UTC.
        update_count: the A/B sequence counter: 1 for the first image written to a unit,
            one more for each later write; the valid slot with the highest count is current.
        sample_period_s: T_sampl of Algorithm 1 (s).
        ma_length: n of the one-sided moving average, eq. (6).
        accel: accelerometer triad (m/s^2).
        gyro: gyroscope triad (rad/s).
        g_sensitivity: gyro output per unit specific force (rad/s per m/s^2), (3, 3).
        effects: the layout-2 additions (temperature terms, nonlinearity, time offset); None: a layout-1 image.
    """

    serial: str
    params_id: bytes
    station_id: str
    calibration_time_us: int
    update_count: int
    sample_period_s: float
    ma_length: int
    accel: TriadImage
    gyro: TriadImage
    g_sensitivity: np.ndarray
    effects: EffectsImage | None = None

    @property
    def layout_version(self) -> int:
        """1 without effects (the bytes of a layout-1 image, as before), 2 with, 3 with the scale polynomial."""
        if self.effects is None:
            return LAYOUT_VERSION
        return LAYOUT_VERSION_3 if self.effects.polynomial else LAYOUT_VERSION_2

    @property
    def size(self) -> int:
        return _SIZES[self.layout_version]

    def __post_init__(self) -> None:
        g = np.array(self.g_sensitivity, dtype=np.float64)
        if g.shape != (3, 3):
            raise ImageContentError(f"g_sensitivity must have shape (3, 3), got {g.shape}")
        g.flags.writeable = False
        object.__setattr__(self, "g_sensitivity", g)

    @classmethod
    def from_params(
        cls,
        params: ParameterSet,
        station_id: str,
        calibration_time: datetime | None = None,
        *,
        update_count: int = 1,
        params_id_bytes: bytes | None = None,
    ) -> CalibrationImage:
        """The image of ``params``; ``calibration_time`` defaults to now (UTC).

        The image holds the fitted warm-up curve ``b_stat + b_drift exp(-t/T_c)`` also where the recording
        cannot determine the three on their own (:func:`image_notes` says where): Algorithm 1 applies it from
        every power-on, and over the recording's length the curve is what the data determine.
        """
        when = calibration_time if calibration_time is not None else datetime.now(UTC)
        if when.tzinfo is None:
            raise ImageContentError("calibration time must be timezone-aware")
        epoch = datetime(1970, 1, 1, tzinfo=UTC)
        us = (when - epoch) // _ONE_US
        return cls(
            serial=params.serial,
            params_id=params_id_bytes if params_id_bytes is not None else params_id(params),
            station_id=station_id,
            calibration_time_us=int(us),
            update_count=update_count,
            sample_period_s=float(params.sample_period_s),
            ma_length=int(params.moving_average_length),
            accel=TriadImage.from_triad(params.accel),
            gyro=TriadImage.from_triad(params.gyro),
            g_sensitivity=params.gyro.g_sensitivity,
            effects=EffectsImage.from_params(params),
        )

    @property
    def calibration_time(self) -> datetime:
        """Calibration time (UTC); :class:`ImageContentError` when the field is beyond what a date can be."""
        try:
            return datetime(1970, 1, 1, tzinfo=UTC) + self.calibration_time_us * _ONE_US
        except OverflowError:
            raise ImageContentError(
                f"calibration time {self.calibration_time_us} us since 1970 is not a date (beyond years 1..9999)"
            ) from None

    def with_update_count(self, count: int) -> CalibrationImage:
        return replace(self, update_count=count)

    def to_params(self) -> ParameterSet:
        """A :class:`ParameterSet` with what the image holds (uncertainties and Allan figures NaN)."""
        nan3, nan33 = np.full(3, np.nan), np.full((3, 3), np.nan)

        fx = self.effects

        def triad(t: TriadImage, g: np.ndarray | None) -> TriadParams:
            i = 0 if g is None else 1
            more = {} if fx is None else {
                "temp_bias_coeff": fx.temp_bias[i], "temp_scale_coeff": fx.temp_scale[i],
                "scale_nonlinearity": fx.nonlinearity[i], "temp_bias_coeff_std": np.full((3, 3), np.nan),
                "temp_scale_coeff_std": np.full((3, 3), np.nan), "scale_nonlinearity_std": nan3,
                "scale_quadratic": fx.quadratic[i], "scale_cubic": fx.cubic[i],
                "scale_quadratic_std": nan3, "scale_cubic_std": nan3,
            }
            return TriadParams(
                misalignment=t.misalignment, misalignment_std=nan33,
                bias_static=t.bias_static, bias_static_std=nan3,
                bias_drift=t.bias_drift, bias_drift_std=nan3,
                correlation_time_s=t.correlation_time_s, correlation_time_s_std=nan3,
                drift_noise=nan3, drift_noise_std=nan3,
                noise_std=t.noise_std, noise_std_std=nan3,
                allan=AllanCoefficients(nan3, nan3, nan3, nan3, nan3, nan3),
                residual_rms=nan3,
                g_sensitivity=np.zeros((3, 3)) if g is None else g,
                g_sensitivity_std=nan33,
                **more,
            )

        return ParameterSet(
            serial=self.serial,
            sample_period_s=self.sample_period_s,
            moving_average_length=self.ma_length,
            accel=triad(self.accel, None),
            gyro=triad(self.gyro, self.g_sensitivity),
            source={"kind": "eeprom image", "params_id": self.params_id.hex(), "station": self.station_id,
                    "update_count": self.update_count, "layout_version": self.layout_version},
            reference_temperature_degc=math.nan if fx is None else fx.reference_temperature_degc,
            time_offset_s=0.0 if fx is None else fx.time_offset_s,
            time_offset_std_s=0.0 if fx is None or fx.time_offset_s == 0.0 else math.nan,
            thermal=ThermalFit() if fx is None else ThermalFit(
                "fitted" if np.any(fx.temp_bias != 0) or np.any(fx.temp_scale != 0) else "absent",
                "from the EEPROM image"),
        )

    def same_as(self, other: CalibrationImage) -> bool:
        """Field by field equal (floats bitwise, NaN equals NaN)."""
        return (
            self.serial == other.serial
            and self.params_id == other.params_id
            and self.station_id == other.station_id
            and self.calibration_time_us == other.calibration_time_us
            and self.update_count == other.update_count
            and _same_float(self.sample_period_s, other.sample_period_s)
            and self.ma_length == other.ma_length
            and self.accel.same_as(other.accel)
            and self.gyro.same_as(other.gyro)
            and np.array_equal(self.g_sensitivity, other.g_sensitivity, equal_nan=True)
            and (self.effects.same_as(other.effects) if self.effects is not None else other.effects is None)
        )


def image_notes(params: ParameterSet) -> tuple[str, ...]:
    """One line per axis with parameters the recording cannot determine: the image holds their fitted warm-up
    curve (see :meth:`CalibrationImage.from_params`), determined over the recording's length, not beyond it."""
    q = params.quality
    out = []
    for name in ("accel", "gyro"):
        for k in sorted({u.axis for u in q.undetermined if u.triad == name}):
            which = ", ".join(u.parameter for u in q.undetermined if (u.triad, u.axis) == (name, k))
            out.append(f"{name} {'xyz'[k]}: the image holds the fitted warm-up curve, determined over the recording's "
                       f"{q.record_end_s:.1f} s after power-on, not beyond ({which} not determined on their own)")
    return tuple(out)


def run_image(params: ParameterSet, station_id: str, run_started_at: datetime) -> CalibrationImage:
    """The image of a run's parameter set: the one function every writer and reader builds it with.

    Its station and calibration time are the run's (its station id and start, UTC), its update count 1
    (the writer gives it the next count of the unit's slots). The provisioning step, the stored write,
    the API download and ``station eeprom image`` therefore agree byte for byte on a unit's first image.
    """
    return CalibrationImage.from_params(params, station_id, run_started_at)


_ONE_US = datetime(1970, 1, 1, 0, 0, 0, 1, tzinfo=UTC) - datetime(1970, 1, 1, tzinfo=UTC)


def _same_float(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def _check_content(img: CalibrationImage) -> None:
    """Domain checks shared by encode and decode."""
    if not (math.isfinite(img.sample_period_s) and img.sample_period_s > 0):
        raise ImageContentError(f"sample period must be a positive number of seconds, got {img.sample_period_s}")
    if not 1 <= img.ma_length <= 0xFFFF:
        raise ImageContentError(f"moving-average length must be 1..65535, got {img.ma_length}")
    if not 1 <= img.update_count <= 0xFFFFFFFF:
        raise ImageContentError(f"update count must be 1..2^32-1, got {img.update_count}")
    if len(img.params_id) != ID_FIELD:
        raise ImageContentError(f"parameter-set id must be {ID_FIELD} bytes, got {len(img.params_id)}")
    for name, tri in (("accel", img.accel), ("gyro", img.gyro)):
        for field in ("misalignment", "bias_static", "bias_drift"):
            if not np.isfinite(getattr(tri, field)).all():
                raise ImageContentError(f"{name} {field} has non-finite entries")
        tc = tri.correlation_time_s
        if np.any(np.isinf(tc)) or np.any(tc[~np.isnan(tc)] <= 0):
            raise ImageContentError(f"{name} correlation time must be positive or NaN, got {tc.tolist()}")
    if not np.isfinite(img.g_sensitivity).all():
        raise ImageContentError("g_sensitivity has non-finite entries")
    if img.effects is not None:
        problems = img.effects.problems()
        if problems:
            raise ImageContentError(problems[0])


#: What the unit's firmware holds and accepts (station/eeprom/layout.md, "Usable content").
FIRMWARE_MAX_MA_LENGTH = 1000  # samples in the moving-average ring buffer
MAX_CONDITION = 10.0  # cond(M): a matrix further from a rotation-and-scale is no calibration
MAX_SCALE_DEVIATION = 0.5  # |M_ii - 1|
MAX_CROSS_AXIS = 0.2  # |M_ij|, i != j
MAX_BIAS = {"accel": 16.0 * 9.80665, "gyro": math.radians(4000.0)}  # |b_stat|, |b_drift| (m/s^2, rad/s)
RATE_TOLERANCE = 0.005  # relative mismatch of 1 / sample period and the unit's rate


class ImageRefused(ImageContentError):
    """An image the station will not write: its content would make the firmware refuse it or miscorrect."""


def image_problems(img: CalibrationImage, rates_hz: tuple[float, ...] | None = None) -> list[str]:
    """Why the unit's firmware could not use ``img`` to correct sensibly; empty when it can.

    Checked: every value finite (an unresolved T_c is NaN by design); each M invertible, with
    ``cond(M) <= MAX_CONDITION`` and within ``MAX_SCALE_DEVIATION`` / ``MAX_CROSS_AXIS`` of the
    identity; biases within ``MAX_BIAS``; positive T_c and noise; a moving-average length the
    firmware holds; and, given the unit's sample rates ``rates_hz``, a sample period that is one of them.
    """
    out: list[str] = []
    if not (math.isfinite(img.sample_period_s) and 1e-5 <= img.sample_period_s <= 1.0):
        out.append(f"sample period {img.sample_period_s!r} s outside [1e-5, 1] s")
    elif rates_hz:
        rate = 1.0 / img.sample_period_s
        if not any(abs(rate - r) <= RATE_TOLERANCE * r for r in rates_hz):
            out.append(f"sample period {img.sample_period_s:g} s is {rate:.6g} Hz; the unit samples at "
                       f"{', '.join(f'{r:g}' for r in rates_hz)} Hz")
    if not 1 <= img.ma_length <= FIRMWARE_MAX_MA_LENGTH:
        out.append(f"moving-average length {img.ma_length} outside 1..{FIRMWARE_MAX_MA_LENGTH}")
    for name, tri in (("accel", img.accel), ("gyro", img.gyro)):
        m = np.asarray(tri.misalignment)
        if not np.isfinite(m).all():
            out.append(f"{name} M has non-finite entries")
            continue
        cond = float(np.linalg.cond(m)) if np.isfinite(m).all() else math.inf
        if not cond <= MAX_CONDITION:
            out.append(f"{name} M is singular or nearly so (condition number {cond:.3g} > {MAX_CONDITION:g})")
        off = m - np.diag(np.diag(m))
        if np.max(np.abs(np.diag(m) - 1.0)) > MAX_SCALE_DEVIATION or np.max(np.abs(off)) > MAX_CROSS_AXIS:
            out.append(f"{name} M is far from identity (scale {np.diag(m).round(4).tolist()}, largest cross-axis "
                       f"{float(np.max(np.abs(off))):.3g})")
        for field in ("bias_static", "bias_drift"):
            v = np.asarray(getattr(tri, field))
            if not np.isfinite(v).all() or np.max(np.abs(v)) > MAX_BIAS[name]:
                out.append(f"{name} {field} {v.tolist()} not finite or beyond {MAX_BIAS[name]:.4g}")
        tc = np.asarray(tri.correlation_time_s)
        if np.any(np.isinf(tc)) or np.any(tc[~np.isnan(tc)] <= 0):
            out.append(f"{name} T_c {tc.tolist()} must be positive or NaN (unresolved)")
        noise = np.asarray(tri.noise_std)
        if not (np.isfinite(noise).all() and np.all(noise >= 0)):
            out.append(f"{name} noise_std {noise.tolist()} must be finite and >= 0")
    if not np.isfinite(img.g_sensitivity).all():
        out.append("g_sensitivity has non-finite entries")
    if img.effects is not None:
        out.extend(img.effects.problems())
        fx = img.effects
        if not np.any(np.isnan(fx.temp_scale)):
            # the firmware divides by 1 + s(dT): it must stay well away from 0 over the operating range
            for dt in np.linspace(-100.0, 100.0, 201):
                den = 1.0 + ((fx.temp_scale[..., 2] * dt + fx.temp_scale[..., 1]) * dt + fx.temp_scale[..., 0]) * dt
                if np.any(np.abs(den - 1.0) > MAX_SCALE_DEVIATION):
                    out.append(f"temperature scale terms change the scale by more than {MAX_SCALE_DEVIATION:g} "
                               f"within 100 K of T_ref (at dT = {dt:g} K)")
                    break
        if math.isfinite(fx.time_offset_s) and img.sample_period_s > 0:
            s = fx.time_offset_s / img.sample_period_s  # line 0 of Algorithm 1 applies this much at most
            if s > MAX_LAG_SAMPLES or s < -MAX_LEAD_SAMPLES:
                out.append(f"time offset {fx.time_offset_s:g} s ({s:.3g} samples) beyond what Algorithm 1 applies "
                           f"({MAX_LAG_SAMPLES:g} samples of lag, {MAX_LEAD_SAMPLES:g} of lead)")
    return out


def check_writable(img: CalibrationImage, rates_hz: tuple[float, ...] | None = None) -> None:
    """Raise :class:`ImageRefused` (one line, the first problems) unless ``img`` is usable (:func:`image_problems`)."""
    problems = image_problems(img, rates_hz)
    if problems:
        raise ImageRefused(f"image of {img.serial} refused, nothing written: " + "; ".join(problems[:3]))


def encode_image(img: CalibrationImage) -> bytes:
    """The image's bytes, CRC-32 last: layout version 1 (:data:`IMAGE_SIZE` bytes) without effects, 2
    (:data:`IMAGE_SIZE_2`) with."""
    _check_content(img)
    header = _HEADER.pack(
        MAGIC,
        img.layout_version,
        img.size,
        img.update_count,
        _text(img.serial, "serial"),
        img.params_id,
        _text(img.station_id, "station id"),
        img.calibration_time_us,
        img.sample_period_s,
        img.ma_length,
        0,
    )
    body = header + _TRIAD.pack(*img.accel.values()) + _TRIAD.pack(*img.gyro.values())
    body += _GSENS.pack(*img.g_sensitivity.ravel().tolist())
    fx = img.effects
    if fx is not None:
        body += _EFFECTS_HEAD.pack(fx.reference_temperature_degc, fx.time_offset_s)
        body += _EFFECTS_TRIAD.pack(*fx.triad_values(0)) + _EFFECTS_TRIAD.pack(*fx.triad_values(1))
        if fx.polynomial:
            body += _POLY_TRIAD.pack(*fx.poly_values(0)) + _POLY_TRIAD.pack(*fx.poly_values(1))
    return body + _CRC.pack(zlib.crc32(body))


def image_length(data: bytes) -> int:
    """The total length an image starting at ``data`` claims (checks magic and version first)."""
    if len(data) < MIN_HEADER:
        raise ImageLengthError(f"{len(data)} bytes are too few for an image header ({MIN_HEADER})")
    magic, version, length = cast(tuple[bytes, int, int], struct.unpack_from("<4sHH", data))
    if magic != MAGIC:
        raise ImageMagicError(f"no calibration image: magic {magic!r}, expected {MAGIC!r}")
    if version not in LAYOUT_VERSIONS:
        raise ImageVersionError(f"image layout version {version}; this station reads versions "
                                f"{', '.join(map(str, LAYOUT_VERSIONS))} only")
    if length != _SIZES[version]:
        raise ImageLengthError(f"image length field says {length} bytes; layout {version} has {_SIZES[version]}")
    return length


def decode_image(data: bytes) -> CalibrationImage:
    """Decode exactly one image; raises an :class:`ImageError` subclass for anything else."""
    data = bytes(data)
    length = image_length(data)
    if len(data) != length:
        raise ImageLengthError(f"image has {len(data)} bytes; its length field says {length}")
    body_size = length - _CRC.size
    (crc,) = _CRC.unpack_from(data, body_size)
    if zlib.crc32(data[:body_size]) != crc:
        raise ImageCrcError("image CRC-32 mismatch: the image is corrupted or was not completely written")
    (_, _, _, count, serial, pid, station, t_us, period, n, reserved) = _HEADER.unpack_from(data)
    if reserved != 0:
        raise ImageContentError(f"reserved header field is {reserved}, must be 0")
    off = _HEADER.size
    accel = TriadImage.from_values(_TRIAD.unpack_from(data, off))
    gyro = TriadImage.from_values(_TRIAD.unpack_from(data, off + _TRIAD.size))
    g = np.reshape(_GSENS.unpack_from(data, off + 2 * _TRIAD.size), (3, 3))
    effects = None
    if length in (IMAGE_SIZE_2, IMAGE_SIZE_3):
        at = BODY_SIZE
        t_ref, offset = _EFFECTS_HEAD.unpack_from(data, at)
        at += _EFFECTS_HEAD.size
        tri = [np.array(_EFFECTS_TRIAD.unpack_from(data, at + k * _EFFECTS_TRIAD.size)) for k in (0, 1)]
        effects = EffectsImage(
            reference_temperature_degc=t_ref, time_offset_s=offset,
            temp_bias=np.stack([v[0:9].reshape(3, 3) for v in tri]),
            temp_scale=np.stack([v[9:18].reshape(3, 3) for v in tri]),
            nonlinearity=np.stack([v[18:21] for v in tri]),
        )
        if length == IMAGE_SIZE_3:
            at = BODY_SIZE_2
            poly = [np.array(_POLY_TRIAD.unpack_from(data, at + k * _POLY_TRIAD.size)) for k in (0, 1)]
            effects = replace(effects, quadratic=np.stack([v[:3] for v in poly]), cubic=np.stack([v[3:] for v in poly]))
            if not effects.polynomial:
                raise ImageContentError("a layout-3 image without a scale polynomial term (layout 2 holds it)")
    img = CalibrationImage(
        serial=_untext(serial, "serial"),
        params_id=pid,
        station_id=_untext(station, "station id"),
        calibration_time_us=t_us,
        update_count=count,
        sample_period_s=period,
        ma_length=n,
        accel=accel,
        gyro=gyro,
        g_sensitivity=g,
        effects=effects,
    )
    _check_content(img)
    return img


def image_sha256(data: bytes) -> str:
    """Hex SHA-256 of image bytes (what the unit records store)."""
    return hashlib.sha256(bytes(data)).hexdigest()


# --- the two slots --------------------------------------------------------------------------------


@dataclass(frozen=True)
class SlotLayout:
    """Where the two image slots lie in the EEPROM (bytes).

    Attributes:
        base: address of slot A; slot B follows at ``base + slot_size``.
        slot_size: bytes reserved per slot (>= :data:`IMAGE_SIZE`, a multiple of the page size).
    """

    base: int = 0
    slot_size: int = 512

    def __post_init__(self) -> None:
        if self.slot_size < IMAGE_SIZE or self.base < 0:
            raise ValueError(f"slot size must be >= {IMAGE_SIZE} bytes and base >= 0")

    def address(self, slot: int) -> int:
        if slot not in (0, 1):
            raise ValueError("slot must be 0 (A) or 1 (B)")
        return self.base + slot * self.slot_size

    @property
    def end(self) -> int:
        return self.base + 2 * self.slot_size


DEFAULT_SLOTS = SlotLayout()
#: The slots of layout-2 images (844 bytes): two of 1024 bytes in the upper half of a 4 KiB EEPROM, apart
#: from the layout-1 slots, so that a write in one region never touches an image of the other.
WIDE_SLOTS = SlotLayout(base=0x800, slot_size=1024)
#: Every slot region, in the order they are read.
REGIONS = (DEFAULT_SLOTS, WIDE_SLOTS)
SLOT_NAMES = ("A", "B")


def slots_for(img: CalibrationImage, layout: SlotLayout = DEFAULT_SLOTS) -> SlotLayout:
    """Where ``img`` is written: ``layout`` (the layout-1 slots) for a layout-1 image, :data:`WIDE_SLOTS` for 2
    and 3."""
    return layout if img.layout_version == LAYOUT_VERSION else WIDE_SLOTS


@dataclass(frozen=True, eq=False)
class SlotState:
    """What one slot holds: the decoded image, or why it does not decode."""

    slot: int
    image: CalibrationImage | None
    error: str = ""
    layout: SlotLayout = DEFAULT_SLOTS

    @property
    def name(self) -> str:
        """'A' or 'B' (layout-1 slots), 'A2' or 'B2' (:data:`WIDE_SLOTS`)."""
        return SLOT_NAMES[self.slot] + ("2" if self.layout == WIDE_SLOTS else "")

    @property
    def address(self) -> int:
        return self.layout.address(self.slot)


def decode_slot(slot: int, raw: bytes, layout: SlotLayout = DEFAULT_SLOTS) -> SlotState:
    """Decode the image at the start of a slot's bytes (the rest of the slot is ignored)."""
    try:
        length = image_length(raw)
        if len(raw) < length:
            raise ImageLengthError(f"slot has {len(raw)} bytes, the image claims {length}")
        return SlotState(slot, decode_image(raw[:length]), layout=layout)
    except ImageError as exc:
        return SlotState(slot, None, str(exc), layout)


def select_image(slots: list[SlotState], serial: str | None = None) -> SlotState | None:
    """The current slot: the valid one (for ``serial`` if given) with the highest update count."""
    valid = [s for s in slots if s.image is not None and (serial is None or s.image.serial == serial)]
    if not valid:
        return None
    def newest(s: SlotState) -> tuple[int, int, int]:
        assert s.image is not None  # valid slots only
        return s.image.update_count, -s.layout.base, -s.slot

    return max(valid, key=newest)


def next_write(slots: list[SlotState]) -> tuple[int, int]:
    """(slot to write, update count to give the new image): the slot not holding the current image."""
    current = select_image(slots)
    if current is None:
        return 0, 1
    assert current.image is not None
    return 1 - current.slot, current.image.update_count + 1


def read_slots(raw: bytes, layout: SlotLayout = DEFAULT_SLOTS) -> list[SlotState]:
    """Decode both slots from a whole EEPROM dump (or at least ``layout.end`` bytes of it)."""
    if len(raw) < layout.end:
        raise ImageLengthError(f"EEPROM dump of {len(raw)} bytes does not cover both slots ({layout.end})")
    return [decode_slot(k, raw[layout.address(k) : layout.address(k) + layout.slot_size], layout) for k in (0, 1)]


def read_all_slots(raw: bytes, layout: SlotLayout = DEFAULT_SLOTS) -> list[SlotState]:
    """The slots of every region a whole EEPROM dump covers: ``layout`` (layout 1), then :data:`WIDE_SLOTS`
    (layout 2) when the dump reaches its end. :func:`select_image` over them gives the current image."""
    out = read_slots(raw, layout)
    if len(raw) >= WIDE_SLOTS.end and layout != WIDE_SLOTS:
        out += read_slots(raw, WIDE_SLOTS)
    return out


def next_write_in(region: SlotLayout, slots: list[SlotState]) -> tuple[int, int]:
    """(slot of ``region`` to write, update count) given every region's ``slots``: the region's slot not holding
    its newest image, and a count above every valid image of any region (so the new one becomes current)."""
    slot, _ = next_write([s for s in slots if s.layout == region])
    counts = [s.image.update_count for s in slots if s.image is not None]
    return slot, max(counts, default=0) + 1
