"""Diagnoses (:mod:`station.diagnose`) of a unit's session recordings for the web pages, computed in the background.

A diagnosis takes seconds (about 8 s for a 15-minute recording), so a request never runs
one: :meth:`DiagnosisService.get` answers at once with the result, or ``pending`` after
queueing the recording for a small pool of worker threads (one by default: the station
has few cores and the capture of a running sequence may share the process). The workers
run at a lower scheduling priority (Linux ``nice`` of the thread) so a capture in the same
process keeps its CPU.

A result is identified by the recording's SHA-256 (as the store holds it) and computed
once. It is also kept as a JSON file next to the recording (``<name>.diagnosis.json``,
see :func:`sidecar_path`): the diagnosis is a pure function of the recording's bytes and
of the code that computes it, both are in that file, so a restarted server (or a second
one on the same store) reads it instead of spending the seconds again; a file from other
code (a different :func:`code_digest`) or for other bytes is ignored and replaced. Where
the directory is not writable the result is kept in memory only. The file holds the report
(``station-diagnosis/1``, :meth:`~station.diagnose.results.DiagnosisReport.to_json`, read back into the types by
:func:`~station.diagnose.results.load_report`, which refuses another format: the file is then ignored) and the
figure's block residuals (SI: m/s^2, rad/s, time s since power-on).

A diagnosis that the recording refuses (:class:`~station.kernel.errors.FitError`, a session format
error, a recording changed since its run) is a result too: status ``error`` with the
one-line reason.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import logging
import math
import os
import queue
import sys
import tempfile
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from station.kernel.errors import StationError
from station.store.recorder import sha256_file

if TYPE_CHECKING:
    from station.diagnose.outcome import Diagnosis
    from station.diagnose.results import DiagnosisReport

log = logging.getLogger(__name__)

#: Format tag of the file next to the recording.
FORMAT = "station-web-diagnosis/1"
SIDECAR_SUFFIX = ".diagnosis.json"
PENDING: Final = "pending"
READY: Final = "ready"
ERROR: Final = "error"
#: Packages whose source a diagnosis depends on (their digest invalidates persisted results).
_CODE_PACKAGES = ("diagnose", "fit", "session", "sim")


class DiagnosisBusy(StationError):
    """Too many recordings are waiting for a diagnosis; ask again later."""


@dataclass(frozen=True)
class Recording:
    """A unit's session recording in one run, as the store holds it.

    Attributes:
        run_id: the run.
        path: the session CSV.
        sha256: hex SHA-256 of the file when the run recorded it.
    """

    run_id: str
    path: Path
    sha256: str


@dataclass(frozen=True)
class Curve:
    """One figure row: block-mean residual of one sensor before and after a finding (or of the base model alone).

    Attributes:
        title: e.g. ``"accel lever_arm"``, ``"gyro base model"``, ``"accel simulator re-run"``.
        unit: SI unit of ``before``/``after``: ``m/s^2`` (accel) or ``rad/s`` (gyro).
        t_s: block centre times (s since power-on), (m,).
        before: residual of the base model, (m, 3).
        after: residual with the finding modelled, (m, 3); None for the base model alone.
        labels: what ``before`` and ``after`` are.
    """

    title: str
    unit: str
    t_s: np.ndarray
    before: np.ndarray
    after: np.ndarray | None
    labels: tuple[str, str] = ("before", "after")


@dataclass(frozen=True)
class Result:
    """State of one recording's diagnosis.

    Attributes:
        status: ``pending``, ``ready`` or ``error``.
        report: the typed report when ready (:meth:`json_report` gives its strict-JSON object).
        error: the one-line reason when status is ``error``.
        curves: the figure's residuals when ready.
        elapsed_s: wall time the diagnosis took (s), when computed.
        lasting: the result follows from the recording's bytes and the code alone (it may be persisted);
            False for a file that cannot be read or changed since its run, or an unexpected failure.
    """

    status: str
    report: DiagnosisReport | None = None
    error: str | None = None
    curves: tuple[Curve, ...] = ()
    elapsed_s: float | None = None
    lasting: bool = True

    def json_report(self) -> dict[str, Any] | None:
        """The ``station-diagnosis/1`` object of the report, strict JSON (non-finite numbers as None)."""
        return None if self.report is None else json_safe(self.report.to_json())


def sidecar_path(recording: Path) -> Path:
    """Where the diagnosis of ``recording`` is kept: ``unit.csv`` -> ``unit.diagnosis.json``."""
    return recording.with_suffix(SIDECAR_SUFFIX)


@functools.cache
def code_digest() -> str:
    """Hex SHA-256 over this module's :data:`FORMAT` and the sources a diagnosis depends on."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256(FORMAT.encode())
    for pkg in _CODE_PACKAGES:
        for f in sorted((root / pkg).rglob("*.py")):
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def json_safe(obj: Any) -> Any:
    """``obj`` with numpy values as Python ones and non-finite floats as None (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _curves_of(diagnosis: Diagnosis) -> tuple[Curve, ...]:
    """The figure rows of a :class:`station.diagnose.outcome.Diagnosis` (base model residuals without findings)."""
    out = []
    for item in diagnosis.curves:
        try:
            title, t, before, after = item[:4]
            t, before, after = (np.asarray(a, dtype=float) for a in (t, before, after))
        except (TypeError, ValueError):
            continue
        labels = getattr(item, "labels", None) or ("before", "after")
        if before.ndim == 2 and before.shape == after.shape and before.shape[0] == t.size:
            out.append(Curve(str(title), "rad/s" if str(title).startswith("gyro") else "m/s^2", t, before, after,
                             (str(labels[0]), str(labels[1]))))
    baseline = diagnosis.baseline
    runs = diagnosis.rerun  # the simulator re-run with the findings switched on, when present
    if out and baseline is not None and runs is not None and runs.extended is not runs.base:
        n = len(runs.extended.effects)
        for sensor, unit in (("accel", "m/s^2"), ("gyro", "rad/s")):
            try:
                t = np.asarray(baseline.sensor(sensor).t_s, dtype=float)
                before, after = (np.asarray(r.block_residual[sensor], dtype=float) for r in (runs.base, runs.extended))
            except (AttributeError, KeyError, TypeError, ValueError):
                continue
            if before.ndim == 2 and before.shape == after.shape and before.shape[0] == t.size:
                out.append(Curve(f"{sensor} simulator re-run", unit, t, before, after,
                                 ("recording − base simulation", f"recording − simulation with {n} effect(s)")))
    if not out and baseline is not None:
        for sensor, unit in (("accel", "m/s^2"), ("gyro", "rad/s")):
            sd = getattr(baseline, sensor, None)
            if sd is not None:
                out.append(Curve(f"{sensor} base model", unit, np.asarray(sd.t_s, dtype=float),
                                 np.asarray(sd.y, dtype=float), None))
    return tuple(out)


def compute(recording: Recording, *, warmup_tc_s: Mapping[str, tuple[float, float]] | None = None) -> Result:
    """Diagnose ``recording`` now (seconds): ready, or error with the reason the recording gives.

    ``warmup_tc_s``: the sensor class's T_c range per sensor (s), see :func:`station.diagnose.diagnose`.
    Raises OSError when the file cannot be read.
    """
    from station.diagnose.report import diagnose
    from station.session.csv_v1 import read_session

    digest, _ = sha256_file(recording.path)
    if digest != recording.sha256:
        return Result(ERROR, error=f"the recording {recording.path.name} has changed since run {recording.run_id} "
                                   f"(SHA-256 {digest[:12]}..., recorded {recording.sha256[:12]}...)",
                      lasting=False)
    t0 = time.perf_counter()
    try:
        diagnosis = diagnose(read_session(recording.path), warmup_tc_s=warmup_tc_s)
    except StationError as exc:
        return Result(ERROR, error=f"{type(exc).__name__}: {exc}", elapsed_s=time.perf_counter() - t0)
    return Result(READY, report=diagnosis.report, curves=_curves_of(diagnosis),
                  elapsed_s=time.perf_counter() - t0)


#: :func:`compute` under a name that DiagnosisService's ``compute`` argument does not shadow.
_compute_default = compute


def _round(a: np.ndarray) -> list[Any]:
    return json_safe(np.vectorize(lambda v: float(f"{v:.7g}"), otypes=[float])(a) if a.size else a)


def _settings(warmup_tc_s: Mapping[str, tuple[float, float]] | None) -> dict[str, Any]:
    """What a diagnosis depends on besides the recording and the code (kept in, and checked against, the file)."""
    ranges = {k: [float(lo), float(hi)] for k, (lo, hi) in sorted((warmup_tc_s or {}).items())}
    return {"warmup_tc_range_s": ranges or None}


def _dump(recording: Recording, result: Result, settings: dict[str, Any]) -> str:
    curves = [{"title": c.title, "unit": c.unit, "labels": list(c.labels), "t_s": _round(c.t_s),
               "before": _round(c.before), "after": None if c.after is None else _round(c.after)}
              for c in result.curves]
    return json.dumps({"format": FORMAT, "session_sha256": recording.sha256, "code": code_digest(),
                       "settings": settings, "status": result.status, "report": result.json_report(),
                       "error": result.error,
                       "elapsed_s": result.elapsed_s, "curves": curves}, allow_nan=False)


def _array(v: Any) -> np.ndarray:
    return np.array([np.nan if x is None else x for x in v] if v and not isinstance(v[0], list)
                    else [[np.nan if x is None else x for x in row] for row in v], dtype=float)


def _load(recording: Recording, settings: dict[str, Any]) -> Result | None:
    """The persisted result of ``recording`` when it is for these bytes, this code and these settings, else None
    (also for a report of another format: :func:`~station.diagnose.results.load_report` refuses it)."""
    from station.diagnose.results import ReportFormatError, load_report

    path = sidecar_path(recording.path)
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
        if (d.get("format") != FORMAT or d.get("session_sha256") != recording.sha256 or d.get("code") != code_digest()
                or d.get("settings") != settings or d.get("status") not in (READY, ERROR)):
            return None
        curves = tuple(Curve(c["title"], c["unit"], _array(c["t_s"]), _array(c["before"]),
                             None if c["after"] is None else _array(c["after"]), tuple(c["labels"]))
                       for c in d.get("curves") or ())
        report = None if d.get("report") is None else load_report(d["report"])
        return Result(d["status"], report=report, error=d.get("error"), curves=curves, elapsed_s=d.get("elapsed_s"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError, IndexError, ReportFormatError) as exc:
        log.info("ignoring %s: %s", path, exc)
        return None


def _save(recording: Recording, result: Result, settings: dict[str, Any]) -> None:
    path = sidecar_path(recording.path)
    try:
        text = _dump(recording, result, settings)
        fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    except (OSError, ValueError) as exc:
        log.info("diagnosis of %s kept in memory only: %s", recording.path, exc)


def _lower_priority(nice: int) -> None:
    """Raise the calling thread's nice value (Linux: per thread) so other threads of the process come first."""
    if sys.platform.startswith("linux") and nice > 0:
        with contextlib.suppress(OSError, AttributeError):
            tid = threading.get_native_id()
            os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + nice))


class DiagnosisService:
    """Diagnoses recordings in background worker threads, once per recording (by SHA-256).

    Args:
        workers: worker threads (diagnoses at the same time).
        max_queued: recordings waiting at most; beyond that :meth:`get` raises :class:`DiagnosisBusy`.
        persist: keep results next to the recordings (see the module docstring).
        memory_entries: results kept in memory (least recently used dropped first).
        nice: how much lower the workers' scheduling priority is (Linux nice steps; 0: unchanged).
        retry_s: a result that is not lasting (see :class:`Result`) is recomputed when asked for after this (s).
        compute: the function that diagnoses one recording (tests may replace it; default :func:`compute`).
        warmup_tc_s: the sensor class's T_c range per sensor (s) the default ``compute`` gives the diagnosis,
            e.g. the station's limits file's (``LimitsFile.correlation_time_s``); persisted results made with
            another range are recomputed.
    """

    def __init__(self, *, workers: int = 1, max_queued: int = 16, persist: bool = True, memory_entries: int = 64,
                 nice: int = 10, retry_s: float = 60.0, compute: Callable[[Recording], Result] | None = None,
                 warmup_tc_s: Mapping[str, tuple[float, float]] | None = None) -> None:
        self.workers, self.max_queued, self.persist, self.memory_entries = workers, max_queued, persist, memory_entries
        self.nice, self.retry_s = nice, retry_s
        self._settings = _settings(warmup_tc_s)
        self._compute = (compute if compute is not None
                         else functools.partial(_compute_default, warmup_tc_s=warmup_tc_s))
        self._lock = threading.Lock()
        self._results: OrderedDict[str, tuple[Result, float]] = OrderedDict()  # result, monotonic time kept
        self._pending: set[str] = set()
        self._queue: queue.Queue[Recording | None] | None = None
        self._threads: list[threading.Thread] = []

    def start(self) -> None:
        """Start the worker threads (no-op when running)."""
        with self._lock:
            if self._queue is not None:
                return
            self._queue = q = queue.Queue[Recording | None]()
            self._threads = [threading.Thread(target=self._work, args=(q,), name=f"station-diagnosis-{k}",
                                              daemon=True) for k in range(self.workers)]
        for t in self._threads:
            t.start()

    def stop(self, timeout_s: float = 1.0) -> None:
        """Drop the waiting recordings and stop the workers; a diagnosis in progress finishes in its daemon thread
        (waited for up to ``timeout_s`` s) and its result is kept."""
        with self._lock:
            q, threads = self._queue, self._threads
            self._queue, self._threads = None, []
            if q is None:
                return
            while True:
                try:
                    rec = q.get_nowait()
                except queue.Empty:
                    break
                if rec is not None:
                    self._pending.discard(rec.sha256)
            for _ in threads:
                q.put(None)
        deadline = time.monotonic() + timeout_s
        for t in threads:
            t.join(max(0.0, deadline - time.monotonic()))

    def peek(self, recording: Recording) -> Result | None:
        """The result of ``recording`` when known (in memory or persisted), without queueing anything."""
        with self._lock:
            kept = self._results.get(recording.sha256)
            if kept is not None:
                result, at = kept
                if result.lasting or time.monotonic() - at < self.retry_s:
                    self._results.move_to_end(recording.sha256)
                    return result
                del self._results[recording.sha256]  # a passing failure: try again
            if recording.sha256 in self._pending:
                return Result(PENDING)
        loaded = _load(recording, self._settings) if self.persist else None
        if loaded is not None:
            self._keep(recording.sha256, loaded)
        return loaded

    def get(self, recording: Recording) -> Result:
        """The result of ``recording``, or ``pending`` after queueing it (never waits for a diagnosis).

        Raises :class:`DiagnosisBusy` when ``max_queued`` recordings are already waiting.
        """
        known = self.peek(recording)
        if known is not None:
            return known
        self.start()
        with self._lock:
            if recording.sha256 in self._results:
                return self._results[recording.sha256][0]
            if recording.sha256 not in self._pending:
                if self._queue is None:  # stopped meanwhile
                    raise DiagnosisBusy("the diagnosis service is stopping")
                if len(self._pending) >= self.max_queued:
                    raise DiagnosisBusy(f"{len(self._pending)} recordings are waiting for a diagnosis")
                self._pending.add(recording.sha256)
                self._queue.put(recording)
        return Result(PENDING)

    def _keep(self, key: str, result: Result) -> None:
        with self._lock:
            self._results[key] = (result, time.monotonic())
            self._results.move_to_end(key)
            while len(self._results) > self.memory_entries:
                self._results.popitem(last=False)

    def _work(self, q: queue.Queue[Recording | None]) -> None:
        _lower_priority(self.nice)
        while (rec := q.get()) is not None:
            try:
                result = self._compute(rec)
            except OSError as exc:
                result = Result(ERROR, error=f"cannot read the recording: {exc}", lasting=False)
            except Exception as exc:  # a worker outlives any bug in the diagnosis; the page shows it
                log.exception("diagnosis of %s failed", rec.path)
                result = Result(ERROR, error=f"the diagnosis failed: {type(exc).__name__}: {exc}", lasting=False)
            if self.persist and result.lasting and result.status in (READY, ERROR):
                _save(rec, result, self._settings)
            self._keep(rec.sha256, result)
            with self._lock:
                self._pending.discard(rec.sha256)


__all__ = [
    "ERROR", "FORMAT", "PENDING", "READY", "Curve", "DiagnosisBusy", "DiagnosisService", "Recording", "Result",
    "code_digest", "compute", "json_safe", "sidecar_path",
]
