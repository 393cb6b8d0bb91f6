"""One provisioning that dies at a given point, and the next start that checks database and sensor agree.

Used by ``benchmarks/bad_inputs.py`` (family "provisioning"); also runnable alone:

    python benchmarks/provision_crash.py crash WORKDIR POINT   # dies (os._exit) at POINT
    python benchmarks/provision_crash.py check WORKDIR          # the next start: reconcile, compare, exit 0 / 4
    python benchmarks/provision_crash.py crash-legacy WORKDIR POINT  # the old order: write, then record

POINT: ``page:K:before|after`` (the K-th page write of the image, 0..15; the header page is written last),
``intend|written|verified:before|after`` (around that record's commit), or ``none``. The sensor is the
in-process fake with the simulated firmware; its EEPROM is kept in WORKDIR/eeprom.bin after every page so it
outlives the process, like a real unit's. The database is WORKDIR/station.sqlite. ``check`` exits 4 ("lost
data") when the unit holds an image the database never heard of, or when they disagree after reconciliation.
"""

from __future__ import annotations

import os
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

SERIAL = "CRASH-0001"


class _Still:
    def power_on(self) -> None:
        pass

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = len(np.asarray(t_s))
        return np.tile([0.0, 0.0, 9.8], (n, 1)), np.zeros((n, 3)), np.zeros(n)


def _unit(work: Path):
    from station.kernel.clock import ManualClock
    from station.sensor import open_sensor
    from station.sim.eeprom import Eeprom
    from station.sim.fakes import FakeSensorDevice, publish
    from station.sim.firmware import install_firmware

    clock = ManualClock()
    image = (work / "eeprom.bin").read_bytes() if (work / "eeprom.bin").is_file() else None
    eeprom = Eeprom(clock=clock, image=image)
    device = FakeSensorDevice(_Still(), clock, url="fake-sensor://crash/0", serial=SERIAL, eeprom=eeprom)
    publish(device)
    install_firmware(device, clock)
    return device, open_sensor(device.url, clock, command_timeout_s=0.25, attempts=1)


def crash(work: Path, point: str, legacy: bool = False) -> None:
    from station.kernel.sensor_class import TABLE1
    from station.physics.unit import draw_unit
    from station.sequence.provision import EepromProvisioner
    from station.sequence.records import Outcome
    from station.sequence.runner import UnitResult
    from station.store.db import open_database
    from station.store.write_ahead import StoreJournal

    device, sensor = _unit(work)
    db = open_database(f"sqlite:///{work / 'station.sqlite'}")
    parts = point.split(":")
    pages = {"n": 0}
    write_page = sensor.eeprom_write_page

    def die() -> None:
        os._exit(137)  # a process killed here: no finally, no flush, no rollback

    def page(addr: int, data: bytes) -> None:
        k = pages["n"]
        pages["n"] += 1
        if parts[0] == "page" and int(parts[1]) == k and parts[2] == "before":
            die()
        write_page(addr, data)
        (work / "eeprom.bin").write_bytes(device.eeprom.image())
        if parts[0] == "page" and int(parts[1]) == k and parts[2] == "after":
            die()

    sensor.eeprom_write_page = page  # type: ignore[method-assign]

    class Journal(StoreJournal):
        def _at(self, name: str, when: str) -> None:
            if parts[0] == name and parts[1] == when:
                die()

        def intend(self, plan, slot):  # type: ignore[no-untyped-def]
            self._at("intend", "before")
            out = super().intend(plan, slot)
            self._at("intend", "after")
            return out

        def written(self, intent, report):  # type: ignore[no-untyped-def]
            self._at("written", "before")
            super().written(intent, report)
            self._at("written", "after")

        def verified(self, intent, passed, message):  # type: ignore[no-untyped-def]
            self._at("verified", "before")
            super().verified(intent, passed, message)
            self._at("verified", "after")

    seed = sum(map(ord, point)) + len(list(work.glob("*")))
    params = draw_unit(TABLE1, np.random.default_rng(seed), serial=SERIAL).as_parameter_set(0.01)
    if legacy:  # the order before write-ahead: write and read back, then record (a death between loses the row)
        from station.eeprom.image import run_image
        from station.eeprom.provision import write_image
        from station.store.recorder import record_eeprom_write

        report = write_image(sensor, run_image(params, "BENCH", datetime(2026, 1, 1, tzinfo=UTC)))
        if parts[0] == "written" and parts[1] == "before":
            die()
        record_eeprom_write(db, report.serial, report.sha256, attempts=report.attempts, read_back_ok=True)
        (work / "eeprom.bin").write_bytes(device.eeprom.image())
        return
    prov = EepromProvisioner("BENCH", power_cycle=False, journal=Journal(db, source="benchmark"),
                             now=lambda: datetime(2026, 1, 1, tzinfo=UTC))
    prov.provision(UnitResult(0, device.url, SERIAL, Outcome.PASS, "", params=params), sensor)
    (work / "eeprom.bin").write_bytes(device.eeprom.image())


def check(work: Path) -> int:
    from sqlalchemy import select

    from station.eeprom.provision import current_image_sha256
    from station.sequence.provision import reconcile_unit
    from station.store.db import open_database
    from station.store.models import EepromWrite
    from station.store.write_ahead import COMPLETE, INTENDED, StoreJournal

    _device, sensor = _unit(work)
    with open_database(f"sqlite:///{work / 'station.sqlite'}") as db:
        current = current_image_sha256(sensor)
        with db.transaction() as s:
            known = {r.image_sha256 for r in s.scalars(select(EepromWrite))}
        if current is not None and current[0] not in known:
            print(f"lost data: the unit holds image #{current[1]} the database never heard of", file=sys.stderr)
            return 4
        lines = reconcile_unit(StoreJournal(db, source="benchmark check"), sensor)
        with db.transaction() as s:
            rows = list(s.scalars(select(EepromWrite).order_by(EepromWrite.id)))
        complete = [r.image_sha256 for r in rows if r.state == COMPLETE]
        if any(r.state == INTENDED for r in rows) or (complete[-1] if complete else None) != (
                current[0] if current else None):
            print("lost data: database and unit disagree after reconciliation", file=sys.stderr)
            return 4
    print(f"agree ({len(rows)} write(s) recorded; {len(lines)} reconciled)")
    return 0


def verify_fault(work: Path) -> int:
    """The rig faults while each written unit is verified (two units on the fake station): both ERROR, and
    every image on a sensor recorded. Exit 0: agree; 4: an image the database never heard of."""
    from sqlalchemy import select

    from station.eeprom.provision import current_image_sha256
    from station.kernel.limits import table1_limits
    from station.kernel.plan import RigPlan
    from station.rig import open_rig
    from station.rig.protocol import RigFault
    from station.sensor import open_sensor
    from station.sequence.options import SequenceOptions
    from station.sequence.provision import EepromProvisioner
    from station.sequence.runner import SequenceRunner
    from station.sim.fakes import FakeStation
    from station.sim.firmware import install_firmware
    from station.store.db import open_database
    from station.store.models import EepromWrite
    from station.store.write_ahead import StoreJournal

    class Faulting:
        def verify(self, sensor: object, image: object) -> object:
            raise RigFault(5)

    plan = RigPlan(sample_rate_hz=50.0, rest_s=20.0, pose_hold_s=2.0,
                   rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=2.0)
    options = SequenceOptions(move_timeout_s=30.0, spin_timeout_s=30.0, rest_timeout_s=60.0)
    with FakeStation(2, 400.0, seed=41, plan=plan) as fake, open_database(
            f"sqlite:///{work / 'station.sqlite'}") as db:
        for u in fake.units:
            install_firmware(u.sensor, fake.clock)
        rig = open_rig(fake.rig_url, fake.clock, **fake.rig_client_options())
        sensors = [open_sensor(url, fake.clock) for url in fake.sensor_urls]
        try:
            result = SequenceRunner(rig, sensors, fake.clock, plan=plan, options=options.for_scale(fake.scale),
                                    limits=table1_limits(), provisioner=EepromProvisioner(
                                        "BENCH", verifier=Faulting(), journal=StoreJournal(db))).run()  # type: ignore[arg-type]
            images = [current_image_sha256(s) for s in sensors]
        finally:
            for s in sensors:
                s.close()
            rig.close()
        with db.transaction() as s:
            known = {r.image_sha256 for r in s.scalars(select(EepromWrite))}
    outcomes = [u.outcome.value for u in result.units]
    unknown = [i for i in images if i is not None and i[0] not in known]
    print(f"units {outcomes}; images on the sensors {sum(i is not None for i in images)}, recorded {len(known)}")
    return 4 if unknown else 0


if __name__ == "__main__":
    mode, work = sys.argv[1], Path(sys.argv[2])
    work.mkdir(parents=True, exist_ok=True)
    if mode == "verify-fault":
        sys.exit(verify_fault(work))
    if mode in ("crash", "crash-legacy"):
        crash(work, sys.argv[3], legacy=mode == "crash-legacy")
        sys.exit(0)
    sys.exit(check(work))
