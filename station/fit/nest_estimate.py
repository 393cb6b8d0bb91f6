"""Each nest's mounting error from one reference unit fitted in every nest.

A unit whose own misalignment is ``M`` fitted in nest ``j`` gives ``A_j = M R_j^T`` (see
:mod:`station.kernel.nest_frames`). So ``A_0^{-1} A_j = R_0 R_j^T`` depends on the nests alone: its
orthogonal (polar) factor is the relative rotation ``R_0 R_j^T``. The datum is the mean nest (the rotation
vectors sum to zero), unless the reference unit's own M is known from a calibration elsewhere: then
``polar(M^{-1} A_j) = R_j^T`` and the rotations are absolute. Accelerometer and gyroscope see the same mount;
each gives an estimate, combined with inverse-variance weights from the fitted M's uncertainties, and the
angle between the two is kept as a check.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np

from station.kernel.errors import FitError
from station.kernel.nest_frames import NestCalibration, rotation_matrix, rotation_vector


@dataclass(frozen=True)
class TriadFit:
    """One sensor triad's fitted M (3x3) and its standard uncertainties (3x3), in one nest."""

    misalignment: np.ndarray
    misalignment_std: np.ndarray


@dataclass(frozen=True)
class NestFits:
    """The reference unit's accelerometer and gyroscope fits in one nest."""

    accel: TriadFit
    gyro: TriadFit


def _polar(d: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(d)
    r = u @ vt
    if np.linalg.det(r) < 0:  # keep a proper rotation
        u[:, -1] *= -1.0
        r = u @ vt
    return np.asarray(r)


def _one_sensor(fits: list[TriadFit], reference: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(theta (k, 3) rad, their std (k, 3) rad) from one triad's fits in k nests.

    With the reference unit's own M (``reference``, from a calibration elsewhere) every nest's rotation is
    absolute: ``R_j^T = polar(M^{-1} A_j)``. Without it only the relative rotations ``R_0 R_j^T =
    polar(A_0^{-1} A_j)`` are known; the datum is then chosen so that the rotation vectors sum to zero
    (found by a few fixed-point steps; exact, not a small-angle approximation).
    """
    if reference is not None:
        m_inv = np.linalg.inv(reference)
        rot = [_polar(m_inv @ f.misalignment).T for f in fits]
    else:
        a0_inv = np.linalg.inv(fits[0].misalignment)
        c = [_polar(a0_inv @ f.misalignment) for f in fits]  # R_0 R_j^T
        r0 = np.eye(3)
        for _ in range(50):
            mean = np.mean([rotation_vector(cj.T @ r0) for cj in c], axis=0)
            r0 = r0 @ rotation_matrix(-mean)
            if float(np.linalg.norm(mean)) < 1e-15:
                break
        rot = [cj.T @ r0 for cj in c]
    theta = np.array([rotation_vector(r) for r in rot])
    # first-order std of a rotation vector from M's off-diagonal pair (i, j): half the std of their difference
    pairs = ((2, 1), (0, 2), (1, 0))

    def pair_var(s: np.ndarray) -> np.ndarray:
        return np.array([(s[i, j] ** 2 + s[j, i] ** 2) / 4.0 for i, j in pairs])

    v0 = pair_var(fits[0].misalignment_std) if reference is None else 0.0
    var = np.array([pair_var(f.misalignment_std) + (v0 if k else 0.0) for k, f in enumerate(fits)])
    return theta, np.sqrt(var)


def estimate_nest_calibration(rig: str, reference_serial: str, per_nest: Mapping[int, NestFits],
                              reference: NestFits | None = None) -> NestCalibration:
    """The nests' mounting errors from the reference unit's fits in nests ``0 .. k-1`` (all of them needed).

    ``reference``: the reference unit's M (accelerometer and gyroscope) from a calibration elsewhere (a
    laboratory's, traceable): the nests' rotations are then absolute, a tilt common to all nests included.
    Without it the datum is the mean nest.

    Raises :class:`~station.kernel.errors.FitError` when a nest is missing or a fit's M is singular.
    """
    k = len(per_nest)
    if k < 2:
        raise FitError("a nest calibration needs the reference unit's fits in at least 2 nests")
    missing = [j for j in range(k) if j not in per_nest]
    if missing:
        raise FitError(f"no fit of the reference unit in nest {missing[0] + 1}: run it in every nest")
    try:
        th_a, sd_a = _one_sensor([per_nest[j].accel for j in range(k)],
                                 None if reference is None else reference.accel.misalignment)
        th_w, sd_w = _one_sensor([per_nest[j].gyro for j in range(k)],
                                 None if reference is None else reference.gyro.misalignment)
    except np.linalg.LinAlgError:
        raise FitError("a fitted misalignment matrix of the reference unit is singular") from None
    wa = 1.0 / np.maximum(sd_a, 1e-12) ** 2
    ww = 1.0 / np.maximum(sd_w, 1e-12) ** 2
    theta = (wa * th_a + ww * th_w) / (wa + ww)
    std = 1.0 / np.sqrt(wa + ww)
    agree = np.degrees(np.linalg.norm(th_a - th_w, axis=1))
    return NestCalibration(
        rig=rig, version=0, reference_serial=reference_serial,
        created_at=datetime.now(UTC).isoformat(timespec="seconds"),
        rotations_deg=tuple((float(a), float(b), float(c)) for a, b, c in np.degrees(theta)),
        rotations_std_deg=tuple((float(a), float(b), float(c)) for a, b, c in np.degrees(std)),
        agreement_deg=tuple(float(a) for a in agree),
        datum="mean nest" if reference is None else "reference",
    )
