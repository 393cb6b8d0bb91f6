"""The operator status page, the engineer's unit and population pages and the JSON API (FastAPI).

:func:`create_app` builds the application from one router per area (:mod:`station.web.routes`) around a
:class:`~station.web.context.WebContext` (the database, the live status, the diagnosis service, the token).

Pages (server-rendered Jinja2 templates in ``templates/``, no front-end build step):

* ``/``: the station's live status; updated by server-sent events from ``/events``
  (the browser's EventSource reconnects by itself after a dropped connection);
* ``/units/{serial}``: parameter set against limits (marginal values highlighted), run
  history and plots (``/units/{serial}/plots/{name}.svg``, see :mod:`station.web.plots`), and the
  diagnosis of each run's recording (loaded by the page from the API, figure at
  ``/units/{serial}/diagnosis.svg``; computed in the background, see :mod:`station.web.diagnosis_worker`);
* ``/units/{serial}/certificate.pdf`` and ``.html``: the unit's calibration certificate (see
  :mod:`station.web.routes.certificate`);
* ``/operator``: the operator console (sign in, lot and serials by barcode scanner, the station's prompts, start
  and abort, progress and the verdict per nest in plain words; see :mod:`station.web.routes.operator_console`);
* ``/msa``: the measurement system analysis (Gage R&R) of a lot's runs (see :mod:`station.web.routes.msa`);
* ``/population``: a histogram per limit-checked parameter over all units, with limits;
* ``/quality``: yield (first pass, final; by station, shift, day, lot) and its trend, parameters ranked by Cpk,
  control charts with run rules, histograms, CSV exports; filters by date, station, lot, limits version.

JSON API (documented in ``/openapi.json``, every answer a typed model of :mod:`station.web.models`):
``GET /api/units``, ``GET /api/units/{serial}``, ``GET /api/units/{serial}/eeprom.bin``,
``GET /api/units/{serial}/diagnosis``, ``GET /api/runs``, ``GET /api/status``, ``GET /api/quality/yield``,
``/api/quality/capability``, ``/api/quality/control-charts``, ``/api/quality/histogram/{name}``. The write
actions ``POST /api/runs`` and ``POST /api/runs/{run_id}/abort`` need ``Authorization:
Bearer <token>`` with the token configured on the station; without a configured token
they always answer 401 (read-only by default).
"""

from __future__ import annotations

import asyncio
import os
import secrets
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from starlette.middleware.sessions import SessionMiddleware

from station.kernel.limits_file import load_limits
from station.store.db import Database, open_database
from station.store.quality import ShiftCalendar
from station.web.console import ConsoleOperator, ConsoleSettings
from station.web.context import WebContext
from station.web.diagnosis_worker import DiagnosisService
from station.web.openapi import StationAPI, add_store_errors
from station.web.routes import (
    certificate,
    diagnosis,
    msa,
    operator_console,
    population,
    quality,
    runs,
    status,
    units,
)
from station.web.security import SecurityHeaders
from station.web.state import LiveStatus

# a serial may hold any printable character, "/" too ({serial:path}): the routes with something after the serial
# (certificate, diagnosis, plots, eeprom.bin) are matched before the unit's own page and record
ROUTERS = (status.router, runs.router, certificate.router, diagnosis.router, units.router, population.router,
           quality.router, msa.router, operator_console.router)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Run the diagnosis workers while the application serves; close the database if the application opened it."""
    web: WebContext = app.state.web
    web.diagnoses.start()
    try:
        yield
    finally:
        await asyncio.to_thread(web.diagnoses.stop)
        if web.owns_db:
            web.db.close()


def create_app(db_url: str | None = None, *, token: str | None = None, live: LiveStatus | None = None,
               limits_path: Path | None = None, database: Database | None = None,
               diagnosis: DiagnosisService | None = None, shifts: ShiftCalendar | str | None = None,
               console: ConsoleSettings | None = None, prompter: ConsoleOperator | None = None,
               session_key: str | None = None, https_only: bool = False) -> FastAPI:
    """The web application on the station database at ``db_url`` (see :func:`station.store.open_database`).

    Args:
        db_url: database URL (None: ``$STATION_DB`` or ``sqlite:///station.sqlite``).
        token: bearer token that allows the write actions (None: they always answer 401).
        live: the station's live status, a subscriber of the running sequence (None: an idle station).
            Its ``on_start``/``on_abort`` hooks start and abort runs; unset hooks answer 503.
        limits_path: limits file for the marginal band and the sensor class's T_c range of the default diagnosis
            service (default: the station's default limits file).
        database: an already open database (instead of ``db_url``).
        diagnosis: the background diagnosis of recordings (default: one worker thread, results kept next to
            the recordings, the limits file's T_c range); started and stopped with the application.
        shifts: the shift calendar (a :class:`~station.store.quality.ShiftCalendar` or its text form
            ``"A=06:00,B=14:00,C=22:00"``; None: ``$STATION_SHIFTS`` or that default).
        console: the operator console's settings (serial pattern, failed attempts, sign-in life; default: the
            limits file's attempts).
        prompter: the console as the station's prompt answerer (None: ``POST /api/prompts/...`` answers 503).
        session_key: the key that signs the console's session cookie (None: ``$STATION_SESSION_KEY`` or a random
            key for this application: a restart signs everyone out).
        https_only: mark the session cookie ``Secure`` (the browser sends it over HTTPS only): set when the
            server is served with TLS (``station serve --tls-cert/--tls-key``). Plain HTTP on a line's own
            network cannot use it (the browser would drop the cookie), so it is off by default.
    """
    db = database if database is not None else open_database(db_url)
    live = live if live is not None else LiveStatus(db)
    if live.db is None:
        live.db = db
    limits = load_limits(limits_path)
    # the unit page's diagnoses keep eq. 3's warm-up inside the sensor class's T_c range of the station's limits
    diagnoses = diagnosis if diagnosis is not None else DiagnosisService(warmup_tc_s=limits.correlation_time_s)
    if shifts is None:
        shifts = os.environ.get("STATION_SHIFTS") or ShiftCalendar()
    calendar = ShiftCalendar.parse(shifts) if isinstance(shifts, str) else shifts
    live.shifts = calendar
    web = WebContext(db=db, live=live, diagnoses=diagnoses, marginal_fraction=limits.marginal_fraction, token=token,
                     owns_db=database is None, shifts=calendar)
    app = StationAPI(title="station", version="1", lifespan=lifespan,
                     description="End-of-line MEMS IMU calibration station: live status, units, runs, EEPROM images.")
    app.add_middleware(SecurityHeaders)
    add_store_errors(app)
    app.state.web = web
    app.state.console = console if console is not None else ConsoleSettings(max_attempts=limits.retest.max_attempts)
    app.state.prompter = prompter
    key = session_key or os.environ.get("STATION_SESSION_KEY") or secrets.token_urlsafe(32)
    app.add_middleware(SessionMiddleware, secret_key=key, session_cookie="station_operator",
                       max_age=app.state.console.session_max_age_s, same_site="strict", https_only=https_only)
    app.state.db, app.state.live, app.state.diagnosis = db, live, diagnoses
    for router in ROUTERS:
        app.include_router(router)
    status.add_events(app, live)
    return app


__all__ = ["ROUTERS", "create_app", "lifespan"]
