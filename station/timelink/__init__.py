"""A virtual clock served across processes: ``virtual://HOST:PORT`` (see :mod:`station.timelink.link`)."""

from station.timelink.link import ClockServer, RemoteClock, open_clock

__all__ = ["ClockServer", "RemoteClock", "open_clock"]
