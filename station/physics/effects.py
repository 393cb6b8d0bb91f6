"""Optional physics the paper's base model (eq. 1) leaves out, for the simulator.

Every effect is off (0) by default. An :class:`Effects` value holds one magnitude per
effect in the units documented on the class; a unit's random *shape* of each effect
(which axes, which signs) is drawn once per unit (:class:`EffectShapes`, part of
:class:`~station.physics.unit.UnitTruth`), so switching an effect on or off never
changes the rest of the unit. :meth:`Effects.realize` combines both into the SI
coefficients the simulator applies (:class:`EffectTruth`), which a diagnosis tool can
be scored against.

Effects that exist for both sensors are given by one magnitude in the accelerometer's
unit; the gyroscope gets that magnitude times :data:`GYRO_PER_ACCEL` (deg/s per m/s^2).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from station.kernel.constants import EARTH_RATE_RADPS, STANDARD_GRAVITY
from station.kernel.errors import StationError
from station.kernel.geometry import AXIS_INDEX, POSE_ANGLES_DEG

#: Gyro magnitude per accelerometer magnitude for two-sensor effects, (deg/s) per (m/s^2).
#: Typical MEMS data sheets pair an accelerometer tempco of ~0.2 mg/K (~0.002 m/s^2/K) with a gyro
#: tempco of ~0.01 deg/s/K.
GYRO_PER_ACCEL = 5.0
#: Reference input of the gyro nonlinearity: 200 deg/s (rad/s).
GYRO_NONLINEARITY_REF_RADPS = math.radians(200.0)

_DEG = math.pi / 180.0
#: The six gravity poses in the row order of the ``pose_tilt`` arrays.
POSES: tuple[str, ...] = tuple(POSE_ANGLES_DEG)
_SHAPE_SHAPES = {"g_sensitivity": (3, 3), "pose_tilt": (len(POSES), 3)}
_SHAPE_TRUTH = {"g_sensitivity": (3, 3), "pose_tilt_rad": (len(POSES), 3)}


class EffectError(StationError):
    """An ``--effect NAME=VALUE`` option names no known effect or has a bad value."""


def _ro(a: object, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class Effects:
    """Magnitudes of the optional effects; 0 switches an effect off.

    Attributes:
        temperature_bias: bias change per kelvin of sensor temperature above its power-on
            value. Accelerometer: ``temperature_bias`` m/s^2/K times the unit's per-axis shape
            (each component's magnitude in [0.5, 1], random sign); gyroscope:
            ``temperature_bias * GYRO_PER_ACCEL`` deg/s/K times its own shape.
        temperature_scale: relative scale-factor change per kelvin, in ppm/K, per axis times the
            unit's shape (magnitudes in [0.5, 1], random sign), both sensors.
        g_sensitivity: gyro bias per specific force, deg/s per g (g = 9.80665 m/s^2); the
            3x3 matrix has entries of magnitude in [0.5, 1] times this value, random signs.
        scale_nonlinearity: symmetric quadratic scale term ``y = u + k u|u|``, given as the
            relative scale error ``k |u_ref|`` at ``u_ref`` = 1 g (accelerometer) and 200 deg/s
            (gyroscope), per axis times the unit's shape (magnitudes in [0.5, 1]).
        scale_asymmetry: relative difference of the scale factor for positive and negative
            inputs: positive inputs are scaled by ``1 + a/2``, negative by ``1 - a/2``, with
            ``a`` = this value times the unit's shape (magnitudes in [0.5, 1]), both sensors.
        lever_arm: distance (mm) of the accelerometer from the rig's centre of rotation, along
            a unit-specific random direction; adds ``w x (w x r) + alpha x r``.
        earth_rotation: multiple of the Earth rate (1.0 = 15.041 deg/h) seen by the gyro,
            using the site's ``latitude_deg`` and the rig's ``heading_deg``.
        time_offset: sensor time minus rig time, in ms: the sample stamped ``t`` was taken at
            rig time ``t - time_offset``, so with a positive value motion appears later in the
            sensor columns than in the reference columns.
        bias_random_walk: bias random walk density K: the bias wanders by ``K sqrt(t)``
            (1 sigma). Accelerometer K in m/s^2/sqrt(s); gyro ``K * GYRO_PER_ACCEL``
            deg/s/sqrt(s).
        outliers: extra outlier probability per sample and axis, both sensors, on top of the
            sensor class's own; outlier size as set by the sensor class.
        pose_tilt: rms tilt (deg) of the rig's actual attitude in each still gravity pose against
            the commanded one: per pose (each of the six, see
            :data:`station.kernel.geometry.POSE_ANGLES_DEG`) a small rotation of the sensor about the
            two axes perpendicular to that pose's up axis, each component normal with std
            ``pose_tilt / sqrt(2)`` times the unit's shape (so the tilt's rms size is ``pose_tilt``).
            It acts in ``pose`` segments only; the reference columns keep the nominal +-g.
    """

    temperature_bias: float = 0.0
    temperature_scale: float = 0.0
    g_sensitivity: float = 0.0
    scale_nonlinearity: float = 0.0
    scale_asymmetry: float = 0.0
    lever_arm: float = 0.0
    earth_rotation: float = 0.0
    time_offset: float = 0.0
    bias_random_walk: float = 0.0
    outliers: float = 0.0
    pose_tilt: float = 0.0

    _SIGNED = ("time_offset", "earth_rotation")

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise EffectError(f"effect {f.name}: value must be a number, got {value!r}")
            value = float(value)
            if not math.isfinite(value):
                raise EffectError(f"effect {f.name}: value must be finite, got {value!r}")
            if f.name not in self._SIGNED and value < 0:
                raise EffectError(f"effect {f.name}: value must be >= 0, got {value!r}")
            object.__setattr__(self, f.name, value)
        if self.outliers >= 1.0:
            raise EffectError(f"effect outliers: a probability per sample must be < 1, got {self.outliers!r}")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def parse(cls, items: str | Iterable[str]) -> Effects:
        """Effects from ``NAME=VALUE`` items (the CLI's ``--effect``), e.g. ``["lever_arm=30"]``.

        A single string may hold several items separated by commas; ``""`` and ``"none"``
        mean no effects (the inverse of :meth:`describe`). Raises :class:`EffectError`
        (a :class:`~station.kernel.errors.StationError`) for an unknown name or a bad value.
        """
        if isinstance(items, str):
            items = [items]
        values: dict[str, float] = {}
        known = cls.names()
        for item in items:
            for part in item.split(","):
                part = part.strip()
                if not part or part == "none":
                    continue
                name, sep, text = part.partition("=")
                name = name.strip()
                if not sep:
                    raise EffectError(f"effect {part!r}: expected NAME=VALUE")
                if name not in known:
                    raise EffectError(f"unknown effect {name!r}; known: {', '.join(known)}")
                try:
                    value = float(text)
                except ValueError:
                    raise EffectError(f"effect {name}: {text.strip()!r} is not a number") from None
                values[name] = value
        return cls(**values)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def active(self) -> dict[str, float]:
        """Only the effects that are switched on."""
        return {k: v for k, v in self.as_dict().items() if v != 0.0}

    def describe(self) -> str:
        """``name=value,...`` of the active effects (``none`` if none); :meth:`parse` reads it back."""
        active = self.active()
        if not active:
            return "none"
        return ",".join(f"{k}={v!r}" for k, v in active.items())

    def realize(self, shapes: EffectShapes, *, latitude_deg: float = 0.0, heading_deg: float = 0.0) -> EffectTruth:
        """The SI coefficients these magnitudes give a unit with ``shapes`` at the given site."""
        g_unit = GYRO_PER_ACCEL * _DEG  # (rad/s) per (m/s^2)
        lat, head = math.radians(latitude_deg), math.radians(heading_deg)
        # Rig world frame: x, y horizontal with y at azimuth heading_deg (clockwise from north), z up.
        north = np.array([-math.sin(head), math.cos(head), 0.0])
        earth = self.earth_rotation * EARTH_RATE_RADPS * (math.cos(lat) * north + np.array([0.0, 0.0, math.sin(lat)]))
        return EffectTruth(
            accel_temp_bias=self.temperature_bias * shapes.accel_temp_bias,
            gyro_temp_bias=self.temperature_bias * g_unit * shapes.gyro_temp_bias,
            accel_temp_scale=self.temperature_scale * 1e-6 * shapes.accel_temp_scale,
            gyro_temp_scale=self.temperature_scale * 1e-6 * shapes.gyro_temp_scale,
            g_sensitivity=self.g_sensitivity * _DEG / STANDARD_GRAVITY * shapes.g_sensitivity,
            accel_nonlinearity=self.scale_nonlinearity / STANDARD_GRAVITY * shapes.accel_nonlinearity,
            gyro_nonlinearity=self.scale_nonlinearity / GYRO_NONLINEARITY_REF_RADPS * shapes.gyro_nonlinearity,
            accel_asymmetry=self.scale_asymmetry * shapes.accel_asymmetry,
            gyro_asymmetry=self.scale_asymmetry * shapes.gyro_asymmetry,
            lever_arm_m=self.lever_arm * 1e-3 * shapes.lever_arm,
            earth_rate_radps=earth,
            time_offset_s=self.time_offset * 1e-3,
            accel_random_walk=self.bias_random_walk,
            gyro_random_walk=self.bias_random_walk * g_unit,
            extra_outlier_probability=self.outliers,
            pose_tilt_rad=self.pose_tilt * _DEG * shapes.pose_tilt,
        )


@dataclass(frozen=True, eq=False)
class EffectShapes:
    """A unit's random pattern of each effect, independent of its magnitude (dimensionless).

    Vectors (3,) have components of magnitude in [0.5, 1] with random signs;
    ``g_sensitivity`` is (3, 3) likewise; ``lever_arm`` is a unit vector (uniform on the sphere).
    ``pose_tilt`` (6, 3): per pose in the order of :data:`POSES`, a rotation vector (sensor frame)
    perpendicular to that pose's up axis, its two components normal with std ``1/sqrt(2)``
    (rms length 1); zeros when not given. It is drawn from its own stream (:meth:`draw`), so
    adding it changed no other draw.
    """

    accel_temp_bias: np.ndarray
    gyro_temp_bias: np.ndarray
    accel_temp_scale: np.ndarray
    gyro_temp_scale: np.ndarray
    g_sensitivity: np.ndarray
    accel_nonlinearity: np.ndarray
    gyro_nonlinearity: np.ndarray
    accel_asymmetry: np.ndarray
    gyro_asymmetry: np.ndarray
    lever_arm: np.ndarray
    pose_tilt: np.ndarray = field(default_factory=lambda: np.zeros((len(POSES), 3)))

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "pose_tilt" and value is None:  # as before the default factory: zeros
                value = np.zeros((len(POSES), 3))
            object.__setattr__(self, f.name, _ro(value, _SHAPE_SHAPES.get(f.name, (3,))))

    @classmethod
    def draw(cls, rng: np.random.Generator) -> EffectShapes:
        """Draw a unit's shapes (fixed draw order: the same generator state gives the same shapes).

        ``pose_tilt`` comes from a child stream spawned from ``rng``'s seed sequence
        (``rng.spawn``), which leaves ``rng``'s own draws, and so every other shape, unchanged.
        """

        def signed(shape: tuple[int, ...]) -> np.ndarray:
            mag = rng.uniform(0.5, 1.0, size=shape)
            sign = np.where(rng.random(size=shape) < 0.5, -1.0, 1.0)
            return mag * sign

        kwargs: dict[str, np.ndarray] = {}
        for f in fields(cls):
            if f.name == "lever_arm":
                v = rng.standard_normal(3)
                kwargs[f.name] = v / np.linalg.norm(v)
            elif f.name == "pose_tilt":
                kwargs[f.name] = _pose_tilt_shape(rng.spawn(1)[0])
            else:
                kwargs[f.name] = signed((3, 3) if f.name == "g_sensitivity" else (3,))
        return cls(**kwargs)


def _pose_tilt_shape(rng: np.random.Generator) -> np.ndarray:
    """(6, 3): per pose of :data:`POSES`, normal components (std 1/sqrt(2)) on the two axes perpendicular to up."""
    draws = rng.standard_normal((len(POSES), 2)) / math.sqrt(2.0)
    out = np.zeros((len(POSES), 3))
    for i, pose in enumerate(POSES):
        perp = [k for k in range(3) if k != AXIS_INDEX[pose[1]]]
        out[i, perp] = draws[i]
    return out


@dataclass(frozen=True, eq=False)
class EffectTruth:
    """The effect coefficients the simulator applies, SI units (zeros where an effect is off).

    Attributes:
        accel_temp_bias: accelerometer bias per kelvin (m/s^2/K), (3,).
        gyro_temp_bias: gyro bias per kelvin (rad/s/K), (3,).
        accel_temp_scale, gyro_temp_scale: relative scale change per kelvin (1/K), (3,);
            the output is ``(1 + s dT) * (M x)`` per axis.
        g_sensitivity: gyro bias per specific force (rad/s per m/s^2), (3, 3): ``+ G f``
            (same meaning as ``TriadParams.g_sensitivity``).
        accel_nonlinearity: k in ``y = u + k u|u|`` per axis, 1/(m/s^2), (3,).
        gyro_nonlinearity: the same for the gyro, 1/(rad/s), (3,).
        accel_asymmetry, gyro_asymmetry: a per axis (1): scale ``1 + a/2`` for ``u > 0``,
            ``1 - a/2`` for ``u < 0``, (3,).
        lever_arm_m: accelerometer position relative to the rig's rotation centre, sensor
            frame (m), (3,).
        earth_rate_radps: Earth rate in the rig's world frame (x, y horizontal, z up) (rad/s), (3,);
            the gyro sees ``R^T`` of it.
        time_offset_s: sensor time minus rig time (s).
        accel_random_walk: bias random walk density (m/s^2/sqrt(s)), all axes.
        gyro_random_walk: bias random walk density (rad/s/sqrt(s)), all axes.
        extra_outlier_probability: added outlier probability per sample and axis.
        pose_tilt_rad: per pose of :data:`POSES`, the rotation vector ``phi`` (rad, sensor frame,
            perpendicular to the pose's up axis) of the sensor's actual attitude against the
            commanded one, (6, 3): ``R_true = R_nominal exp([phi]x)``, so the specific force the
            sensor feels is ``exp(-[phi]x) f_ref ~ f_ref + f_ref x phi``. Pose segments only.
        accel_quadratic, gyro_quadratic, accel_cubic, gyro_cubic: the IEEE 952 scale polynomial
            ``y = u + k2 u^2 + k3 u^3`` per axis (1/U, 1/U^2), (3,); zeros unless given explicitly (no
            :class:`Effects` magnitude realizes them: benchmarks and tests set them on the truth).

    Temperature effects act on ``T - T_ref``, the true sensor temperature minus its
    value at power-on (:attr:`station.physics.imu.Environment.ambient_degc`).
    """

    accel_temp_bias: np.ndarray
    gyro_temp_bias: np.ndarray
    accel_temp_scale: np.ndarray
    gyro_temp_scale: np.ndarray
    g_sensitivity: np.ndarray
    accel_nonlinearity: np.ndarray
    gyro_nonlinearity: np.ndarray
    accel_asymmetry: np.ndarray
    gyro_asymmetry: np.ndarray
    lever_arm_m: np.ndarray
    earth_rate_radps: np.ndarray
    time_offset_s: float = 0.0
    accel_random_walk: float = 0.0
    gyro_random_walk: float = 0.0
    extra_outlier_probability: float = 0.0
    pose_tilt_rad: np.ndarray | None = None
    accel_quadratic: np.ndarray | None = None
    gyro_quadratic: np.ndarray | None = None
    accel_cubic: np.ndarray | None = None
    gyro_cubic: np.ndarray | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "pose_tilt_rad" and value is None:
                value = np.zeros((len(POSES), 3))
            if f.name.endswith(("_quadratic", "_cubic")) and value is None:
                value = np.zeros(3)
            if isinstance(value, float | int):
                object.__setattr__(self, f.name, float(value))
            else:
                object.__setattr__(self, f.name, _ro(value, _SHAPE_TRUTH.get(f.name, (3,))))

    def pose_tilts(self) -> dict[str, np.ndarray]:
        """The non-zero pose tilts: pose name ('+x', ...) -> rotation vector (rad, sensor frame), (3,)."""
        tilt = np.asarray(self.pose_tilt_rad)
        return {pose: tilt[i] for i, pose in enumerate(POSES) if np.any(tilt[i])}
