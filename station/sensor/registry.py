"""Sensors by URL: the scheme registry of sensor implementations and :func:`open_sensor`.

Built in: ``serial:///dev/ttyX?baud=N`` (:mod:`station.sensor.client`). Other implementations
register their scheme with ``SENSORS.register(scheme, opener)``, where
``opener(url, clock, **options)`` returns an open :class:`~station.sensor.protocol.Sensor`.
"""

from __future__ import annotations

from typing import Any

from station.kernel.clock import Clock
from station.kernel.schemes import SchemeRegistry
from station.sensor import client
from station.sensor.protocol import Sensor
from station.sensor.serial_url import SensorUrlError, parse_sensor_url

SENSORS: SchemeRegistry[Sensor] = SchemeRegistry("sensor", SensorUrlError)
SENSORS.register("serial", client.open_sensor, parse_sensor_url)


def open_sensor(url: str, clock: Clock | None = None, **options: Any) -> Sensor:
    """Open the sensor at ``url`` with the implementation its scheme names (``options`` go to it).

    Raises :class:`~station.sensor.serial_url.SensorUrlError` for a scheme nobody registered.
    """
    return SENSORS.open(url, clock, **options)


__all__ = ["SENSORS", "open_sensor"]
