"""The diagnosis's locator on the real recordings (``/work/shared/real``, read-only): what it locates, against which
sensor class.

Per recording (imucal's Ferraris session through the rig path; OpenAXES's hand-held log through the rig-free
path, with each of its two accelerometers) and per sensor class (``--limits`` files; ``table1`` = the station's
own Table 1 class): the findings, and every ``unexplained`` entry (sensor, axes, segment kinds, covariate, how far
the free fit stretched eq. 3's drift noise over the class's bound: ``q/class``).

Run: ``python benchmarks/bench_diagnose_real.py [--limits FILE ...]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from realdata import IMUCAL_FERRARIS, IMUCAL_SECTIONS, OPENAXES_LOG, real_path

from station.diagnose import diagnose
from station.diagnose.locator import TABLE1_DRIFT, DriftClass
from station.kernel.limits_file import load_limits
from station.session.imucal_import import import_imucal_ferraris
from station.session.multipos_import import import_openaxes


def recordings() -> dict[str, object]:
    out: dict[str, object] = {}
    if real_path(IMUCAL_FERRARIS).is_file():
        out["imucal ferraris"] = import_imucal_ferraris(str(real_path(IMUCAL_FERRARIS)),
                                                        str(real_path(IMUCAL_SECTIONS)))
    if real_path(OPENAXES_LOG).is_file():
        for accel in ("adxl355", "bmi160"):
            out[f"openaxes {accel}"] = import_openaxes(str(real_path(OPENAXES_LOG)), accel=accel)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limits", nargs="*", default=[], help="limits files of other sensor classes")
    ap.add_argument("--only", default="", help="run only recordings whose name holds this")
    args = ap.parse_args()
    classes: list[tuple[str, DriftClass, dict | None]] = [("table1", TABLE1_DRIFT, None)]
    for f in args.limits:
        lim = load_limits(f)
        classes.append((os.path.basename(f), DriftClass.from_limits(lim), dict(lim.correlation_time_s) or None))
    for name, session in recordings().items():
        if args.only and args.only not in name:
            continue
        for cname, cls, tc in classes:
            t0 = time.process_time()
            rep = diagnose(session, drift_class=cls, warmup_tc_s=tc).report.to_json()  # type: ignore[arg-type]
            dt = time.process_time() - t0
            named = sorted(f"{f['effect']}:{f['sensor']}" for f in rep["findings"])
            print(f"{name} [{cname}] ({dt:.1f} s CPU): findings {named or '-'}")
            for u in rep["unexplained"]:
                loc = u.get("locator") or {}
                q = ", ".join(f"{v:.3g}" for v in loc.get("q_over_class", []))
                emp = ", ".join(f"{e['axis']} {e['heldout_improvement']:.2f}" for e in u.get("empirical", []))
                print(f"    unexplained {u['sensor']} {''.join(u['axes'])} {'/'.join(u['segment_kinds'])}: "
                      f"{u['covariate'][:90]} | q/class {q or '-'} | held-out {emp or '-'}")
            if not rep["unexplained"]:
                print("    nothing located")


if __name__ == "__main__":
    main()
