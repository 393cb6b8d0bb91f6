"""The station's live status for the operator page: a record subscriber with change notification.

:class:`LiveStatus` is passed to the sequence runner as one more subscriber (see
:mod:`station.sequence.records`); it keeps the station state (``idle``, ``running``,
``fault``), the current step with progress and the estimated time remaining, and one
tile per fixture slot (serial, state, verdict). It is fed from the runner's thread and
read from the web server's event loop: every change bumps :attr:`LiveStatus.version`
under a lock and wakes the asyncio waiters of :meth:`LiveStatus.wait_change`
thread-safely, which is what the server-sent events stream waits on.

Times: ``t_s`` and step durations are station clock seconds (rig seconds, s). The time
remaining is the unfinished part of the planned capture (``hold_s``) of the current
step plus, for each step still to come, its planned capture time from the plan (the run's
:class:`~station.sequence.records.RunStarted` carries every step's hold) and the mean rig
overhead (step duration minus hold: motion and settling) of the steps finished so far; before
the first step finished the motion is not known yet and the status says so
(``remaining_basis``). A run whose start does not carry the plan's holds falls back to the hold
of the last step of the same kind (rest, pose, rate; the current step's for a kind not seen yet).

Units per hour are counted over a stated window (:data:`RATE_WINDOW_S`, the last hour), not since
the shift's start: the figure does not fall while the station is idle at the start of a shift.

The shift's figures come from the store's quality tables (:func:`shift_stats`, shift calendar
:class:`~station.store.quality.ShiftCalendar`), so they include earlier runs and other stations' results in the
same database: units tested are distinct units with a tested result (PASS, FAIL, RETEST), first-pass yield is over
units whose first tested result fell in the shift (ERROR, ABORTED, UNFINISHED results are not tested).

:meth:`LiveStatus.status` is the typed status (:class:`~station.web.models.StationStatus`, the
answer of ``GET /api/status``); :meth:`LiveStatus.snapshot` is the same as plain JSON-able data
for the status page and its events.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import and_, case, func, select

from station.sequence.records import (
    Measured,
    Outcome,
    PromptAnswered,
    PromptShown,
    Record,
    RigReading,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.store.db import Database
from station.store.models import QualityResult
from station.store.models import Station as StationRow
from station.store.quality import ShiftCalendar
from station.web.listing import list_runs
from station.web.models import PromptStatus, RigState, RunSummary, ShiftStats, SlotStatus, StationStatus, StepProgress
from station.web.models.status import StationState
from station.web.verdicts import Missed, plain_reason

#: The window of the units-per-hour figure (wall-clock s): the last hour.
RATE_WINDOW_S = 3600.0


def shift_start(now: datetime, shifts: ShiftCalendar | None = None) -> tuple[datetime, str]:
    """The start (UTC, timezone-aware) and name of the shift of ``shifts`` (default A 06:00, B 14:00, C 22:00 UTC)
    that contains ``now``."""
    cal = shifts if shifts is not None else ShiftCalendar()
    now = now.astimezone(UTC)
    midnight = now.replace(hour=0, minute=0, second=0, microsecond=0)
    minute = now.hour * 60 + now.minute
    started = [(name, m) for name, m in cal.shifts if m <= minute]
    if started:
        name, m = started[-1]
        return midnight + timedelta(minutes=m), name
    name, m = cal.shifts[-1]
    return midnight - timedelta(days=1) + timedelta(minutes=m), name


def shift_stats(db: Database, now: datetime | None = None, station: str | None = None,
                shifts: ShiftCalendar | None = None) -> ShiftStats:
    """The figures of the shift containing ``now`` (default: now, UTC) from the quality tables (all stations in
    the database, or ``station``). Definitions: :mod:`station.store.quality_index` (tested, first pass)."""
    now = now if now is not None else datetime.now(UTC)
    since, name = shift_start(now, shifts)
    window_start = now - timedelta(seconds=RATE_WINDOW_S)
    q = QualityResult
    first = q.attempt == 1
    shift_q = select(func.count(), func.sum(case((q.tested, 0), else_=1)),
                     func.count(func.distinct(case((q.tested, q.unit_id)))), func.sum(case((first, 1), else_=0)),
                     func.sum(case((and_(first, q.outcome == Outcome.PASS.value), 1), else_=0))
                     ).where(q.started_at >= since, q.started_at <= now)
    window_q = select(func.count(func.distinct(q.unit_id))).where(q.tested, q.started_at >= window_start,
                                                                  q.started_at <= now)
    if station is not None:
        shift_q = shift_q.join(StationRow, q.station_id == StationRow.id).where(StationRow.name == station)
        window_q = window_q.join(StationRow, q.station_id == StationRow.id).where(StationRow.name == station)
    with db.transaction() as s:
        results, not_tested, units, first_tested, first_pass = (int(x or 0) for x in s.execute(shift_q).one())
        in_window = int(s.scalar(window_q) or 0)
    return ShiftStats(shift=name, since=since.isoformat(), results=results, not_tested=not_tested,
                      units_tested=units, first_pass_units=first_tested,
                      first_pass_yield=first_pass / first_tested if first_tested else None,
                      units_per_hour=in_window * 3600.0 / RATE_WINDOW_S, rate_window_s=RATE_WINDOW_S,
                      units_in_window=in_window)


def _aware(t: datetime) -> datetime:
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


@dataclass
class _Live:
    state: StationState = "idle"
    run_id: str = ""
    station: str = ""
    rig: str = ""
    message: str = ""
    steps: tuple[str, ...] = ()
    step_index: int = -1
    step_name: str = ""
    step_kind: str = ""
    step_hold_s: float = 0.0
    step_started_t_s: float = 0.0
    t_s: float = 0.0
    steps_done: int = 0
    done_overheads: list[float] = field(default_factory=list)
    hold_by_kind: dict[str, float] = field(default_factory=dict)
    rig_state: RigState | None = None  # the rig's last reading in this run
    slots: list[SlotStatus] = field(default_factory=list)
    outcome: str | None = None
    holds_s: tuple[float, ...] = ()  # every step's planned capture (s), from the run's start
    prompt: PromptStatus | None = None
    missed: dict[int, list[Missed]] = field(default_factory=dict)  # slot -> limit checks it did not pass


def _kind_of(step_name: str) -> str:
    """'rest', 'pose' or 'rate' from a step name such as ``'pose -z'`` or ``'rate x +50'``."""
    return step_name.split(" ", 1)[0]


class LiveStatus:
    """Thread-safe live model of the station, fed by sequence records (call it with each record).

    Args:
        db: the station database for the shift figures and recent runs (None: none shown).
        now: wall clock (UTC) for the shift (default :func:`datetime.now`).
    """

    def __init__(self, db: Database | None = None, now: Callable[[], datetime] | None = None) -> None:
        self.db = db
        self.shifts = ShiftCalendar()
        """The shift calendar of the shift figures (set by :func:`station.web.app.create_app`)."""
        self._now = now if now is not None else (lambda: datetime.now(UTC))
        self._lock = threading.Lock()
        self._live = _Live()
        self._version = 0
        self._store_epoch = 0
        self._store_cache: tuple[int, float, tuple[ShiftStats, list[RunSummary]]] | None = None
        self._waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Future[None]]] = []
        self.on_start: Callable[[dict[str, Any]], str] | None = None
        """Starts a run when the API is asked to (returns its run id); None: the station cannot start runs."""
        self.on_abort: Callable[[str], bool] | None = None
        """Aborts the run with this id (False: no such run); None: the station cannot abort runs."""
        self.nests = 0
        """Nests of the station's fixture (0: unknown); set by the server that runs the station."""

    @property
    def version(self) -> int:
        """Increases with every change."""
        with self._lock:
            return self._version

    def __call__(self, record: Record) -> None:
        """Update from one record (the runner's subscriber interface)."""
        with self._lock:
            self._apply(record)
            self._version += 1
            if isinstance(record, (RunStarted, UnitFinished, RunFinished)):
                self._store_epoch += 1
            waiters, self._waiters = self._waiters, []
        self._wake(waiters)

    def set_fault(self, message: str) -> None:
        """Put the station in the fault state (e.g. the rig or the runner failed outside a run)."""
        with self._lock:
            self._live.state, self._live.message = "fault", message
            self._version += 1
            waiters, self._waiters = self._waiters, []
        self._wake(waiters)

    @staticmethod
    def _wake(waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Future[None]]]) -> None:
        for loop, fut in waiters:
            def done(f: asyncio.Future[None] = fut) -> None:
                if not f.done():
                    f.set_result(None)
            with contextlib.suppress(RuntimeError):  # a closed loop: the client is gone
                loop.call_soon_threadsafe(done)

    async def wait_change(self, version: int, timeout_s: float) -> int:
        """Wait until :attr:`version` differs from ``version`` or ``timeout_s`` (s) passed; return the version."""
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[None] = loop.create_future()
        with self._lock:
            if self._version != version:
                return self._version
            self._waiters.append((loop, fut))
        try:
            await asyncio.wait_for(fut, timeout_s)
        except TimeoutError:
            with self._lock:
                self._waiters = [w for w in self._waiters if w[1] is not fut]
        return self.version

    def _apply(self, r: Record) -> None:
        lv = self._live
        if isinstance(r, RunStarted):
            self._live = lv = _Live(state="running", run_id=r.run_id, station=r.station, rig=r.rig, steps=r.steps,
                                    t_s=r.t_s, step_started_t_s=r.t_s, holds_s=r.holds_s,
                                    slots=[SlotStatus(slot=k, sensor=s) for k, s in enumerate(r.sensors)])
            for sl in lv.slots:
                sl.state = "reading serial…"
        elif isinstance(r, PromptShown):
            if r.run_id == lv.run_id:
                lv.prompt = PromptStatus(prompt_id=r.prompt_id, kind=r.kind, text=r.text, nests=list(r.nests),
                                         timeout_s=r.timeout_s, shown_at=self._now().isoformat())
        elif isinstance(r, PromptAnswered):
            if lv.prompt is not None and lv.prompt.prompt_id == r.prompt_id:
                lv.prompt = None
        elif isinstance(r, RigReading):
            if r.run_id == lv.run_id:
                lv.rig_state = RigState(roll_deg=round(r.roll_deg, 3), pitch_deg=round(r.pitch_deg, 3),
                                        yaw_deg=round(r.yaw_deg, 3), rate_dps=round(r.rate_dps, 3),
                                        status=r.status, fault_code=r.fault_code, t_s=r.t_s)
        elif isinstance(r, StepStarted):
            lv.step_index, lv.step_name, lv.step_kind = r.index, r.name, r.kind
            lv.step_hold_s, lv.step_started_t_s, lv.t_s = r.hold_s, r.t_s, r.t_s
            lv.hold_by_kind[r.kind] = r.hold_s
            for sl in lv.slots:
                if sl.state == "reading serial…" and sl.verdict is None:
                    sl.state = "measuring"
        elif isinstance(r, StepFinished):
            lv.t_s = r.t_s
            lv.steps_done = r.index + 1
            lv.done_overheads.append(max(r.duration_s - lv.step_hold_s, 0.0))
            if lv.steps_done == len(lv.steps):
                lv.step_name, lv.step_kind = "fit and limits", "fit"
                for sl in lv.slots:
                    if sl.verdict is None and sl.state == "measuring":
                        sl.state = "fitting"
        elif isinstance(r, Measured):
            sl = self._slot(r.slot)
            if r.serial:
                sl.serial = r.serial
            m = r.measurement
            if not m.passed and r.step != "limits":
                sl.state = f"{r.step}: {m.name} = {m.value:.4g} out of limits"
            if not m.passed and not m.link:
                lv.missed.setdefault(r.slot, []).append(Missed.of(m))
        elif isinstance(r, UnitFinished):
            sl = self._slot(r.slot)
            sl.serial = r.serial or sl.serial
            sl.verdict, sl.message, sl.state = r.outcome.value, r.message, "done"
            sl.reason = plain_reason(r.outcome.value, r.message, tuple(lv.missed.get(r.slot, ())))
        elif isinstance(r, RunFinished):
            lv.t_s = r.t_s
            lv.outcome = r.outcome.value
            for u in r.units:
                sl = self._slot(u.slot)
                if sl.verdict is None:
                    sl.serial = u.serial or sl.serial
                    sl.verdict, sl.message, sl.state = u.outcome.value, u.message, "done"
                    sl.reason = plain_reason(u.outcome.value, u.message, tuple(lv.missed.get(u.slot, ())))
            lv.prompt = None
            lv.state = "fault" if r.outcome == Outcome.ERROR and not r.rig_at_rest else "idle"
            lv.message = r.message
            lv.step_name, lv.step_kind = "", ""

    def _slot(self, k: int) -> SlotStatus:
        while len(self._live.slots) <= k:
            self._live.slots.append(SlotStatus(slot=len(self._live.slots)))
        return self._live.slots[k]

    def status(self, *, with_store: bool = True) -> StationStatus:
        """The status (``GET /api/status``); ``with_store=False``: without the shift figures and recent runs."""
        shift, recent = self._store_figures() if with_store else (None, [])
        with self._lock:
            lv = self._live
            total = len(lv.steps)
            remaining, basis = self._remaining(lv) if lv.state == "running" and total else (None, "")
            return StationStatus(
                version=self._version, state=lv.state, run_id=lv.run_id, station=lv.station, rig=lv.rig,
                message=lv.message, outcome=lv.outcome,
                step=StepProgress(index=lv.step_index, name=lv.step_name, kind=lv.step_kind, hold_s=lv.step_hold_s),
                steps_done=lv.steps_done, steps_total=total,
                progress=lv.steps_done / total if total else (1.0 if lv.outcome else 0.0), remaining_s=remaining,
                remaining_basis=basis, slots=[s.model_copy() for s in lv.slots], shift=shift, recent_runs=recent,
                rig_state=lv.rig_state if lv.state == "running" else None,  # only while a run holds the rig
                prompt=lv.prompt, nests=self.nests or len(lv.slots),
            )

    @staticmethod
    def _remaining(lv: _Live) -> tuple[float, str]:
        """Estimated station clock seconds until the steps end, and how it was estimated (see the module docstring)."""
        n_done = len(lv.done_overheads)
        overhead = sum(lv.done_overheads) / n_done if n_done else 0.0
        current = 0.0
        if lv.step_index >= lv.steps_done:  # a step is under way
            current = max(lv.step_hold_s - (lv.t_s - lv.step_started_t_s), 0.0)
        first = max(lv.step_index + 1, lv.steps_done)
        future = lv.steps[first:]
        if len(lv.holds_s) == len(lv.steps):
            holds = sum(lv.holds_s[first:])
            basis = "estimated from the plan's capture times"
        else:  # a start that did not carry the plan: the hold of the last step of the same kind
            holds = sum(lv.hold_by_kind.get(_kind_of(name), lv.step_hold_s) for name in future)
            basis = "estimated from the capture times of the steps seen so far"
        motion = overhead * len(future)
        if lv.steps_done >= len(lv.steps):
            return 0.0, "the rig's steps are done; the fit, the limits and writing the units are not estimated"
        if n_done:
            basis += f" + rig motion {overhead:.0f} s per step (mean of {n_done} finished step(s))"
        else:
            basis += "; rig motion not measured yet (known after the first step)"
        return current + holds + motion, basis

    def snapshot(self, *, with_store: bool = True) -> dict[str, Any]:
        """:meth:`status` as plain JSON-able data (the status page and its server-sent events)."""
        return self.status(with_store=with_store).model_dump()

    def _store_figures(self) -> tuple[ShiftStats | None, list[RunSummary]]:
        """Shift figures and recent runs, re-read when a unit or run finished or after 10 s (s of wall time)."""
        if self.db is None:
            return None, []
        with self._lock:
            epoch = self._store_epoch
            cached = self._store_cache
        now = time.monotonic()
        if cached is not None and cached[0] == epoch and now - cached[1] < 10.0:
            return cached[2]
        figures = shift_stats(self.db, self._now(), shifts=self.shifts), list_runs(self.db, limit=10)[0]
        with self._lock:
            self._store_cache = (epoch, now, figures)
        return figures
