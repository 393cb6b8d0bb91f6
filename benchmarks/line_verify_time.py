"""Rig time of the line demo with its EEPROM write and verification, per N (the virtual clock: the same seconds on
every run, whatever the load).

For each N: the line demo's units (``station.sim.demo.run_line_demo``: 1200 s in the simulated rack, the line's
rig part, joint fit, limits, EEPROM written and verified), its rig sequence seconds and the seconds of the
provisioning phase that follows on the rig (write, power cycle, verification of every PASS unit: the runner's
``verify_s``), and the rig time per unit with both.

    PYTHONPATH=. python benchmarks/line_verify_time.py 1 4 16
"""

from __future__ import annotations

import io
import sys
import tempfile
from pathlib import Path
from typing import Any

from rich.console import Console

import station.sequence.runner as runner_module
from station.kernel.virtual_clock import VirtualClock
from station.sim.demo import run_line_demo


def main() -> None:
    units = [int(x) for x in sys.argv[1:]] or [1, 4]
    seen: dict[str, float] = {}
    provision = runner_module.SequenceRunner._provision

    def recorded(self: Any, results: Any) -> Any:
        out = provision(self, results)
        seen["verify_s"] = float(self.verify_s)
        return out

    runner_module.SequenceRunner._provision = recorded  # type: ignore[method-assign]
    print("| N | rig sequence s | write + verification s | rig time per unit s | outcomes |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for n in units:
            seen.clear()
            r = run_line_demo(units=n, out_dir=None, console=Console(file=io.StringIO()), clock=VirtualClock(),
                              db_url=f"sqlite:///{Path(tmp) / f'line-{n}.sqlite'}")
            v = seen.get("verify_s", 0.0)
            outcomes = ", ".join(sorted({f"{sum(u.outcome == o for u in r.units)} {o.value}"
                                         for o in {u.outcome for u in r.units}}))
            print(f"| {n} | {r.sequence_s:.1f} | {v:.1f} | {(r.sequence_s + v) / n:.1f} | {outcomes} |", flush=True)


if __name__ == "__main__":
    main()
