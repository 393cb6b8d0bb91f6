"""Known-angle gyro scale fit (Ferraris-style, as imucal does) for ``angle.N`` rotations.

For each rotation segment n the integral of the bias-corrected gyro output equals
``M_w theta_n`` (theta_n: the applied rotation in rad about the nominal axes), as long
as the rotation is about a fixed axis and starts and ends at rest. With rotations that
span three axes, ``M_w = I Theta^T (Theta Theta^T)^-1`` (columns: rotations).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.session.model import Session


@dataclass(frozen=True, eq=False)
class AngleFit:
    """M_w (1) and its standard uncertainty, plus per-rotation figures in ``report``."""

    misalignment: np.ndarray
    misalignment_std: np.ndarray
    report: dict[str, Any] = field(default_factory=dict)


def fit_known_angles(
    session: Session, bias_radps: np.ndarray, bias_std_radps: np.ndarray, sigma_radps: np.ndarray
) -> AngleFit:
    """Fit M_w from the ``angle.N`` segments.

    Args:
        session: the recording; ``session.angles_deg`` names the rotation segments.
        bias_radps: the gyro bias at every sample (rad/s), shape (n, 3).
        bias_std_radps: standard uncertainty of the static bias per axis (rad/s).
        sigma_radps: white-noise std per sample per axis (rad/s).

    The uncertainty includes the white noise of each integral and the bias uncertainty
    times the rotation's duration (the same for every rotation, so correlated). An
    optional metadata key ``angle_std_deg`` adds the uncertainty of the applied angles.
    """
    ts = 1.0 / session.sample_rate_hz
    ints, thetas, durations, counts, names = [], [], [], [], []
    for index, angle in sorted(session.angles_deg.items()):
        sel = np.flatnonzero(session.segment == index)
        if sel.size == 0:
            continue
        a, b = int(sel[0]), int(sel[-1]) + 1
        ints.append(((session.gyro_radps[a:b] - bias_radps[a:b]) * ts).sum(axis=0))
        thetas.append(np.radians(angle))
        durations.append((b - a) * ts)
        counts.append(b - a)
        names.append(index)
    big_i = np.array(ints).T  # (3, n)
    theta = np.array(thetas).T  # (3, n)
    a_mat = theta.T @ np.linalg.inv(theta @ theta.T)  # (n, 3)
    m = big_i @ a_mat
    dur = np.array(durations)
    angle_std = np.radians(session.meta_float("angle_std_deg") or 0.0)
    m_std = np.zeros((3, 3))
    chi2, z = 0.0, np.zeros(len(names))
    for k in range(3):
        cov_i = np.diag(sigma_radps[k] ** 2 * ts**2 * np.array(counts, dtype=float))
        cov_i += bias_std_radps[k] ** 2 * np.outer(dur, dur)
        # an error in the applied angle enters as M_k . delta_theta
        cov_i += np.eye(len(dur)) * (angle_std**2) * float(m[k] @ m[k])
        m_std[k] = np.sqrt(np.clip(np.diag(a_mat.T @ cov_i @ a_mat), 0.0, None))
        # residual of the integrals about the fitted row, in its covariance (rotations beyond three)
        resid = big_i[k] - m[k] @ theta
        if len(names) > 3:
            proj = np.eye(len(names)) - theta.T @ a_mat.T
            cov_r = proj @ cov_i @ proj.T
            chi2 += float(resid @ np.linalg.pinv(cov_r, rcond=1e-10, hermitian=True) @ resid)
            z = np.maximum(z, np.abs(resid) / np.sqrt(np.clip(np.diag(cov_r), 1e-300, None)))
    measured = np.linalg.solve(m, big_i)  # integrated angles after calibration (rad)
    report = {
        "segments": names,
        "applied_deg": np.degrees(theta.T).round(6).tolist(),
        "calibrated_deg": np.degrees(measured.T).round(6).tolist(),
        "rotations": len(names),
        "chi2": round(chi2, 3),
        "dof": 3 * max(len(names) - 3, 0),
        "worst_segment": int(names[int(np.argmax(z))]),
        "worst_z": round(float(z.max()), 3),
    }
    return AngleFit(misalignment=m, misalignment_std=m_std, report=report)
