"""The mounting error of each nest of a rig, and how a run takes it out of the rig's references.

A unit sits in its nest rotated by the nest's mounting error ``R_j`` (sensor frame to nest frame). What
the rig commands is known in the nest's frame; what the sensor measures is in its own: ``x_sensor =
R_j^T x_nest``. Uncorrected, the fit of eq. 1 puts ``R_j^T`` into the unit's M (``M_fit = M R_j^T``):
every unit measured in nest ``j`` gets the nest's tilt as cross-axis terms. A :class:`NestCalibration`
(fitted from one reference unit run in every nest, see :mod:`station.fit.nest_estimate`) holds ``R_j``
per nest as a rotation vector; :meth:`NestCalibration.to_sensor_frame` turns a run's references into the
sensor frame before the fit.

Only relative tilts can be measured with a reference unit whose own M is unknown: the calibration's
datum is then the mean nest (the rotation vectors sum to zero), and a tilt common to all nests stays in
every unit's M. With the reference unit's M from a calibration elsewhere (a laboratory's) the tilts are
absolute (``datum``: ``"reference"``).

Saved as JSON, format ``station-nests/1``; :func:`nest_calibration_from_json` refuses other formats.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.kernel.errors import FormatError, UnsupportedVersionError

FORMAT = "station-nests/1"


def rotation_matrix(rotvec_rad: np.ndarray) -> np.ndarray:
    """The rotation matrix of a rotation vector (rad), Rodrigues' formula."""
    v = np.asarray(rotvec_rad, dtype=float).reshape(3)
    angle = float(np.linalg.norm(v))
    if angle < 1e-15:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx))


def rotation_vector(r: np.ndarray) -> np.ndarray:
    """The rotation vector (rad) of a rotation matrix (angles below pi)."""
    m = np.asarray(r, dtype=float).reshape(3, 3)
    c = max(-1.0, min(1.0, (float(np.trace(m)) - 1.0) / 2.0))
    angle = math.acos(c)
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / 2.0
    if angle < 1e-12:
        return np.asarray(w)
    return np.asarray(w * angle / math.sin(angle))


@dataclass(frozen=True)
class NestCalibration:
    """The fitted mounting errors of one rig's nests.

    Attributes:
        rig: the rig these nests belong to (the station configuration's rig key, normally its URL).
        version: 1 for the rig's first calibration, counting up (assigned when stored).
        reference_serial: the reference unit that was run in every nest.
        created_at: ISO 8601 time of the estimate (UTC).
        rotations_deg: per nest (slot order) the rotation vector from the sensor frame to the nest frame (deg).
        rotations_std_deg: their standard uncertainties (deg), per nest and axis.
        agreement_deg: per nest the angle between the accelerometer's and the gyroscope's estimate (deg):
            both see the same mount, so a large value says the reference unit or the fit misbehaved.
        datum: ``"mean nest"`` (relative tilts) or ``"reference"`` (absolute: the reference unit's own M was
            known from a calibration elsewhere).
    """

    rig: str
    version: int
    reference_serial: str
    created_at: str
    rotations_deg: tuple[tuple[float, float, float], ...]
    rotations_std_deg: tuple[tuple[float, float, float], ...]
    agreement_deg: tuple[float, ...]
    datum: str = "mean nest"

    @property
    def nests(self) -> int:
        return len(self.rotations_deg)

    def rotation(self, slot: int) -> np.ndarray | None:
        """``R_j`` of nest ``slot`` (sensor frame to nest frame); None for a nest it does not cover."""
        if not 0 <= slot < self.nests:
            return None
        return rotation_matrix(np.radians(self.rotations_deg[slot]))

    def to_sensor_frame(self, slot: int, ref_nest: np.ndarray) -> np.ndarray:
        """References (n, 3) commanded in nest ``slot``'s frame, expressed in the sensor's frame (``R^T x``)."""
        r = self.rotation(slot)
        ref = np.asarray(ref_nest, dtype=float)
        return ref if r is None else np.asarray(ref @ r)

    @property
    def label(self) -> str:
        """How records name it: rig, version and the first 12 hex digits of its content hash."""
        return f"{self.rig} v{self.version} ({self.sha256[:12]})"

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.to_json_text().encode()).hexdigest()

    def to_json(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "rig": self.rig,
            "version": self.version,
            "reference_serial": self.reference_serial,
            "created_at": self.created_at,
            "rotations_deg": [list(r) for r in self.rotations_deg],
            "rotations_std_deg": [list(r) for r in self.rotations_std_deg],
            "agreement_deg": list(self.agreement_deg),
            "datum": self.datum,
        }

    def to_json_text(self) -> str:
        return json.dumps(self.to_json(), sort_keys=True, separators=(",", ":"))


def _triples(data: Mapping[str, Any], key: str) -> tuple[tuple[float, float, float], ...]:
    raw = data.get(key)
    if not isinstance(raw, list) or not all(isinstance(r, list) and len(r) == 3 for r in raw):
        raise FormatError(f"{FORMAT}: {key} must be a list of [x, y, z] triples")
    out = tuple((float(r[0]), float(r[1]), float(r[2])) for r in raw)
    if not all(math.isfinite(v) for r in out for v in r):
        raise FormatError(f"{FORMAT}: {key} holds a value that is not finite")
    return out


def nest_calibration_from_json(data: Mapping[str, Any]) -> NestCalibration:
    """Read a nest calibration; refuses an unknown format or a malformed one."""
    fmt = data.get("format")
    if fmt != FORMAT:
        raise UnsupportedVersionError(f"nest calibration format {fmt!r} is not {FORMAT!r}")
    rot = _triples(data, "rotations_deg")
    std = _triples(data, "rotations_std_deg")
    agree = data.get("agreement_deg")
    if len(std) != len(rot) or not isinstance(agree, list) or len(agree) != len(rot):
        raise FormatError(f"{FORMAT}: rotations, their uncertainties and agreements differ in length")
    return NestCalibration(
        rig=str(data.get("rig", "")), version=int(data.get("version", 0)),
        reference_serial=str(data.get("reference_serial", "")), created_at=str(data.get("created_at", "")),
        rotations_deg=rot, rotations_std_deg=std, agreement_deg=tuple(float(a) for a in agree),
        datum=str(data.get("datum", "mean nest")),
    )
