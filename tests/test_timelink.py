"""The virtual clock served across processes: `station sim --clock virtual` and `station run --clock virtual://...`.

In one process: remote actors (each thread its own connection) wake in time order at their own times, an
event one of them sets wakes another at that instant, and a stall of the served clock reaches the remote
waiter as ClockStalled. Across processes: the simulator and the station in two processes, run twice with fresh
processes, the second time under CPU load, give the same recording and parameter set bytes.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from station.kernel.virtual_clock import ClockStalled, VirtualClock, acting, wait_event
from station.timelink import ClockServer, RemoteClock, open_clock
from station.timelink.link import ClockLinkError

STATION = str(Path(sys.executable).with_name("station"))


@pytest.fixture
def served() -> Iterator[tuple[VirtualClock, RemoteClock]]:
    clock = VirtualClock(stall_wall_s=0.5)
    with ClockServer(clock) as server:
        remote = open_clock(server.url)
        try:
            yield clock, remote
        finally:
            remote.close()


def test_remote_actors_wake_in_time_order_and_events_wake_at_once(served: tuple[VirtualClock, RemoteClock]) -> None:
    clock, remote = served
    seen: list[tuple[str, float]] = []
    stop = threading.Event()
    lock = threading.Lock()

    def ticker(actor: object) -> None:
        with acting(remote, actor):  # type: ignore[arg-type]
            for _ in range(3):
                remote.sleep(0.5)
                with lock:
                    seen.append(("tick", remote.now()))
            stop.set()  # another actor waits for this: it must wake at this instant, 1.5 s
            remote.sleep(10.0)

    def waiter(actor: object) -> None:
        with acting(remote, actor):  # type: ignore[arg-type]
            woke = wait_event(remote, stop, 100.0)
            with lock:
                seen.append(("stop" if woke else "timeout", remote.now()))

    threads = [threading.Thread(target=ticker, args=(remote.enroll("ticker"),)),
               threading.Thread(target=waiter, args=(remote.enroll("waiter"),))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20.0)
    assert seen == [("tick", 0.5), ("tick", 1.0), ("tick", 1.5), ("stop", 1.5)]
    assert clock.now() == 11.5 and remote.now() == 11.5


def test_a_stall_of_the_served_clock_reaches_the_remote_waiter(served: tuple[VirtualClock, RemoteClock]) -> None:
    clock, remote = served
    never = threading.Event()
    holder = clock.enroll("holder-in-the-simulator")

    def hold() -> None:
        with holder.bind():
            never.wait(10.0)

    t = threading.Thread(target=hold)
    t.start()
    try:
        with acting(remote, name="station"), pytest.raises(ClockStalled, match="holder-in-the-simulator"):
            remote.sleep(1.0)
    finally:
        never.set()
        t.join(10.0)


def test_a_wake_that_arrives_before_its_wait_is_kept() -> None:
    """The station sets an actor's event right after the actor sent its wait, and the wake (control connection)
    reaches the server before the wait (actor connection): the wait must start set. Dropped, the actor waited
    for an event set long ago while the simulator's other actors moved time on (a stall no guard could see)."""
    clock = VirtualClock(stall_wall_s=2.0)
    with ClockServer(clock) as server:
        host, port = server.url.removeprefix("virtual://").split(":")
        with socket.create_connection((host, int(port)), timeout=10) as actor_sock, \
                socket.create_connection((host, int(port)), timeout=10) as control_sock:
            actor, control = actor_sock.makefile("rwb"), control_sock.makefile("rwb")

            def call(f: object, msg: dict[str, object]) -> dict[str, object]:
                f.write(json.dumps(msg).encode() + b"\n")  # type: ignore[attr-defined]
                f.flush()  # type: ignore[attr-defined]
                return json.loads(f.readline())  # type: ignore[attr-defined, no-any-return]

            ident = call(actor, {"op": "enroll", "name": "early"})["id"]
            assert call(control, {"op": "control"}) == {"ok": True}
            assert call(control, {"op": "wake", "id": ident, "seq": 1}) == {"ok": True}  # before wait 1
            assert call(actor, {"op": "wait", "seconds": None, "event": True, "seq": 1}) == {"t": 0.0, "set": True}
            # the kept wake is for wait 1 only: wait 2 waits for its own (here: its time limit)
            assert call(actor, {"op": "wait", "seconds": 3.0, "event": True, "seq": 2}) == {"t": 3.0, "set": False}
            # and a wake that comes while its wait runs still wakes it
            reply: list[dict[str, object]] = []
            waiter = threading.Thread(target=lambda: reply.append(
                call(actor, {"op": "wait", "seconds": None, "event": True, "seq": 3})))
            waiter.start()
            time.sleep(0.2)
            assert call(control, {"op": "wake", "id": ident, "seq": 3}) == {"ok": True}
            waiter.join(10.0)
            assert reply == [{"t": 3.0, "set": True}]


def test_a_bad_clock_url_is_refused() -> None:
    with pytest.raises(ClockLinkError, match="expected virtual://HOST:PORT"):
        open_clock("tcp://127.0.0.1:1")


# --- two processes --------------------------------------------------------------------------------------------


def _simulator(tmp: Path) -> tuple[subprocess.Popen[str], list[str]]:
    proc = subprocess.Popen([STATION, "sim", "--units", "1", "--seed", "4", "--clock", "virtual"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    assert proc.stdout is not None
    deadline = time.monotonic() + 60
    command: list[str] = []
    while time.monotonic() < deadline and not command:
        line = proc.stdout.readline()
        if not line:
            break
        if line.strip().startswith("station run "):
            command = [STATION, *re.sub(r"'", "", line.strip()).split()[1:]]
    assert command, proc.stderr.read() if proc.poll() is not None else "no run line"
    return proc, command


def _run_once(tmp: Path) -> dict[str, bytes]:
    proc, command = _simulator(tmp)
    try:
        assert "--clock" in command and any(a.startswith("virtual://127.0.0.1:") for a in command)
        done = subprocess.run([*command, "--yes", "--db", f"sqlite:///{tmp / 's.sqlite'}", "--out", str(tmp / "out")],
                              capture_output=True, text=True, timeout=600, env={**os.environ,
                                                                                 "STATION_LOCK_DIR": str(tmp)})
        assert done.returncode in (0, 1), done.stderr[-2000:]
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
    files: dict[str, bytes] = {}
    for path in sorted((tmp / "out").iterdir()):
        serial = path.name.split("_")[0]
        if path.name.endswith(".params.json"):
            files[f"{serial}.params.json"] = path.read_bytes()
        elif path.suffix == ".csv":
            lines = path.read_bytes().splitlines(keepends=True)
            files[f"{serial}.csv"] = b"".join(line for line in lines if not line.startswith(b"# run_id:"))
    return files


pytest_integration = pytest.mark.integration


@pytest_integration
def test_simulator_and_station_in_two_processes_repeat_bit_for_bit_under_load(tmp_path: Path) -> None:
    first = _run_once(tmp_path / "quiet")
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        second = _run_once(tmp_path / "loaded")
    finally:
        for p in procs:
            p.kill()
            p.wait()
    assert sorted(first) == sorted(second) and len(first) == 2
    for name in first:
        assert len(first[name]) > 1000 and first[name] == second[name], f"{name} differs between the two runs"
