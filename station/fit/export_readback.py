"""Exported calibrations read back as the other tools read them, and applied as they apply them.

What :mod:`station.fit.export` writes is only useful if the other tool, reading the file its own way, corrects
the data as the station would. These readers do what those tools do, not what the station's writer intends:

* **imu_tk** (``imu_tk::CalibratedTriad_::load``): 21 whitespace-separated numbers, the misalignment T (3 x 3),
  the scale K (3 x 3), the bias B (3), matrices read row by row (``>>`` into ``mis_mat_(i, j)`` for i, j); its
  ``unbiasNormalize`` corrects a raw reading X as ``T K (X - B)`` for both triads.
* **OpenAXES** (the coefficient list its calibration script prints and its firmware's host code uses): per
  accelerometer its matrix ``T K`` (9, column-major, MATLAB's order) and its bias after the matrix (3), then the
  gyro matrix (9, column-major) and its bias before it (3, rad/s): 24 numbers for one accelerometer, 36 for two.
  Accelerometer ``calibrated = TK raw - b``, gyro ``calibrated = M (raw - b)``.

Hand-written (a few lines each): neither tool ships a Python reader of its files.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.kernel.errors import FormatError

__all__ = ["ImuTkTriad", "OpenAxesList", "read_imu_tk_calib", "read_openaxes_list"]


@dataclass(frozen=True)
class ImuTkTriad:
    """One triad as imu_tk holds it: misalignment T, scale K, bias B."""

    t: np.ndarray
    k: np.ndarray
    b: np.ndarray

    def correct(self, x: np.ndarray) -> np.ndarray:
        """imu_tk's ``unbiasNormalize``: ``T K (X - B)`` per row of ``x`` (n, 3)."""
        return (np.asarray(x, dtype=float) - self.b) @ (self.t @ self.k).T


@dataclass(frozen=True)
class OpenAxesList:
    """The coefficient list: accelerometer matrices and biases (one per accelerometer), the gyro's."""

    accel_tk: tuple[np.ndarray, ...]
    accel_bias_after: tuple[np.ndarray, ...]
    gyro_m: np.ndarray
    gyro_bias: np.ndarray

    def correct_accel(self, x: np.ndarray, which: int = 0) -> np.ndarray:
        """``TK raw - b`` with accelerometer ``which`` (0: the first in the list)."""
        return np.asarray(x, dtype=float) @ self.accel_tk[which].T - self.accel_bias_after[which]

    def correct_gyro(self, x: np.ndarray) -> np.ndarray:
        """``M (raw - b)``."""
        return (np.asarray(x, dtype=float) - self.gyro_bias) @ self.gyro_m.T


def read_imu_tk_calib(path: Path | str) -> ImuTkTriad:
    """A ``*.calib`` file as ``CalibratedTriad_::load`` reads it (21 numbers; :class:`FormatError` otherwise)."""
    try:
        values = [float(v) for v in Path(path).read_text(encoding="ascii").split()]
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise FormatError(f"{path}: not an imu_tk calibration file: {exc}") from None
    if len(values) != 21:
        raise FormatError(f"{path}: imu_tk's load reads 21 numbers (T, K, B), the file has {len(values)}")
    a = np.array(values)
    return ImuTkTriad(a[0:9].reshape(3, 3), a[9:18].reshape(3, 3), a[18:21].copy())


def read_openaxes_list(text: str | Sequence[float]) -> OpenAxesList:
    """The list of 24 (one accelerometer) or 36 (two) numbers, whitespace-separated or given as numbers."""
    try:
        values = np.array([float(v) for v in (text.split() if isinstance(text, str) else text)])
    except ValueError as exc:
        raise FormatError(f"not an OpenAXES coefficient list: {exc}") from None
    if len(values) not in (24, 36):
        raise FormatError(f"an OpenAXES coefficient list has 24 or 36 numbers, this one {len(values)}")
    n = (len(values) - 12) // 12
    tk = tuple(values[12 * i:12 * i + 9].reshape(3, 3, order="F") for i in range(n))
    after = tuple(values[12 * i + 9:12 * i + 12].copy() for i in range(n))
    g = values[12 * n:]
    return OpenAxesList(tk, after, g[:9].reshape(3, 3, order="F"), g[9:12].copy())
