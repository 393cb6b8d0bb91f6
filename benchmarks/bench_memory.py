"""Peak memory and CPU time of `station fit` and `station diagnose` against recording size, and refusals.

Each case runs the station's command line in a fresh process under ``/usr/bin/time -v`` (GNU time:
``apt-get install time``) and reads its "Maximum resident set size" (peak RSS) and user + system CPU time.
The recordings come from the station's simulator (``station simulate --seed 3 --effect lever_arm=30``,
the default 818 s plan with the sample rate raised until it holds the wanted rows); they are made once
into ``--dir`` and reused (they are 68 MB, 219 MB and 684 MB of text).

The refusal probes time ``station fit`` on inputs that must be refused quickly: ``/dev/zero``, a FIFO
nobody writes to, a 2 GB sparse file (``truncate -s 2G``) and a file of 0.5 M rows with the row limit
set below it (``STATION_SESSION_MAX_ROWS``). Probes run with a 20 s timeout and a 6 GB address-space
limit, so that code without limits (before this benchmark's change) cannot take the shared machine down.

Run (one case at a time; about 4 min at the default sizes on a quiet 2-core machine):

    python benchmarks/bench_memory.py [--sizes 0.5e6,1.6e6,5e6] [--commands fit,diagnose] [--code DIR]

``--code DIR`` measures the station found in DIR (put first on ``PYTHONPATH``), e.g. another checkout,
so before/after numbers come from one script.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PLAN_S = 818.0  # the default plan's duration at any sample rate (station simulate)
TIME_LIMIT_S = 20.0
PROBE_AS_BYTES = 6 * 2**30


def station_exe() -> str:
    return str(Path(sys.executable).with_name("station"))


def env_for(code: Path, extra: dict[str, str] | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(code)
    env.update(extra or {})
    return env


def recording(directory: Path, rows: float, code: Path) -> Path:
    """The simulated recording with about ``rows`` samples, made once into ``directory``."""
    path = directory / f"rows{round(rows / 1e3)}k.csv"
    if not path.exists():
        rate = round(rows / PLAN_S * 4) / 4  # quarter-Hz steps: ~rows samples over the 818 s plan
        subprocess.run([station_exe(), "simulate", "-o", str(path), "--seed", "3", "--sample-rate", str(rate),
                        "--effect", "lever_arm=30"], env=env_for(code), check=True, capture_output=True)
    return path


def timed(args: list[str], env: dict[str, str], *, limit_s: float | None = None,
          as_bytes: int | None = None) -> dict[str, object]:
    """Run under /usr/bin/time -v: exit code, peak RSS (MB), CPU s, wall s, last stderr line."""
    def limits() -> None:
        if as_bytes is not None:
            resource.setrlimit(resource.RLIMIT_AS, (as_bytes, as_bytes))

    with tempfile.NamedTemporaryFile("r", suffix=".time") as report:
        start = time.perf_counter()
        # a session of its own: on a timeout the whole group goes (time's child too, e.g. one blocked on a FIFO)
        proc = subprocess.Popen(["/usr/bin/time", "-v", "-o", report.name, *args], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, preexec_fn=limits, start_new_session=True)
        try:
            _, stderr = proc.communicate(timeout=limit_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            return {"code": "timeout", "wall_s": time.perf_counter() - start, "rss_mb": None, "cpu_s": None,
                    "message": f"no answer in {limit_s:.0f} s (killed)"}
        text = Path(report.name).read_text()
    values = dict(re.findall(r"^\s*(.+?):\s+(.+)$", text, re.M))
    cpu = float(values["User time (seconds)"]) + float(values["System time (seconds)"])
    wall = values["Elapsed (wall clock) time (h:mm:ss or m:ss)"].split(":")
    wall_s = sum(float(x) * 60**i for i, x in enumerate(reversed(wall)))
    lines = [ln for ln in stderr.strip().splitlines() if ln.strip()]
    return {"code": proc.returncode, "rss_mb": int(values["Maximum resident set size (kbytes)"]) / 1024,
            "cpu_s": cpu, "user_s": float(values["User time (seconds)"]),
            "sys_s": float(values["System time (seconds)"]), "wall_s": wall_s,
            "message": lines[-1][:100] if lines else ""}


def cell(value: object, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="0.5e6,1.6e6,5e6", help="comma-separated sample counts ('' for none)")
    ap.add_argument("--commands", default="fit,diagnose", help="subset of fit,diagnose")
    ap.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "station-bench-memory",
                    help="where the recordings are made once and reused")
    ap.add_argument("--code", type=Path, default=Path(__file__).resolve().parents[1],
                    help="the station checkout to measure (default: this one)")
    ap.add_argument("--no-probes", action="store_true", help="skip the refusal probes")
    args = ap.parse_args()
    args.dir.mkdir(parents=True, exist_ok=True)
    code = args.code.resolve()
    env = env_for(code)
    print(f"code: {code}")
    print(f"{'command':<9} {'rows':>9} {'file MB':>8} {'exit':>5} {'peak RSS MB':>12} {'user s':>7} {'sys s':>6} "
          f"{'CPU s':>7} {'CPU us/row':>11} {'wall s':>7}")
    for rows in [float(x) for x in args.sizes.split(",") if x.strip()]:
        path = recording(args.dir, rows, code)
        with path.open("rb") as f:
            n = sum(1 for line in f if not line.startswith(b"#")) - 1  # data rows: not metadata, not the header
        for command in args.commands.split(","):
            r = timed([station_exe(), command, str(path)], env)
            per_row = None if r["cpu_s"] is None else 1e6 * r["cpu_s"] / n  # type: ignore[operator]
            print(f"{command:<9} {n:>9d} {path.stat().st_size / 1e6:>8.0f} {r['code']!s:>5} "
                  f"{cell(r['rss_mb'], '.0f'):>12} {cell(r.get('user_s'), '.1f'):>7} {cell(r.get('sys_s'), '.1f'):>6} "
                  f"{cell(r['cpu_s'], '.1f'):>7} {cell(per_row, '.2f'):>11} {r['wall_s']:>7.1f}", flush=True)
    if args.no_probes:
        return
    print()
    print(f"{'refusal probe (station fit)':<34} {'exit':>7} {'wall s':>7} {'CPU s':>6} {'peak RSS MB':>12}  message")
    with tempfile.TemporaryDirectory() as tmp:
        sparse = Path(tmp) / "sparse.csv"
        with sparse.open("wb") as f:
            f.truncate(2 * 2**30)
        fifo = Path(tmp) / "fifo.csv"
        os.mkfifo(fifo)
        small = recording(args.dir, 0.5e6, code)
        probes = [("/dev/zero", "/dev/zero", {}), ("a FIFO nobody writes", str(fifo), {}),
                  ("2 GB sparse file", str(sparse), {}),
                  ("0.5 M rows, row limit 100 000", str(small), {"STATION_SESSION_MAX_ROWS": "100000"})]
        for name, target, extra in probes:
            r = timed([station_exe(), "fit", target], env_for(code, extra), limit_s=TIME_LIMIT_S,
                      as_bytes=PROBE_AS_BYTES)
            print(f"{name:<34} {r['code']!s:>7} {r['wall_s']:>7.2f} {cell(r['cpu_s'], '.2f'):>6} "
                  f"{cell(r['rss_mb'], '.0f'):>12}  {r['message']}", flush=True)


if __name__ == "__main__":
    main()
