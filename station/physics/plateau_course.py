"""A unit's temperature in a climate chamber that steps through plateaus (for simulated thermal sessions).

The chamber's setpoint jumps to plateau ``k`` at ``starts_s[k]``; the unit follows with a first-order
lag ``lag_s`` (air and housing lumped), and its own self-heating since power-on rides on top:

    T(t) = T_chamber(t) + h (1 - exp(-t / tau_h)),
    T_chamber(t) = P_k + (T_chamber(s_k) - P_k) exp(-(t - s_k) / lag_s)   for s_k <= t < s_(k+1),

with ``T_chamber(0) = P_0``: the unit is powered on soaked at the first plateau, so its power-on
temperature (the temperature effects' ``T_ref``) is ``P_0``. Units: s, degC, K.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlateauCourse:
    """The unit's true temperature (degC) as a function of time since power-on (s); call it with an array.

    Attributes:
        plateaus_degc: chamber setpoints, in order.
        starts_s: time each plateau's setpoint is applied (s); ``starts_s[0]`` is 0.
        lag_s: first-order lag of the unit behind the setpoint (s).
        self_heating_k, self_heating_tau_s: the unit's self-heating since power-on (K, s).
    """

    plateaus_degc: tuple[float, ...]
    starts_s: tuple[float, ...]
    lag_s: float = 150.0
    self_heating_k: float = 0.0
    self_heating_tau_s: float = 300.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "plateaus_degc", tuple(float(p) for p in self.plateaus_degc))
        object.__setattr__(self, "starts_s", tuple(float(s) for s in self.starts_s))
        if not self.plateaus_degc or len(self.plateaus_degc) != len(self.starts_s):
            raise ValueError("plateau course: one start time per plateau, at least one plateau")
        if self.starts_s[0] != 0.0 or any(b <= a for a, b in zip(self.starts_s, self.starts_s[1:], strict=False)):
            raise ValueError(f"plateau course: starts must begin at 0 and increase, got {self.starts_s}")
        if not (self.lag_s > 0 and self.self_heating_tau_s > 0 and all(map(math.isfinite, self.plateaus_degc))):
            raise ValueError("plateau course: lag and self-heating time constant must be > 0, plateaus finite")

    def chamber_lagged(self, t_s: np.ndarray) -> np.ndarray:
        """The unit's temperature without self-heating (degC) at ``t_s`` (s since power-on)."""
        t = np.asarray(t_s, dtype=float)
        out = np.empty_like(t)
        level = self.plateaus_degc[0]  # T_chamber at the start of the current block
        edges = (*self.starts_s[1:], math.inf)
        for k, (s0, s1) in enumerate(zip(self.starts_s, edges, strict=True)):
            p = self.plateaus_degc[k]
            sel = (t >= s0) & (t < s1)
            out[sel] = p + (level - p) * np.exp(-(t[sel] - s0) / self.lag_s)
            if math.isfinite(s1):
                level = p + (level - p) * math.exp(-(s1 - s0) / self.lag_s)
        out[t < 0] = self.plateaus_degc[0]
        return out

    def __call__(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        return self.chamber_lagged(t) + self.self_heating_k * -np.expm1(-np.maximum(t, 0.0) / self.self_heating_tau_s)
