"""Thermal calibration plans: what the climate chamber does around the rig plan.

A :class:`ThermalPlan` wraps a :class:`~station.kernel.plan.RigPlan` (site, sample rate, poses, rate
steps, holds) with a temperature schedule, in one of two ways:

* ``plateaus``: for each temperature the chamber is set, the air confirmed at the setpoint, then the
  units are *soaked* until every unit's own temperature changes by less than ``soak_rate_k_per_min``
  over ``soak_window_s``, then the poses and rate steps (or a subset) are captured;
* ``ramp`` (the PX4 way): a cold soak at ``ramp_from_degc``, then the chamber ramps slowly to
  ``ramp_to_degc`` while the rig tumbles through the poses (and, with ``ramp_rate_steps``, turns),
  and a final soak and plateau at ``ramp_to_degc``.

Both start with the power-on rest at the room temperature (eq. 3's warm-up) and may end with a
raw *check* plateau at ``verify_degc`` (excluded from the fit, for comparing corrections offline);
after the image is written, the corrected output is verified on the rig at ``verify_degc``, a
temperature the fit did not use. The chamber goes back to ``ambient_degc`` in the teardown.
Temperatures degC, rates K/min, times s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from station.kernel.geometry import AXIS_INDEX, POSE_ANGLES_DEG
from station.kernel.plan import PlanError, RigPlan

THERMAL_MODES = ("plateaus", "ramp")


@dataclass(frozen=True)
class ThermalPlan:
    """A rig plan under a chamber temperature schedule (see the module docstring).

    Attributes:
        base: the rig plan (rest, poses, rate steps, holds, site, sample rate).
        mode: ``'plateaus'`` or ``'ramp'``.
        plateaus_degc: calibration temperatures (plateaus mode), in order.
        poses, rate_steps: the subset captured at each plateau (None: the base plan's).
        ramp_from_degc, ramp_to_degc, ramp_k_per_min: the continuous ramp (ramp mode).
        ramp_rate_steps: rate steps cycled with the poses during the ramp (rig allowing).
        verify_degc: the verification temperature (None: verify at the last calibration temperature);
            it must be at least ``min_verify_gap_k`` away from every calibration temperature.
        raw_check: capture the poses and rate steps also raw at ``verify_degc`` before the fit (kept out
            of the fit's recording; a separate check recording).
        ambient_degc: the room; the chamber returns to it in the teardown.
        move_ramp_k_per_min: chamber ramp between plateaus (0: as fast as the plant can).
        setpoint_timeout_s: the air must be confirmed at a setpoint within this (else a station ERROR).
        soak_rate_k_per_min, soak_window_s: the soak gate: every unit's temperature slope over the last
            window at most this (K/min, s).
        soak_timeout_s: a unit not stable within this fails its soak gate.
        soak_poll_s: how often the soak is judged (s).
        ambient_timeout_s: the teardown waits this long for the chamber at ambient (0: command only).
    """

    base: RigPlan = field(default_factory=RigPlan)
    mode: str = "plateaus"
    plateaus_degc: tuple[float, ...] = (5.0, 25.0, 45.0)
    poses: tuple[str, ...] | None = None
    rate_steps: tuple[tuple[str, float], ...] | None = None
    ramp_from_degc: float = 0.0
    ramp_to_degc: float = 50.0
    ramp_k_per_min: float = 0.5
    ramp_rate_steps: tuple[tuple[str, float], ...] = ()
    verify_degc: float | None = 35.0
    raw_check: bool = False
    ambient_degc: float = 23.0
    move_ramp_k_per_min: float = 0.0
    setpoint_timeout_s: float = 3600.0
    soak_rate_k_per_min: float = 0.1
    soak_window_s: float = 120.0
    soak_timeout_s: float = 3600.0
    soak_poll_s: float = 20.0
    ambient_timeout_s: float = 3600.0
    min_verify_gap_k: float = 2.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "plateaus_degc", tuple(float(t) for t in self.plateaus_degc))
        if self.poses is not None:
            object.__setattr__(self, "poses", tuple(self.poses))
        if self.rate_steps is not None:
            object.__setattr__(self, "rate_steps", tuple((str(a), float(r)) for a, r in self.rate_steps))
        object.__setattr__(self, "ramp_rate_steps", tuple((str(a), float(r)) for a, r in self.ramp_rate_steps))
        if self.mode not in THERMAL_MODES:
            raise PlanError(f"thermal plan: mode {self.mode!r} must be one of {', '.join(THERMAL_MODES)}")
        for pose in self.poses or ():
            if pose not in POSE_ANGLES_DEG:
                raise PlanError(f"thermal plan: unknown pose {pose!r}")
        for axis, _ in (*(self.rate_steps or ()), *self.ramp_rate_steps):
            if axis not in AXIS_INDEX:
                raise PlanError(f"thermal plan: unknown rate axis {axis!r}")
        temps = [*self.plateaus_degc, self.ramp_from_degc, self.ramp_to_degc, self.ambient_degc]
        if self.verify_degc is not None:
            temps.append(self.verify_degc)
        if not all(math.isfinite(t) and -100.0 <= t <= 250.0 for t in temps):
            raise PlanError(f"thermal plan: temperatures must be finite, within [-100, 250] degC: {temps}")
        if self.mode == "plateaus" and not self.plateaus_degc:
            raise PlanError("thermal plan: plateaus mode needs at least one plateau")
        if self.mode == "ramp":
            if self.ramp_from_degc == self.ramp_to_degc:
                raise PlanError("thermal plan: the ramp needs two different temperatures")
            if not self.ramp_k_per_min > 0:
                raise PlanError(f"thermal plan: ramp_k_per_min must be > 0, got {self.ramp_k_per_min!r}")
        for name in ("setpoint_timeout_s", "soak_rate_k_per_min", "soak_window_s", "soak_timeout_s", "soak_poll_s"):
            if not getattr(self, name) > 0:
                raise PlanError(f"thermal plan: {name} must be > 0, got {getattr(self, name)!r}")
        for name in ("move_ramp_k_per_min", "ambient_timeout_s"):
            if not getattr(self, name) >= 0:
                raise PlanError(f"thermal plan: {name} must be >= 0, got {getattr(self, name)!r}")
        if self.verify_degc is not None:
            gap = min(abs(self.verify_degc - t) for t in self.calibration_degc)
            inside_ramp = self.mode == "ramp" and (
                min(self.ramp_from_degc, self.ramp_to_degc) < self.verify_degc < max(self.ramp_from_degc,
                                                                                         self.ramp_to_degc))
            if gap < self.min_verify_gap_k and not inside_ramp:
                raise PlanError(f"thermal plan: verification at {self.verify_degc:g} degC is within "
                                f"{self.min_verify_gap_k:g} K of a calibration temperature")
        if self.raw_check and self.verify_degc is None:
            raise PlanError("thermal plan: raw_check needs a verify_degc")

    @property
    def calibration_degc(self) -> tuple[float, ...]:
        """The temperatures the fit gets settled data at (degC)."""
        if self.mode == "plateaus":
            return self.plateaus_degc
        return (self.ramp_from_degc, self.ramp_to_degc)

    @property
    def plateau_poses(self) -> tuple[str, ...]:
        return self.poses if self.poses is not None else self.base.poses

    @property
    def plateau_rate_steps(self) -> tuple[tuple[str, float], ...]:
        return self.rate_steps if self.rate_steps is not None else self.base.rate_steps


def default_thermal_plan() -> ThermalPlan:
    """Four plateaus (5, 15, 25, 45 degC: a cubic in the temperature stays checked), all poses and +-100 deg/s
    about each axis, verified at 35 degC."""
    steps = tuple((axis, sign * 100.0) for axis in "xyz" for sign in (1.0, -1.0))
    return ThermalPlan(base=RigPlan(sample_rate_hz=50.0, rest_s=300.0, pose_hold_s=20.0, rate_hold_s=10.0),
                       plateaus_degc=(5.0, 15.0, 25.0, 45.0), rate_steps=steps)


__all__ = ["THERMAL_MODES", "ThermalPlan", "default_thermal_plan"]
