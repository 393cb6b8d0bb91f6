"""The operator status page, the engineer's unit and population pages and the JSON API (FastAPI).

Pages (server-rendered Jinja2 templates in ``templates/``, no front-end build step):

* ``/``: the station's live status; updated by server-sent events from ``/events``
  (the browser's EventSource reconnects by itself after a dropped connection);
* ``/units/{serial}``: parameter set against limits (marginal values highlighted), run
  history and plots (``/units/{serial}/plots/{name}.svg``, see :mod:`station.web.plots`), and the
  diagnosis of each run's recording (loaded by the page from the API, figure at
  ``/units/{serial}/diagnosis.svg``; computed in the background, see :mod:`station.web.diagnosis`);
* ``/population``: a histogram per limit-checked parameter over all units, with limits.

JSON API (documented in ``/openapi.json``): ``GET /api/units``, ``GET /api/units/{serial}``,
``GET /api/units/{serial}/eeprom.bin``, ``GET /api/units/{serial}/diagnosis``, ``GET /api/runs``,
``GET /api/status``. The write
actions ``POST /api/runs`` and ``POST /api/runs/{run_id}/abort`` need ``Authorization:
Bearer <token>`` with the token configured on the station; without a configured token
they always answer 401 (read-only by default).
"""

from __future__ import annotations

import asyncio
import hmac
import json
import math
import threading
from collections import OrderedDict
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Annotated, Any

from fastapi import Body, Depends, FastAPI, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, JSONResponse, Response, StreamingResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from fastapi.templating import Jinja2Templates

from station.eeprom.image import CalibrationImage, ImageError, encode_image
from station.fit.params import ParameterSet
from station.kernel.errors import StationBusy, StationError
from station.kernel.limits_file import load_limits
from station.session.csv_v1 import read_session
from station.session.model import Session
from station.store.db import Database, open_database
from station.store.queries import latest_parameter_set, show_unit
from station.web import plots
from station.web.diagnosis import ERROR, PENDING, DiagnosisBusy, DiagnosisService, Recording
from station.web.listing import is_marginal, latest_checks, list_runs, list_unit_results, population
from station.web.state import LiveStatus

TEMPLATES_DIR = Path(__file__).resolve().parent / "templates"
PLOT_NAMES = ("raw_corrected", "drift", "acf", "allan", "residuals")
SSE_KEEPALIVE_S = 15.0
SSE_COALESCE_S = 0.05

_bearer = HTTPBearer(auto_error=False)
_UNAUTHORIZED = {401: {"description": "missing or wrong bearer token (or no token configured)"}}
_NOT_FOUND = {404: {"description": "unknown serial or run"}}
#: Seconds a client should wait before asking again for a diagnosis in progress.
DIAGNOSIS_RETRY_S = 2


def _fmt(value: float | None, unit: str = "") -> str:
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value:.4g}"


class _PlotCache:
    """Sessions and rendered SVGs of the last few units (rendering takes ~0.1-1 s)."""

    def __init__(self, size: int = 32) -> None:
        self.size = size
        self._lock = threading.Lock()
        self._svgs: OrderedDict[tuple[str, str, str], str] = OrderedDict()

    def get(self, key: tuple[str, str, str], make: Callable[[], str]) -> str:
        with self._lock:
            if key in self._svgs:
                self._svgs.move_to_end(key)
                return self._svgs[key]
        svg = make()
        with self._lock:
            self._svgs[key] = svg
            while len(self._svgs) > self.size:
                self._svgs.popitem(last=False)
        return svg


def _recordings(detail: Any) -> list[Recording]:
    """The unit's runs with a session recording that is still on disk, newest first."""
    return [Recording(r.run_id, Path(r.session_path), r.session_sha256) for r in detail.runs
            if r.session_path and r.session_sha256 and Path(r.session_path).is_file()]


def create_app(db_url: str | None = None, *, token: str | None = None, live: LiveStatus | None = None,
               limits_path: Path | None = None, database: Database | None = None,
               diagnosis: DiagnosisService | None = None) -> FastAPI:
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
    """
    db = database if database is not None else open_database(db_url)
    live = live if live is not None else LiveStatus(db)
    if live.db is None:
        live.db = db
    limits = load_limits(limits_path)
    marginal_fraction = limits.marginal_fraction
    templates = Jinja2Templates(directory=str(TEMPLATES_DIR))
    templates.env.filters["fmt"] = _fmt
    cache = _PlotCache()
    # the unit page's diagnoses keep eq. 3's warm-up inside the sensor class's T_c range of the station's limits
    diagnoses = diagnosis if diagnosis is not None else DiagnosisService(warmup_tc_s=limits.correlation_time_s)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        diagnoses.start()
        try:
            yield
        finally:
            await asyncio.to_thread(diagnoses.stop)
            if database is None:  # opened here: closed here
                db.close()

    app = FastAPI(title="station", version="1", lifespan=lifespan,
                  description="End-of-line MEMS IMU calibration station: live status, units, runs, EEPROM images.")
    app.state.db, app.state.live, app.state.diagnosis = db, live, diagnoses

    def require_token(creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]) -> None:
        ok = (token is not None and creds is not None and creds.scheme.lower() == "bearer"
              and hmac.compare_digest(creds.credentials.encode(), token.encode()))
        if not ok:
            raise HTTPException(401, "a valid bearer token is required", headers={"WWW-Authenticate": "Bearer"})

    # ---- pages -------------------------------------------------------------------------------------------

    @app.get("/", response_class=HTMLResponse, include_in_schema=False)
    def status_page(request: Request) -> HTMLResponse:
        snap = live.snapshot()
        return templates.TemplateResponse(request, "status.html", {"s": snap, "s_json": json.dumps(snap)})

    @app.get("/events", include_in_schema=False)
    async def events(request: Request) -> StreamingResponse:
        async def stream() -> AsyncIterator[str]:
            yield "retry: 1000\n\n"
            version = -1
            while not await request.is_disconnected():
                current = live.version
                if current != version:
                    snap = await asyncio.to_thread(live.snapshot)
                    version = snap["version"]
                    yield f"id: {version}\nevent: status\ndata: {json.dumps(snap)}\n\n"
                    continue
                new = await live.wait_change(version, SSE_KEEPALIVE_S)
                if new == version:
                    yield ": keepalive\n\n"
                else:
                    await asyncio.sleep(SSE_COALESCE_S)  # let a burst of records land in one event

        return StreamingResponse(stream(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})

    @app.get("/units/{serial}", response_class=HTMLResponse, include_in_schema=False)
    def unit_page(request: Request, serial: str) -> HTMLResponse:
        detail = show_unit(db, serial)
        if detail is None:
            return templates.TemplateResponse(request, "missing.html", {"what": f"unit {serial}"}, status_code=404)
        checks = latest_checks(db, serial)
        for c in checks:
            c["marginal"] = c["passed"] and is_marginal(c["value"], c["low"], c["high"], marginal_fraction)
        has_plots = _plot_source(detail) is not None
        recorded = {rec.run_id for rec in _recordings(detail)}
        return templates.TemplateResponse(request, "unit.html", {
            "d": detail, "checks": checks, "plots": PLOT_NAMES if has_plots else (),
            "params": detail.latest_params(), "marginal_fraction": marginal_fraction,
            "diag_runs": [r for r in detail.runs if r.run_id in recorded],
        })

    def _recording(serial: str, run_id: str | None) -> Recording:
        """The unit's recording of run ``run_id`` (None: its newest recording); 404 when there is none."""
        detail = show_unit(db, serial)
        if detail is None:
            raise HTTPException(404, f"unknown unit {serial}")
        for rec in _recordings(detail):
            if run_id is None or rec.run_id == run_id:
                return rec
        if run_id is None:
            raise HTTPException(404, f"no session recording of unit {serial}")
        raise HTTPException(404, f"no session recording of unit {serial} in run {run_id}")

    @app.get("/units/{serial}/diagnosis.svg", include_in_schema=False)
    def unit_diagnosis_svg(serial: str, run_id: str | None = None) -> Response:
        rec = _recording(serial, run_id)
        try:
            result = diagnoses.get(rec)
        except DiagnosisBusy as exc:
            return Response(plots.message_svg(f"diagnosis busy: {exc}"), status_code=503,
                            media_type="image/svg+xml", headers={"Retry-After": str(DIAGNOSIS_RETRY_S)})
        if result.status == PENDING:
            return Response(plots.message_svg("diagnosis in progress"), status_code=202, media_type="image/svg+xml",
                            headers={"Cache-Control": "no-store", "Retry-After": str(DIAGNOSIS_RETRY_S)})
        if result.status == ERROR:
            return Response(plots.message_svg(f"no diagnosis: {result.error}"), status_code=422,
                            media_type="image/svg+xml", headers={"Cache-Control": "no-store"})
        title = f"{serial}, run {rec.run_id}: " + ("block residual before and after each finding"
                                                  if any(c.after is not None for c in result.curves)
                                                  else "block residual of the base model (no findings)")
        svg = cache.get((serial, f"{rec.run_id}:{rec.sha256}", "diagnosis"),
                        lambda: plots.diagnosis_svg(result.curves, title))
        return Response(svg, media_type="image/svg+xml", headers={"Cache-Control": "max-age=60"})

    def _plot_source(detail: Any) -> tuple[str, str] | None:
        if detail.latest_params_json is None:
            return None
        for run in detail.runs:
            if run.run_id == detail.latest_params_run_id and run.session_path and Path(run.session_path).is_file():
                return run.run_id, run.session_path
        return None

    @app.get("/units/{serial}/plots/{name}.svg", include_in_schema=False)
    def unit_plot(serial: str, name: str) -> Response:
        if name not in PLOT_NAMES:
            raise HTTPException(404, f"no plot {name}")
        detail = show_unit(db, serial)
        if detail is None:
            raise HTTPException(404, f"unknown unit {serial}")
        source = _plot_source(detail)
        if source is None:
            svg = plots.message_svg("no recording or parameter set for this unit")
        else:
            run_id, path = source

            def render() -> str:
                params = detail.latest_params()
                assert params is not None
                try:
                    session: Session = read_session(path)
                    if name == "residuals":
                        return plots.residuals_svg(params)
                    fn = {"raw_corrected": plots.raw_corrected_svg, "drift": plots.drift_svg, "acf": plots.acf_svg,
                          "allan": plots.allan_svg}[name]
                    return fn(session, params)
                except (StationError, ValueError) as exc:
                    return plots.message_svg(f"cannot plot: {exc}")

            svg = cache.get((serial, run_id, name), render)
        return Response(svg, media_type="image/svg+xml", headers={"Cache-Control": "max-age=60"})

    @app.get("/population", response_class=HTMLResponse, include_in_schema=False)
    def population_page(request: Request) -> HTMLResponse:
        params = population(db)
        return templates.TemplateResponse(request, "population.html", {"params": params})

    @app.get("/population/plots/{name}.svg", include_in_schema=False)
    def population_plot(name: str) -> Response:
        for p in population(db, name=name):
            svg = plots.histogram_svg(p.name, p.unit, p.values, p.low, p.high)
            return Response(svg, media_type="image/svg+xml")
        raise HTTPException(404, f"no parameter {name}")

    # ---- JSON API ----------------------------------------------------------------------------------------

    @app.get("/api/status", tags=["status"])
    def api_status() -> dict[str, Any]:
        """The station's live status: state (idle/running/fault), current step, progress, time remaining
        (station clock s), one entry per fixture slot, first-pass yield and units per hour of the shift."""
        return live.snapshot()

    @app.get("/api/units", tags=["units"])
    def api_units(
        date_from: Annotated[date | None, Query(description="first UTC day of the run start (inclusive)")] = None,
        date_to: Annotated[date | None, Query(description="last UTC day of the run start (inclusive)")] = None,
        outcome: Annotated[str | None, Query(description="the unit's latest outcome: PASS, FAIL, ERROR, ABORTED")]
        = None,
        station: Annotated[str | None, Query(description="station name")] = None,
    ) -> list[dict[str, Any]]:
        """Units with their latest result among the runs matching the filters."""
        return list_unit_results(db, day_from=date_from, day_to=date_to, outcome=outcome, station=station)

    @app.get("/api/units/{serial}", tags=["units"], responses=_NOT_FOUND)
    def api_unit(serial: str) -> dict[str, Any]:
        """One unit: its runs (newest first), latest parameter set (SI units), limit checks, EEPROM writes."""
        detail = show_unit(db, serial)
        if detail is None:
            raise HTTPException(404, f"unknown unit {serial}")
        out = detail.to_dict()
        out["checks"] = latest_checks(db, serial)
        return out

    @app.get("/api/units/{serial}/eeprom.bin", tags=["units"], response_class=Response,
             responses={200: {"content": {"application/octet-stream": {}}, "description": "the EEPROM image"},
                        409: {"description": "the parameter set does not fit the image format"}, **_NOT_FOUND})
    def api_eeprom(serial: str) -> Response:
        """The calibration image (see ``station/eeprom/layout.md``) of the unit's latest PASS parameter set."""
        params = latest_parameter_set(db, serial, passed_only=True)
        if params is None:
            raise HTTPException(404, f"no passed parameter set for unit {serial}")
        station_name, when = _image_origin(serial, params)
        try:
            data = encode_image(CalibrationImage.from_params(params, station_name, when))
        except ImageError as exc:
            raise HTTPException(409, f"cannot encode the image: {exc}") from exc
        return Response(data, media_type="application/octet-stream",
                        headers={"Content-Disposition": f'attachment; filename="{_safe(serial)}.eeprom.bin"'})

    @app.get("/api/units/{serial}/diagnosis", tags=["units"], response_model=None, responses={
        200: {"description": "the diagnosis is ready: {status: 'ready', serial, run_id, session_sha256, elapsed_s, "
                             "report} with the station-diagnosis/1 report"},
        202: {"description": "the diagnosis is being computed: {status: 'pending', ...}; ask again (Retry-After)"},
        404: {"description": "unknown serial, or no session recording of the unit (in that run)"},
        422: {"description": "the recording cannot be diagnosed: {status: 'error', detail: the reason, ...}"},
        503: {"description": "too many recordings are waiting for a diagnosis; ask again (Retry-After)"},
    })
    def api_unit_diagnosis(
        serial: str,
        run_id: Annotated[str | None, Query(description="the run whose recording to diagnose (default: the newest "
                                                        "run with a recording)")] = None,
    ) -> dict[str, Any] | JSONResponse:
        """Where the unit's session recording and the base model (eq. 1 + eq. 3) disagree and which physics is
        missing (``station diagnose``): findings with parameters and uncertainties, rejected and inseparable
        effects. Computed once per recording in the background: answers 202 until it is ready."""
        rec = _recording(serial, run_id)
        head: dict[str, Any] = {"serial": serial, "run_id": rec.run_id, "session_sha256": rec.sha256}
        try:
            result = diagnoses.get(rec)
        except DiagnosisBusy as exc:
            return JSONResponse({"status": "busy", "detail": str(exc), **head}, status_code=503,
                                headers={"Retry-After": str(DIAGNOSIS_RETRY_S)})
        if result.status == PENDING:
            return JSONResponse({"status": PENDING, **head}, status_code=202,
                                headers={"Retry-After": str(DIAGNOSIS_RETRY_S), "Cache-Control": "no-store"})
        if result.status == ERROR:
            return JSONResponse({"status": ERROR, "detail": result.error, **head}, status_code=422)
        return {"status": result.status, **head, "elapsed_s": result.elapsed_s, "report": result.report}

    def _image_origin(serial: str, params: ParameterSet) -> tuple[str, datetime]:
        detail = show_unit(db, serial)
        for run in detail.runs if detail else ():
            if run.outcome == "PASS" and run.started_at:
                return run.station[:16], datetime.fromisoformat(run.started_at).replace(tzinfo=UTC)
        return "station", datetime(1970, 1, 1, tzinfo=UTC)

    @app.get("/api/runs", tags=["runs"])
    def api_runs(
        limit: Annotated[int, Query(ge=1, le=1000, description="newest runs to return")] = 50,
        station: Annotated[str | None, Query(description="station name")] = None,
        outcome: Annotated[str | None, Query(description="run outcome")] = None,
    ) -> list[dict[str, Any]]:
        """Runs, newest first, with every slot's unit and outcome."""
        return list_runs(db, limit=limit, station=station, outcome=outcome)

    @app.post("/api/runs", tags=["runs"], status_code=202, dependencies=[Depends(require_token)],
              responses={**_UNAUTHORIZED, 409: {"description": "a run is in progress"},
                         503: {"description": "this station cannot start runs"}})
    def api_start_run(options: Annotated[dict[str, Any] | None, Body()] = None) -> dict[str, str]:
        """Start a run on the station (write action: bearer token)."""
        if live.on_start is None:
            raise HTTPException(503, "this station cannot start runs from the API")
        if live.snapshot(with_store=False)["state"] == "running":
            raise HTTPException(409, "a run is in progress")
        try:
            return {"run_id": live.on_start(options or {})}
        except StationBusy as exc:
            raise HTTPException(409, str(exc)) from None
        except StationError as exc:
            raise HTTPException(503, str(exc)) from None

    @app.post("/api/runs/{run_id}/abort", tags=["runs"], status_code=202, dependencies=[Depends(require_token)],
              responses={**_UNAUTHORIZED, **_NOT_FOUND, 503: {"description": "this station cannot abort runs"}})
    def api_abort_run(run_id: str) -> dict[str, str]:
        """Abort the running run ``run_id`` (write action: bearer token)."""
        if live.on_abort is None:
            raise HTTPException(503, "this station cannot abort runs from the API")
        if not live.on_abort(run_id):
            raise HTTPException(404, f"no running run {run_id}")
        return {"run_id": run_id, "state": "aborting"}

    return app


def _safe(serial: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in serial) or "unit"
