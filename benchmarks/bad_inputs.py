"""Probe the command line with bad inputs, as a new user would, and print the README table (issue 15).

Each family generates bad inputs from one good simulated recording (and the shared real imucal
recording, read from its path), runs the ``station`` command on each in a subprocess and sorts the
outcome:

* refused cleanly: exit code 1, 2 or 3 (3: the fit contradicts its recording), no traceback, and
  stderr holds one ``error:`` line (or the command line's usage message for a bad option);
* traceback: anything else that is not exit 0 (a Python traceback, a LAPACK message, several lines);
* silently accepted: exit 0 on an input that is wrong.

    python benchmarks/bad_inputs.py [--families session,params,...] [--workdir DIR] [--verbose]

Every probe is a bad input, so the targets are 0 tracebacks and 0 silently accepted.
"""

from __future__ import annotations

import argparse
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
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

REAL = Path(os.environ.get("STATION_SHARED", Path(__file__).resolve().parents[2] / "shared")) / "real" / "imucal"
if not REAL.is_dir():
    REAL = Path("/work/shared/real/imucal")
STATION = [str(Path(sys.executable).with_name("station"))]


@dataclass
class Probe:
    family: str
    name: str
    args: list[str]


@dataclass
class Outcome:
    probe: Probe
    code: int
    stderr: str
    stdout: str

    @property
    def verdict(self) -> str:
        text = self.stderr + self.stdout
        if "Traceback" in text or "On entry to" in text:
            return "traceback"
        if self.code == 0:
            return "silently accepted"
        usage = "Usage:" in self.stderr
        lines = [line for line in self.stderr.splitlines() if line.strip()]
        if self.code in (1, 2, 3) and (usage or (len(lines) == 1 and lines[0].startswith("error: "))):
            return "refused cleanly"
        return "traceback"


def run(probe: Probe, cwd: Path) -> Outcome:
    env = {**os.environ, "STATION_DB": f"sqlite:///{cwd / 'probe.sqlite'}", "COLUMNS": "200"}
    done = subprocess.run([*STATION, *probe.args], cwd=cwd, capture_output=True, text=True, env=env, timeout=600,
                          errors="replace")
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
        variant("format v2", set_("format", value="station-params/2")),
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
    newer = w / "newer.sqlite"
    subprocess.run([*STATION, "units", "list", "--db", f"sqlite:///{newer}"], check=True, capture_output=True)
    with sqlite3.connect(newer) as c:
        c.execute("UPDATE alembic_version SET version_num = '9999_future'")
    foreign = w / "foreign.sqlite"
    with sqlite3.connect(foreign) as c:
        c.execute("CREATE TABLE IF NOT EXISTS customers (id INTEGER PRIMARY KEY, name TEXT)")
    corrupt = w / "corrupt.sqlite"
    subprocess.run([*STATION, "units", "list", "--db", f"sqlite:///{corrupt}"], check=True, capture_output=True)
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


FAMILIES = ("session", "params", "eeprom", "limits", "imucal", "options", "databases")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--verbose", action="store_true")
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
    ):
        if name in chosen:
            probes += make()
    outcomes = []
    for probe in probes:
        o = run(probe, w)
        outcomes.append(o)
        if args.verbose or o.verdict != "refused cleanly":
            last = (o.stderr.strip().splitlines() or [""])[-1][:160]
            print(f"[{o.verdict}] {probe.family}: {probe.name} (exit {o.code}) {last}", file=sys.stderr)
    families: dict[str, list[Outcome]] = {}
    for o in outcomes:
        families.setdefault(o.probe.family, []).append(o)
    print("| family | inputs tried | refused cleanly | tracebacks | silently accepted |")
    print("| --- | --- | --- | --- | --- |")
    totals = [0, 0, 0, 0]
    for family, items in families.items():
        row = [len(items), *(sum(o.verdict == v for o in items)
                             for v in ("refused cleanly", "traceback", "silently accepted"))]
        totals = [a + b for a, b in zip(totals, row, strict=True)]
        print(f"| {family} | " + " | ".join(map(str, row)) + " |")
    print("| all | " + " | ".join(map(str, totals)) + " |")
    if args.workdir is None:
        shutil.rmtree(w, ignore_errors=True)
    sys.exit(0 if totals[2] == totals[3] == 0 else 1)


if __name__ == "__main__":
    main()
