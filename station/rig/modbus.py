"""The station's Modbus client for the rig (map in :mod:`station.rig.registers`).

``open_rig(url, clock)`` connects over Modbus/TCP or Modbus RTU (pymodbus sync
clients), checks the map version and starts the heartbeat thread. Every Modbus
transaction goes through one lock and a bounded retry loop: a request that gets
no answer (or whose connection dropped) is retried ``retries`` times after
closing and reopening the link, then :class:`RigTimeout` is raised. Command writes
are idempotent because the rig executes a command only when COMMAND_SEQ changes,
so a retried write whose reply was lost does not run the command twice.

What the registers mean to the station (motion confirmed by the status bits *and* the
readbacks within tolerance, polled on the injected clock: ``WallClock`` for hardware,
``SimClock`` in simulation, so timeouts are in rig seconds) is
:class:`~station.rig.mapped.RegisterRig`'s; this module is its Modbus transport. I/O timeouts
are wall seconds.
"""

from __future__ import annotations

from typing import Any

from station.kernel.clock import Clock
from station.modbus.client import ModbusTransport
from station.rig.mapped import RegisterRig, start_rig
from station.rig.protocol import RigProtocolError, RigTimeout
from station.rig.rig_url import RigUrl, parse_rig_url


class ModbusRig(ModbusTransport, RegisterRig):
    """A rig behind Modbus; implements :class:`station.rig.protocol.Rig` (see :class:`RegisterRig`).

    The transport (retries, reconnects) is :class:`station.modbus.client.ModbusTransport`'s.

    Args:
        url: rig URL (see :mod:`station.rig.rig_url`) or a parsed :class:`RigUrl`.
        clock: time base for waits, polling and the heartbeat (rig seconds).
        retry_backoff_s: pause before a retry (wall s).
        options: the motion and supervision settings of :class:`RegisterRig`.
    """

    _role = "rig"
    _protocol_error = RigProtocolError
    _timeout_error = RigTimeout

    url: RigUrl

    def __init__(
        self,
        url: RigUrl | str,
        clock: Clock | None = None,
        *,
        retry_backoff_s: float = 0.05,
        **options: Any,
    ) -> None:
        super().__init__(clock, **options)
        self.url = url if isinstance(url, RigUrl) else parse_rig_url(url)
        self.retry_backoff_s = retry_backoff_s
        self._open_transport()

    def __enter__(self) -> ModbusRig:
        return self


def rig_client_options(scale: float = 1.0) -> dict[str, Any]:
    """Keyword arguments for :func:`open_rig` on a clock running ``scale`` times real time.

    At scale 1 these are the client defaults (poll 0.1 s, heartbeat 0.5 s, watchdog 2 s).
    On a fast simulated clock the rig seconds between polls and heartbeats grow so the
    wall-clock rates stay modest (~50 polls and ~25 heartbeats per wall second), and
    the watchdog and acknowledgement timeouts keep a margin of several wall periods.
    """
    s = float(scale)
    return {
        "poll_s": max(0.1, 0.02 * s),
        "heartbeat_period_s": max(0.5, 0.04 * s),
        "ack_timeout_s": max(2.0, 0.5 * s),
        "alive_timeout_s": max(2.0, 0.5 * s),
        "watchdog_s": min(60.0, max(2.0, 1.0 * s)),
    }


def open_rig(
    url: str | RigUrl,
    clock: Clock | None = None,
    *,
    heartbeat: bool = True,
    watchdog_s: float | None = None,
    **options: Any,
) -> ModbusRig:
    """Connect to the rig at ``url``, identify it, and start the heartbeat.

    ``watchdog_s`` (rig s) is written to the rig's WATCHDOG_MS if given; ``options``
    are the keyword arguments of :class:`ModbusRig`. Raises :class:`RigTimeout`
    when the rig does not answer and :class:`RigProtocolError` on a map mismatch.
    """
    return start_rig(ModbusRig(url, clock, **options), heartbeat=heartbeat, watchdog_s=watchdog_s)
