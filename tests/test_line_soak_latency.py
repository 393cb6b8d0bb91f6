"""The simulated rack keeps every soak when its peers answer late: the simulated sensors answer from threads of the
station's own process, so on a busy host a command's answer waits for the interpreter (two threads per unit take it
in turns), not for a sensor's firmware. Real peers: the relay board on Modbus/TCP (127.0.0.1), sensors on ptys,
the virtual clock; each peer answers a new command 2 s of wall time late (as a starved host made them)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from station.kernel.line_plan import load_line_plan_file
from station.kernel.virtual_clock import VirtualClock, acting
from station.line.recordings import MemoryArchive
from station.sim.line_station import SimLine
from station.sim.sensor_peer import SimulatedSensor

UNITS = 16
LATE_S = 2.0  # wall s: beyond the client's default 3 attempts x 0.5 s


def test_a_soak_of_late_answering_peers_keeps_every_recording(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    handle = SimulatedSensor._handle
    seen: set[tuple[int, bytes]] = set()

    def late(self: SimulatedSensor, payload: bytes) -> None:
        if (id(self), payload) not in seen:  # a retry of the same frame is answered at once, from the cache
            seen.add((id(self), payload))
            time.sleep(LATE_S)
        handle(self, payload)

    monkeypatch.setattr(SimulatedSensor, "_handle", late)
    line = load_line_plan_file(None)
    clock = VirtualClock()
    archive = MemoryArchive()
    with acting(clock, name="test"), SimLine(UNITS, 1.0, 3, line.rig_plan(), clock=clock) as sim:
        report = sim.soak(range(UNITS), 20.0, archive)
        serials = [sim.serial(k) for k in range(UNITS)]
    errors = [r.error for r in report.units if r.session is None]
    assert errors == []
    assert all(archive.latest(s) is not None for s in serials)
