"""The discrete-event clock: time moves only when every actor waits, to the earliest wake time."""

from __future__ import annotations

import threading
import time

import pytest

from station.kernel.errors import StationError
from station.kernel.virtual_clock import ActorPool, ClockStalled, VirtualClock, acting, wait_event, wait_futures


def test_without_actors_sleep_advances_at_once() -> None:
    clock = VirtualClock(start=5.0)
    clock.sleep(2.5)
    clock.sleep(-1.0)
    assert clock.now() == 7.5
    assert clock.scale == 1.0


def test_actors_wake_in_time_order_at_their_own_times() -> None:
    clock = VirtualClock()
    seen: list[tuple[str, float]] = []
    lock = threading.Lock()

    def ticker(name: str, period: float, n: int, actor: object) -> None:
        with acting(clock, actor):  # type: ignore[arg-type]
            for _ in range(n):
                clock.sleep(period)
                with lock:
                    seen.append((name, clock.now()))

    threads = [threading.Thread(target=ticker, args=(name, period, n, clock.enroll(name)))
               for name, period, n in (("a", 0.3, 4), ("b", 0.5, 2))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    times = [t for _, t in seen]
    assert times == sorted(times)
    assert sorted(seen) == sorted([("a", 0.3), ("a", 0.6), ("a", 0.8999999999999999), ("a", 1.2),
                                   ("b", 0.5), ("b", 1.0)])
    assert clock.now() == pytest.approx(1.2)


def test_time_is_frozen_while_an_actor_runs() -> None:
    clock = VirtualClock()
    release = threading.Event()
    started = threading.Event()
    holder = clock.enroll("holder")

    def hold() -> None:
        with holder.bind():
            started.set()
            release.wait(10.0)  # blocked on something that is not the clock: time must not move

    t = threading.Thread(target=hold)
    t.start()
    started.wait(10.0)
    woke: list[float] = []

    def sleeper(actor: object) -> None:
        with acting(clock, actor):  # type: ignore[arg-type]
            clock.sleep(1.0)
            woke.append(clock.now())

    s = threading.Thread(target=sleeper, args=(clock.enroll("sleeper"),))
    s.start()
    s.join(0.3)
    assert woke == [] and clock.now() == 0.0  # the holder runs: no time passed
    release.set()
    t.join(10.0)
    s.join(10.0)
    assert woke == [1.0]


def test_an_event_set_by_an_actor_wakes_the_waiter_at_that_instant() -> None:
    clock = VirtualClock()
    stop = threading.Event()
    result: list[tuple[bool, float]] = []

    def waiter(actor: object) -> None:
        with acting(clock, actor):  # type: ignore[arg-type]
            result.append((wait_event(clock, stop, 100.0), clock.now()))

    def setter(actor: object) -> None:
        with acting(clock, actor):  # type: ignore[arg-type]
            clock.sleep(3.0)
            stop.set()
            clock.sleep(50.0)

    threads = [threading.Thread(target=waiter, args=(clock.enroll("waiter"),)),
               threading.Thread(target=setter, args=(clock.enroll("setter"),))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    assert result == [(True, 3.0)]
    assert clock.now() == 53.0


def test_pool_tasks_hold_time_from_submit_and_their_waits_go_through_the_clock() -> None:
    clock = VirtualClock()
    ends: list[float] = []
    with acting(clock, name="main"), ActorPool(clock, max_workers=2) as pool:
        def task(d: float) -> float:
            clock.sleep(d)
            ends.append(clock.now())
            return d

        futures = [pool.submit(task, d) for d in (2.0, 5.0)]
        assert not wait_futures(clock, futures, 1.0)  # a time limit on the clock, not the wall
        assert clock.now() == 1.0
        assert wait_futures(clock, futures)
        assert clock.now() == 5.0
    assert sorted(ends) == [2.0, 5.0]


def test_an_actor_blocked_on_another_actor_fails_loudly() -> None:
    clock = VirtualClock(stall_wall_s=0.3)
    never = threading.Event()
    stuck = clock.enroll("stuck-on-a-plain-event")

    def hold() -> None:
        with stuck.bind():
            never.wait(5.0)  # a wait that should have gone through the clock

    t = threading.Thread(target=hold)
    t.start()
    try:
        with acting(clock, name="main"), pytest.raises(ClockStalled, match="stuck-on-a-plain-event") as info:
            clock.sleep(1.0)
        assert isinstance(info.value, StationError)
    finally:
        never.set()
        t.join(10.0)


def test_busy_actors_do_not_trip_the_stall_guard() -> None:
    clock = VirtualClock(stall_wall_s=0.2)
    done = threading.Event()
    worker = clock.enroll("fit")

    def fit() -> None:
        with worker.bind(), clock.busy():
            time.sleep(0.5)  # long work without clock waits, declared
        done.set()

    t = threading.Thread(target=fit)
    t.start()
    with acting(clock, name="main"):
        clock.sleep(1.0)
    t.join(10.0)
    assert done.is_set() and clock.now() == 1.0


def test_time_runs_at_most_a_horizon_ahead_of_a_follower() -> None:
    clock = VirtualClock(horizon_s=2.0, stall_wall_s=0.3)
    follower = clock.follow("sensor")
    with acting(clock, name="main"):
        with pytest.raises(ClockStalled, match=r"sensor \(a follower, produced to 0.000000 s\)"):
            clock.sleep(5.0)  # the follower never catches up: time stops at its horizon
        assert clock.now() == 2.0
        follower.caught_up(2.5)
        clock.sleep(2.5)  # to 4.5, which the follower at 2.5 allows
        assert clock.now() == 4.5
    follower.close()
    clock.sleep(1.0)  # no follower, no actor: time moves at once
    assert clock.now() == 5.5
