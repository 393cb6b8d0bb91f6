"""Physical constants the station uses (SI)."""

from __future__ import annotations

STANDARD_GRAVITY = 9.80665  # m/s^2, the conventional standard gravity (1 g)
EARTH_RATE_RADPS = 7.292115e-5  # rad/s, Earth's sidereal rotation rate
