"""One virtual clock for two processes: the simulator serves it, the station's threads are its actors.

``station sim --clock virtual`` owns a :class:`~station.kernel.virtual_clock.VirtualClock` and serves it with
:class:`ClockServer` on 127.0.0.1; ``station run --clock virtual://HOST:PORT`` opens a :class:`RemoteClock`.
This is the time management of a conservative co-simulation (HLA's time-advance request and grant, FMI's
master algorithm), not a model of any device's protocol: every actor thread of the station holds one TCP
connection, which is an actor of the served clock. A request ``wait`` is a time-advance request; its answer,
the grant, comes when the served clock has advanced to the wake time (or the actor's event was set). While a
station thread runs, its actor runs on the served clock, so time stands still while it talks to the simulated
rig or sensors, exactly as in one process.

Messages are JSON lines. On an actor connection: ``{"op": "enroll", "name": N}`` -> ``{"id": I, "t": T}``,
then ``{"op": "wait", "seconds": S|null, "event": bool, "seq": K}`` -> ``{"t": T, "set": bool}`` (or
``{"error": text}`` when the served clock stalled), and ``{"op": "leave"}`` (or the connection closing). On the
control connection: ``{"op": "control"}`` -> ``{"ok": true}``, then ``now`` -> ``{"t": T}``, ``{"op": "wake",
"id": I, "seq": K}`` -> ``{"ok": true}`` (an event the station set for actor I's wait K: sent before the setter's
own next request, so the served clock sees it before it could advance; kept when it arrives before wait K
itself), ``{"op": "busy", "n": +-1}``.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import select
import socket
import threading
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlsplit

from station.kernel.errors import StationError
from station.kernel.virtual_clock import ActorClock, ClockStalled, VirtualClock, Waitable

SCHEME = "virtual"
#: wall seconds between looks at a local event while a wait is granted remotely
_EVENT_POLL_WALL_S = 0.005


class ClockLinkError(StationError):
    """The served clock cannot be reached, or answered nonsense."""


def _send(f: Any, msg: dict[str, Any]) -> None:
    f.write(json.dumps(msg).encode() + b"\n")
    f.flush()


def _recv(f: Any, where: str) -> dict[str, Any]:
    line = f.readline()
    if not line:
        raise ClockLinkError(f"the clock at {where} closed the connection")
    msg = json.loads(line)
    if not isinstance(msg, dict):
        raise ClockLinkError(f"the clock at {where} answered {line!r}")
    return msg


# --- the simulator's side -------------------------------------------------------------------------------


class _Served:
    """One remote actor's wait as the server sees it: its event, the wait it belongs to, and the latest wait a
    ``wake`` was sent for.

    The wake comes on the control connection, the wait on the actor's own: a wake can arrive before the wait it
    is for (the event was set in the station right after the actor sent its request, and the control connection
    was read first). It is kept (``woken``) and the wait then starts set, instead of being dropped, which would
    leave the actor waiting for an event that was set long ago.
    """

    def __init__(self) -> None:
        self.event = threading.Event()
        self.seq = -1
        self.woken = -1
        self.lock = threading.Lock()

    def begin(self, seq: int) -> None:
        """The actor's wait ``seq`` starts: set at once if its wake already came."""
        with self.lock:
            self.seq = seq
            if self.woken >= seq:
                self.event.set()
            else:
                self.event.clear()

    def wake(self, seq: int) -> None:
        """An event the station set for the actor's wait ``seq`` (before or after that wait reached here)."""
        with self.lock:
            self.woken = max(self.woken, seq)
            if self.seq == seq:
                self.event.set()


class ClockServer:
    """Serve ``clock`` on ``host:port`` (0: a free port) until :meth:`stop`; a context manager."""

    def __init__(self, clock: VirtualClock, host: str = "127.0.0.1", port: int = 0) -> None:
        self.clock = clock
        self._sock = socket.create_server((host, port))
        self.url = f"{SCHEME}://{host}:{self._sock.getsockname()[1]}"
        self._served: dict[int, _Served] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()
        self._conns: list[socket.socket] = []
        self._thread = threading.Thread(target=self._accept, name="clock-server", daemon=True)

    def start(self) -> ClockServer:
        self._thread.start()
        return self

    def stop(self) -> None:
        with contextlib.suppress(OSError):
            self._sock.close()
        with self._lock:
            conns, self._conns = self._conns, []
        for c in conns:
            with contextlib.suppress(OSError):
                c.shutdown(socket.SHUT_RDWR)
        self._thread.join(5.0)

    def __enter__(self) -> ClockServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self._sock.accept()
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._conns.append(conn)
            threading.Thread(target=self._serve, args=(conn,), name="clock-link", daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn, conn.makefile("rwb") as f:
            try:
                first = _recv(f, "station")
                if first.get("op") == "control":
                    _send(f, {"ok": True})
                    self._control(f)
                elif first.get("op") == "enroll":
                    self._actor(f, str(first.get("name", "remote")))
            except (OSError, ValueError, ClockLinkError):
                return  # the station went away: its actors leave (below), time moves on without them

    def _actor(self, f: Any, name: str) -> None:
        served = _Served()
        ident = next(self._ids)
        with self._lock:
            self._served[ident] = served
        try:
            with self.clock.enroll(f"{name} (station)").bind():
                _send(f, {"id": ident, "t": self.clock.now()})
                while True:
                    msg = _recv(f, "station")
                    if msg.get("op") != "wait":
                        return
                    served.begin(int(msg["seq"]))
                    seconds = msg.get("seconds")
                    try:
                        was_set = self.clock.wait(served.event if msg.get("event") else None,
                                                  None if seconds is None else float(seconds))
                    except ClockStalled as exc:
                        _send(f, {"error": str(exc)})
                        continue
                    _send(f, {"t": self.clock.now(), "set": bool(was_set)})
        finally:
            with self._lock:
                self._served.pop(ident, None)

    def _control(self, f: Any) -> None:
        while True:
            msg = _recv(f, "station")
            op = msg.get("op")
            if op == "now":
                _send(f, {"t": self.clock.now()})
            elif op == "wake":
                with self._lock:
                    served = self._served.get(int(msg["id"]))
                if served is not None:
                    served.wake(int(msg["seq"]))
                _send(f, {"ok": True})
            elif op == "busy":
                self.clock.add_busy(int(msg["n"]))
                _send(f, {"ok": True})
            else:
                _send(f, {"error": f"unknown op {op!r}"})


# --- the station's side -----------------------------------------------------------------------------------


class RemoteActor:
    """One station thread's actor on the served clock (its own connection)."""

    def __init__(self, clock: RemoteClock, name: str) -> None:
        self.clock = clock
        self.name = name
        self.closed = False
        self.seq = 0
        self._sock = socket.create_connection(clock.address, timeout=clock.connect_timeout_s)
        self._sock.settimeout(None)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._f = self._sock.makefile("rwb")
        _send(self._f, {"op": "enroll", "name": name})
        reply = _recv(self._f, clock.url)
        self.ident = int(reply["id"])
        self.t: float | None = float(reply["t"])  # the time while this actor runs (it cannot move meanwhile)

    @contextlib.contextmanager
    def bind(self) -> Iterator[RemoteActor]:
        self.clock._bind(self)
        try:
            yield self
        finally:
            self.clock.leave(self)

    def wait(self, event: Waitable | None, seconds: float | None) -> bool:
        self.seq += 1
        seq = self.seq
        self.t = None
        waiter = (self, event, seq)
        if event is not None:
            self.clock._add_waiter(waiter)
        try:
            _send(self._f, {"op": "wait", "seconds": seconds, "event": event is not None, "seq": seq})
            while True:
                ready, _, _ = select.select([self._sock], [], [], _EVENT_POLL_WALL_S if event is not None else None)
                if ready:
                    break
                self.clock._flush_wakes()  # an event set by a thread that then blocked without the clock
            reply = _recv(self._f, self.clock.url)
        finally:
            if event is not None:
                self.clock._drop_waiter(waiter)
        if "error" in reply:
            raise ClockStalled(f"served clock: {reply['error']}")
        self.t = float(reply["t"])
        return event.is_set() if event is not None else False

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(OSError):
            _send(self._f, {"op": "leave"})
        with contextlib.suppress(OSError):
            self._f.close()
            self._sock.close()

    def __repr__(self) -> str:
        return f"{self.name} (remote)"


class RemoteClock(ActorClock):
    """A :class:`~station.kernel.virtual_clock.VirtualClock` served by another process (``virtual://HOST:PORT``).

    Same interface: actors (:meth:`actor`, :meth:`enroll`), :meth:`sleep`, :meth:`wait`, :meth:`busy`; ``scale``
    is 1 and wall-clock I/O timeouts are not derived from it.
    """

    def __init__(self, host: str, port: int, *, connect_timeout_s: float = 5.0) -> None:
        self.address = (host, port)
        self.url = f"{SCHEME}://{host}:{port}"
        self.connect_timeout_s = float(connect_timeout_s)
        try:
            self._sock = socket.create_connection(self.address, timeout=connect_timeout_s)
        except OSError as exc:
            raise ClockLinkError(f"cannot reach the clock at {self.url}: {exc.strerror or exc}") from None
        self._sock.settimeout(None)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._f = self._sock.makefile("rwb")
        self._lock = threading.Lock()
        self._by_thread: dict[int, Any] = {}
        self._waiters: list[tuple[RemoteActor, Waitable | None, int]] = []
        self._woken: set[tuple[int, int]] = set()
        self._wait_lock = threading.Lock()
        self._call({"op": "control"})

    def _call(self, msg: dict[str, Any]) -> dict[str, Any]:
        with self._lock:
            _send(self._f, msg)
            reply = _recv(self._f, self.url)
        if "error" in reply:
            raise ClockLinkError(f"the clock at {self.url}: {reply['error']}")
        return reply

    # --- reading ---------------------------------------------------------------------------------------

    def now(self) -> float:
        actor = self._by_thread.get(threading.get_ident())
        if actor is not None and actor.t is not None:
            return actor.t
        return float(self._call({"op": "now"})["t"])

    # --- actors ----------------------------------------------------------------------------------------

    def enroll(self, name: str) -> RemoteActor:
        self._flush_wakes()
        return RemoteActor(self, name)

    def _bind(self, actor: RemoteActor) -> None:
        self._by_thread[threading.get_ident()] = actor

    def leave(self, actor: RemoteActor) -> None:
        self._flush_wakes()
        for k, a in list(self._by_thread.items()):
            if a is actor:
                del self._by_thread[k]
        actor.close()

    def add_busy(self, n: int) -> None:
        self._call({"op": "busy", "n": n})

    # --- waiting ---------------------------------------------------------------------------------------

    def wait(self, event: Waitable | None, seconds: float | None) -> bool:
        if event is not None and event.is_set():
            return True
        actor = self._by_thread.get(threading.get_ident())
        if actor is None:  # a thread that is no actor waits as a temporary one
            with self.actor() as temporary:
                return temporary.wait(event, seconds)
        self._flush_wakes()
        return actor.wait(event, None if seconds is None else max(0.0, seconds))

    def _add_waiter(self, waiter: tuple[RemoteActor, Waitable | None, int]) -> None:
        with self._wait_lock:
            self._waiters.append(waiter)

    def _drop_waiter(self, waiter: tuple[RemoteActor, Waitable | None, int]) -> None:
        with self._wait_lock:
            self._waiters.remove(waiter)
            self._woken.discard((waiter[0].ident, waiter[2]))

    def _flush_wakes(self) -> None:
        """Tell the served clock about every event set for a waiting actor, before this thread's next request."""
        with self._wait_lock:
            due = [(a.ident, seq) for a, ev, seq in self._waiters
                   if ev is not None and ev.is_set() and (a.ident, seq) not in self._woken]
            self._woken.update(due)
            for ident, seq in due:
                self._call({"op": "wake", "id": ident, "seq": seq})

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._f.close()
            self._sock.close()


def open_clock(url: str) -> RemoteClock:
    """The served clock at ``virtual://HOST:PORT``."""
    parts = urlsplit(url)
    if parts.scheme != SCHEME or not parts.hostname or not parts.port:
        raise ClockLinkError(f"clock URL {url!r}: expected {SCHEME}://HOST:PORT (as `station sim --clock virtual` "
                             "prints it)")
    return RemoteClock(parts.hostname, parts.port)


__all__ = ["ClockLinkError", "ClockServer", "RemoteActor", "RemoteClock", "open_clock"]
