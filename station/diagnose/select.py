"""Compatibility: the diagnosis's selection used to live here; it is now split into
:mod:`station.diagnose.likelihood` (block covariance, nested tests), :mod:`station.diagnose.selection`
(forward selection, inseparable pairs), :mod:`station.diagnose.robust` (checks under misspecification,
unexplained) and :mod:`station.diagnose.reporting` (report entries)."""

from station.diagnose.likelihood import (
    ALPHA,
    DRIFT_NOISE_MAX,
    FOLDS,
    HELDOUT_SE,
    PROFILE_TC,
    RCOND,
    TC_FLOOR_S,
    SensorProblem,
    Test,
    base_drift,
)
from station.diagnose.reporting import AX, DETECT_POWER, OUTLIER_ALLOWANCE, detectable_from
from station.diagnose.selection import COLLINEAR_R2, NUISANCE, TEMPERATURE_R2, Decision, select

__all__ = [
    "ALPHA", "AX", "COLLINEAR_R2", "DETECT_POWER", "DRIFT_NOISE_MAX", "FOLDS", "HELDOUT_SE", "NUISANCE",
    "OUTLIER_ALLOWANCE", "PROFILE_TC", "RCOND", "TC_FLOOR_S", "TEMPERATURE_R2", "Decision", "SensorProblem", "Test",
    "base_drift", "detectable_from", "select",
]
