"""Readable names and units of the stored parameter names (``accel.M.xy``, ``fit.gyro.M_std.zx``, ...)."""

from __future__ import annotations

SENSORS = {"accel": "accelerometer", "gyro": "gyroscope"}
FAMILIES = {
    "bias_static": "static bias", "bias_drift": "drift bias (eq. 3)", "noise_std": "white noise sigma",
    "correlation_time_s": "drift correlation time", "residual_rms": "fit residual RMS",
    "bias_static_std": "uncertainty of the static bias",
}
UNITS = {"m/s^2": "m/s²", "rad/s": "rad/s", "s": "s", "1": "–", "": ""}


def parameter_label(name: str) -> str:
    """E.g. 'accel.M.xx' -> 'accelerometer scale factor x'; 'fit.gyro.M_std.zx' -> 'gyroscope uncertainty of M
    z←x (fit quality)'. Unknown names come back unchanged."""
    parts = name.split(".")
    fit = parts[0] == "fit"
    if fit:
        parts = parts[1:]
    if len(parts) != 3 or parts[0] not in SENSORS:
        return name
    sensor, family, axes = SENSORS[parts[0]], parts[1], parts[2]
    if family in ("M", "M_std"):
        what = (f"scale factor {axes[0]}" if len(axes) == 2 and axes[0] == axes[1]
                else f"cross-axis {axes[0]}←{axes[1]}" if len(axes) == 2 else f"M {axes}")
        if family == "M_std":
            what = f"uncertainty of {what}"
    else:
        what = f"{FAMILIES.get(family, family.replace('_', ' '))} {axes}"
    return f"{sensor} {what}" + (" (fit quality)" if fit else "")


def unit_label(unit: str) -> str:
    """The SI unit as shown ('m/s^2' -> 'm/s²'; '1' -> '–', dimensionless)."""
    return UNITS.get(unit, unit)


__all__ = ["parameter_label", "unit_label"]
