"""The operator console's server side: who is signed in, what a scan is worth, and the prompts' answers.

* :class:`ConsoleSettings` (on ``app.state.console``): the serial number pattern, the retest policy's attempts,
  the session cookie's life.
* :func:`check_scan`: a scanned serial is refused on the spot when it is not a serial number (the pattern), was
  already scanned into another nest, was scrapped (a ``scrap`` disposition in the store) or is over its failed
  attempts (the retest policy); otherwise it is accepted with what the store knows of it (new, or its last
  outcome). The station has no list of the serials to expect: "unknown" means not a serial of this line.
* :class:`ConsoleOperator`: the web console as the station's prompt answerer
  (:class:`~station.sequence.prompts.Operator`): the runner's thread waits in :meth:`ConsoleOperator.ask`
  until ``POST /api/prompts/{id}`` answers, the prompt times out, or the run is aborted.

Sign-in is an operator's name and role kept in a signed session cookie (Starlette's ``SessionMiddleware``,
itsdangerous); the signing key is ``$STATION_SESSION_KEY`` or a random key per server start (then a restart signs
everyone out).
"""

from __future__ import annotations

import re
import threading
import time
from dataclasses import dataclass, field
from typing import Literal

from sqlalchemy import func, select

from station.sequence.prompts import Answer, Prompt
from station.store.db import Database
from station.store.models import Run, RunUnit, Unit
from station.store.queries import attempt_count, scrapped_at

#: What the console accepts as a serial number unless configured: 4 to 40 letters, digits, ``- _ . /``.
SERIAL_PATTERN = r"[A-Za-z0-9][A-Za-z0-9._/-]{3,39}"
#: What the console accepts as a lot: 1 to 40 letters, digits, ``- _ . /``.
LOT_PATTERN = r"[A-Za-z0-9][A-Za-z0-9._/-]{0,39}"
#: Who may sign in (recorded with the name; every role may start, answer and abort runs).
ROLES = ("operator", "technician", "engineer")
Role = Literal["operator", "technician", "engineer"]


@dataclass(frozen=True)
class ConsoleSettings:
    """The console's configuration.

    Attributes:
        serial_pattern: a scanned serial must match it whole (a regular expression).
        max_attempts: failed attempts after which a unit is refused until a disposition (the limits file's).
        session_max_age_s: how long a sign-in lasts (s; default 12 h, a shift and some).
    """

    serial_pattern: str = SERIAL_PATTERN
    max_attempts: int = 3
    session_max_age_s: int = 12 * 3600


@dataclass(frozen=True)
class ScanCheck:
    """What a scan is worth: ``accepted`` or not, the serial as scanned (trimmed), and why, in plain words."""

    accepted: bool
    serial: str
    message: str


def check_scan(db: Database, text: str, settings: ConsoleSettings, scanned: dict[int, str] | None = None,
               nest: int | None = None) -> ScanCheck:
    """Check one scanned serial before it goes into ``nest`` (the other nests' scans in ``scanned``)."""
    serial = text.strip()
    if not serial:
        return ScanCheck(False, serial, "nothing scanned")
    if not re.fullmatch(settings.serial_pattern, serial):
        return ScanCheck(False, serial, f"not a serial number of this line: {serial!r}")
    for other, other_serial in (scanned or {}).items():
        if other_serial == serial and other != nest:
            return ScanCheck(False, serial, f"{serial} is already scanned into nest {other}")
    when = scrapped_at(db, serial)
    if when is not None:
        return ScanCheck(False, serial, f"{serial} was scrapped on {when:%Y-%m-%d}: do not test it, hand it to the "
                                        "engineer")
    failed = attempt_count(db, serial)
    if failed >= settings.max_attempts:
        return ScanCheck(False, serial, f"{serial} has failed {failed} attempt(s), the limit is "
                                        f"{settings.max_attempts}: a disposition is needed before it is tested again")
    with db.transaction() as s:
        tested = s.scalar(select(func.count(RunUnit.id)).join(Unit, RunUnit.unit_id == Unit.id)
                          .where(Unit.serial == serial)) or 0
        last = s.scalar(select(RunUnit.outcome).join(Unit, RunUnit.unit_id == Unit.id).join(Run)
                        .where(Unit.serial == serial).order_by(Run.started_at.desc(), Run.id.desc()).limit(1))
    if not tested:
        return ScanCheck(True, serial, "new unit: first test")
    return ScanCheck(True, serial, f"tested {tested} time(s) before, last {last}")


@dataclass
class _Pending:
    answer: Answer | None = None
    by: str = ""
    event: threading.Event = field(default_factory=threading.Event)


class ConsoleOperator:
    """The web console answering the station's prompts (see the module docstring).

    An answer that arrives before the runner started waiting is kept (the prompt's record reaches the page
    first); answers to prompts the runner no longer waits for are refused (:meth:`answer` returns False).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pending: dict[str, _Pending] = {}
        self._closed: set[str] = set()

    def ask(self, prompt_id: str, prompt: Prompt, cancel: threading.Event) -> tuple[Answer, str]:
        with self._lock:
            p = self._pending.setdefault(prompt_id, _Pending())
        deadline = time.monotonic() + prompt.timeout_s
        try:
            while not p.event.wait(min(max(deadline - time.monotonic(), 0.0), 0.1)):
                if cancel.is_set():
                    return "cancelled", ""
                if time.monotonic() >= deadline:
                    return "timeout", ""
            assert p.answer is not None
            return p.answer, p.by
        finally:
            with self._lock:
                self._pending.pop(prompt_id, None)
                self._closed.add(prompt_id)

    def answer(self, prompt_id: str, answer: Literal["confirmed", "cancelled"], by: str) -> bool:
        """Answer ``prompt_id``; False when it is closed already (answered, timed out)."""
        with self._lock:
            if prompt_id in self._closed:
                return False
            p = self._pending.setdefault(prompt_id, _Pending())
            if p.answer is not None:
                return False
            p.answer, p.by = answer, by
        p.event.set()
        return True


__all__ = ["LOT_PATTERN", "ROLES", "SERIAL_PATTERN", "ConsoleOperator", "ConsoleSettings", "Role", "ScanCheck",
           "check_scan"]
