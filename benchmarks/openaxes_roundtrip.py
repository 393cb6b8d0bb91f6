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
        text = station("fit", str(csv), "--json")
        (tmp / "s.params.json").write_text(text, encoding="utf-8")
        station("export", str(tmp / "s.params.json"), "--format", "imu-tk", "-o", str(tmp / "s"))
        station("export", str(tmp / "s.params.json"), "--format", "openaxes", "-o", str(tmp / "s.openaxes.txt"))
        params = ParameterSet.from_json(text)
        session = read_session(csv)
        still, acc, gyr = still_means(session)
        calib = {"acc": (tmp / "s_acc.calib").read_text(encoding="ascii"),
                 "gyro": (tmp / "s_gyro.calib").read_text(encoding="ascii")}
        listing = (tmp / "s.openaxes.txt").read_text(encoding="ascii")
        cli_cpu = sum(os.times()[2:4])
        rows = scores(params, calib, listing, acc, gyr, tmp)

        pub = read_openaxes_list(" ".join(f"{v!r}" for v in PUBLISHED))
        rows_all = {"raw (identity, no bias)": (acc, gyr),
                    "published coefficients (OpenAXES list)": (pub.correct_accel(acc, WHICH[args.accel]),
                                                              pub.correct_gyro(gyr)),
                    **{f"station export: {k}": v for k, v in rows.items()}}
        q = params.quality.rig_free or {}
        print(f"OpenAXES {LOG.name}, {args.accel}: {len(session)} samples, {len(still)} still segments "
              f"({sum(s.kind == Kind.POSE for s in still)} poses); fit {params.source.get('method', '')}")
        print(f"exported bias: {'; '.join(params.constant_bias_values()[1]) or 'b_stat on every axis'}")
        print("\n| calibration | gravity-norm RMS @9.81744, mm/s^2 | @9.8128 | gyro still rate RMS, deg/s |")
        print("| --- | --- | --- | --- |")
        for name, (a, w) in rows_all.items():
            print(f"| {name} | {norm_rms(a, G_TK):.3f} | {norm_rms(a, G_LOCAL):.3f} | {rate_rms(w):.4f} |")
        if q:
            print(f"| station, eq. 3 drift (its own score, not exportable) | {1e3 * q['accel_norm_rms_mps2']:.3f} "
                  f"| | |")
        ref = norm_rms(rows["in memory (M, b of the set)"][0], G_TK)
        for k in ("imu_tk files read back", "OpenAXES list read back"):
            dev = float(np.max(np.abs(np.linalg.norm(rows[k][0], axis=1)
                                      - np.linalg.norm(rows["in memory (M, b of the set)"][0], axis=1))))
            print(f"round trip {k}: RMS {norm_rms(rows[k][0], G_TK) - ref:+.2e} mm/s^2 from in memory, "
                  f"largest per-segment norm difference {1e3 * dev:.2e} mm/s^2")

        # --- held out ----------------------------------------------------------------------------------
        is_pose = np.array([s.kind == Kind.POSE for s in still])
        order = np.cumsum(is_pose) - 1
        err: dict[str, np.ndarray] = {k: np.full(len(still), np.nan) for k in rows}
        for f in range(args.folds):
            held = is_pose & (order % args.folds == f)
            fold = fit_rig_free(held_out_session(session, held, still), RigFreeOptions(cv_folds=0))
            fold_rows = scores(fold, imu_tk_calib_files(fold), openaxes_text([fold]), acc[held], gyr[held], tmp)
            for k, (a, _) in fold_rows.items():
                err[k][held] = np.linalg.norm(a, axis=1) - G_TK
        tk = imu_tk_cross_validation(session, folds=args.folds)
        print(f"\nheld out ({args.folds} folds, leave-poses-out; {int(is_pose.sum())} poses), gravity-norm RMS "
              "@9.81744, mm/s^2:")
        print("| calibration | held out | fitted (all poses) |")
        print("| --- | --- | --- |")
        for k in rows:
            e = err[k][is_pose]
            print(f"| station export per fold: {k} | {1e3 * np.sqrt(np.mean(e**2)):.3f} "
                  f"| {norm_rms(rows[k][0][is_pose], G_TK):.3f} |")
        print(f"| imu_tk's model re-fitted per fold (the published model) | "
              f"{1e3 * np.sqrt(np.mean(tk['norm_held_out']**2)):.3f} | "
              f"{1e3 * np.sqrt(np.mean(tk['norm_fitted']**2)):.3f} |")
        if q.get("cross_validation"):
            print(f"| station, eq. 3 drift (its own cross-validation, not exportable) | "
                  f"{1e3 * q['cross_validation']['accel_norm_rms_mps2']:.3f} | {1e3 * q['accel_norm_rms_mps2']:.3f} |")
        pub_a = pub.correct_accel(acc, WHICH[args.accel])
        print(f"| published coefficients (one fit on all poses: no held-out figure) | - | "
              f"{norm_rms(pub_a[is_pose], G_TK):.3f} |")
        print(json.dumps({"cpu_s_this_process": round(time.process_time() - cpu0, 1),
                          "cpu_s_station_commands": round(cli_cpu, 1)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
