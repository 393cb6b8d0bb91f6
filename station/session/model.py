"""In-memory session recording: what a sensor measured and what the rig imposed.

Units are SI inside the program: specific force in m/s^2, angular rate in rad/s,
time in s, temperature in degC. (The CSV v1 file stores angular rates in deg/s;
the reader and writer convert.) Cells the rig or sensor does not know are NaN.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from types import MappingProxyType

import numpy as np

from station.kernel.errors import SessionFormatError
from station.session.metadata import metadata_problem, number_problem

REQUIRED_KEYS = ("serial", "sample_rate_hz", "gravity_mps2")


class Kind(IntEnum):
    """What the rig was doing during a segment (spec: column ``kind``)."""

    REST = 0  # still from power-on, used for drift and noise
    POSE = 1  # settled static orientation
    RATE = 2  # settled constant rotation rate
    MOVE = 3  # anything in between (tumble, ramp, hand rotation)

    @property
    def label(self) -> str:
        return self.name.lower()

    @classmethod
    def parse(cls, text: str) -> Kind:
        return cls[text.upper()]


KIND_LABELS: tuple[str, ...] = tuple(k.label for k in Kind)


@dataclass(frozen=True)
class Segment:
    """A contiguous run of samples with one segment index and one kind."""

    index: int
    kind: Kind
    start: int  # first sample (inclusive)
    stop: int  # last sample (exclusive)

    @property
    def slice(self) -> slice:
        return slice(self.start, self.stop)

    def __len__(self) -> int:
        return self.stop - self.start


def _frozen(a: np.ndarray, dtype: type | np.dtype, shape_tail: tuple[int, ...]) -> np.ndarray:
    """A read-only copy of ``a``; an array that is already read-only, owns its memory and has the dtype is
    taken as it is (a reader's arrays, another Session's), so a long recording is not held twice."""
    taken = (isinstance(a, np.ndarray) and a.dtype == dtype and not a.flags.writeable and a.flags.owndata
             and a.flags.c_contiguous)
    arr = a if taken else np.array(a, dtype=dtype, copy=True)
    if arr.shape[1:] != shape_tail:
        raise ValueError(f"expected shape (n, {shape_tail}), got {arr.shape}")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class Session:
    """One calibration session of one unit.

    Attributes:
        metadata: every ``# key: value`` line except ``imu-session`` and ``angle.N``,
            values as written (strings). Required: serial, sample_rate_hz, gravity_mps2.
        angles_deg: segment index -> total rotation (deg) about the nominal x, y, z
            axes applied during that segment (``# angle.N`` lines).
        t_s: sample times since power-on (s), strictly increasing, shape (n,).
        segment: rig step index per sample, shape (n,).
        kind: :class:`Kind` code per sample, shape (n,).
        accel_mps2: measured specific force (m/s^2), shape (n, 3).
        gyro_radps: measured angular rate (rad/s), shape (n, 3).
        temp_degc: sensor temperature (degC), NaN where absent, shape (n,).
        ref_accel_mps2: rig specific-force reference (m/s^2), NaN where unknown.
        ref_gyro_radps: rig angular-rate reference (rad/s), NaN where unknown.
    """

    metadata: Mapping[str, str]
    t_s: np.ndarray
    segment: np.ndarray
    kind: np.ndarray
    accel_mps2: np.ndarray
    gyro_radps: np.ndarray
    temp_degc: np.ndarray
    ref_accel_mps2: np.ndarray
    ref_gyro_radps: np.ndarray
    angles_deg: Mapping[int, tuple[float, float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "metadata", MappingProxyType(dict(self.metadata)))
        set_(self, "angles_deg", MappingProxyType({int(k): tuple(map(float, v)) for k, v in self.angles_deg.items()}))
        set_(self, "t_s", _frozen(self.t_s, np.float64, ()))
        n = self.t_s.shape[0]
        set_(self, "segment", _frozen(self.segment, np.int64, ()))
        set_(self, "kind", _frozen(self.kind, np.int8, ()))
        for name in ("accel_mps2", "gyro_radps", "ref_accel_mps2", "ref_gyro_radps"):
            set_(self, name, _frozen(getattr(self, name), np.float64, (3,)))
        set_(self, "temp_degc", _frozen(self.temp_degc, np.float64, ()))
        for name in ("segment", "kind", "accel_mps2", "gyro_radps", "temp_degc", "ref_accel_mps2", "ref_gyro_radps"):
            if getattr(self, name).shape[0] != n:
                raise ValueError(f"{name} has {getattr(self, name).shape[0]} rows, t_s has {n}")
        missing = [k for k in REQUIRED_KEYS if k not in self.metadata]
        if missing:
            raise SessionFormatError(f"missing required metadata key(s): {', '.join(missing)}")

    # --- metadata accessors -------------------------------------------------
    @property
    def serial(self) -> str:
        return self.metadata["serial"]

    @property
    def sample_rate_hz(self) -> float:
        return float(self.metadata["sample_rate_hz"])

    @property
    def gravity_mps2(self) -> float:
        return float(self.metadata["gravity_mps2"])

    def meta_float(self, key: str) -> float | None:
        """A numeric metadata value, or None when the key is absent.

        Raises :class:`SessionFormatError` when the value is not a finite number in its range
        (:mod:`station.session.metadata`).
        """
        value = self.metadata.get(key)
        if value is None or value == "":
            return None
        problem = metadata_problem(key, value) or number_problem(str(value).strip())
        if problem:
            raise SessionFormatError(f"metadata {key}: {problem}")
        return float(value)

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) if len(self) else 0.0

    @property
    def has_temperature(self) -> bool:
        return bool(np.isfinite(self.temp_degc).any())

    # --- segments -----------------------------------------------------------
    def segments(self) -> list[Segment]:
        """Contiguous runs of equal (segment, kind), in recording order."""
        n = len(self)
        if n == 0:
            return []
        change = np.flatnonzero((np.diff(self.segment) != 0) | (np.diff(self.kind) != 0)) + 1
        starts = np.concatenate(([0], change))
        stops = np.concatenate((change, [n]))
        return [
            Segment(int(self.segment[a]), Kind(int(self.kind[a])), int(a), int(b))
            for a, b in zip(starts, stops, strict=True)
        ]

    def segments_of(self, *kinds: Kind) -> list[Segment]:
        return [s for s in self.segments() if s.kind in kinds]

    def replace(self, **changes: object) -> Session:
        """A copy with some fields replaced (arrays are copied, never shared writable)."""
        fields = {
            name: getattr(self, name)
            for name in (
                "metadata", "t_s", "segment", "kind", "accel_mps2", "gyro_radps",
                "temp_degc", "ref_accel_mps2", "ref_gyro_radps", "angles_deg",
            )
        }
        fields.update(changes)
        return Session(**fields)
