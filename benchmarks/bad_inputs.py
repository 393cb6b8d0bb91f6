"""Probe the command line with bad inputs and faults, as a new user (and a bad day) would; print a table.

Each family generates bad inputs from one good simulated recording (and the shared real imucal
recording, read from its path), runs the ``station`` command on each in a subprocess and sorts the
outcome:

* clean: exit code 1, 2 or 3 (3: the fit contradicts its recording), no traceback, and stderr holds one
  ``error:`` line of at most :data:`MAX_LINE` characters (or the command line's usage message for a bad option);
* traceback: anything else that is not exit 0 (a Python traceback, a LAPACK message, several lines, an error
  line that echoes megabytes of input);
* silently wrong: exit 0 on an input that is wrong;
* lost data: a fault after which the database and what it records disagree (an image on a sensor the
  database never heard of, records that vanish with the process);
* hang: no answer within the probe's time limit (the process is killed).

Families added for faults: ``arguments`` (URLs, paths and sizes validated before anything starts; error lines
cut), ``store`` (databases that keep nothing, a locked database, a full disk), ``provisioning`` (a process
killed at every page write and every record of an EEPROM write, then the next start:
``benchmarks/provision_crash.py``), ``memory`` (``/dev/zero`` and a 2 GB sparse file: bounded memory, under a
4 GB address-space limit so the machine survives).

    python benchmarks/bad_inputs.py [--families session,params,...] [--workdir DIR] [--verbose] [--legacy]

``--legacy``: the provisioning family with the order before write-ahead (write, then record), to show the
family detects lost data. Every probe is a bad input or a fault, so the target is every probe clean.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import json
import os
import re
import shutil
import sqlite3
import struct
import subprocess
import sys
import tempfile
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

REAL = Path(os.environ.get("STATION_REAL") or Path(__file__).resolve().parents[2] / "shared" / "real") / "imucal"
STATION = [str(Path(sys.executable).with_name("station"))]


#: The longest error line that still counts as readable (characters).
MAX_LINE = 500
VERDICTS = ("clean", "traceback", "silently wrong", "lost data", "hang")


@dataclass
class Probe:
    family: str
    name: str
    args: list[str]
    cmd: list[str] | None = None  # instead of ``station``
    timeout_s: float = 600.0
    env: dict[str, str] | None = None
    judge: Callable[[Outcome], str | None] | None = None  # a verdict of its own (e.g. 'lost data'), or None
    around: Callable[[], contextlib.AbstractContextManager[object]] | None = None  # held while the probe runs
    limit_memory: bool = False


@dataclass
class Outcome:
    probe: Probe
    code: int
    stderr: str
    stdout: str
    timed_out: bool = False

    @property
    def verdict(self) -> str:
        if self.timed_out:
            return "hang"
        if self.probe.judge is not None:
            own = self.probe.judge(self)
            if own is not None:
                return own
        text = self.stderr + self.stdout
        if "Traceback" in text or "On entry to" in text:
            return "traceback"
        if self.code == 0:
            return "silently wrong"
        usage = "Usage:" in self.stderr
        lines = [line for line in self.stderr.splitlines() if line.strip()]
        if self.code in (1, 2, 3) and (usage or (len(lines) == 1 and lines[0].startswith("error: ")
                                                 and len(lines[0]) <= MAX_LINE)):
            return "clean"
        return "traceback"


def _limit_memory() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))


def run(probe: Probe, cwd: Path) -> Outcome:
    env = {**os.environ, "STATION_DB": f"sqlite:///{cwd / 'probe.sqlite'}", "COLUMNS": "200", **(probe.env or {})}
    cmd = probe.cmd if probe.cmd is not None else [*STATION, *probe.args]
    with probe.around() if probe.around is not None else contextlib.nullcontext():
        try:
            done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=env, timeout=probe.timeout_s,
                                  errors="replace", preexec_fn=_limit_memory if probe.limit_memory else None)
        except subprocess.TimeoutExpired as exc:
            out = exc.stdout.decode("utf-8", "replace") if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            err = exc.stderr.decode("utf-8", "replace") if isinstance(exc.stderr, bytes) else (exc.stderr or "")
            return Outcome(probe, -9, err, out, timed_out=True)
    return Outcome(probe, done.returncode, done.stderr, done.stdout)


# --------------------------------------------------------------------------- generators


def _edit_csv(src: Path, dst: Path, meta: dict[str, str | None] | None = None,
              row: Callable[[int, list[str]], list[str] | None] | None = None, extra_meta: str = "") -> Path:
    lines = src.read_text().split("\n")
    header = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    out = []
    for i, line in enumerate(lines):
        if i < header and meta:
            key = line[1:].split(":")[0].strip()
            if key in meta:
                value = meta[key]
                if value is not None:
                    out.append(f"# {key}: {value}")
                continue
        if i == header and extra_meta:
            out.append(extra_meta)
        if i > header and row is not None and line:
            cells = row(i - header - 1, line.split(","))
            if cells is None:
                continue
            line = ",".join(cells)
        out.append(line)
    dst.write_text("\n".join(out))
    return dst


def _segments(path: Path) -> dict[int, tuple[str, list[float]]]:
    """segment -> (kind, first row's ref_a)"""
    out: dict[int, tuple[str, list[float]]] = {}
    lines = path.read_text().split("\n")
    header = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    for line in lines[header + 1:]:
        if not line:
            continue
        c = line.split(",")
        seg = int(c[1])
        if seg not in out:
            out[seg] = (c[2], [float(x) if x else 0.0 for x in c[10:13]])
    return out


def session_probes(w: Path, good: Path) -> list[Probe]:
    segs = _segments(good)
    poses = [s for s, (k, _) in segs.items() if k == "pose"]
    rates = [s for s, (k, _) in segs.items() if k == "rate"]
    z_down = next(s for s in poses if segs[s][1][2] < -5)
    x_up = next(s for s in poses if segs[s][1][0] > 5)

    def cell(col: int, value: str, at: int = 3000) -> Callable[[int, list[str]], list[str]]:
        def f(i: int, c: list[str]) -> list[str]:
            if i == at:
                c[col] = value
            return c
        return f

    def seg_col(seg: int, col: int, fn: Callable[[float], float]) -> Callable[[int, list[str]], list[str]]:
        def f(i: int, c: list[str]) -> list[str]:
            if int(c[1]) == seg and c[col]:
                c[col] = f"{fn(float(c[col])):.6f}"
            return c
        return f

    def shift_t(at: int, by: float) -> Callable[[int, list[str]], list[str]]:
        def f(i: int, c: list[str]) -> list[str]:
            if i >= at:
                c[0] = f"{float(c[0]) + by:.6f}"
            return c
        return f

    p: list[tuple[str, Path]] = []

    def add(name: str, **kw: object) -> None:
        p.append((name, _edit_csv(good, w / f"s_{len(p)}.csv", **kw)))  # type: ignore[arg-type]

    add("one huge value 1e30 in ax", row=cell(3, "1e30"))
    add("huge value 1e300 in gz", row=cell(8, "1e300"))
    add("temperature 1e300", row=cell(9, "1e300"))
    add("sample_rate_hz 1000 on 100 Hz data", meta={"sample_rate_hz": "1000"})
    add("sample_rate_hz 10 on 100 Hz data", meta={"sample_rate_hz": "10"})
    add("sample_rate_hz 0", meta={"sample_rate_hz": "0"})
    add("sample_rate_hz abc", meta={"sample_rate_hz": "abc"})
    add("gravity_mps2 -9.81", meta={"gravity_mps2": "-9.81"})
    add("latitude abc", meta={"latitude_deg": "abc"})
    add("latitude 500", meta={"latitude_deg": "500"})
    add("latitude nan", meta={"latitude_deg": "nan"})
    add("heading inf", meta={"heading_deg": "inf"})
    add("gap of 1e5 s in t", row=shift_t(40000, 1e5))
    add("t does not increase", row=shift_t(40000, -5.0))
    add("NaN cell", row=cell(4, "nan"))
    add("empty ax cell", row=cell(3, ""))
    add("text in a cell", row=cell(5, "abc"))
    add("pose reference says 2 g", row=seg_col(z_down, 12, lambda v: 2 * v))
    add("pose reference flipped", row=seg_col(x_up, 10, lambda v: -v))
    add("pose reference on the wrong axis", row=seg_col(x_up, 10, lambda v: 0.0))
    add("rate step reference flipped", row=seg_col(rates[0], 13, lambda v: -v))
    add("rate step reference 2x", row=seg_col(rates[1], 13, lambda v: 2 * v))
    add("pose mean 50 mm/s^2 off its reference", row=seg_col(x_up, 5, lambda v: v + 0.05))
    add("accel in counts (x2048/g)", row=lambda i, c: [*c[:3], *(f"{float(x) * 208.8:.6f}" for x in c[3:6]), *c[6:]])
    add("angle.N on a missing segment", extra_meta="# angle.999: 90,0,0")
    add("angle.N on a pose", extra_meta=f"# angle.{x_up}: 90,0,0")
    add("missing imu-session line", meta={"imu-session": None})
    add("imu-session version 2", meta={"imu-session": "2"})
    add("missing serial", meta={"serial": None})
    add("drop every pose with x down", row=lambda i, c: None if c[2] == "pose" and float(c[10] or 0) < -5 else c)
    probes = [Probe("session CSV", name, ["fit", str(path)]) for name, path in p]
    raw = w / "s_bytes.csv"
    raw.write_bytes(b"\xff\xfe\x00garbage\n" * 10)
    probes.append(Probe("session CSV", "binary garbage", ["fit", str(raw)]))
    empty = w / "s_empty.csv"
    empty.write_text("")
    probes.append(Probe("session CSV", "empty file", ["fit", str(empty)]))
    probes.append(Probe("session CSV", "a directory", ["fit", str(w)]))
    probes.append(Probe("session CSV", "missing file", ["fit", str(w / "none.csv")]))
    lat = p[10][1]
    probes += [
        Probe("diagnose", "latitude nan", ["diagnose", str(lat)]),
        Probe("diagnose", "latitude abc", ["diagnose", str(p[8][1])]),
        Probe("diagnose", "temperature 1e300", ["diagnose", str(p[2][1])]),
        Probe("diagnose", "--plot /nonexistent/d.png", ["diagnose", str(good), "--plot", "/nonexistent/d.png"]),
        Probe("diagnose", "--plot d.txt", ["diagnose", str(good), "--plot", str(w / "d.txt")]),
        Probe("diagnose", "--plot v (no suffix)", ["diagnose", str(good), "--plot", str(w / "v")]),
        Probe("diagnose", "--plot DIR", ["diagnose", str(good), "--plot", str(w)]),
    ]
    return probes


def params_probes(w: Path, good: Path, params: dict) -> list[Probe]:
    def variant(name: str, change: Callable[[dict], object], raw: bytes | None = None) -> tuple[str, Path]:
        path = w / f"p_{abs(hash(name)) % 10**8}.json"
        if raw is not None:
            path.write_bytes(raw)
        else:
            d = json.loads(json.dumps(params))
            change(d)
            path.write_text(json.dumps(d, allow_nan=True))
        return name, path

    def set_(*keys: str, value: object) -> Callable[[dict], None]:
        def f(d: dict) -> None:
            for k in keys[:-1]:
                d = d[k]
            d[keys[-1]] = value
        return f

    cases = [
        variant("sample_period_s 0", set_("sample_period_s", value=0)),
        variant("sample_period_s -0.01", set_("sample_period_s", value=-0.01)),
        variant("sample_period_s 0.001 (recording 100 Hz)", set_("sample_period_s", value=0.001)),
        variant("sample_period_s as text", set_("sample_period_s", value="0.01")),
        variant("bias_drift 1e300", set_("accel", "bias_drift", value=[1e300, 0, 0])),
        variant("bias_static NaN", set_("gyro", "bias_static", value=[None, 0, 0])),
        variant("allan as a list", set_("accel", "allan", value=[1, 2, 3])),
        variant("moving-average length 10^12", set_("moving_average_length", value=10**12)),
        variant("moving-average length 0", set_("moving_average_length", value=0)),
        variant("moving-average length 2.5", set_("moving_average_length", value=2.5)),
        variant("singular M", set_("accel", "misalignment", value=[[1, 0, 0], [1, 0, 0], [0, 0, 1]])),
        variant("M of zeros", set_("gyro", "misalignment", value=[[0, 0, 0], [0, 0, 0], [0, 0, 0]])),
        variant("M with null", set_("gyro", "misalignment", value=[[None, 0, 0], [0, 1, 0], [0, 0, 1]])),
        variant("M 2x2", set_("gyro", "misalignment", value=[[1, 0], [0, 1]])),
        variant("M scale 100", set_("accel", "misalignment", value=[[100, 0, 0], [0, 1, 0], [0, 0, 1]])),
        variant("T_c negative", set_("accel", "correlation_time_s", value=[-5, 100, 100])),
        variant("another serial", set_("serial", value="SOMEONE-ELSE")),
        variant("serial as a number", set_("serial", value=12)),
        variant("format from a newer version", set_("format", value="station-params/99")),
        variant("no format", lambda d: d.pop("format")),
        variant("no gyro", lambda d: d.pop("gyro")),
        variant("non-UTF-8", lambda d: None, raw=b'{"format": "\xff\xfe"}'),
        variant("deep nesting", lambda d: None, raw=b"[" * 100000 + b"]" * 100000),
        variant("not JSON", lambda d: None, raw=b"hello"),
        variant("a JSON list", lambda d: None, raw=b"[1, 2]"),
        variant("empty file", lambda d: None, raw=b""),
    ]
    out = [Probe("parameter JSON", name, ["correct", str(good), "--params", str(path), "-o", str(w / "c.csv")])
           for name, path in cases]
    good_params = w / "good.json"
    serial = params["serial"]
    out += [
        Probe("parameter JSON", "output = input session", ["correct", str(good), "--params", str(good_params),
                                                             "-o", str(good)]),
        Probe("parameter JSON", "output = input via ./..", ["correct", str(good), "--params", str(good_params),
                                                              "-o", str(w / ".." / w.name / good.name)]),
        Probe("parameter JSON", "output = params file", ["correct", str(good), "--params", str(good_params),
                                                           "-o", str(good_params)]),
        Probe("parameter JSON", "-o /nonexistent/c.csv", ["correct", str(good), "--params", str(good_params),
                                                            "-o", "/nonexistent/c.csv"]),
        Probe("parameter JSON", "-o DIR", ["correct", str(good), "--params", str(good_params), "-o", str(w)]),
        Probe("parameter JSON", "eeprom image from bias_drift 1e300",
              ["eeprom", "image", serial, "--params", str(cases[4][1]), "-o", str(w / "i.bin")]),
        Probe("parameter JSON", "eeprom image from allan list",
              ["eeprom", "image", serial, "--params", str(cases[6][1]), "-o", str(w / "i.bin")]),
    ]
    return out


def eeprom_probes(w: Path, good_params: Path) -> list[Probe]:
    image = w / "good.bin"
    serial = json.loads(good_params.read_text())["serial"]
    subprocess.run([*STATION, "eeprom", "image", serial, "--params", str(good_params), "-o", str(image)],
                   check=True, capture_output=True)
    data = image.read_bytes()

    def with_crc(body: bytes) -> bytes:
        return body[:-4] + struct.pack("<I", zlib.crc32(body[:-4]))

    def patched(offset: int, fmt: str, value: object) -> bytes:
        b = bytearray(data)
        struct.pack_into(fmt, b, offset, value)
        return with_crc(bytes(b))

    time_offset = 4 + 2 + 2 + 4 + 16 + 16 + 16
    cases = {
        "calibration_time int64 max, valid CRC": patched(time_offset, "<q", 2**63 - 1),
        "calibration_time int64 min, valid CRC": patched(time_offset, "<q", -(2**63)),
        "sample period NaN, valid CRC": patched(time_offset + 8, "<d", float("nan")),
        "sample period 0, valid CRC": patched(time_offset + 8, "<d", 0.0),
        "moving average 0, valid CRC": patched(time_offset + 16, "<H", 0),
        "M_a[0][0] inf, valid CRC": patched(80, "<d", float("inf")),
        "reserved field set, valid CRC": patched(time_offset + 18, "<H", 7),
        "serial non-ASCII, valid CRC": patched(12, "<4s", b"\xff\xfe\xfd\xfc"),
        "bit flip": bytes([data[0], *data[1:100], data[100] ^ 1, *data[101:]]),
        "truncated": data[:-10],
        "random bytes": bytes(range(256)) * 2,
        "empty": b"",
        "version 9": bytes(data[:4]) + struct.pack("<H", 9) + data[6:],
    }
    out = []
    for i, (name, raw) in enumerate(cases.items()):
        path = w / f"e_{i}.bin"
        path.write_bytes(raw)
        out.append(Probe("EEPROM image", name, ["eeprom", "decode", str(path)]))
    out.append(Probe("EEPROM image", "a directory", ["eeprom", "decode", str(w)]))
    out.append(Probe("EEPROM image", "--dump of one image", ["eeprom", "decode", "--dump", str(image)]))
    return out


def limits_probes(w: Path, good: Path) -> list[Probe]:
    base = Path(__file__).resolve().parents[1] / "fixtures" / "limits" / "default.toml"
    text = base.read_text()
    cases = {
        "not TOML": "this is = not [toml",
        "empty": "",
        "non-UTF-8": None,
        "format station-limits/99": re.sub(r'^format = ".*"$', 'format = "station-limits/99"', text, count=1,
                                           flags=re.M),
        "no format": "\n".join(line for line in text.splitlines() if not line.startswith("format")),
        "an integer beyond float": re.sub(r"^(\w+) = \d+\.\d+", r"\1 = " + "9" * 400, text, count=1, flags=re.M),
        "a range reversed": re.sub(r"^scale = \[([0-9.]+), ([0-9.]+)\]", r"scale = [\2, \1]", text, count=1,
                                   flags=re.M),
        "a number as text": re.sub(r"^(\w+) = \d+\.\d+", r'\1 = "three"', text, count=1, flags=re.M),
        "unknown key": text + "\n[product.extra]\nfoo = 1\n",
    }
    out = []
    for i, (name, content) in enumerate(cases.items()):
        path = w / f"l_{i}.toml"
        if content is None:
            path.write_bytes(b"version = \xff\xfe\n")
        else:
            path.write_text(content)
        out.append(Probe("limits TOML", name, ["diagnose", str(good), "--limits", str(path)]))
    out.append(Probe("limits TOML", "missing file", ["diagnose", str(good), "--limits", str(w / "none.toml")]))
    return out


def imucal_probes(w: Path) -> list[Probe]:
    csv, sections = REAL / "example_ferraris_session.csv", REAL / "example_ferraris_session_list.json"
    good = json.loads(sections.read_text())

    def with_sections(name: str, change: Callable[[dict], object] | None = None, raw: str | None = None) -> Probe:
        path = w / f"i_{abs(hash(name)) % 10**8}.json"
        if raw is not None:
            path.write_text(raw)
        else:
            d = json.loads(json.dumps(good))
            if change is not None:
                change(d)
            path.write_text(json.dumps(d))
        return Probe("imucal import", name, ["import", "imucal", str(csv), "--segments", str(path),
                                            "-o", str(w / "imported.csv")])

    def swap(a: str, b: str) -> Callable[[dict], None]:
        def f(d: dict) -> None:
            d[a], d[b] = d[b], d[a]
        return f

    out = [
        with_sections("x_p / x_a swapped", swap("x_p", "x_a")),
        with_sections("z_p / z_a swapped", swap("z_p", "z_a")),
        with_sections("x_rot / y_rot swapped", swap("x_rot", "y_rot")),
        with_sections("y_rot / z_rot swapped", swap("y_rot", "z_rot")),
        with_sections("unknown label", lambda d: d.update(w_p={"start": 0, "end": 10})),
        with_sections("range beyond the file", lambda d: d.update(x_p={"start": 0, "end": 10**9})),
        with_sections("overlapping sections", lambda d: d.update(x_a=dict(d["x_p"]))),
        with_sections("start as text", lambda d: d.update(x_p={"start": "a", "end": 10})),
        with_sections("not JSON", raw="{"),
        with_sections("a JSON list", raw="[]"),
        Probe("imucal import", "annotated, turns the other way round (default -360)",
              ["import", "imucal", str(REAL / "annotated_session.csv"), "-o", str(w / "imported.csv")]),
        Probe("imucal import", "--expected-angle 0", ["import", "imucal", str(csv), "--segments", str(sections),
                                                      "--expected-angle", "0", "-o", str(w / "imported.csv")]),
        Probe("imucal import", "-o /nonexistent/x.csv", ["import", "imucal", str(csv), "--segments", str(sections),
                                                         "-o", "/nonexistent/x.csv"]),
        Probe("imucal import", "-o DIR", ["import", "imucal", str(csv), "--segments", str(sections), "-o", str(w)]),
        Probe("imucal import", "-o the input CSV", ["import", "imucal", str(csv), "--segments", str(sections),
                                                    "-o", str(csv)]),
        Probe("imucal import", "a session CSV v1 as imucal CSV", ["import", "imucal", str(w / "good.csv"),
                                                                  "-o", str(w / "imported.csv")]),
    ]
    one = w / "i_one.json"
    one.write_text(json.dumps({"x_p": {"start": 1, "end": 1271}}))
    one_csv = w / "one_section.csv"
    subprocess.run([*STATION, "import", "imucal", str(csv), "--segments", str(one), "-o", str(one_csv)],
                   capture_output=True)
    out.append(Probe("imucal import", "fit of {x_p: 1..1271} only", ["fit", str(one_csv)]))
    return out


def option_probes(w: Path) -> list[Probe]:
    return [
        Probe("options", "simulate --seed -1", ["simulate", "-o", str(w / "x.csv"), "--seed", "-1"]),
        Probe("options", "demo --seed -1", ["demo", "--seed", "-1"]),
        Probe("options", "sim --seed -1", ["sim", "--seed", "-1"]),
        Probe("options", "sim --port 99999", ["sim", "--port", "99999"]),
        Probe("options", "sim --port -5", ["sim", "--port", "-5"]),
        Probe("options", "simulate -o /nonexistent/x.csv", ["simulate", "-o", "/nonexistent/x.csv"]),
        Probe("options", "simulate -o DIR", ["simulate", "-o", str(w)]),
        Probe("options", "simulate --sample-rate 0", ["simulate", "-o", str(w / "x.csv"), "--sample-rate", "0"]),
        Probe("options", "simulate --effect nonsense", ["simulate", "-o", str(w / "x.csv"), "--effect", "nonsense"]),
    ]


def database_probes(w: Path) -> list[Probe]:
    def make_store(path: Path) -> None:  # a read-only command no longer creates one
        subprocess.run([sys.executable, "-c", "import sys; from station.store.db import open_database; "
                        "open_database(sys.argv[1]).close()", f"sqlite:///{path}"], check=True, capture_output=True)

    newer = w / "newer.sqlite"
    make_store(newer)
    with sqlite3.connect(newer) as c:
        c.execute("UPDATE alembic_version SET version_num = '9999_future'")
    foreign = w / "foreign.sqlite"
    with sqlite3.connect(foreign) as c:
        c.execute("CREATE TABLE IF NOT EXISTS customers (id INTEGER PRIMARY KEY, name TEXT)")
    corrupt = w / "corrupt.sqlite"
    make_store(corrupt)
    data = bytearray(corrupt.read_bytes())
    for i in range(200, len(data), 7):
        data[i] = 0xA5
    corrupt.write_bytes(bytes(data))
    text_file = w / "notes.sqlite"
    text_file.write_text("not a database\n" * 100)
    urls = {
        "schema from a newer version": f"sqlite:///{newer}",
        "foreign SQLite file": f"sqlite:///{foreign}",
        "corrupt file": f"sqlite:///{corrupt}",
        "text file": f"sqlite:///{text_file}",
        "a directory": f"sqlite:///{w}",
        "mysql://": "mysql://user@localhost/db",
        "not a URL": "::::",
        "missing directory": "sqlite:////nonexistent/dir/x.sqlite",
    }
    out = []
    for name, url in urls.items():
        out.append(Probe("databases", f"units list: {name}", ["units", "list", "--db", url]))
        out.append(Probe("databases", f"units show: {name}", ["units", "show", "X", "--db", url]))
        out.append(Probe("databases", f"eeprom image: {name}", ["eeprom", "image", "X", "-o", str(w / "i.bin"),
                                                                 "--db", url]))
    return out

def _tmpfs(w: Path, name: str, size: str = "2m") -> Path | None:
    """A small file system mounted for the run (root only; None elsewhere: those probes are left out)."""
    mnt = w / name
    mnt.mkdir(exist_ok=True)
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)],
                                          capture_output=True).returncode != 0:
        print(f"note: no tmpfs for {name} (needs root): its probes are left out", file=sys.stderr)
        return None
    atexit.register(subprocess.run, ["umount", "-l", str(mnt)], check=False)
    return mnt


def _fill(directory: Path) -> None:
    with contextlib.suppress(OSError), (directory / "filler").open("wb") as f:
        while True:
            f.write(b"\0" * 65536)
            f.flush()


def _mentions(*words: str) -> Callable[[Outcome], str | None]:
    """A clean refusal must also name the cause (e.g. 'locked', 'full'): else it is silently wrong."""
    def judge(o: Outcome) -> str | None:
        text = (o.stderr + o.stdout).lower()
        if o.code in (1, 2, 3) and "Traceback" not in o.stderr and not all(w in text for w in words):
            return "silently wrong"
        return None
    return judge


def argument_probes(w: Path, good: Path) -> list[Probe]:
    """Every URL, path and size argument checked before anything starts; error lines cut to a readable length."""
    a = "a" * 5000
    regular = w / "regular-file"
    regular.write_text("x")
    db = f"sqlite:///{w / 'args.sqlite'}"
    run = ["run", "--sensor", "serial:///dev/null", "--db", db]
    probes = [
        Probe("arguments", "run --rig modbus-tcp://127.0.0.1:99999", [*run, "--rig", "modbus-tcp://127.0.0.1:99999"]),
        Probe("arguments", "run --rig modbus-tcp://127.0.0.1:65536", [*run, "--rig", "modbus-tcp://127.0.0.1:65536"]),
        Probe("arguments", "run --rig modbus-tcp://[::1", [*run, "--rig", "modbus-tcp://[::1"]),
        Probe("arguments", "run --rig of 3000 characters", [*run, "--rig", "modbus-tcp://" + "h" * 3000]),
        Probe("arguments", "run --sensor with a control character",
              ["run", "--rig", "modbus-tcp://127.0.0.1:1502", "--sensor", "serial:///dev/tty\x01S0", "--db", db]),
        Probe("arguments", "run --chamber modbus-tcp://h:70000",
              [*run, "--rig", "modbus-tcp://127.0.0.1:1502", "--chamber", "modbus-tcp://h:70000"]),
        Probe("arguments", "units list --db postgresql://[::1", ["units", "list", "--db", "postgresql://[::1"]),
        Probe("arguments", "units list --db sqlite:///<5000 characters>", ["units", "list", "--db", f"sqlite:///{a}"]),
        Probe("arguments", "run --db sqlite:///<5000 characters>",
              ["run", "--rig", "modbus-tcp://127.0.0.1:1502", "--sensor", "serial:///dev/null", "--db",
               f"sqlite:///{a}"]),
        Probe("arguments", "simulate -o /proc/x.csv", ["simulate", "-o", "/proc/x.csv"]),
        Probe("arguments", "simulate -o under a regular file", ["simulate", "-o", str(regular / "x.csv")]),
        Probe("arguments", "simulate -o <5000 characters>", ["simulate", "-o", str(w / f"{a}.csv")]),
        Probe("arguments", "run --out under a regular file",
              [*run, "--rig", "modbus-tcp://127.0.0.1:1502", "--out", str(regular / "sub")], timeout_s=60),
        Probe("arguments", "run --out /proc/x", [*run, "--rig", "modbus-tcp://127.0.0.1:1502", "--out", "/proc/x"],
              timeout_s=60),
    ]
    text = good.read_text()
    cr = w / "cr-only.csv"
    cr.write_text(text.replace("\n", "\r"))
    big_field = w / "ten-mb-field.csv"
    lines = text.split("\n")
    k = next(i for i, line in enumerate(lines) if line[:1].isdigit())
    lines[k] = "x" * 10_000_000 + lines[k][lines[k].index(","):]
    big_field.write_text("\n".join(lines))
    negative = w / "negative-time.csv"
    out = []
    for line in text.split("\n"):
        if line[:1].isdigit():
            t, rest = line.split(",", 1)
            line = f"{float(t) - 1000.0:.6f},{rest}"
        out.append(line)
    negative.write_text("\n".join(out))
    probes += [
        Probe("arguments", "fit: CR-only line endings (11 MB line)", ["fit", str(cr)]),
        Probe("arguments", "fit: a 10 MB field", ["fit", str(big_field)]),
        Probe("arguments", "fit: negative time stamps", ["fit", str(negative)], judge=_mentions("time")),
    ]
    full = _tmpfs(w, "full-out")
    if full is not None:
        _fill(full)
        probes.append(Probe("arguments", "simulate -o on a full disk", ["simulate", "-o", str(full / "x.csv")],
                            judge=_mentions("full")))
    return probes


def store_probes(w: Path) -> list[Probe]:
    """Databases that keep nothing refused for writing; a locked database waited for, then one line, exit 2; a full
    disk named as such."""
    rig = ["--rig", "modbus-tcp://127.0.0.1:1502", "--sensor", "serial:///dev/null"]
    probes = [
        Probe("store", "run --db sqlite:///:memory:", ["run", *rig, "--db", "sqlite:///:memory:"],
              judge=_mentions("keeps no records")),
        Probe("store", "run --db sqlite:// (a temporary file SQLite deletes)", ["run", *rig, "--db", "sqlite://"],
              judge=_mentions("keeps no records")),
        Probe("store", "units disposition --db sqlite:///:memory:",
              ["units", "disposition", "X", "retest", "--operator", "a", "--reason", "b", "--db",
               "sqlite:///:memory:"], judge=_mentions("keeps no records")),
        Probe("store", "eeprom write --db sqlite:///:memory:",
              ["eeprom", "write", "SIM-000003", "--sensor", "serial:///dev/null", "--params", str(w / "good.json"),
               "--db", "sqlite:///:memory:"]),
    ]
    locked = w / "locked.sqlite"
    subprocess.run([sys.executable, "-c", "import sys; from station.store.db import open_database; "
                    "from station.store.recorder import record_eeprom_write; db = open_database(sys.argv[1]); "
                    "record_eeprom_write(db, 'U1', '0' * 64, attempts=1, read_back_ok=True)", f"sqlite:///{locked}"],
                   check=True, capture_output=True)

    @contextlib.contextmanager
    def held() -> Iterator[None]:
        holder = sqlite3.connect(locked, isolation_level=None)
        holder.execute("BEGIN EXCLUSIVE")
        try:
            yield
        finally:
            holder.execute("ROLLBACK")
            holder.close()

    env = {"STATION_DB_LOCK_TIMEOUT_S": "2"}
    probes += [
        Probe("store", "units disposition on a locked database",
              ["units", "disposition", "U1", "retest", "--operator", "a", "--reason", "b", "--db", f"sqlite:///{locked}"],
              env=env, around=held, timeout_s=60, judge=_mentions("locked", "waited 2 s")),
        Probe("store", "run on a locked database (the rig lock's row)", ["run", *rig, "--db", f"sqlite:///{locked}"],
              env=env, around=held, timeout_s=60, judge=_mentions("locked")),
    ]
    full = _tmpfs(w, "full-db", "3m")
    if full is not None:
        url = f"sqlite:///{full / 's.sqlite'}"
        subprocess.run([sys.executable, "-c", "import sys; from station.store.db import open_database; "
                        "from station.store.recorder import record_eeprom_write; db = open_database(sys.argv[1]); "
                        "record_eeprom_write(db, 'U1', '0' * 64, attempts=1, read_back_ok=True)", url],
                       check=True, capture_output=True)
        _fill(full)
        probes.append(Probe("store", "units disposition on a full disk",
                            ["units", "disposition", "U1", "retest", "--operator", "a", "--reason", "b", "--db", url],
                            judge=_mentions("full")))
    return probes


#: Where a provisioning may die: around each of the 16 page writes and each record.
CRASH_POINTS = ([f"page:{k}:{when}" for k in range(16) for when in ("before", "after")]
                + [f"{name}:{when}" for name in ("intend", "written", "verified") for when in ("before", "after")])


def _agreement(o: Outcome) -> str | None:
    if o.code == 0:
        return "clean"
    return "lost data" if o.code == 4 else "traceback"


def provisioning_probes(w: Path, legacy: bool) -> list[Probe]:
    """A process killed at every step of an EEPROM write; the next start must find database and sensor agreeing."""
    script = Path(__file__).resolve().with_name("provision_crash.py")
    mode = "crash-legacy" if legacy else "crash"
    points = ["written:before"] if legacy else CRASH_POINTS
    out = []
    for k, point in enumerate(points):
        d = w / f"crash-{k}"
        shell = (f'"{sys.executable}" "{script}" crash "{d}" none && "{sys.executable}" "{script}" {mode} "{d}" '
                 f'{point}; "{sys.executable}" "{script}" check "{d}"')
        out.append(Probe("provisioning", f"killed at {point}", [], cmd=["sh", "-c", shell], judge=_agreement,
                         timeout_s=120))
    shell = f'"{sys.executable}" "{script}" verify-fault "{w / "verify-fault"}"'
    out.append(Probe("provisioning", "rig fault during on-rig verification (2 units)", [], cmd=["sh", "-c", shell],
                     judge=_agreement, timeout_s=300))
    return out


def memory_probes(w: Path) -> list[Probe]:
    """Bounded memory: endless and huge inputs refused quickly (4 GB address-space limit, 20 s)."""
    sparse = w / "sparse-2g.csv"
    with sparse.open("wb") as f:
        f.truncate(2 << 30)
    return [
        Probe("memory", "fit /dev/zero", ["fit", "/dev/zero"], timeout_s=20, limit_memory=True),
        Probe("memory", "fit a 2 GB sparse file", ["fit", str(sparse)], timeout_s=20, limit_memory=True),
    ]


FAMILIES = ("session", "params", "eeprom", "limits", "imucal", "options", "databases", "arguments", "store",
            "provisioning", "memory")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--legacy", action="store_true", help="provisioning in the order before write-ahead")
    args = ap.parse_args()
    w = args.workdir or Path(tempfile.mkdtemp(prefix="bad-inputs-"))
    w.mkdir(parents=True, exist_ok=True)
    good = w / "good.csv"
    subprocess.run([*STATION, "simulate", "-o", str(good), "--seed", "3"], check=True, capture_output=True)
    fitted = subprocess.run([*STATION, "fit", str(good), "--json"], check=True, capture_output=True, text=True)
    (w / "good.json").write_text(fitted.stdout)
    params = json.loads(fitted.stdout)
    chosen = args.families.split(",")
    probes: list[Probe] = []
    for name, make in (
        ("session", lambda: session_probes(w, good)),
        ("params", lambda: params_probes(w, good, params)),
        ("eeprom", lambda: eeprom_probes(w, w / "good.json")),
        ("limits", lambda: limits_probes(w, good)),
        ("imucal", lambda: imucal_probes(w)),
        ("options", lambda: option_probes(w)),
        ("databases", lambda: database_probes(w)),
        ("arguments", lambda: argument_probes(w, good)),
        ("store", lambda: store_probes(w)),
        ("provisioning", lambda: provisioning_probes(w, args.legacy)),
        ("memory", lambda: memory_probes(w)),
    ):
        if name in chosen:
            probes += make()
    outcomes = []
    for probe in probes:
        o = run(probe, w)
        outcomes.append(o)
        if args.verbose or o.verdict != "clean":
            lines = o.stderr.strip().splitlines() or [""]
            last = lines[-1][:160] + (f" ... ({len(lines[-1])} characters)" if len(lines[-1]) > 160 else "")
            print(f"[{o.verdict}] {probe.family}: {probe.name} (exit {o.code}) {last}", file=sys.stderr)
    families: dict[str, list[Outcome]] = {}
    for o in outcomes:
        families.setdefault(o.probe.family, []).append(o)
    print("| family | probes | " + " | ".join(VERDICTS) + " |")
    print("| --- | --- | " + " | ".join("---" for _ in VERDICTS) + " |")
    totals = [0] * (1 + len(VERDICTS))
    for family, items in families.items():
        row = [len(items), *(sum(o.verdict == v for o in items) for v in VERDICTS)]
        totals = [a + b for a, b in zip(totals, row, strict=True)]
        print(f"| {family} | " + " | ".join(map(str, row)) + " |")
    print("| all | " + " | ".join(map(str, totals)) + " |")
    if args.workdir is None:
        shutil.rmtree(w, ignore_errors=True)
    sys.exit(0 if totals[1] == totals[0] else 1)


if __name__ == "__main__":
    main()
