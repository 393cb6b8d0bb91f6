"""The IMU's binary serial protocol and the station-side client (station/sensor/protocol.md).

- :mod:`station.sensor.frames`: framing, CRC-16/CCITT-FALSE, sample encoding, :class:`FrameParser`.
- :mod:`station.sensor.commands`: command/ACK/NAK codes and payloads.
- :mod:`station.sensor.client`: :func:`open_sensor` -> :class:`SerialSensor`.
- :mod:`station.sensor.url`: ``serial:///dev/...?baud=N`` parsing.
"""

from station.sensor.client import (
    CrcStormError,
    LinkStats,
    SampleBlock,
    SensorLinkError,
    SensorNak,
    SensorTimeout,
    SerialSensor,
    open_sensor,
)
from station.sensor.commands import EepromInfo, NakCode, OutputMode, SensorIdentity, SensorStatus
from station.sensor.frames import Frame, FrameParser, FrameType, ParserStats, SampleFlag
from station.sensor.url import SensorUrlError, SerialUrl, parse_sensor_url

__all__ = [
    "CrcStormError",
    "EepromInfo",
    "Frame",
    "FrameParser",
    "FrameType",
    "LinkStats",
    "NakCode",
    "OutputMode",
    "ParserStats",
    "SampleBlock",
    "SampleFlag",
    "SensorIdentity",
    "SensorLinkError",
    "SensorNak",
    "SensorStatus",
    "SensorTimeout",
    "SensorUrlError",
    "SerialSensor",
    "SerialUrl",
    "open_sensor",
    "parse_sensor_url",
]
