"""The test rig: register map, the station's :class:`Rig` protocol and the Modbus client."""

from station.rig.modbus import ModbusRig, rig_client_options
from station.rig.protocol import (
    Orientation,
    Rig,
    RigCommandRejected,
    RigError,
    RigFault,
    RigIdentity,
    RigMotionTimeout,
    RigProtocolError,
    RigState,
    RigTimeout,
)
from station.rig.registry import RIGS, open_rig
from station.rig.rig_url import RigUrl, RigUrlError, parse_rig_url

__all__ = [
    "RIGS",
    "ModbusRig",
    "Orientation",
    "Rig",
    "RigCommandRejected",
    "RigError",
    "RigFault",
    "RigIdentity",
    "RigMotionTimeout",
    "RigProtocolError",
    "RigState",
    "RigTimeout",
    "RigUrl",
    "RigUrlError",
    "open_rig",
    "parse_rig_url",
    "rig_client_options",
]
