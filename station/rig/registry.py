"""Rigs by URL: the scheme registry of rig implementations and :func:`open_rig`.

Built in: ``modbus-tcp://HOST:PORT`` and ``modbus-rtu:///dev/ttyX?baud=N`` (:mod:`station.rig.modbus`).
Other implementations register their scheme with ``RIGS.register(scheme, opener)``, where
``opener(url, clock, **options)`` returns an open :class:`~station.rig.protocol.Rig`.
"""

from __future__ import annotations

from typing import Any

from station.kernel.clock import Clock
from station.kernel.schemes import SchemeRegistry
from station.rig import modbus
from station.rig.protocol import Rig
from station.rig.rig_url import SCHEMES, RigUrl, RigUrlError, parse_rig_url

RIGS: SchemeRegistry[Rig] = SchemeRegistry("rig", RigUrlError)
for _scheme in SCHEMES:
    RIGS.register(_scheme, modbus.open_rig, parse_rig_url)


def open_rig(url: str | RigUrl, clock: Clock | None = None, **options: Any) -> Rig:
    """Open, identify and supervise the rig at ``url`` with the implementation its scheme names.

    ``options`` go to that implementation (for Modbus: :func:`station.rig.modbus.open_rig`).
    Raises :class:`~station.rig.rig_url.RigUrlError` for a scheme nobody registered.
    """
    if isinstance(url, RigUrl):
        return modbus.open_rig(url, clock, **options)
    return RIGS.open(url, clock, **options)


__all__ = ["RIGS", "open_rig"]
