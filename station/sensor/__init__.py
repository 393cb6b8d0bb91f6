"""The IMU's binary serial protocol and the station-side client (station/sensor/protocol.md).

- :mod:`station.sensor.frames`: framing, CRC-16/CCITT-FALSE, sample encoding, :class:`FrameParser`.
- :mod:`station.sensor.commands`: command/ACK/NAK codes and payloads.
- :mod:`station.sensor.protocol`: the :class:`Sensor` protocol, :class:`SampleBlock`, the link faults.
- :mod:`station.sensor.base`: :class:`~station.sensor.base.ProtocolSensor`, the protocol's semantics over any transport.
- :mod:`station.sensor.client`: :class:`SerialSensor`, the protocol over a serial port.
- :mod:`station.sensor.registry`: :func:`open_sensor` by URL scheme.
- :mod:`station.sensor.serial_url`: ``serial:///dev/...?baud=N`` parsing.
"""

from station.sensor.client import SerialSensor
from station.sensor.commands import EepromInfo, NakCode, OutputMode, SensorIdentity, SensorStatus
from station.sensor.frames import Frame, FrameParser, FrameType, ParserStats, SampleFlag
from station.sensor.protocol import (
    CrcStormError,
    LinkStats,
    SampleBlock,
    Sensor,
    SensorLinkError,
    SensorNak,
    SensorTimeout,
)
from station.sensor.registry import SENSORS, open_sensor
from station.sensor.serial_url import SensorUrlError, SerialUrl, parse_sensor_url

__all__ = [
    "SENSORS",
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
    "Sensor",
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
