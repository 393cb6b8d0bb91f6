"""Convert recordings of the imucal project (Ferraris calibrations) into a :class:`Session`.

imucal (https://github.com/mad-lab-fau/imucal, MIT) labels the parts of a Ferraris session:

* ``x_p`` / ``x_a`` (likewise y, z): static holds with the positive / negative sensor axis
  "aligned with gravity". imucal's documentation of ``FerrarisCalibration`` states that in
  ``x_p`` "x-acc measures +1g" and in ``x_a`` "x-acc measures -1g" (default ``grav=+9.81``).
  An accelerometer at rest measures the specific force, which points *up*, so ``x_p`` means the
  sensor x axis points up: reference specific force ``+g e_x``; ``x_a``: ``-g e_x``. This is
  also the spec's convention ("the specific force at rest points up").
* ``x_rot`` / ``y_rot`` / ``z_rot``: one hand-turned rotation about that axis. imucal's default
  ``expected_angle`` is -360 deg (its docs: "rotated clockwise ... (x-gyro shows negative
  values)"; "If you perform a counter-clockwise rotation ... set expected_angle to +360").
  Such a segment becomes ``kind = move`` with empty references and an ``angle.N`` of
  ``expected_angle_deg`` about that axis.

The poses are held by hand: the metadata ``reference_tolerance_mps2`` (:data:`HAND_TOLERANCE_MPS2`,
about 3 deg of alignment) says how far the true specific force may be from the label's reference; the
goodness-of-fit test of the fit takes it into account (:mod:`station.fit.goodness`).

Samples outside every labelled part become ``move`` segments with empty references. Segments are
numbered 0, 1, 2, ... in time order. There is no temperature channel (temp is NaN).
Units in the returned Session are SI: m/s^2, rad/s, s.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd

from station.kernel.errors import FormatError
from station.session.model import Kind, Session

__all__ = ["POSE_LABELS", "ROTATION_LABELS", "import_imucal_annotated", "import_imucal_ferraris"]

STANDARD_GRAVITY_MPS2 = 9.80665  # the "g" of a datasheet sensitivity in LSB/g
#: how far a hand-held pose's specific force may be from its label's reference (m/s^2, ~3 deg at 1 g)
HAND_TOLERANCE_MPS2 = 0.5

# label -> (axis index, sign of that axis' specific force): x_p = x axis up, reads +1 g.
POSE_LABELS: dict[str, tuple[int, float]] = {
    f"{axis}_{side}": (i, sign) for i, axis in enumerate("xyz") for side, sign in (("p", 1.0), ("a", -1.0))
}
# label -> axis index of the rotation
ROTATION_LABELS: dict[str, int] = {f"{axis}_rot": i for i, axis in enumerate("xyz")}
_KNOWN_LABELS = frozenset(POSE_LABELS) | frozenset(ROTATION_LABELS)

_FERRARIS_COLUMNS = ("n_samples", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z")
_ANNOTATED_COLUMNS = ("part", "samples", "acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z")


def import_imucal_ferraris(
    csv_path: str | os.PathLike[str],
    segments_json_path: str | os.PathLike[str],
    *,
    serial: str = "imucal-example",
    gravity_mps2: float = 9.81,
    sample_rate_hz: float = 102.4,
    expected_angle_deg: float = -360.0,
) -> Session:
    """Import imucal's ``example_ferraris_session.csv`` with its section list JSON.

    The CSV holds ``n_samples`` (sample counter), ``gyr_x..z`` in deg/s and ``acc_x..z`` in m/s^2.
    The JSON maps labels to ``{"start": i, "end": j}`` row ranges (end exclusive, as imucal's
    ``data.iloc[start:end]``). Time is ``n_samples / sample_rate_hz`` (s).
    """
    csv_name = os.fspath(csv_path)
    frame = _read_csv(csv_name, _FERRARIS_COLUMNS)
    counter = _integer_column(frame, "n_samples", csv_name)
    n = len(frame)
    label_array = np.full(n, -1, dtype=np.int64)
    sections = _read_sections(os.fspath(segments_json_path), n)
    for code, (label, start, stop) in enumerate(sections):
        if (label_array[start:stop] >= 0).any():
            raise FormatError(f"{os.fspath(segments_json_path)}: section {label!r} overlaps another section")
        label_array[start:stop] = code
    names = [label for label, _, _ in sections]
    labels: list[str | None] = [None if code < 0 else names[code] for code in label_array.tolist()]
    accel = frame[["acc_x", "acc_y", "acc_z"]].to_numpy(dtype=np.float64)
    gyro = np.deg2rad(frame[["gyr_x", "gyr_y", "gyr_z"]].to_numpy(dtype=np.float64))
    metadata = {
        "serial": serial,
        "sample_rate_hz": _number_text(sample_rate_hz),
        "gravity_mps2": _number_text(gravity_mps2),
        "source": "imucal",
        "source_file": Path(csv_name).name,
        "source_sections": Path(os.fspath(segments_json_path)).name,
        "reference_tolerance_mps2": _number_text(HAND_TOLERANCE_MPS2),
    }
    return _build(counter / sample_rate_hz, accel, gyro, labels, metadata, gravity_mps2, expected_angle_deg)


def import_imucal_annotated(
    csv_path: str | os.PathLike[str],
    *,
    serial: str = "imucal-annotated",
    accel_lsb_per_g: float = 2048.0,
    gyro_lsb_per_dps: float = 16.4,
    gravity_mps2: float = 9.81,
    sample_rate_hz: float = 204.8,
    expected_angle_deg: float = -360.0,
) -> Session:
    """Import imucal's ``annotated_session.csv``: raw counts, only the labelled parts.

    Columns ``part`` (label), ``samples`` (sample index), ``acc_x..z`` (counts, nominal
    ``accel_lsb_per_g`` per standard g = 9.80665 m/s^2) and ``gyr_x..z`` (counts, nominal
    ``gyro_lsb_per_dps`` per deg/s). Rows are grouped by label in the file; they are put in
    time order by ``samples``; time is ``samples / sample_rate_hz`` (s).
    """
    csv_name = os.fspath(csv_path)
    frame = _read_csv(csv_name, _ANNOTATED_COLUMNS)
    if not (accel_lsb_per_g > 0 and gyro_lsb_per_dps > 0 and sample_rate_hz > 0):
        raise FormatError("sensitivities and sample rate must be positive")
    counter = _integer_column(frame, "samples", csv_name, sort_ok=True)
    order = np.argsort(counter, kind="stable")
    counter = counter[order]
    if (np.diff(counter) <= 0).any():
        i = int(np.flatnonzero(np.diff(counter) <= 0)[0])
        raise FormatError(f"{csv_name}: sample index {int(counter[i])} appears more than once")
    frame = frame.iloc[order].reset_index(drop=True)
    labels: list[str | None] = [str(p) for p in frame["part"].tolist()]
    unknown = sorted({str(label) for label in labels} - _KNOWN_LABELS)
    if unknown:
        raise FormatError(f"{csv_name}: unknown part label(s) {', '.join(map(repr, unknown))}")
    accel = frame[["acc_x", "acc_y", "acc_z"]].to_numpy(dtype=np.float64) / accel_lsb_per_g * STANDARD_GRAVITY_MPS2
    gyro = np.deg2rad(frame[["gyr_x", "gyr_y", "gyr_z"]].to_numpy(dtype=np.float64) / gyro_lsb_per_dps)
    metadata = {
        "serial": serial,
        "sample_rate_hz": _number_text(sample_rate_hz),
        "gravity_mps2": _number_text(gravity_mps2),
        "source": "imucal",
        "source_file": Path(csv_name).name,
        "accel_lsb_per_g": _number_text(accel_lsb_per_g),
        "gyro_lsb_per_dps": _number_text(gyro_lsb_per_dps),
        "reference_tolerance_mps2": _number_text(HAND_TOLERANCE_MPS2),
    }
    return _build(counter / sample_rate_hz, accel, gyro, labels, metadata, gravity_mps2, expected_angle_deg)


def _number_text(value: float) -> str:
    number = float(value)
    if not np.isfinite(number) or number <= 0:
        raise FormatError(f"expected a positive finite number, got {value!r}")
    return repr(number)


def _read_csv(path: str, columns: tuple[str, ...]) -> pd.DataFrame:
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:  # EmptyDataError is a ValueError
        raise FormatError(f"{path}: cannot read imucal CSV: {exc}") from exc
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise FormatError(f"{path}: missing column(s) {', '.join(missing)}")
    if frame.empty:
        raise FormatError(f"{path}: no samples")
    numeric = [c for c in columns if c != "part"]
    for column in numeric:
        if not pd.api.types.is_numeric_dtype(frame[column]) or not np.isfinite(frame[column].to_numpy(float)).all():
            raise FormatError(f"{path}: column {column!r} must hold finite numbers")
    return frame


def _integer_column(frame: pd.DataFrame, column: str, path: str, *, sort_ok: bool = False) -> np.ndarray:
    values = frame[column].to_numpy(dtype=np.float64)
    if (values != np.round(values)).any() or (values < 0).any():
        raise FormatError(f"{path}: {column!r} must hold non-negative integers")
    if not sort_ok and (np.diff(values) <= 0).any():
        i = int(np.flatnonzero(np.diff(values) <= 0)[0]) + 1
        raise FormatError(f"{path}: {column!r} does not increase at row {i}")
    return values


def _read_sections(path: str, n_samples: int) -> list[tuple[str, int, int]]:
    """Labelled row ranges [start, stop) from an imucal section list, sorted by start."""
    try:
        with open(path, encoding="utf-8") as handle:
            raw = json.load(handle)
    except (OSError, ValueError) as exc:
        raise FormatError(f"{path}: cannot read imucal section list: {exc}") from exc
    if not isinstance(raw, dict):
        raise FormatError(f"{path}: expected an object mapping labels to {{'start', 'end'}}")
    sections: list[tuple[str, int, int]] = []
    for label, bounds in raw.items():
        if label not in _KNOWN_LABELS:
            raise FormatError(f"{path}: unknown section label {label!r}")
        try:
            start, stop = bounds["start"], bounds["end"]
        except (TypeError, KeyError) as exc:
            raise FormatError(f"{path}: section {label!r} needs 'start' and 'end'") from exc
        if not (isinstance(start, int) and isinstance(stop, int)) or not 0 <= start < stop <= n_samples:
            raise FormatError(f"{path}: section {label!r} range {start!r}..{stop!r} is outside 0..{n_samples}")
        sections.append((label, start, stop))
    return sorted(sections, key=lambda s: s[1])


def _build(
    t_s: np.ndarray,
    accel_mps2: np.ndarray,
    gyro_radps: np.ndarray,
    labels: list[str | None],
    metadata: dict[str, str],
    gravity_mps2: float,
    expected_angle_deg: float,
) -> Session:
    """Number runs of equal label in time order and attach kinds, references and angles."""
    n = len(labels)
    segment = np.empty(n, dtype=np.int64)
    kind = np.empty(n, dtype=np.int8)
    ref_accel = np.full((n, 3), np.nan)
    ref_gyro = np.full((n, 3), np.nan)
    angles: dict[int, tuple[float, float, float]] = {}
    index = -1
    start = 0
    while start < n:
        label = labels[start]
        stop = start + 1
        while stop < n and labels[stop] == label:
            stop += 1
        index += 1
        run = slice(start, stop)
        segment[run] = index
        if label in POSE_LABELS:
            axis, sign = POSE_LABELS[label]
            kind[run] = Kind.POSE
            up = np.zeros(3)
            up[axis] = sign * gravity_mps2  # specific force at rest points up (spec; imucal: x_p reads +1 g)
            ref_accel[run] = up
            ref_gyro[run] = 0.0  # the rig knows it is still; Earth rotation is not in the reference
        else:
            kind[run] = Kind.MOVE
            if label in ROTATION_LABELS:
                angle = [0.0, 0.0, 0.0]
                angle[ROTATION_LABELS[label]] = float(expected_angle_deg)
                angles[index] = (angle[0], angle[1], angle[2])
        start = stop
    return Session(
        metadata=metadata,
        t_s=t_s,
        segment=segment,
        kind=kind,
        accel_mps2=accel_mps2,
        gyro_radps=gyro_radps,
        temp_degc=np.full(n, np.nan),
        ref_accel_mps2=ref_accel,
        ref_gyro_radps=ref_gyro,
        angles_deg=angles,
    )
