"""The composition root: the one place that builds a station from its configuration.

A :class:`StationConfig` names the hardware by URL (a rig and one sensor per fixture
slot), the database, the limits file, the station id and the clock scale. :class:`Station`
wires the rest once: the clock, the limits (and with them the fit's prior on T_c), the record
subscribers (the store's recorder after the caller's own), the retest gate, and for each run the hardware (opened by URL
through the scheme registries of :mod:`station.rig` and :mod:`station.sensor`), the
provisioner with its on-rig verifier, and the :class:`~station.sequence.runner.SequenceRunner`.

``station run``, ``station serve`` (the web control) and ``station demo`` all call it; the
demo is this root with the URLs of the simulated peers. Nothing here knows whether a URL
is real hardware or a simulation.
"""

from __future__ import annotations

import logging
import math
import os
import signal
import sys
import threading
import tomllib
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from station.chamber import CHAMBERS, chamber_client_options, open_chamber
from station.fit.calibrate import FitOptions
from station.kernel.clock import Clock, SimClock, WallClock
from station.kernel.errors import StationError, path_problem, shorten
from station.kernel.golden import GoldenCheck
from station.kernel.limits_file import LimitsFile, load_limits
from station.kernel.line_plan import LinePlanFile
from station.kernel.nest_frames import NestCalibration
from station.kernel.plan import RigPlan, default_plan
from station.kernel.thermal_plan import ThermalPlan
from station.kernel.urls import split_url
from station.kernel.virtual_clock import acting
from station.rig import RIGS, open_rig, rig_client_options
from station.rig.protocol import Rig, RigIdentity
from station.rig_lock import RigLock
from station.sensor import SENSORS, open_sensor
from station.sensor.protocol import Sensor
from station.sequence.options import SequenceOptions
from station.sequence.prompts import Operator
from station.sequence.provision import EepromProvisioner, ProvisionJournal, ProvisionRecord, reconcile_unit
from station.sequence.records import Record
from station.sequence.runner import RunResult, SequenceRunner
from station.sequence.steps import plan_steps
from station.sequence.thermal_sequence import thermal_runner
from station.sequence.verify import RigVerifier
from station.timelink import open_clock

if TYPE_CHECKING:  # the database code loads only when a station records
    from station.store.recorder import Recorder, RunContext

Subscriber = Callable[[Record], None]
CONFIG_FORMAT = "station-config/1"

log = logging.getLogger(__name__)


class ConfigError(StationError):
    """A station configuration the station cannot run with."""

Admit = Callable[[str, str], "str | None"]


@dataclass(frozen=True)
class StationConfig:
    """What a station is: its hardware by URL, where it records, which limits it applies.

    Attributes:
        rig_url: the rig (``modbus-tcp://HOST:PORT``, ``modbus-rtu:///dev/ttyX?baud=N``, or any
            registered scheme).
        sensor_urls: one sensor URL per fixture slot (``serial:///dev/ttyX``, ...).
        station_id: the station's name in records, session metadata and EEPROM images.
        db_url: database URL (None: ``$STATION_DB`` or ``sqlite:///station.sqlite``).
        record: subscribe the store's recorder (and apply its retest gate).
        limits_path: limits file (None: ``fixtures/limits/default.toml``).
        out_dir: where session CSVs and parameter JSONs go (None: not saved).
        clock_scale: 1 for real hardware; a simulated station's scale otherwise.
        clock_url: ``virtual://HOST:PORT``: the virtual clock ``station sim --clock virtual`` serves (the run
            repeats bit for bit); None: the wall clock or the scaled one (``clock_scale``).
        plan: the rig plan (poses, rate steps, durations, site gravity).
        operator: who runs the station (recorded on every run).
        lot: the production lot of the units the station calibrates (recorded on every run; '' unknown).
        provision: write each PASS unit's image, read it back, verify the corrected output on the rig.
        rig_options: keyword arguments of the rig's opener (None: :func:`~station.rig.rig_client_options`
            for ``clock_scale``); sensor_options: of the sensor's opener.
        chamber_url: the climate chamber (``modbus-tcp://HOST:PORT``, any scheme of ``CHAMBERS``); needed
            by a thermal plan. chamber_options: keyword arguments of its opener (None:
            :func:`~station.chamber.chamber_client_options` for ``clock_scale``).
        thermal: run this thermal plan (its ``base`` becomes ``plan``) in the chamber instead of the plain
            sequence; with ``provision`` the corrected output is verified at its ``verify_degc``.
        rig_key: the rig's name for its nest calibrations (None: ``rig_url``).
        nest_calibration: take each unit's references into its sensor frame with the rig's newest nest
            calibration in the database (:mod:`station.kernel.nest_frames`); the plain sequence only.
        golden: ``"off"``, or ``"per-shift"``: production units are admitted only after a golden unit passed its
            check on this station in the current shift, and never after a golden check failed
            (:mod:`station.kernel.golden`); every golden unit a run measures is checked and recorded.
        shifts: the shift calendar (``"A=06:00,B=14:00,C=22:00"``, UTC starts) for ``golden``.
        line: run the calibration line's rig role with this plan file (``station plan``): the units soaked in
            the line's rack, their rack recordings are in this database (found by serial), the rig runs the
            plan's rig part (which becomes ``plan``), each unit is fitted over both recordings; a unit whose
            power was interrupted since the rack is REFUSED with the reason (it gets the full plan, or goes
            back to the rack with ``back_to_rack``). The run's record names the plan file and its SHA-256.
        back_to_rack: see ``line``.
    """

    rig_url: str
    sensor_urls: tuple[str, ...]
    station_id: str = "station"
    db_url: str | None = None
    record: bool = True
    limits_path: Path | None = None
    out_dir: Path | None = Path("runs")
    clock_scale: float = 1.0
    plan: RigPlan = field(default_factory=default_plan)
    operator: str = ""
    lot: str = ""
    provision: bool = False
    rig_options: Mapping[str, Any] | None = None
    sensor_options: Mapping[str, Any] | None = None
    chamber_url: str | None = None
    chamber_options: Mapping[str, Any] | None = None
    thermal: ThermalPlan | None = None
    rig_key: str | None = None
    nest_calibration: bool = True
    golden: str = "off"
    shifts: str = "A=06:00,B=14:00,C=22:00"
    clock_url: str | None = None
    line: LinePlanFile | None = None
    back_to_rack: bool = False

    @property
    def nest_rig(self) -> str:
        """The key the rig's nest calibrations are stored under."""
        return self.rig_key if self.rig_key else self.rig_url

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensor_urls", tuple(self.sensor_urls))
        if self.thermal is not None:
            object.__setattr__(self, "plan", self.thermal.base)
            if not self.chamber_url:
                raise ConfigError("a thermal plan needs a chamber URL")
        if self.line is not None:
            object.__setattr__(self, "plan", self.line.rig_plan())
            if self.thermal is not None:
                raise ConfigError("the line's rig role runs at room temperature: no thermal plan with a line plan")
            if not self.record:
                raise ConfigError("the line's rig role reads the rack recordings from the database (record = true)")
        sid = self.station_id
        if not (isinstance(sid, str) and 1 <= len(sid) <= 16 and sid.isascii() and sid.isprintable()):
            raise ConfigError(f"station id {sid!r}: 1 to 16 printable ASCII characters (it is written into images)")
        if not self.sensor_urls:
            raise ConfigError("a station needs at least one sensor URL")
        if not (math.isfinite(self.clock_scale) and self.clock_scale > 0):
            raise ConfigError(f"clock scale must be a positive number, got {self.clock_scale!r}")
        if self.golden not in ("off", "per-shift"):
            raise ConfigError(f"golden {self.golden!r}: 'off' or 'per-shift'")
        # every URL and path before anything starts: a bad one is one line, not a traceback minutes later (the
        # URL's scheme is checked against the registries when the station is built: a plugin may register later)
        split_url(self.rig_url, "rig")
        for url in self.sensor_urls:
            split_url(url, "sensor")
        if self.chamber_url:
            split_url(self.chamber_url, "chamber")
        if self.out_dir is not None:
            check_out_dir(self.out_dir)

    def check_urls(self) -> None:
        """Each device URL against its registry: a registered scheme whose parser takes it (one line if not)."""
        RIGS.check(self.rig_url)
        for url in self.sensor_urls:
            SENSORS.check(url)
        if self.chamber_url:
            CHAMBERS.check(self.chamber_url)

    @classmethod
    def from_file(cls, path: Path, **overrides: Any) -> StationConfig:
        """A station configuration file (TOML, ``format = "station-config/1"``); ``overrides`` win.

        Keys: ``rig`` (URL), ``sensors`` (list of URLs), ``station`` (id), ``db`` (URL), ``limits``
        (path, relative to the file), ``out`` (directory, relative to the file), ``scale``, ``operator``, ``lot``,
        ``rig_key`` (the rig's name for its nest calibrations; default the rig URL), ``golden`` ("off" or
        "per-shift") and ``shifts`` (the shift calendar, e.g. "A=06:00,B=14:00,C=22:00").
        Unknown keys are refused, as in a limits file.
        """
        try:
            data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        except OSError as exc:
            raise ConfigError(f"cannot read station configuration {path}: {exc.strerror or exc}") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path}: not valid TOML: {exc}") from None
        if data.get("format") != CONFIG_FORMAT:
            raise ConfigError(f"{path}: format {data.get('format')!r}; this station reads {CONFIG_FORMAT!r}")
        known = {"format", "rig", "sensors", "station", "db", "limits", "out", "scale", "operator", "lot",
                 "rig_key", "golden", "shifts"}
        extra = sorted(set(data) - known)
        if extra:
            raise ConfigError(f"{path}: unknown key(s) {', '.join(extra)}")
        base = Path(path).resolve().parent

        def text(key: str) -> str | None:
            v = data.get(key)
            if v is not None and not isinstance(v, str):
                raise ConfigError(f"{path}: {key} must be a string, got {v!r}")
            return v

        sensors = data.get("sensors", [])
        if not (isinstance(sensors, list) and all(isinstance(u, str) for u in sensors)):
            raise ConfigError(f"{path}: sensors must be a list of URLs")
        scale = data.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, int | float):
            raise ConfigError(f"{path}: scale must be a number, got {scale!r}")
        kw: dict[str, Any] = {
            "rig_url": text("rig"), "sensor_urls": tuple(sensors), "station_id": text("station") or "station",
            "db_url": text("db"), "clock_scale": float(scale), "operator": text("operator") or "",
            "lot": text("lot") or "", "rig_key": text("rig_key"),
        }
        for key in ("golden", "shifts"):
            if text(key):
                kw[key] = text(key)
        if text("limits"):
            kw["limits_path"] = base / str(data["limits"])
        if text("out"):
            kw["out_dir"] = base / str(data["out"])
        kw.update({k: v for k, v in overrides.items() if v is not None})
        if not kw.get("rig_url"):
            raise ConfigError(f"{path}: no rig URL (key rig)")
        return cls(**kw)


def make_clock(scale: float, url: str | None = None) -> Clock:
    """The wall clock at scale 1, a scaled clock (``station sim``'s speed) otherwise; with ``url``
    (``virtual://HOST:PORT``, served by ``station sim --clock virtual``) the simulator's virtual clock."""
    if url:
        return open_clock(url)
    return WallClock() if scale == 1.0 else SimClock(scale)


@dataclass(frozen=True, eq=False)
class Hardware:
    """An open rig and the fixture's open sensors (slot order)."""

    rig: Rig
    sensors: tuple[Sensor, ...]
    identity: RigIdentity

    @property
    def rig_name(self) -> str:
        return f"{self.identity.firmware_id} {self.identity.firmware_version}"


@contextmanager
def open_hardware(
    rig_url: str,
    sensor_urls: Sequence[str],
    clock: Clock,
    *,
    rig_options: Mapping[str, Any] | None = None,
    sensor_options: Mapping[str, Any] | None = None,
) -> Iterator[Hardware]:
    """Open the rig and the sensors by URL, identify the rig, and close everything on the way out.

    Raises a :class:`~station.kernel.errors.HardwareError` (or a URL error) when any of them cannot
    be opened; whatever was opened by then is closed.
    """
    rig = open_rig(rig_url, clock, **dict(rig_options or {}))
    sensors: list[Sensor] = []
    try:
        for url in sensor_urls:
            sensors.append(open_sensor(url, clock, **dict(sensor_options or {})))
        identity = rig.identify()
        yield Hardware(rig, tuple(sensors), identity)
    finally:
        for s in sensors:
            s.close()
        rig.close()


def run_context(plan: RigPlan | None = None, limits: Any = None, operator: str = "", lot: str = "") -> RunContext:
    """A :class:`~station.store.recorder.RunContext` fingerprinting a rig plan and product limits.

    The sequence version names the step count, the hashes are SHA-256 of the frozen objects' ``repr``;
    the limits version is their ``name`` (for a limits file: its name, version and the file's SHA-256).
    None leaves the corresponding fields empty.
    """
    from station.store.recorder import RunContext, digest_of

    kw: dict[str, str] = {"operator": operator, "lot": lot}
    if isinstance(limits, LimitsFile):
        kw["limits_version"] = f"{limits.name} {limits.version}"
        kw["limits_hash"] = str(limits.sha256)
    elif limits is not None:
        kw["limits_version"] = str(getattr(limits, "name", ""))
        kw["limits_hash"] = digest_of(limits)
    if plan is not None:
        kw["sequence_version"] = f"plan/{len(plan_steps(plan))} steps"
        kw["sequence_hash"] = digest_of(plan)
    return RunContext(**kw)


def attach_recorder(
    runner_or_subscribe: SequenceRunner | Callable[[Subscriber], Any],
    db_url: str | None = None,
    *,
    station_name: str | None = None,
    operator: str = "",
    plan: RigPlan | None = None,
    limits: Any = None,
    context: RunContext | None = None,
    notify: Callable[[str], None] | None = None,
    lot: str = "",
) -> Recorder:
    """Open the database at ``db_url`` (migrating it), recover stale runs, subscribe a recorder.

    Args:
        runner_or_subscribe: a :class:`~station.sequence.runner.SequenceRunner` (its ``subscribe`` is used;
            its station name, plan and limits are taken), or any callable taking a subscriber, such as
            ``subscribers.append`` of the list later given to the runner.
        db_url: database URL (None: ``$STATION_DB`` or ``sqlite:///station.sqlite``).
        station_name: recover only this station's UNFINISHED runs (default: the runner's station; None
            without a runner: every stale run).
        operator: who runs the station.
        plan, limits: the rig plan and limits the run uses, fingerprinted into the run row
            (taken from the runner when one is given).
        context: overrides everything derived above.
        notify: where to say that stale runs were recovered (default: stderr).

    Returns the recorder; its ``db`` stays open for the process (``recorder.db.close()`` to release it).
    Raises :class:`~station.store.db.StoreError` if the database cannot be opened.
    """
    from station.store.db import open_database
    from station.store.recorder import Recorder

    db = open_database(db_url)
    subscribe: Callable[[Subscriber], Any]
    if isinstance(runner_or_subscribe, SequenceRunner):
        subscribe = runner_or_subscribe.subscribe
        plan = plan if plan is not None else runner_or_subscribe.plan
        limits = limits if limits is not None else runner_or_subscribe.limits
        if station_name is None:
            station_name = runner_or_subscribe.station
    else:
        subscribe = runner_or_subscribe
    ctx = context if context is not None else run_context(plan, limits, operator, lot)
    recorder = Recorder(db, ctx)
    recovered = recorder.recover(station_name)
    if recovered:
        message = f"recovered {len(recovered)} unfinished run(s): {', '.join(recovered)}"
        (notify or (lambda text: print(text, file=sys.stderr)))(message)
    subscribe(recorder)
    return recorder


@contextmanager
def abort_on_signals(runner: Callable[[], SequenceRunner | None]) -> Iterator[None]:
    """SIGTERM and SIGHUP do what Ctrl-C does: abort the run (rig to rest, ABORTED with the signal's name).

    ``runner`` returns the run in progress (None before it exists). The handlers give it the reason
    ``'aborted by SIGTERM'`` (or SIGHUP, SIGINT) and raise :class:`KeyboardInterrupt` in the main
    thread, the path Ctrl-C takes. The previous handlers are restored on exit. Outside the main
    thread this does nothing (signals are delivered to the main thread only).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, _frame: object) -> None:
        r = runner()
        if r is not None:
            r.abort(f"aborted by {signal.Signals(signum).name}")
        raise KeyboardInterrupt

    wanted = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {sig: signal.signal(sig, handler) for sig in wanted}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def check_out_dir(path: Path, what: str = "output directory") -> None:
    """Refuse an output directory that cannot be one: a file, under a file, or a name too long (no side effect)."""
    text = str(path)
    shown = shorten(text, 120)
    try:
        if path.exists() and not path.is_dir():
            raise ConfigError(f"{what} {shown} is a file, not a directory")
        for parent in path.parents:
            if parent.exists():
                if not parent.is_dir():
                    raise ConfigError(f"{what} {shown}: {parent} is a file, not a directory")
                break
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{what} {shown}: {path_problem(exc, text)}") from None


def prepare_out_dir(path: Path, what: str = "output directory") -> None:
    """Create the output directory and write a probe file in it now, not after the cycle; refuses one the
    station cannot write (e.g. under /proc, read-only, a full disk)."""
    import tempfile

    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path) as probe:
            probe.write(b"\0" * 4096)
            probe.flush()
            os.fsync(probe.fileno())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{what} {shorten(str(path), 120)}: cannot write there "
                          f"({path_problem(exc, str(path))})") from None


class Station:
    """A station built from its configuration; :meth:`run` runs the sequence once on its hardware.

    Args:
        config: the station's configuration.
        clock: the clock its hardware lives by (default: :func:`make_clock` of ``config.clock_scale``).
        limits: the limits file (default: loaded from ``config.limits_path``).
        options: sequence options (default :class:`SequenceOptions`), adapted to the clock's scale.
        subscribers: record subscribers called before the store's recorder (e.g. a display).
        admit: the retest policy (default: the store's retest gate when recording, else none).
        on_provision: called with each unit's EEPROM write and verification (default: the recorder's).
        prompter: answers the station's prompts (load, close the lid, unload; :mod:`station.sequence.prompts`);
            None: the sequence runs without prompts.

    Raises :class:`~station.kernel.errors.StationError` when the limits file or the database cannot
    be used: a station that cannot record or judge does not start.
    """

    def __init__(
        self,
        config: StationConfig,
        *,
        clock: Clock | None = None,
        limits: LimitsFile | None = None,
        options: SequenceOptions | None = None,
        subscribers: Sequence[Subscriber] = (),
        admit: Admit | None = None,
        on_provision: Callable[[ProvisionRecord], None] | None = None,
        prompter: Operator | None = None,
    ) -> None:
        self.config = config
        self.prompter = prompter
        config.check_urls()
        if config.out_dir is not None:
            prepare_out_dir(config.out_dir)
        self.clock = clock if clock is not None else make_clock(config.clock_scale, config.clock_url)
        self.limits = limits if limits is not None else load_limits(config.limits_path)
        self.options = (options if options is not None else SequenceOptions()).for_scale(self.clock.scale)
        # the sensor class's T_c range (the limits file's correlation_time_s) is the fit's prior on T_c
        # a thermal plan moves the temperature on purpose: the fit adds the temperature polynomials where the
        # recording separates them from the eq. 3 warm-up ("auto"); a plain plan holds it constant ("off").
        # The found terms (docs/found-terms.md) are fitted as `station fit` fits them: the gyro's IEEE 952
        # polynomial where the rate steps determine it and the time offset where the transitions do, each kept
        # where significant; one the plan cannot determine is flagged in the set's quality, not stored.
        self.fit_options = FitOptions(
            tc_range_s=dict(self.limits.correlation_time_s), thermal="auto" if config.thermal is not None else "off",
            scale_nonlinearity="auto", time_offset="auto",
        )
        self.subscribers: list[Subscriber] = list(subscribers)
        self.recorder: Recorder | None = None
        if config.record:
            context = run_context(config.plan, self.limits, config.operator, config.lot)
            if config.line is not None:  # the record names the plan file the units were calibrated with
                context = replace(context, sequence_version=config.line.version, sequence_hash=config.line.sha256)
            self.recorder = attach_recorder(
                self.subscribers.append, config.db_url, station_name=config.station_id, context=context,
            )
        if admit is None and self.recorder is not None:
            from station.store.queries import retest_gate

            admit = retest_gate(self.recorder.db, self.limits.retest.max_attempts)
        if config.golden == "per-shift":
            if self.recorder is None:
                raise ConfigError("golden = 'per-shift' needs the database (record = true)")
            from station.store.golden_records import golden_gate
            from station.store.quality import QualityFilterError, ShiftCalendar

            try:
                calendar = ShiftCalendar.parse(config.shifts)
            except QualityFilterError as exc:
                raise ConfigError(str(exc)) from None
            admit = golden_gate(self.recorder.db, config.station_id, calendar, inner=admit)
        self.admit = admit
        self.golden_checks: list[GoldenCheck] = []  # the last run's golden-unit checks
        self.on_provision = on_provision
        self.journal: ProvisionJournal | None = None  # EEPROM writes recorded ahead (the recorder's database)
        if self.recorder is not None:
            from station.store.write_ahead import StoreJournal

            self.journal = StoreJournal(self.recorder.db, self.recorder.current_run)
        self.reconciled: list[str] = []  # unfinished EEPROM writes found and closed when the last run started
        self.provisioner: EepromProvisioner | None = None  # the last run's, with its records

    def subscribe(self, fn: Subscriber) -> None:
        """Call ``fn`` with every record of later runs (after the subscribers given so far)."""
        self.subscribers.append(fn)

    def _rig_options(self) -> Mapping[str, Any]:
        c = self.config
        return c.rig_options if c.rig_options is not None else rig_client_options(self.clock.scale)

    def nests(self) -> NestCalibration | None:
        """The rig's newest nest calibration in the database (None: none, not recording, or switched off)."""
        if not self.config.nest_calibration or self.recorder is None:
            return None
        from station.store.nest_records import latest_nest_calibration

        return latest_nest_calibration(self.recorder.db, self.config.nest_rig)

    def _provisioner(self, hw: Hardware, nests: NestCalibration | None = None) -> EepromProvisioner | None:
        if not self.config.provision:
            return None
        plan = self.config.plan
        verifier = RigVerifier(hw.rig, self.clock, self.limits.verification, gravity_mps2=plan.gravity_mps2,
                               sample_rate_hz=int(plan.sample_rate_hz), options=self.options, nests=nests,
                               sensors=hw.sensors)
        return EepromProvisioner(self.config.station_id, verifier=verifier, journal=self.journal,
                                 on_record=self.on_provision)

    def _verifier(self, hw: Hardware) -> RigVerifier:
        plan = self.config.plan
        return RigVerifier(hw.rig, self.clock, self.limits.verification, gravity_mps2=plan.gravity_mps2,
                           sample_rate_hz=int(plan.sample_rate_hz), options=self.options)

    def _thermal_runner(self, hw: Hardware, chamber: Any, serials: Mapping[int, str] | None = None) -> SequenceRunner:
        c = self.config
        assert c.thermal is not None
        self.provisioner = (EepromProvisioner(c.station_id, verifier=self._verifier(hw), journal=self.journal,
                                              on_record=self.on_provision) if c.provision else None)
        return thermal_runner(
            hw.rig, hw.sensors, self.clock, chamber, c.thermal,
            options=self.options, limits=self.limits.product, out_dir=c.out_dir, station=c.station_id,
            rig_name=hw.rig_name, sensor_urls=list(c.sensor_urls), subscribers=self.subscribers,
            provisioner=self.provisioner, admit=self.admit, fit_options=self.fit_options,
            operator=self.prompter, expected_serials=serials,
        )

    def reconcile(self, sensors: Sequence[Sensor]) -> list[str]:
        """Close the unfinished EEPROM writes (a crash between a write and its record) of the units on the
        fixture against what they hold; one line per write closed (also logged). A unit that cannot be read
        keeps its intents open (the run itself will report it)."""
        if self.journal is None or not self.journal.any_open():
            return []
        lines: list[str] = []
        for sensor in sensors:
            try:
                lines += reconcile_unit(self.journal, sensor)
            except StationError as exc:
                log.warning("could not reconcile the EEPROM writes of %s: %s", getattr(sensor, "url", sensor), exc)
        return lines

    def run(self, on_runner: Callable[[SequenceRunner], None] | None = None, operator: str | None = None, *,
            lot: str | None = None, serials: Mapping[int, str] | None = None) -> RunResult:
        """Take the rig, open the hardware, run the sequence once, close everything; the run's result.

        ``on_runner`` gets the runner before it runs (its ``run_id``, and :meth:`SequenceRunner.abort`).
        ``operator``: who started this run (default: the configuration's), recorded on the run; ``lot``: the
        units' lot (default: the configuration's); ``serials``: fixture slot -> the serial scanned for it (a
        unit reporting another serial is REFUSED). The station's :attr:`prompter` answers its prompts.
        Raises :class:`~station.rig_lock.RigBusy` (before anything is touched) when another run holds the
        rig, :class:`~station.kernel.errors.HardwareError` if the rig or a sensor cannot be opened.
        """
        c = self.config
        db = self.recorder.db if self.recorder is not None else None
        if self.recorder is not None:
            who = c.operator if operator is None else operator
            self.recorder.context = replace(self.recorder.context, operator=who, lot=c.lot if lot is None else lot)
        # on a virtual clock this thread owns time from the opening of the hardware to its closing
        with acting(self.clock, name="station"), RigLock(c.rig_url, c.station_id, db), open_hardware(
            c.rig_url, c.sensor_urls, self.clock, rig_options=self._rig_options(), sensor_options=c.sensor_options
        ) as hw:
            self.reconciled = self.reconcile(hw.sensors)
            if c.thermal is not None:
                assert c.chamber_url is not None
                options = c.chamber_options if c.chamber_options is not None else chamber_client_options(
                    self.clock.scale)
                chamber = open_chamber(c.chamber_url, self.clock, **dict(options))
                try:
                    runner: SequenceRunner = self._thermal_runner(hw, chamber, serials)
                    if on_runner is not None:
                        on_runner(runner)
                    return runner.run()
                finally:
                    chamber.close()
            nests = self.nests()
            self.provisioner = self._provisioner(hw, nests)
            if c.line is not None:
                runner = self._line_runner(hw, nests, serials)
            else:
                runner = SequenceRunner(
                    hw.rig, hw.sensors, self.clock, plan=c.plan, options=self.options, limits=self.limits.product,
                    out_dir=c.out_dir, station=c.station_id, rig_name=hw.rig_name, sensor_urls=list(c.sensor_urls),
                    subscribers=self.subscribers, provisioner=self.provisioner, admit=self.admit,
                    fit_options=self.fit_options, nests=nests, operator=self.prompter, expected_serials=serials,
                )
            if on_runner is not None:
                on_runner(runner)
            result = runner.run()
        self._check_golden_units(result)
        return result

    def _line_runner(self, hw: Hardware, nests: NestCalibration | None,
                     serials: Mapping[int, str] | None) -> SequenceRunner:
        """The line's rig role (``config.line``): its units' plans decided from their rack recordings in this
        station's database before anything moves, each unit fitted over both recordings."""
        from station.line.recordings import DatabaseArchive
        from station.line.rigrole import BACK_TO_RACK, FULL, LineRigRunner

        c = self.config
        assert c.line is not None and self.recorder is not None
        return LineRigRunner(
            hw.rig, hw.sensors, self.clock, archive=DatabaseArchive(self.recorder.db.sessions),
            max_transfer_s=c.line.plan.max_transfer_s, on_interruption=BACK_TO_RACK if c.back_to_rack else FULL,
            rack_orientation=c.line.plan.rack_orientation, rack_tilt_tolerance_deg=c.line.plan.rack_tilt_tolerance_deg,
            clock_slack_s=2.0 + 0.2 * self.clock.scale,  # a simulated clock's round trips take `scale` times longer
            plan=c.plan, options=self.options, limits=self.limits.product, out_dir=c.out_dir, station=c.station_id,
            rig_name=hw.rig_name, sensor_urls=list(c.sensor_urls), subscribers=self.subscribers,
            provisioner=self.provisioner, admit=self.admit, fit_options=self.fit_options, nests=nests,
            operator=self.prompter, expected_serials=serials,
        )

    def _check_golden_units(self, result: RunResult) -> None:
        """Judge every registered golden unit the run fitted against its references, and record it."""
        self.golden_checks = []
        if self.recorder is None:
            return
        from station.kernel.golden import check_golden
        from station.sequence.limits import check_limits
        from station.store.golden_records import golden_units, record_golden_check

        goldens = golden_units(self.recorder.db)
        for r in result.units:
            if r.serial not in goldens or r.params is None:
                continue
            version, golden = goldens[r.serial]
            measured = {m.name: m.value for m in check_limits(r.params, self.limits.product)}
            check = check_golden(golden, measured)
            record_golden_check(self.recorder.db, check, station=self.config.station_id, version=version,
                                run_uid=result.run_id, slot=r.slot)
            self.golden_checks.append(check)


__all__ = [
    "CONFIG_FORMAT",
    "ConfigError",
    "Hardware",
    "Station",
    "StationConfig",
    "abort_on_signals",
    "attach_recorder",
    "make_clock",
    "open_hardware",
    "run_context",
]
