"""OpenAXES round trip: ``station fit`` -> ``station export`` -> the exported files read back as imu_tk and OpenAXES
read them -> scored on the recording's own still intervals against the published coefficients.

    python benchmarks/openaxes_roundtrip.py [--accel bmi160|adxl355] [--folds 5]

Reads ../shared/real/openaxes/ ($STATION_REAL overrides ../shared/real; never copied into the repo). In a temporary
folder it runs the station's own commands, as a user would:

    station import openaxes LOG.csv --accel bmi160 --gravity 9.81744 -o s.csv
    station fit s.csv --json > s.params.json          (rig-free, chosen automatically)
    station export s.params.json --format imu-tk -o s  (s_acc.calib, s_gyro.calib)
    station export s.params.json --format openaxes -o s.openaxes.txt

then reads the files back with :mod:`station.fit.export_readback` (imu_tk's ``CalibratedTriad_::load`` and
``unbiasNormalize``; OpenAXES's list: accel ``TK raw - b``, gyro ``M (raw - b)``) and scores, over the still
segments of the import (each segment's raw mean, as the published figures were computed):

* the gravity-norm RMS, ``| corrected mean | - g`` (mm/s^2), at 9.81744 (the fits' and the published g) and
  9.8128 (Hannover);
* the gyro's still rate: RMS over the still segments and axes of the corrected mean rate (deg/s; the Earth
  rate, <= 0.004 deg/s, is left in);
* held out (``--folds`` folds, the station's leave-poses-out scheme: every k-th pose held out, the initial
  still never): per fold the held-out poses are turned into moves of the session, the station's rig-free fit
  (as ``station fit`` runs it, without its own cross-validation) and the same export functions as
  ``station export`` give that fold's files, read back the same way, scored on the held-out poses. The published
  coefficients come from one fit on all poses, so they have no held-out figure; the published model (imu_tk's)
  re-fitted by us in the same folds (``compare_openaxes.imu_tk_cross_validation``) stands in for it.

"in memory" is the station's parameter set applied directly with the bias an export holds (b_stat; where b_stat
is not determined, the bias at the end of the recording: :meth:`ParameterSet.constant_bias_values`): the round
trip must reproduce it to the files' rounding. "eq. 3" is the station's own score with its drift model
(``quality.rig_free``), which no export can carry.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from compare_openaxes import G_LOCAL, G_TK, LOG, PUBLISHED, imu_tk_cross_validation

from station.fit.export import imu_tk_calib_files, openaxes_text
from station.fit.export_readback import read_imu_tk_calib, read_openaxes_list
from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free
from station.kernel.parameters import ParameterSet
from station.session import read_session
from station.session.model import Kind, Session

DEG = float(np.degrees(1.0))
WHICH = {"adxl355": 0, "bmi160": 1}


def station(*args: str) -> str:
    """Run ``station ARGS`` (this checkout first on the path); its stdout."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    exe = Path(sys.executable).with_name("station")
    out = subprocess.run([str(exe), *args], env=env, check=True, capture_output=True, text=True)
    return out.stdout


def still_means(session: Session) -> tuple[list, np.ndarray, np.ndarray]:
    """The still segments and their raw accelerometer and gyro means."""
    still = session.segments_of(Kind.REST, Kind.POSE)
    acc = np.array([session.accel_mps2[s.start:s.stop].mean(axis=0) for s in still])
    gyr = np.array([session.gyro_radps[s.start:s.stop].mean(axis=0) for s in still])
    return still, acc, gyr


def norm_rms(corrected: np.ndarray, g: float) -> float:
    """Gravity-norm RMS (mm/s^2) of corrected still means."""
    return float(1e3 * np.sqrt(np.mean((np.linalg.norm(corrected, axis=1) - g) ** 2)))


def rate_rms(corrected: np.ndarray) -> float:
    """RMS (deg/s) of the corrected still-mean rates over segments and axes."""
    return float(DEG * np.sqrt(np.mean(corrected**2)))


def in_memory(params: ParameterSet) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(accel M^-1, accel b, gyro M^-1, gyro b) with the bias an export holds."""
    p = params.constant_bias_values()[0]
    return (np.linalg.inv(p.accel.misalignment), np.asarray(p.accel.bias_static),
            np.linalg.inv(p.gyro.misalignment), np.asarray(p.gyro.bias_static))


def scores(params: ParameterSet, calib: dict[str, str], listing: str, acc: np.ndarray, gyr: np.ndarray,
           tmp: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Corrected (accel, gyro) still means: in memory, from imu_tk's files, from the OpenAXES list."""
    ai, ab, gi, gb = in_memory(params)
    for name, text in calib.items():
        (tmp / f"{name}.calib").write_text(text, encoding="ascii")
    tk_a, tk_g = read_imu_tk_calib(tmp / "acc.calib"), read_imu_tk_calib(tmp / "gyro.calib")
    oa = read_openaxes_list(listing)
    return {
        "in memory (M, b of the set)": ((acc - ab) @ ai.T, (gyr - gb) @ gi.T),
        "imu_tk files read back": (tk_a.correct(acc), tk_g.correct(gyr)),
        "OpenAXES list read back": (oa.correct_accel(acc), oa.correct_gyro(gyr)),
    }


def held_out_session(session: Session, held: np.ndarray, still: list) -> Session:
    """The session with the held-out still segments turned into moves (the fit does not see them as poses)."""
    kind = session.kind.copy()
    for s, h in zip(still, held, strict=True):
        if h:
            kind[s.start:s.stop] = Kind.MOVE
    return replace(session, kind=kind)


#: the two ways of fitting: ``station fit`` as it runs by default, and with imu_tk's model (no accelerometer drift)
VARIANTS = {"station fit (eq. 3 drift)": (), "station fit --no-accel-drift (imu_tk's model)": ("--no-accel-drift",)}


def round_trip(tmp: Path, csv: Path, name: str, flags: tuple[str, ...]) -> tuple[ParameterSet, dict[str, str], str]:
    """``station fit`` with ``flags``, both exports; the set and the exported files' texts."""
    stem = tmp / ("drift" if not flags else "nodrift")
    text = station("fit", str(csv), "--json", *flags)
    stem.with_suffix(".params.json").write_text(text, encoding="utf-8")
    station("export", str(stem.with_suffix(".params.json")), "--format", "imu-tk", "-o", str(stem))
    station("export", str(stem.with_suffix(".params.json")), "--format", "openaxes", "-o",
            str(stem.with_suffix(".openaxes.txt")))
    calib = {"acc": Path(f"{stem}_acc.calib").read_text(encoding="ascii"),
             "gyro": Path(f"{stem}_gyro.calib").read_text(encoding="ascii")}
    return ParameterSet.from_json(text), calib, stem.with_suffix(".openaxes.txt").read_text(encoding="ascii")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--accel", default="bmi160", choices=sorted(WHICH))
    ap.add_argument("--folds", type=int, default=5)
    args = ap.parse_args()
    if not LOG.is_file():
        print(f"skipped: {LOG} not found (set STATION_REAL to the folder holding openaxes/)")
        return 0
    cpu0 = time.process_time()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        csv = tmp / "s.csv"
        station("import", "openaxes", str(LOG), "--accel", args.accel, "--gravity", repr(G_TK), "-o", str(csv))
        session = read_session(csv)
        still, acc, gyr = still_means(session)
        is_pose = np.array([s.kind == Kind.POSE for s in still])
        order = np.cumsum(is_pose) - 1
        pub = read_openaxes_list(" ".join(repr(float(v)) for v in PUBLISHED))
        pub_a = pub.correct_accel(acc, WHICH[args.accel])
        print(f"OpenAXES {LOG.name}, {args.accel}: {len(session)} samples, {len(still)} still segments "
              f"({int(is_pose.sum())} poses)")
        table = [("raw (identity, no bias)", acc, gyr, math.nan),
                 ("published coefficients (OpenAXES list)", pub_a, pub.correct_gyro(gyr), math.nan)]
        own: list[str] = []
        checks: list[str] = []
        for name, flags in VARIANTS.items():
            params, calib, listing = round_trip(tmp, csv, name, flags)
            rows = scores(params, calib, listing, acc, gyr, tmp)
            own.append(f"{name}: exported bias: {'; '.join(params.constant_bias_values()[1]) or 'b_stat'}")
            q = params.quality.rig_free or {}
            if q:
                own.append(f"{name}: its own score with its model {1e3 * q['accel_norm_rms_mps2']:.3f} fitted, "
                           f"{1e3 * q['cross_validation']['accel_norm_rms_mps2']:.3f} held out (mm/s^2)")
            # held out: per fold the fit without the fold's poses, exported and read back the same way
            err = {k: np.full(len(still), np.nan) for k in rows}
            for f in range(args.folds):
                held = is_pose & (order % args.folds == f)
                fold = fit_rig_free(held_out_session(session, held, still),
                                    RigFreeOptions(cv_folds=0, accel_drift=not flags))
                fold_rows = scores(fold, imu_tk_calib_files(fold), openaxes_text([fold]), acc[held], gyr[held], tmp)
                for k, (a, _) in fold_rows.items():
                    err[k][held] = np.linalg.norm(a, axis=1) - G_TK
            ref = rows["in memory (M, b of the set)"][0]
            for k, (a, w) in rows.items():
                e = err[k][is_pose]
                table.append((f"{name}: {k}", a, w, float(1e3 * np.sqrt(np.mean(e**2)))))
                if k != "in memory (M, b of the set)":
                    dev = float(np.max(np.abs(np.linalg.norm(a, axis=1) - np.linalg.norm(ref, axis=1))))
                    checks.append(f"{name}, {k}: largest per-segment norm difference from in memory "
                                  f"{1e3 * dev:.2e} mm/s^2")
        tk = imu_tk_cross_validation(session, folds=args.folds)
        print("\n| calibration | gravity-norm RMS @9.81744, mm/s^2 | @9.8128 | held out @9.81744 "
              f"({args.folds} folds) | gyro still rate RMS, deg/s |")
        print("| --- | --- | --- | --- | --- |")
        for name, a, w, held_out in table:
            cell = f"{held_out:.3f}" if math.isfinite(held_out) else "-"
            print(f"| {name} | {norm_rms(a, G_TK):.3f} | {norm_rms(a, G_LOCAL):.3f} | {cell} | {rate_rms(w):.4f} |")
        print(f"| imu_tk's model re-fitted by us per fold (the published model's held-out stand-in) | "
              f"{1e3 * np.sqrt(np.mean(tk['norm_fitted']**2)):.3f} | | "
              f"{1e3 * np.sqrt(np.mean(tk['norm_held_out']**2)):.3f} | |")
        print()
        for line in own + checks:
            print(line)
        print(json.dumps({"cpu_s_this_process": round(time.process_time() - cpu0, 1),
                          "cpu_s_station_commands": round(sum(os.times()[2:4]), 1)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
