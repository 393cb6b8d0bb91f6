"""A run's references taken from its nest's frame into the sensor's frame, with the nest calibration.

The session a run saves then holds the references the sensor actually saw (``R_j^T x``, see
:mod:`station.kernel.nest_frames`), so the fit of eq. 1 no longer puts the nest's tilt into the unit's M,
and re-fitting the saved CSV reproduces the run's parameter set. The metadata names the calibration
(``nest_calibration``: rig, version, content hash) and the rotation applied (``nest_rotation_deg``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from station.kernel.nest_frames import NestCalibration
from station.session.model import Session


def in_sensor_frame(session: Session, calibration: NestCalibration | None, slot: int) -> Session:
    """``session`` (recorded in nest ``slot``) with its references in the sensor's frame; unchanged without
    a calibration or for a nest the calibration does not cover."""
    r = calibration.rotation(slot) if calibration is not None else None
    if calibration is None or r is None:
        return session
    rot = calibration.rotations_deg[slot]
    meta = {**session.metadata, "nest_calibration": calibration.label,
            "nest_rotation_deg": ",".join(f"{v:.6f}" for v in rot)}
    angles = {k: tuple(float(v) for v in np.asarray(a, dtype=float) @ r) for k, a in session.angles_deg.items()}
    return replace(session, metadata=meta, ref_accel_mps2=np.asarray(session.ref_accel_mps2 @ r),
                   ref_gyro_radps=np.asarray(session.ref_gyro_radps @ r),
                   angles_deg={k: (a[0], a[1], a[2]) for k, a in angles.items()})
