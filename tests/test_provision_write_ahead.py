"""Write-ahead provisioning: the intent is recorded before the first page, the write after the read-back, and a
crash at any step (each page write, each record) leaves the database and the unit agreeing once reconciled.

Runs on the in-process fakes (:mod:`station.sim.fakes`: the simulated firmware and EEPROM behind the station's
own sensor client) and a SQLite station database. A crash is a ``BaseException`` raised at the injection point,
as a process that dies there; the "next start" is a new journal on the same database file and
:func:`~station.sequence.provision.reconcile_unit` against the unit.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sqlalchemy import select
from typer.testing import CliRunner

from station.commands.eeprom import eeprom_app
from station.eeprom.provision import current_image_sha256
from station.kernel.clock import ManualClock
from station.kernel.errors import HardwareError
from station.kernel.limits import table1_limits
from station.kernel.parameters import ParameterSet
from station.kernel.plan import RigPlan
from station.kernel.sensor_class import TABLE1
from station.physics.unit import draw_unit
from station.rig import open_rig
from station.rig.protocol import RigFault
from station.sensor import Sensor, open_sensor
from station.sequence.options import SequenceOptions
from station.sequence.provision import EepromProvisioner, reconcile_unit
from station.sequence.records import Outcome
from station.sequence.runner import SequenceRunner, UnitResult
from station.sim.eeprom import Eeprom
from station.sim.fakes import FakeSensorDevice, FakeStation, publish, withdraw
from station.sim.firmware import install_firmware
from station.store.db import Database, open_database
from station.store.models import EepromWrite
from station.store.write_ahead import COMPLETE, INTENDED, NOT_APPLIED, StoreJournal

SERIAL = "UNIT-0001"
T0 = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
PAGES = 16  # a layout-1 image is 512 bytes: 16 pages of 32


class Crash(BaseException):
    """The process dies here (not an Exception: nothing in the station may catch it)."""


class ModelSource:
    """A unit at rest: constant raw output (the firmware and EEPROM are what matter here)."""

    def power_on(self) -> None:
        pass

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = len(np.asarray(t_s))
        return np.tile([0.0, 0.0, 9.8], (n, 1)), np.zeros((n, 3)), np.zeros(n)


def _params(seed: int) -> ParameterSet:
    return draw_unit(TABLE1, np.random.default_rng(seed), serial=SERIAL).as_parameter_set(0.01)


@dataclass
class Bench:
    device: FakeSensorDevice
    sensor: Sensor
    db: Database
    url: str


_count = iter(range(10**6))


@pytest.fixture
def make_bench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[[], Bench]]:
    made: list[Bench] = []

    def make() -> Bench:
        k = next(_count)
        clock = ManualClock()
        device = FakeSensorDevice(ModelSource(), clock, url=f"fake-sensor://write-ahead/{k}", serial=SERIAL,
                                  eeprom=Eeprom(clock=clock))
        publish(device)
        install_firmware(device, clock)
        sensor = open_sensor(device.url, clock, command_timeout_s=0.25, attempts=1)
        url = f"sqlite:///{tmp_path_factory.mktemp('wa') / 'station.sqlite'}"
        bench = Bench(device, sensor, open_database(url), url)
        made.append(bench)
        return bench

    yield make
    for b in made:
        b.sensor.close()
        b.db.close()
        withdraw(b.device)
        b.device.close()


def rows(db: Database) -> list[EepromWrite]:
    with db.transaction() as s:
        return list(s.scalars(select(EepromWrite).order_by(EepromWrite.id)))


def assert_agree(bench: Bench, initial: str | None = None) -> None:
    """No open intent; the unit's current image is the last write the database records as complete (or the
    image it had before any, ``initial``); every row marked complete was on the unit at some point (its update
    count is at most the current one)."""
    written = rows(bench.db)
    assert not [r for r in written if r.state == INTENDED]
    complete = [r for r in written if r.state == COMPLETE]
    current = current_image_sha256(bench.sensor)
    expected = complete[-1].image_sha256 if complete else initial
    assert (current[0] if current else None) == expected
    if current is not None:
        assert all((r.update_count or 0) <= current[1] for r in complete)
    assert all(not r.written and r.completed_at is not None for r in written if r.state == NOT_APPLIED)


def known_to_db(bench: Bench, initial: str | None = None) -> bool:
    """Before reconciliation: whatever image the unit holds, the database has heard of it."""
    current = current_image_sha256(bench.sensor)
    return current is None or current[0] == initial or current[0] in {r.image_sha256 for r in rows(bench.db)}


class CrashingJournal(StoreJournal):
    """A StoreJournal that dies before or after one of its records (``point`` = (method, 'before'|'after'))."""

    def __init__(self, db: Database, point: tuple[str, str] | None) -> None:
        super().__init__(db, source="test")
        self.point = point

    def _at(self, name: str, when: str) -> None:
        if self.point == (name, when):
            raise Crash(f"{when} {name}")

    def intend(self, plan: Any, slot: int | None) -> int:
        self._at("intend", "before")
        out = super().intend(plan, slot)
        self._at("intend", "after")
        return out

    def written(self, intent: int, report: Any) -> None:
        self._at("written", "before")
        super().written(intent, report)
        self._at("written", "after")

    def verified(self, intent: int, passed: bool | None, message: str) -> None:
        self._at("verified", "before")
        super().verified(intent, passed, message)
        self._at("verified", "after")


def crash_at_page(sensor: Sensor, page: int, when: str) -> Callable[[], None]:
    """Make the client die before sending (or right after the ACK of) its ``page``-th page write; returns undo."""
    original = sensor.eeprom_write_page
    count = {"n": 0}

    def write_page(addr: int, data: bytes) -> None:
        k = count["n"]
        count["n"] += 1
        if k == page and when == "before":
            raise Crash(f"before page {page}")
        original(addr, data)
        if k == page and when == "after":
            raise Crash(f"after page {page}")

    sensor.eeprom_write_page = write_page  # type: ignore[method-assign]

    def undo() -> None:
        sensor.eeprom_write_page = original  # type: ignore[method-assign]

    return undo


def attempt(bench: Bench, seed: int, point: tuple[str, ...] | None) -> bool:
    """One provisioning with a crash at ``point`` (('page', k, when) or (record, when)); then the next start
    reconciles. Returns whether it crashed."""
    record_point = (point[0], point[1]) if point and point[0] != "page" else None
    undo = crash_at_page(bench.sensor, int(point[1]), str(point[2])) if point and point[0] == "page" else None
    prov = EepromProvisioner("WA", now=lambda: T0, power_cycle=False,
                             journal=CrashingJournal(bench.db, record_point))  # type: ignore[arg-type]
    unit = UnitResult(0, bench.url, SERIAL, Outcome.PASS, "", params=_params(seed))
    crashed = False
    try:
        prov.provision(unit, bench.sensor)
    except Crash:
        crashed = True
    finally:
        if undo is not None:
            undo()
    assert known_to_db(bench)  # even before reconciliation, nothing on the unit is unknown to the database
    lines = reconcile_unit(StoreJournal(bench.db), bench.sensor)  # the next start
    closed_before = {("intend", "before"), ("written", "after"), ("verified", "before"), ("verified", "after")}
    assert len(lines) == (1 if crashed and point not in closed_before else 0)
    assert_agree(bench)
    return crashed


POINTS: list[tuple[str, ...]] = (
    [("page", k, w) for k in range(PAGES) for w in ("before", "after")]
    + [(name, w) for name in ("intend", "written", "verified") for w in ("before", "after")]
)


def test_a_crash_at_every_page_and_every_record_leaves_database_and_unit_agreeing(make_bench: Callable[[], Bench]
                                                                                   ) -> None:
    bench = make_bench()
    attempt(bench, 1, None)  # slot A holds image #1
    for k, point in enumerate(POINTS):
        assert attempt(bench, 10 + k, point), point
    attempt(bench, 99, None)
    states = [r.state for r in rows(bench.db)]
    # the intent is made after 'intend before': every other crash left a row, closed one way or the other
    assert len(states) == 2 + len(POINTS) - 1
    # the write is on the unit once its header page, written last (page 15), is: 'after page 15' and the four
    # crashes in 'written'/'verified' (after the read-back) leave it complete; the other 31 not applied
    assert states.count(COMPLETE) == 2 + 1 + 4 and states.count(NOT_APPLIED) == len(POINTS) - 1 - 5
    last = rows(bench.db)[-1]
    assert last.state == COMPLETE and last.reconciled == ""


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.one_of(st.none(), st.sampled_from(POINTS)), min_size=1, max_size=5))
def test_any_sequence_of_crashed_writes_keeps_database_and_unit_agreeing(
        make_bench: Callable[[], Bench], points: list[tuple[str, ...] | None]) -> None:
    bench = make_bench()
    for k, point in enumerate(points):
        assert attempt(bench, k + 1, point) == (point is not None)
    complete = [r for r in rows(bench.db) if r.state == COMPLETE]
    assert [r.update_count for r in complete] == list(range(1, len(complete) + 1))


def test_intent_is_committed_before_the_first_page(make_bench: Callable[[], Bench]) -> None:
    bench = make_bench()
    seen: list[list[str]] = []
    original = bench.sensor.eeprom_write_page

    def spy(addr: int, data: bytes) -> None:
        if not seen:  # what another connection sees when the first page goes out
            with open_database(bench.url) as other, other.transaction() as s:
                seen.append([r.state for r in s.scalars(select(EepromWrite))])
        original(addr, data)

    bench.sensor.eeprom_write_page = spy  # type: ignore[method-assign]
    prov = EepromProvisioner("WA", now=lambda: T0, power_cycle=False, journal=StoreJournal(bench.db))
    prov.provision(UnitResult(0, bench.url, SERIAL, Outcome.PASS, "", params=_params(3)), bench.sensor)
    assert seen == [[INTENDED]]
    (row,) = rows(bench.db)
    assert (row.state, row.written, row.read_back_ok, row.slot_name, row.update_count) == (COMPLETE, True, True,
                                                                                           "A", 1)
    assert row.intended_at is not None and row.completed_at is not None and row.image is not None


def test_a_failed_write_is_reconciled_at_once_when_the_unit_answers(make_bench: Callable[[], Bench]) -> None:
    bench = make_bench()
    original = bench.sensor.eeprom_write_page
    count = {"n": 0}

    def nak_on_fifth(addr: int, data: bytes) -> None:
        count["n"] += 1
        if count["n"] == 5:
            raise HardwareError("page write NAKed")
        original(addr, data)

    bench.sensor.eeprom_write_page = nak_on_fifth  # type: ignore[method-assign]
    prov = EepromProvisioner("WA", now=lambda: T0, power_cycle=False, journal=StoreJournal(bench.db))
    with pytest.raises(HardwareError, match="NAKed"):
        prov.provision(UnitResult(0, bench.url, SERIAL, Outcome.PASS, "", params=_params(4)), bench.sensor)
    (row,) = rows(bench.db)
    assert row.state == NOT_APPLIED and "not on the unit" in row.reconciled
    assert_agree(bench)


class FaultingVerifier:
    """The rig faults while the written unit is verified (the verification never finishes)."""

    def __init__(self) -> None:
        self.calls = 0

    def verify(self, sensor: Sensor, image: object) -> Any:
        self.calls += 1
        raise RigFault(5)


def test_a_verification_fault_is_error_with_the_write_recorded(tmp_path: Path) -> None:
    """A rig fault during on-rig verification, after the image was written: ERROR, and the write recorded."""
    plan = RigPlan(sample_rate_hz=50.0, rest_s=20.0, pose_hold_s=2.0,
                   rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=2.0)
    options = SequenceOptions(move_timeout_s=30.0, spin_timeout_s=30.0, rest_timeout_s=60.0)
    with FakeStation(2, 400.0, seed=3, plan=plan) as fake, open_database(
            f"sqlite:///{tmp_path / 's.sqlite'}") as db:
        for u in fake.units:
            install_firmware(u.sensor, fake.clock)
        rig = open_rig(fake.rig_url, fake.clock, **fake.rig_client_options())
        sensors = [open_sensor(url, fake.clock) for url in fake.sensor_urls]
        verifier = FaultingVerifier()
        try:
            runner = SequenceRunner(
                rig, sensors, fake.clock, plan=plan, options=options.for_scale(fake.scale), limits=table1_limits(),
                provisioner=EepromProvisioner("test", verifier=verifier, journal=StoreJournal(db)))  # type: ignore[arg-type]
            result = runner.run()
            images = [current_image_sha256(s) for s in sensors]
        finally:
            for s in sensors:
                s.close()
            rig.close()
        assert verifier.calls == 2
        assert [u.outcome for u in result.units] == [Outcome.ERROR, Outcome.ERROR]
        assert all("verification fault: RigFault: rig fault 5 (DRIVE_YAW)" in u.message for u in result.units)
        written = rows(db)
        assert [(r.state, r.written, r.read_back_ok, r.verified_on_rig) for r in written] == [
            (COMPLETE, True, True, None)] * 2
        assert sorted(r.image_sha256 for r in written) == sorted(i[0] for i in images if i is not None)
        assert all("not verified: verification fault" in r.message for r in written)


def test_eeprom_read_reconciles_and_reports(make_bench: Callable[[], Bench]) -> None:
    bench = make_bench()
    undo = crash_at_page(bench.sensor, PAGES - 1, "after")  # the last page (the header) is on the unit
    prov = EepromProvisioner("WA", now=lambda: T0, power_cycle=False, journal=StoreJournal(bench.db))
    with pytest.raises(Crash):
        prov.provision(UnitResult(0, bench.url, SERIAL, Outcome.PASS, "", params=_params(5)), bench.sensor)
    undo()
    assert [r.state for r in rows(bench.db)] == [INTENDED]
    bench.sensor.close()  # the command opens the port itself
    res = CliRunner().invoke(eeprom_app, ["read", "--sensor", bench.device.url, "--db", bench.url])
    assert res.exit_code == 0, res.output
    assert "reconciled an unfinished EEPROM write to slot A" in res.output
    assert "recorded now" in res.output
    assert [r.state for r in rows(bench.db)] == [COMPLETE]
    bench.sensor = open_sensor(bench.device.url, ManualClock(), command_timeout_s=0.25, attempts=1)
    assert_agree(bench)
