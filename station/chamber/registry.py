"""Chambers by URL: the scheme registry of chamber implementations and :func:`open_chamber`.

Built in: ``modbus-tcp://HOST:PORT`` and ``modbus-rtu:///dev/ttyX?baud=N`` (:mod:`station.chamber.client`).
Other implementations register their scheme with ``CHAMBERS.register(scheme, opener)``, where
``opener(url, clock, **options)`` returns an open :class:`~station.chamber.protocol.Chamber`.
"""

from __future__ import annotations

from typing import Any

from station.chamber import client
from station.chamber.chamber_url import SCHEMES, ChamberUrlError, parse_chamber_url
from station.chamber.protocol import Chamber
from station.kernel.clock import Clock
from station.kernel.schemes import SchemeRegistry

CHAMBERS: SchemeRegistry[Chamber] = SchemeRegistry("chamber", ChamberUrlError)
for _scheme in SCHEMES:
    CHAMBERS.register(_scheme, client.open_chamber, parse_chamber_url)


def open_chamber(url: str, clock: Clock | None = None, **options: Any) -> Chamber:
    """Open, identify and supervise the chamber at ``url`` with the implementation its scheme names."""
    return CHAMBERS.open(url, clock, **options)


__all__ = ["CHAMBERS", "open_chamber"]
