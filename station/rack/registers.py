"""The soak rack's relay board register map (``station/rack/register-map.md``): coils and input registers."""

from __future__ import annotations

#: first relay coil; relay k is coil ``RELAY_START + k``
RELAY_START = 0
#: most relays a board of this map has
MAX_CHANNELS = 64

#: input registers
IR_CHANNELS = 0
IR_ALIVE = 1
IR_POWER_ON_COUNT_LO = 2
IR_POWER_ON_COUNT_HI = 3
IR_COUNT = 4

__all__ = ["IR_ALIVE", "IR_CHANNELS", "IR_COUNT", "IR_POWER_ON_COUNT_HI", "IR_POWER_ON_COUNT_LO", "MAX_CHANNELS",
           "RELAY_START"]
