"""The device side of the station's heartbeat, as the simulated rig and chamber both keep it.

The station writes a changing value to the device's HEARTBEAT register; the first write arms the device's
watchdog, and from then on the device trips its WATCHDOG fault (rig) or alarm (chamber) when no new value
arrives within its watchdog time. The device echoes the last value it took and counts an ALIVE register up
from boot, which a stalled-firmware fault freezes. Both register maps (``station.rig.registers``,
``station.chamber.registers``) define these registers alike; only the watchdog's unit and the fault each
device latches differ, and those stay with the device's model.
"""

from __future__ import annotations


class DeviceHeartbeat:
    """Watchdog state and the ALIVE counter of one simulated Modbus device.

    Args:
        t_boot: the device's boot time on its clock (s).
        alive_period_s: how long one ALIVE count lasts (s), from the device's register map.
    """

    def __init__(self, t_boot: float, alive_period_s: float) -> None:
        self.t_boot = t_boot
        self.alive_period_s = alive_period_s
        self.armed = False
        self.last_t = t_boot
        self.echo = 0
        self._alive_frozen: int | None = None

    def written(self, value: int, now: float) -> None:
        """The station wrote ``value`` to HEARTBEAT at ``now``: the first write arms the watchdog, a new value
        refreshes it (a repeated value does not: a station stuck on one value is not alive)."""
        if not self.armed or value != self.echo:
            self.armed = True
            self.echo = value
            self.last_t = now

    def refreshed(self, now: float) -> None:
        """Restart the watchdog time at ``now`` (after a fault is reset or an alarm acknowledged)."""
        self.last_t = max(self.last_t, now)

    def deadline(self, watchdog_s: float) -> float | None:
        """When the watchdog trips (device s), or None while it is not armed."""
        return self.last_t + watchdog_s if self.armed else None

    def alive(self, now: float, stalled: bool) -> int:
        """The ALIVE register at ``now`` (u16, wrapping); frozen at its value while ``stalled``."""
        count = int((now - self.t_boot) / self.alive_period_s) & 0xFFFF
        if stalled:
            if self._alive_frozen is None:
                self._alive_frozen = count
            return self._alive_frozen
        self._alive_frozen = None
        return count
