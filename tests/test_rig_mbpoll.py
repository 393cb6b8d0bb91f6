"""Interoperability: Debian's ``mbpoll`` (libmodbus) talks to the simulated rig
through the documented register map (station/rig/register-map.md).

mbpoll counts references from 1 (``-r 1`` is protocol address 0) and needs ``-B``
for our high-word-first float32 values. Install with ``apt-get install mbpoll``.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from collections.abc import Iterator

import pytest

from station.kernel.clock import SimClock
from station.rig import registers as reg
from station.rig.registers import HR, IR, AckResult, Command, Status
from station.sim.rig_server import SimulatedRig

MBPOLL = shutil.which("mbpoll")
pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(MBPOLL is None, reason="mbpoll not installed (Debian/Ubuntu: apt-get install mbpoll)"),
]

SCALE = 50.0
_VALUE = re.compile(r"^\[(\d+)\]:\s+(\S+)", re.MULTILINE)


def _ref(address: int) -> str:
    """mbpoll reference (1-based) of a 0-based protocol address."""
    return str(address + 1)


class Mbpoll:
    """Runs mbpoll once per call against one simulated rig."""

    def __init__(self, sim: SimulatedRig) -> None:
        self.sim = sim
        if sim.transport == "tcp":
            self.link = ["-m", "tcp", "-p", str(sim.port)]
            self.target = sim.host
        else:
            self.link = ["-m", "rtu", "-b", str(sim.baud), "-P", "none", "-d", "8", "-s", "1"]
            self.target = sim.device_path

    def run(self, *options: str, values: tuple[str, ...] = ()) -> str:
        # options, then the host/device, then (after --) values to write
        cmd = [MBPOLL or "mbpoll", *self.link, "-a", str(self.sim.unit), "-1", "-o", "2", *options, self.target]
        if values:
            cmd += ["--", *values]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=30, check=False)
        assert done.returncode == 0, f"{' '.join(cmd)} failed:\n{done.stdout}\n{done.stderr}"
        return done.stdout

    def read(self, table: str, address: int, count: int) -> dict[int, float]:
        """Read ``count`` values of ``table`` ('3', '4', '3:float', ...) from a protocol address.

        Returns {protocol address: value}.
        """
        out = self.run("-t", table, "-B", "-r", _ref(address), "-c", str(count))
        return {int(ref) - 1: float(value) for ref, value in _VALUE.findall(out)}

    def write(self, table: str, address: int, *values: float) -> None:
        out = self.run("-t", table, "-B", "-r", _ref(address), values=tuple(f"{v:g}" for v in values))
        assert "Written" in out


@pytest.fixture(params=["tcp", "rtu"])
def sim(request: pytest.FixtureRequest) -> Iterator[SimulatedRig]:
    if request.param == "rtu" and os.name != "posix":
        pytest.skip("RTU over a pty needs POSIX")
    server = SimulatedRig(SimClock(scale=SCALE), transport=request.param, watchdog_s=60.0)
    server.start()
    try:
        yield server
    finally:
        server.stop()


def _wait_for(sim: SimulatedRig, flag: Status, timeout_s: float = 60.0) -> tuple[float, float, float, float, Status]:
    deadline = sim.clock.now() + timeout_s
    while True:
        rb = sim.readback()
        if rb[4] & flag and not rb[4] & Status.MOVING:
            return rb
        assert sim.clock.now() < deadline, f"rig never reached {flag!r}: {rb}"
        sim.clock.sleep(0.25)


def test_mbpoll_reads_status_and_identity(sim: SimulatedRig) -> None:
    mb = Mbpoll(sim)
    words = mb.read("3", IR.STATUS, 6)
    status = Status(int(words[IR.STATUS]))
    assert status & Status.READY and status & Status.AT_REST and status & Status.IN_POSITION
    assert words[IR.FAULT_CODE] == 0 and words[IR.ACK_SEQ] == 0
    floats = mb.read("3:float", IR.ACTUAL_ROLL, 4)
    assert floats == {IR.ACTUAL_ROLL: 0.0, IR.ACTUAL_PITCH: 0.0, IR.ACTUAL_YAW: 0.0, IR.ACTUAL_RATE: 0.0}
    ident = mb.read("3", reg.IDENT_START, 10)
    assert ident[IR.MAP_VERSION] == reg.MAP_VERSION
    fw = [int(ident[IR.FIRMWARE_ID + i]) for i in range(reg.FIRMWARE_ID_REGS)]
    assert reg.regs_to_ascii(fw) == "STATION-SIMRIG"
    assert mb.read("3:float", IR.MAX_RATE, 1) == {IR.MAX_RATE: 500.0}


def test_mbpoll_commands_a_move_and_a_spin(sim: SimulatedRig) -> None:
    mb = Mbpoll(sim)
    # target orientation (pose '+x'), then COMMAND + a new COMMAND_SEQ in one write
    mb.write("4:float", HR.TARGET_ROLL, 0.0, -90.0)
    assert mb.read("4:float", HR.TARGET_ROLL, 2) == {HR.TARGET_ROLL: 0.0, HR.TARGET_PITCH: -90.0}
    mb.write("4", HR.COMMAND, Command.MOVE_TO_ORIENTATION, 1)
    roll, pitch, _, _, _ = _wait_for(sim, Status.IN_POSITION)
    assert (roll, pitch) == (0.0, -90.0)
    ack = mb.read("3", IR.ACK_SEQ, 2)
    assert ack == {IR.ACK_SEQ: 1, IR.ACK_RESULT: AckResult.OK}
    assert mb.read("3:float", IR.ACTUAL_ROLL, 2) == {IR.ACTUAL_ROLL: 0.0, IR.ACTUAL_PITCH: -90.0}

    mb.write("4:float", HR.TARGET_RATE, -45.0)
    mb.write("4", HR.COMMAND, Command.SPIN, 2)
    _, _, _, rate, _ = _wait_for_rate(sim)
    assert rate == pytest.approx(-45.0, abs=1e-9)
    assert mb.read("3:float", IR.ACTUAL_RATE, 1) == {IR.ACTUAL_RATE: -45.0}

    mb.write("4", HR.COMMAND, Command.STOP, 3)
    _, _, _, rate, status = _wait_for(sim, Status.AT_REST)
    assert rate == 0.0 and status & Status.IN_POSITION
    assert [c[1] for c in sim.model.commands] == [Command.MOVE_TO_ORIENTATION, Command.SPIN, Command.STOP]


def _wait_for_rate(sim: SimulatedRig, timeout_s: float = 60.0) -> tuple[float, float, float, float, Status]:
    deadline = sim.clock.now() + timeout_s
    while True:
        rb = sim.readback()
        if rb[4] & Status.RATE_SETTLED:
            return rb
        assert sim.clock.now() < deadline, f"table rate never settled: {rb}"
        sim.clock.sleep(0.25)


def test_mbpoll_illegal_address_is_refused(sim: SimulatedRig) -> None:
    # input registers 16..99 are not mapped: the rig answers ILLEGAL DATA ADDRESS
    cmd = [MBPOLL or "mbpoll", *Mbpoll(sim).link, "-a", "1", "-1", "-o", "2", "-t", "3", "-r", _ref(50)]
    done = subprocess.run([*cmd, Mbpoll(sim).target], capture_output=True, text=True, timeout=30, check=False)
    assert "Illegal data address" in done.stdout + done.stderr
