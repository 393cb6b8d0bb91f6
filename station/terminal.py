"""The terminal subscriber: a live progress display of a run, the operator's prompts (:class:`TerminalOperator`:
answered with Enter), and the tables printed after it."""

from __future__ import annotations

import math
import select
import threading
import time
from typing import IO, Any

from rich.console import Console, Group, JustifyMethod, RenderableType
from rich.live import Live
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from station.kernel.display import display_for
from station.sequence.prompts import Answer, NoOperator, Prompt
from station.sequence.provision import EepromProvisioner
from station.sequence.records import (
    Measured,
    Outcome,
    PromptAnswered,
    PromptShown,
    Record,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.sequence.runner import RunResult

_STYLE = {Outcome.PASS: "green", Outcome.RETEST: "cyan", Outcome.FAIL: "red", Outcome.REFUSED: "blue",
          Outcome.ERROR: "magenta", Outcome.ABORTED: "yellow"}


class ProgressDisplay:
    """A record subscriber that shows the run: a step progress bar and one row per unit.

    On a terminal it is a live (refreshing) display; elsewhere it prints one line per
    finished step and unit. Use as a context manager around the run.
    """

    def __init__(self, console: Console, serials: list[str], clock_scale: float) -> None:
        self.console = console
        self.serials = serials
        self.scale = clock_scale
        self.state = ["waiting"] * len(serials)
        self.step_name = ""
        self.steps_total = 1
        self.t_start = 0.0
        self.t_now = 0.0
        self._wall0 = time.monotonic()
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total} steps"),
            TimeElapsedColumn(),
            console=console,
        )
        self.task = self.progress.add_task("starting", total=1)
        self.live: Live | None = Live(self, console=console, refresh_per_second=4) if console.is_terminal else None

    def __enter__(self) -> ProgressDisplay:
        if self.live is not None:
            self.live.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.live is not None:
            self.live.stop()

    def __rich__(self) -> RenderableType:
        table = Table(expand=False, show_edge=False, pad_edge=False)
        table.add_column("slot", justify="right")
        table.add_column("serial")
        table.add_column("state")
        for k, (serial, state) in enumerate(zip(self.serials, self.state, strict=True)):
            table.add_row(str(k), serial, state)
        sim_t = self.t_now - self.t_start
        clock = f"rig time {sim_t:7.1f} s  (clock x{self.scale:g}, wall {time.monotonic() - self._wall0:5.1f} s)"
        return Group(self.progress, clock, table)

    def __call__(self, record: Record) -> None:
        if isinstance(record, PromptShown):
            if self.live is not None:  # the prompt and its answer are typed below the display, not over it
                self.live.stop()
            self.console.print(f"[bold reverse] {record.kind.upper()} [/] {record.text}")
            return
        if isinstance(record, PromptAnswered):
            by = f" by {record.by}" if record.by else ""
            self.console.print(f"  {record.answer}{by} after {record.waited_s:.1f} s")
            if self.live is not None:
                self.live.start()
            return
        if isinstance(record, RunStarted):
            self.steps_total = len(record.steps)
            self.t_start = self.t_now = record.t_s
            self.progress.update(self.task, total=self.steps_total, description="run")
            self.state = ["measuring"] * len(self.serials)
        elif isinstance(record, StepStarted):
            self.t_now = record.t_s
            self.step_name = record.name
            self.progress.update(self.task, description=record.name)
        elif isinstance(record, StepFinished):
            self.t_now = record.t_s
            self.progress.advance(self.task)
            if self.live is None:
                mark = "ok" if record.ok else f"PROBLEM: {record.message}"
                self.console.print(
                    f"step {record.index + 1:2d}/{self.steps_total} {record.name:<12} "
                    f"{record.duration_s:6.1f} s rig time, {record.units_active} unit(s) active  {mark}"
                )
            for k in range(len(self.state)):
                if self.state[k].startswith("measuring"):
                    self.state[k] = f"measuring: {record.name} done"
            if record.index + 1 == self.steps_total:
                self.state = ["fitting" if st.startswith("measuring") else st for st in self.state]
        elif isinstance(record, Measured):
            m = record.measurement
            if not m.passed and record.step != "limits":
                self.state[record.slot] = f"[red]{record.step}: {m.describe()}"
        elif isinstance(record, UnitFinished):
            style = _STYLE[record.outcome]
            text = f"[{style}]{record.outcome.value}[/{style}]"
            if record.message:
                text += f" {record.message}"
            self.state[record.slot] = text
            if record.serial:
                self.serials[record.slot] = record.serial
        elif isinstance(record, RunFinished):
            self.t_now = record.t_s
            self.progress.update(self.task, description=f"done: {record.outcome.value}")


class TerminalOperator:
    """Answers the station's prompts at the terminal: Enter confirms, ``n`` and Enter cancels.

    The prompt's text is printed by the :class:`ProgressDisplay` (a record subscriber); this only waits for the
    answer, up to the prompt's timeout, and gives up when the run is aborted. End of input (a closed terminal,
    stdin from ``/dev/null``) raises :class:`~station.sequence.prompts.NoOperator`: a station fault, nothing moves.
    Ctrl-C, SIGTERM and SIGHUP interrupt the wait (:class:`KeyboardInterrupt`) as they interrupt a run.

    Args:
        console: where the hint goes.
        name: who answers (recorded with the answer; '' if unknown).
        stream: the input (default: stdin); must have a file descriptor (``select``).
    """

    def __init__(self, console: Console, name: str = "", stream: IO[str] | None = None) -> None:
        import sys

        self.console = console
        self.name = name
        self.stream = stream if stream is not None else sys.stdin

    def ask(self, prompt_id: str, prompt: Prompt, cancel: threading.Event) -> tuple[Answer, str]:
        self.console.print(f"  press Enter to confirm, n and Enter to cancel (waiting up to {prompt.timeout_s:g} s)")
        deadline = time.monotonic() + prompt.timeout_s
        while True:
            if cancel.is_set():
                return "cancelled", ""
            left = deadline - time.monotonic()
            if left <= 0:
                return "timeout", ""
            ready, _, _ = select.select([self.stream], [], [], min(left, 0.2))
            if not ready:
                continue
            line = self.stream.readline()
            if line == "":
                raise NoOperator("end of input: no operator at the terminal to answer the prompt "
                                 f"'{prompt.kind.value}' (give --yes to confirm prompts without one)")
            if line.strip().lower() in ("n", "no", "cancel", "abort"):
                return "cancelled", self.name
            return "confirmed", self.name


def _fmt(values: Any, scale: float = 1.0, digits: int = 4, offset: float = 0.0) -> str:
    return "\n".join("—" if not math.isfinite(float(v)) else f"{(float(v) + offset) * scale:+.{digits}f}"
                     for v in values)


_MG, _DPS, _PPM = display_for("acceleration"), display_for("angular_rate"), display_for("scale_error")


def summary_table(result: RunResult) -> Table:
    """One row per unit: outcome, key parameters, recording; caption with cycle time."""
    table = Table(title=f"run {result.run_id}: {result.outcome.value}", show_lines=False)
    table.add_column("slot", justify="right")
    table.add_column("serial", no_wrap=True)
    table.add_column("outcome")
    table.add_column(f"scale-1 ({_PPM.unit})\nM_a xx yy zz", justify="right")
    table.add_column(f"b_stat a\n({_MG.unit}) x y z", justify="right")
    table.add_column(f"b_stat w\n({_DPS.unit}) x y z", justify="right")
    for u in result.units:
        style = _STYLE[u.outcome]
        cells = ["", "", ""]
        if u.params is not None:
            a, g = u.params.accel, u.params.gyro
            diag = [a.misalignment[i, i] for i in range(3)]
            cells = [_fmt(diag, _PPM.scale, 0, _PPM.offset), _fmt(a.bias_static, _MG.scale, 2),
                     _fmt(g.bias_static, _DPS.scale, 3)]
        outcome = f"[{style}]{u.outcome.value}[/{style}]"
        if u.message:
            outcome += f"\n{u.message}"
        table.add_row(str(u.slot), u.serial or "?", outcome, *cells)
    n = len(result.units)
    per_unit = result.cycle_time_per_unit_s
    if result.outcome in (Outcome.PASS, Outcome.FAIL):
        table.caption = (
            f"rig time {result.sequence_s:.0f} s for {n} unit(s), then fit and save {result.post_wall_s:.1f} s: "
            f"{per_unit:.0f} s per unit on a real rig, {3600.0 / per_unit:.1f} units/h; "
            f"wall time {result.wall_s:.1f} s"
        )
    else:
        table.caption = f"rig time {result.sequence_s:.0f} s; wall time {result.wall_s:.1f} s; {result.message}"
    return table


def provisioning_table(provisioner: EepromProvisioner) -> Table:
    """One row per provisioned unit: EEPROM slot and update count, write attempts, verification residuals."""
    table = Table(title="EEPROM write and verification of the corrected output")
    columns: tuple[tuple[str, JustifyMethod], ...] = (
        ("serial", "left"), ("slot #", "left"), ("tries", "right"), (f"accel err\n({_MG.unit})", "right"),
        (f"gyro err\n({_DPS.unit})", "right"), (f"rate err\n({_DPS.unit})", "right"), ("verified", "left"))
    for name, justify in columns:
        table.add_column(name, justify=justify)
    for serial, rec in provisioner.records.items():
        v = rec.verification
        cells = ["", "", "", "not run"]
        if v is not None:
            c = {k.name: k.value for k in v.checks}
            acc = max(c.get("verify.pose.accel_error", math.nan), c.get("verify.rate.accel_error", math.nan))
            cells = [f"{acc * _MG.scale:.3f}", f"{math.degrees(c.get('verify.pose.gyro_error', math.nan)):.4f}",
                     f"{math.degrees(c.get('verify.rate.rate_error', math.nan)):+.4f}",
                     "[green]yes[/green]" if v.passed else f"[red]no[/red] {v.describe()}"]
        table.add_row(serial, f"{rec.write.slot} #{rec.write.update_count}", str(rec.write.attempts), *cells)
    return table
