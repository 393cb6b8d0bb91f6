"""Which physics the calibration carries into the product: effect name -> the parameter-set fields that hold it.

The names are those of :class:`station.physics.effects.Effects` (what the diagnosis finds). An effect is
*compensated* by a parameter set when Algorithm 1 (:mod:`station.correct.streaming`, the firmware) applies
it from that set's fields, and those fields are non-zero in the set at hand (:func:`compensated_by`).

``time_offset`` is applied since ``station-params/3``: Algorithm 1's line 0 moves the input onto the rig's
time by ``ParameterSet.time_offset_s``. Effects without fields (lever arm, Earth rotation, scale asymmetry,
bias random walk, outliers, pose tilt) are not compensated:
the rig or the fit's design takes care of them, or nothing can.
"""

from __future__ import annotations

import math

import numpy as np

from station.kernel.parameters import ParameterSet

#: Effect name -> dotted ParameterSet field paths that compensate it (empty: not compensable by the set).
COMPENSATION: dict[str, tuple[str, ...]] = {
    "temperature_bias": ("accel.temp_bias_coeff", "gyro.temp_bias_coeff"),
    "temperature_scale": ("accel.temp_scale_coeff", "gyro.temp_scale_coeff"),
    "g_sensitivity": ("gyro.g_sensitivity",),
    "scale_nonlinearity": ("accel.scale_nonlinearity", "gyro.scale_nonlinearity", "accel.scale_quadratic",
                           "gyro.scale_quadratic", "accel.scale_cubic", "gyro.scale_cubic"),
    "time_offset": ("time_offset_s",),
    "scale_asymmetry": (),
    "lever_arm": (),
    "earth_rotation": (),
    "bias_random_walk": (),
    "outliers": (),
    "pose_tilt": (),
}
#: Effects Algorithm 1 applies when their fields are non-zero.
APPLIED = frozenset({"temperature_bias", "temperature_scale", "g_sensitivity", "scale_nonlinearity", "time_offset"})


def field_value(params: ParameterSet, path: str) -> object:
    """The value at a dotted field path, e.g. ``'gyro.temp_bias_coeff'``."""
    obj: object = params
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def compensated_by(params: ParameterSet, effect: str) -> bool:
    """Whether ``params`` compensates ``effect`` in the corrected output: Algorithm 1 applies it and its
    fields are non-zero (temperature terms also need a reference temperature). False for unknown names."""
    if effect not in APPLIED:
        return False
    if effect.startswith("temperature_") and not math.isfinite(params.reference_temperature_degc):
        return False
    return any(np.any(np.asarray(field_value(params, p)) != 0) for p in COMPENSATION[effect])


def compensated_effects(params: ParameterSet, findings: list[str] | tuple[str, ...]) -> dict[str, bool]:
    """For each finding (effect name) of a diagnosis: does this parameter set compensate it?"""
    return {name: compensated_by(params, name) for name in findings}


__all__ = ["APPLIED", "COMPENSATION", "compensated_by", "compensated_effects", "field_value"]
