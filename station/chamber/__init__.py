"""The climate chamber: register map, the station's :class:`Chamber` protocol and its Modbus client."""

from station.chamber.chamber_url import ChamberUrl, ChamberUrlError, parse_chamber_url
from station.chamber.client import ModbusChamber, chamber_client_options
from station.chamber.protocol import (
    Chamber,
    ChamberAlarm,
    ChamberError,
    ChamberIdentity,
    ChamberProtocolError,
    ChamberSetpointTimeout,
    ChamberState,
    ChamberTimeout,
)
from station.chamber.registry import CHAMBERS, open_chamber

__all__ = [
    "CHAMBERS",
    "Chamber",
    "ChamberAlarm",
    "ChamberError",
    "ChamberIdentity",
    "ChamberProtocolError",
    "ChamberSetpointTimeout",
    "ChamberState",
    "ChamberTimeout",
    "ChamberUrl",
    "ChamberUrlError",
    "ModbusChamber",
    "chamber_client_options",
    "open_chamber",
    "parse_chamber_url",
]
