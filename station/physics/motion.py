"""Motion profiles of the rig's axes: piecewise-constant acceleration.

A rig axis (roll, pitch or the yaw of the rate table) moves by trapezoidal
profiles: accelerate at ``accel_max``, coast at ``rate_max``, decelerate. A rate
table ramps its rate at a bounded acceleration. Positions in rad, rates in rad/s,
accelerations in rad/s^2, times in s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class AxisTrajectory:
    """One axis as a list of phases ``(t_start, position, rate, accel)``.

    Each phase holds from its start until the next phase starts; within a phase the
    acceleration is constant. Build it forward in time with :meth:`move_to`,
    :meth:`ramp_rate` and :meth:`hold_until`.
    """

    t0: float = 0.0
    p0: float = 0.0
    v0: float = 0.0
    phases: list[tuple[float, float, float, float]] = field(default_factory=list)
    end_time: float = field(init=False)

    def __post_init__(self) -> None:
        if not self.phases:
            self.phases.append((self.t0, self.p0, self.v0, 0.0))
        self.end_time = self.phases[-1][0]

    def state_at(self, t: float) -> tuple[float, float, float]:
        p, v, a = self.state(np.array([t]))
        return float(p[0]), float(v[0]), float(a[0])

    def state(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position, rate, acceleration) at times ``t_s``; the last phase extends forever."""
        starts = np.array([ph[0] for ph in self.phases])
        idx = np.clip(np.searchsorted(starts, t_s, side="right") - 1, 0, len(starts) - 1)
        ph = np.array(self.phases)[idx]
        dt = np.asarray(t_s, dtype=float) - ph[:, 0]
        a = ph[:, 3]
        return ph[:, 1] + ph[:, 2] * dt + 0.5 * a * dt * dt, ph[:, 2] + a * dt, a

    def _append(self, duration: float, accel: float) -> None:
        t, p, v, a = self.phases[-1]
        dt = self.end_time - t
        p_end, v_end = p + v * dt + 0.5 * a * dt * dt, v + a * dt
        if self.phases[-1][0] == self.end_time:
            self.phases[-1] = (self.end_time, p_end, v_end, accel)
        else:
            self.phases.append((self.end_time, p_end, v_end, accel))
        self.end_time += duration

    def _close(self) -> None:
        """End the current phase at ``end_time`` with zero acceleration from there on."""
        self._append(0.0, 0.0)

    def hold_until(self, t: float) -> None:
        """Keep the current rate (no acceleration) until time ``t``."""
        self._close()
        self.end_time = max(self.end_time, t)
        self._close()

    def ramp_rate(self, rate: float, accel_max: float) -> float:
        """Change the rate to ``rate`` at ``accel_max``; returns the ramp duration."""
        self._close()
        v = self.phases[-1][2]
        duration = abs(rate - v) / accel_max
        if duration > 0:
            self._append(duration, math.copysign(accel_max, rate - v))
        self._close()
        return duration

    def move_to(self, position: float, rate_max: float, accel_max: float) -> float:
        """Move from rest to ``position`` by a trapezoidal profile; returns its duration.

        The axis must be at rest (rate 0) when the move starts.
        """
        self._close()
        _, p, v, _ = self.phases[-1]
        if abs(v) > 1e-12:
            raise ValueError("move_to needs the axis at rest")
        dist = position - p
        if dist == 0:
            return 0.0
        sgn = math.copysign(1.0, dist)
        d = abs(dist)
        t_acc = rate_max / accel_max
        if accel_max * t_acc * t_acc >= d:  # triangular: never reaches rate_max
            t_acc = math.sqrt(d / accel_max)
            t_coast = 0.0
        else:
            t_coast = (d - accel_max * t_acc * t_acc) / rate_max
        self._append(t_acc, sgn * accel_max)
        if t_coast > 0:
            self._append(t_coast, 0.0)
        self._append(t_acc, -sgn * accel_max)
        self._close()
        # remove rounding: pin the final state exactly
        t, _, _, _ = self.phases[-1]
        self.phases[-1] = (t, position, 0.0, 0.0)
        return 2 * t_acc + t_coast
