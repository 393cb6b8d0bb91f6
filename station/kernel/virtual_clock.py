"""A discrete-event clock: simulated time that moves only when every actor waits on it.

:class:`VirtualClock` makes a simulated run repeat bit for bit whatever the host's load. Threads
that own time (the sequence runner, capture workers, a heartbeat, a client's pollers) register as
*actors* (:meth:`VirtualClock.actor`, or :meth:`VirtualClock.enroll` in the thread that starts
another one, then :meth:`Actor.bind` in it). Time is frozen while any actor runs, including while
it is blocked on I/O (a Modbus request and its answer, a pty read): those happen at one well-defined
instant. When every actor waits on the clock (:meth:`VirtualClock.sleep`, :meth:`VirtualClock.wait`)
time jumps to the earliest wake time and the actors due then run. Passive peers (a simulated rig
or sensor answering requests) are not actors: they compute their state at :meth:`now`.

Rules for code that runs on it (``docs/simulation.md``):

- every wait of an actor that needs time to pass goes through the clock (:func:`wait_event` for an
  interruptible wait, ``clock.sleep`` otherwise); wall-clock I/O timeouts stay wall timeouts;
- an actor that blocks on another actor (a join, a future) while that one waits on the clock stops
  time for good: such waits go through :func:`wait_event` too;
- a deadlock (an actor waits on the clock, time has not moved and no actor registered, woke or
  waited for ``stall_wall_s`` wall seconds, and nobody declared itself :meth:`VirtualClock.busy`)
  raises :class:`ClockStalled` naming the threads that hold time, instead of hanging.

Without registered actors it behaves as a :class:`~station.kernel.clock.ManualClock`: ``sleep``
advances time at once. ``scale`` is 1.0 (there is no wall time to relate to). No I/O here.
"""

from __future__ import annotations

import contextlib
import itertools
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, Protocol, TypeVar

from station.kernel.errors import StationError

_T = TypeVar("_T")

#: wall seconds between checks of an event set by a thread that is not an actor
_EVENT_POLL_WALL_S = 0.005


class ClockStalled(StationError):
    """Virtual time cannot move: an actor waits on the clock while another holds it and makes no progress."""


class Waitable(Protocol):
    """What a clock wait can wait for besides time (a ``threading.Event``)."""

    def is_set(self) -> bool: ...


class Actor:
    """One thread that owns time on a :class:`VirtualClock` (create with :meth:`VirtualClock.enroll`)."""

    def __init__(self, clock: VirtualClock, name: str) -> None:
        self.clock = clock
        self.name = name
        self.thread: threading.Thread | None = None
        self.waiting = False
        self.deadline = float("inf")
        self.event: Waitable | None = None
        self.closed = False

    @contextlib.contextmanager
    def bind(self) -> Iterator[Actor]:
        """Make the current thread this actor for the ``with`` block; unregisters it at the end."""
        self.clock._bind(self)
        try:
            yield self
        finally:
            self.clock.leave(self)

    def __repr__(self) -> str:
        state = "waiting" if self.waiting else "running"
        return f"{self.name} ({state})"


class Follower:
    """A passive peer's report of how far it has produced its data (:meth:`VirtualClock.follow`)."""

    def __init__(self, clock: VirtualClock, name: str, t: float) -> None:
        self.clock = clock
        self.name = name
        self.t = t

    def caught_up(self, t: float) -> None:
        """Everything due up to time ``t`` (s) has been produced."""
        self.clock._caught_up(self, t)

    def close(self) -> None:
        """Stop following (the peer is gone)."""
        self.clock._unfollow(self)


class ActorClock:
    """What the local :class:`VirtualClock` and one served from another process share: actors by thread,
    ``sleep`` as a wait, long work declared."""

    scale = 1.0
    #: code that needs to know (capture, sample reads) asks ``getattr(clock, "virtual", False)``
    virtual = True
    _by_thread: dict[int, Any]

    def wait(self, event: Waitable | None, seconds: float | None) -> bool:
        raise NotImplementedError

    def enroll(self, name: str) -> Any:
        raise NotImplementedError

    def add_busy(self, n: int) -> None:
        raise NotImplementedError

    def current_actor(self) -> Any:
        """The current thread's actor (None: it is none)."""
        return self._by_thread.get(threading.get_ident())

    def actor(self, name: str | None = None) -> contextlib.AbstractContextManager[Any]:
        """Register the current thread as an actor for the ``with`` block (nested use keeps the outer one)."""
        return thread_actor(self, name)

    def busy(self) -> contextlib.AbstractContextManager[None]:
        """Declare long work without clock waits (a fit): the stall guard does not fire meanwhile."""
        return busy_block(self)

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` of virtual time pass (an actor waits; anyone else advances time directly)."""
        self.wait(None, seconds)


class VirtualClock(ActorClock):
    """Virtual time of a discrete-event simulation (s).

    Args:
        start: time at construction (s).
        stall_wall_s: wall seconds without any progress of the clock, while an actor waits on it,
            after which the waiting actors raise :class:`ClockStalled`.
        horizon_s: how far time may run ahead of the slowest :class:`Follower` (s).
    """

    def __init__(self, start: float = 0.0, *, stall_wall_s: float = 120.0, horizon_s: float = 2.0) -> None:
        self._t = float(start)
        self._cond = threading.Condition(threading.Lock())
        self._actors: list[Actor] = []
        self._by_thread: dict[int, Actor] = {}
        self._seq = itertools.count()
        self._progress = 0  # changes on every advance, registration, wake or wait
        self._busy = 0
        self.stall_wall_s = float(stall_wall_s)
        self.horizon_s = float(horizon_s)
        self._followers: list[Follower] = []
        self.advances = 0

    # --- reading --------------------------------------------------------------------------------

    def now(self) -> float:
        return self._t

    # --- actors ---------------------------------------------------------------------------------

    def enroll(self, name: str) -> Actor:
        """A new actor, running from now on (time is held until it waits or leaves); bind it in its thread."""
        actor = Actor(self, name)
        with self._cond:
            self._actors.append(actor)
            self._progress += 1
        return actor

    def _bind(self, actor: Actor) -> None:
        with self._cond:
            actor.thread = threading.current_thread()
            self._by_thread[threading.get_ident()] = actor

    def leave(self, actor: Actor) -> None:
        """Unregister ``actor`` (idempotent); time may move on without it."""
        with self._cond:
            if actor.closed:
                return
            actor.closed = True
            if actor in self._actors:
                self._actors.remove(actor)
            if actor.thread is not None and self._by_thread.get(actor.thread.ident or -1) is actor:
                del self._by_thread[actor.thread.ident or -1]
            self._progress += 1
            self._step_locked()


    def add_busy(self, n: int) -> None:
        """:meth:`busy` by hand: +1 when long work starts, -1 when it ends."""
        with self._cond:
            self._busy += n
            self._progress += 1

    def follow(self, name: str) -> Follower:
        """A passive peer that produces data as time passes (a streaming sensor): time runs at most
        ``horizon_s`` ahead of the time it reports with :meth:`Follower.caught_up`, so that the data due at a
        barrier stays bounded whatever the host's load. It changes when, in wall time, time moves, never what
        happens at a virtual instant."""
        follower = Follower(self, name, self._t)
        with self._cond:
            self._followers.append(follower)
        return follower

    def _caught_up(self, follower: Follower, t: float) -> None:
        with self._cond:
            if t > follower.t:
                follower.t = t
                self._step_locked()

    def _unfollow(self, follower: Follower) -> None:
        with self._cond:
            if follower in self._followers:
                self._followers.remove(follower)
                self._step_locked()

    def actors(self) -> list[str]:
        """The registered actors, for messages."""
        with self._cond:
            return [repr(a) for a in self._actors]

    # --- waiting --------------------------------------------------------------------------------

    def sleep_until(self, t: float) -> None:
        """Wait until virtual time ``t`` (s)."""
        self.wait(None, t - self._t)

    def wait(self, event: Waitable | None, seconds: float | None) -> bool:
        """Wait until ``event`` is set or ``seconds`` of virtual time passed (None: no time limit);
        returns whether the event is set. Like ``threading.Event.wait`` in virtual seconds."""
        actor = self._by_thread.get(threading.get_ident())
        with self._cond:
            if actor is None:  # not an actor: a driver of a clock nobody else uses
                if event is not None and event.is_set():
                    return True
                if seconds is not None and seconds > 0 and not self._actors:
                    self._t += seconds
                    self._progress += 1
                    self.advances += 1
                    return event.is_set() if event is not None else False
                if not self._actors:
                    return event.is_set() if event is not None else False
                actor = Actor(self, threading.current_thread().name)  # a temporary actor for this wait
                actor.thread = threading.current_thread()
                self._actors.append(actor)
                temporary = True
            else:
                temporary = False
            try:
                return self._wait_locked(actor, event, seconds)
            finally:
                if temporary:
                    actor.closed = True
                    self._actors.remove(actor)
                    self._progress += 1
                    self._step_locked()

    def _wait_locked(self, actor: Actor, event: Waitable | None, seconds: float | None) -> bool:
        if event is not None and event.is_set():
            return True
        actor.deadline = self._t + max(0.0, seconds) if seconds is not None else float("inf")
        actor.event = event
        actor.waiting = True
        self._progress += 1
        self._step_locked()
        seen, since = self._progress, time.monotonic()
        try:
            while actor.waiting:
                if event is not None and event.is_set():
                    actor.waiting = False
                    self._progress += 1
                    break
                self._cond.wait(_EVENT_POLL_WALL_S if event is not None else 1.0)
                if actor.waiting:
                    self._step_locked()  # an event set by a thread that is not an actor
                if self._progress != seen or self._busy:
                    seen, since = self._progress, time.monotonic()
                elif time.monotonic() - since > self.stall_wall_s:
                    actor.waiting = False
                    holders = [repr(a) for a in self._actors if not a.waiting]
                    holders += [f"{f.name} (a follower, produced to {f.t:.6f} s)" for f in self._followers
                                if f.t + self.horizon_s <= self._t]
                    raise ClockStalled(
                        f"virtual clock stalled at t = {self._t:.6f} s for {self.stall_wall_s:g} wall s: "
                        f"{actor.name} waits on it while {', '.join(holders) or 'nobody'} hold(s) time "
                        "(an actor blocked on another actor or on I/O that never comes)")
        finally:  # also when interrupted (Ctrl-C in the main thread): the actor runs again
            if actor.waiting:
                actor.waiting = False
                self._progress += 1
            actor.event = None
            actor.deadline = float("inf")
        return event.is_set() if event is not None else False

    def _step_locked(self) -> None:
        """Advance time if every actor waits: to the earliest wake time; wake whoever is due."""
        if not self._actors or any(not a.waiting for a in self._actors):
            return
        ready = [a for a in self._actors if a.event is not None and a.event.is_set()]
        if not ready:
            t = min(a.deadline for a in self._actors)
            if t == float("inf"):
                return  # every actor waits for an event: only the stall guard can tell
            if self._followers:  # not further than the horizon ahead of the slowest follower
                t = min(t, max(self._t, min(f.t for f in self._followers) + self.horizon_s))
            if t > self._t:
                self._t = t
                self.advances += 1
                self._progress += 1
            ready = [a for a in self._actors if a.deadline <= self._t]
            if not ready:
                return  # time moved as far as the followers allow: they call again when they caught up
        for a in ready:
            a.waiting = False
        self._progress += 1
        self._cond.notify_all()


# --- helpers for code that runs on any clock ---------------------------------------------------------


@contextlib.contextmanager
def thread_actor(clock: Any, name: str | None = None) -> Iterator[Any]:
    """The current thread's actor of a virtual ``clock`` (local or served) if it has one, else a new one for the
    ``with`` block."""
    current = clock.current_actor()
    if current is not None:
        yield current
        return
    with clock.enroll(name or threading.current_thread().name).bind() as a:
        yield a


@contextlib.contextmanager
def busy_block(clock: Any) -> Iterator[None]:
    """``clock.add_busy`` +1 for the ``with`` block (a virtual clock, local or served)."""
    clock.add_busy(1)
    try:
        yield
    finally:
        clock.add_busy(-1)


def is_virtual(clock: object) -> bool:
    """Whether ``clock`` is a :class:`VirtualClock` (time passes only through its waits)."""
    return bool(getattr(clock, "virtual", False))


def wait_event(clock: Any, event: threading.Event, seconds: float | None) -> bool:
    """``event.wait`` for ``seconds`` of ``clock`` time: through a virtual clock, else in wall seconds
    (``seconds / clock.scale``). Returns whether the event is set."""
    if is_virtual(clock):
        return bool(clock.wait(event, seconds))
    return event.wait(None if seconds is None else seconds / clock.scale)


def follow(clock: Any, name: str) -> Follower | None:
    """A :class:`Follower` of ``clock`` for a passive peer that streams data (None unless the clock is virtual)."""
    return clock.follow(name) if isinstance(clock, VirtualClock) else None


def enroll(clock: Any, name: str) -> Actor | None:
    """An actor of ``clock`` for a thread about to be started (None unless the clock is virtual)."""
    return clock.enroll(name) if is_virtual(clock) else None


@contextlib.contextmanager
def acting(clock: Any, actor: Actor | None = None, name: str | None = None) -> Iterator[None]:
    """Run the ``with`` block as ``actor`` (or as a new actor of the current thread) on a virtual clock;
    nothing on any other clock."""
    if not is_virtual(clock):
        yield
        return
    if actor is not None:
        with actor.bind():
            yield
        return
    with clock.actor(name):
        yield


@contextlib.contextmanager
def busy(clock: Any) -> Iterator[None]:
    """:meth:`VirtualClock.busy` on a virtual clock (long work without clock waits); nothing otherwise."""
    if not is_virtual(clock):
        yield
        return
    with clock.busy():
        yield


class ActorPool(ThreadPoolExecutor):
    """A thread pool whose tasks are actors of ``clock`` from submission until their future is done (on a
    virtual clock; a plain pool otherwise): time cannot move between a submit and the task's start, nor
    between its return and the callbacks of its future (which may wake a waiting actor)."""

    def __init__(self, clock: Any, max_workers: int | None = None, thread_name_prefix: str = "") -> None:
        super().__init__(max_workers=max_workers, thread_name_prefix=thread_name_prefix)
        self.clock = clock

    def submit(self, fn: Callable[..., _T], /, *args: Any, **kwargs: Any) -> Future[_T]:
        if not is_virtual(self.clock):
            return super().submit(fn, *args, **kwargs)
        clock = self.clock
        actor = clock.enroll(f"{self._thread_name_prefix or 'pool'}:{getattr(fn, '__name__', 'task')}")
        outer: Future[_T] = Future()

        def task() -> None:
            clock._bind(actor)
            try:
                if not outer.set_running_or_notify_cancel():
                    return
                try:
                    result = fn(*args, **kwargs)
                except BaseException as exc:  # handed to the future, as ThreadPoolExecutor does
                    outer.set_exception(exc)
                else:
                    outer.set_result(result)  # its callbacks run while the task still holds time
            finally:
                clock.leave(actor)

        inner = super().submit(task)

        def cancelled(f: Future[None]) -> None:
            if f.cancelled():
                outer.cancel()
                clock.leave(actor)

        inner.add_done_callback(cancelled)
        return outer


def wait_futures(clock: Any, futures: Any, seconds: float | None = None, *, first_exception: bool = False) -> bool:
    """Wait until every future is done (or, with ``first_exception``, one raised) or ``seconds`` of ``clock``
    time passed; returns whether the wait ended before the time limit.

    On a virtual clock the wait lets time pass (the futures' tasks may wait on the clock themselves);
    on any other clock it is ``concurrent.futures.wait`` in wall seconds (``seconds / clock.scale``).
    """
    from concurrent.futures import ALL_COMPLETED, FIRST_EXCEPTION, wait

    futures = list(futures)
    if not is_virtual(clock):
        _, pending = wait(futures, timeout=None if seconds is None else seconds / clock.scale,
                          return_when=FIRST_EXCEPTION if first_exception else ALL_COMPLETED)
        return not pending or any(f.done() and not f.cancelled() and f.exception() is not None for f in futures)
    done = threading.Event()
    lock = threading.Lock()
    left = [len(futures)]

    def one(f: Future[Any]) -> None:
        with lock:
            left[0] -= 1
            if left[0] <= 0 or (first_exception and not f.cancelled() and f.exception() is not None):
                done.set()

    if not futures:
        return True
    for f in futures:
        f.add_done_callback(one)
    return bool(clock.wait(done, seconds))


__all__ = [
    "Actor",
    "ActorClock",
    "ActorPool",
    "ClockStalled",
    "Follower",
    "VirtualClock",
    "Waitable",
    "acting",
    "busy",
    "busy_block",
    "enroll",
    "follow",
    "is_virtual",
    "thread_actor",
    "wait_event",
    "wait_futures",
]
