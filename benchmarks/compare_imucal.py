"""Our fit against imucal 2.6.0's Ferraris calibration on the real imucal recording.

    python benchmarks/compare_imucal.py [--g-sensitivity]

Reads ../shared/real/imucal/ (never copied into the repo), converts it with the station
importer, fits it, runs imucal's FerrarisCalibration on the same sections, and prints:
gravity norm of each calibrated pose, integrated rotation angles, and the parameter
differences. Units: m/s^2, deg/s, deg.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from station.fit.calibrate import FitOptions, fit_session
from station.kernel.parameters import ParameterSet
from station.session.imucal_import import import_imucal_ferraris
from station.session.model import Session

REAL = Path(os.environ.get("STATION_REAL") or Path(__file__).resolve().parents[2] / "shared" / "real") / "imucal"
CSV = REAL / "example_ferraris_session.csv"
SECTIONS = REAL / "example_ferraris_session_list.json"
RATE_HZ = 102.4
GRAVITY = 9.81  # imucal's default


@dataclass(frozen=True)
class Comparison:
    """Per-pose gravity norms and per-rotation angles for both tools, and parameter pairs."""

    poses: list[tuple[str, float, float]]  # label, ours, imucal (m/s^2)
    rotations: list[tuple[str, float, float]]  # label, ours, imucal (deg, about the rotation axis)
    params: list[tuple[str, np.ndarray, np.ndarray]]  # name, ours, imucal
    ours: ParameterSet


def _sections() -> dict[str, tuple[int, int]]:
    raw = json.loads(SECTIONS.read_text())
    return {k: (int(v["start"]), int(v["end"])) for k, v in raw.items()}


def run_imucal(data: pd.DataFrame) -> object:
    from imucal import FerrarisCalibration, ferraris_regions_from_section_list

    section_list = pd.DataFrame(_sections(), index=["start", "end"]).T
    regions = ferraris_regions_from_section_list(data, section_list)
    return FerrarisCalibration(grav=GRAVITY).compute(regions, RATE_HZ, from_acc_unit="m/s^2", from_gyr_unit="deg/s")


def _our_calibrated(session: Session, p: ParameterSet) -> tuple[np.ndarray, np.ndarray]:
    """Calibrated accel (m/s^2) and gyro (deg/s) sample by sample (no moving average)."""

    def bias(tri: object, t: np.ndarray) -> np.ndarray:
        b = np.asarray(tri.bias_static) + np.zeros((len(t), 3))
        for k in range(3):
            tc = tri.correlation_time_s[k]
            if np.isfinite(tc) and tri.bias_drift[k] != 0:
                b[:, k] += tri.bias_drift[k] * np.exp(-t / tc)
        return b

    t = session.t_s
    acc = (session.accel_mps2 - bias(p.accel, t)) @ np.linalg.inv(p.accel.misalignment).T
    gyr_raw = session.gyro_radps - bias(p.gyro, t) - acc @ np.asarray(p.gyro.g_sensitivity).T
    gyr = gyr_raw @ np.linalg.inv(p.gyro.misalignment).T
    return acc, np.degrees(gyr)


def compare(g_sensitivity: bool = False) -> Comparison:
    data = pd.read_csv(CSV)
    session = import_imucal_ferraris(CSV, SECTIONS, gravity_mps2=GRAVITY, sample_rate_hz=RATE_HZ)
    ours = fit_session(session, FitOptions(g_sensitivity=g_sensitivity))
    cal = run_imucal(data)
    acc_cols, gyr_cols = ["acc_x", "acc_y", "acc_z"], ["gyr_x", "gyr_y", "gyr_z"]
    i_acc, i_gyr = cal.calibrate(data[acc_cols].to_numpy(), data[gyr_cols].to_numpy(), "m/s^2", "deg/s")
    o_acc, o_gyr = _our_calibrated(session, ours)
    sec = _sections()
    poses, rotations = [], []
    for label, (a, b) in sec.items():
        if label.endswith("_rot"):
            axis = "xyz".index(label[0])
            rotations.append((label, float(o_gyr[a:b, axis].sum() / RATE_HZ), float(i_gyr[a:b, axis].sum() / RATE_HZ)))
        else:
            poses.append((label, float(np.linalg.norm(o_acc[a:b].mean(axis=0))),
                          float(np.linalg.norm(i_acc[a:b].mean(axis=0)))))
    params = [
        ("M_a", ours.accel.misalignment, cal.K_a @ cal.R_a),
        ("b_a (m/s^2)", ours.accel.bias_static + ours.accel.bias_drift * 0, cal.b_a),
        ("M_w", ours.gyro.misalignment, cal.K_g @ cal.R_g),
        ("b_w (deg/s)", np.degrees(ours.gyro.bias_static), cal.b_g),
    ]
    if g_sensitivity:
        params.append(("K_ga (deg/s per m/s^2)", np.degrees(ours.gyro.g_sensitivity), cal.K_ga))
    return Comparison(poses=poses, rotations=rotations, params=params, ours=ours)


def main(argv: list[str]) -> None:
    from rich.console import Console
    from rich.table import Table

    c = compare(g_sensitivity="--g-sensitivity" in argv)
    console = Console()
    t = Table(title="Gravity norm of each calibrated pose (m/s^2; reference 9.81)")
    for col in ("pose", "station", "imucal", "station - 9.81", "imucal - 9.81"):
        t.add_column(col, justify="right")
    for label, o, i in c.poses:
        t.add_row(label, f"{o:.5f}", f"{i:.5f}", f"{o - GRAVITY:+.5f}", f"{i - GRAVITY:+.5f}")
    console.print(t)
    t = Table(title="Integrated rotation angle about the turned axis (deg; applied -360)")
    for col in ("rotation", "station", "imucal"):
        t.add_column(col, justify="right")
    for label, o, i in c.rotations:
        t.add_row(label, f"{o:.3f}", f"{i:.3f}")
    console.print(t)
    t = Table(title="Parameters: station - imucal")
    for col in ("parameter", "max |difference|", "station", "imucal"):
        t.add_column(col)
    for name, o, i in c.params:
        t.add_row(name, f"{np.max(np.abs(np.asarray(o) - np.asarray(i))):.2e}",
                  np.array2string(np.asarray(o), precision=5), np.array2string(np.asarray(i), precision=5))
    console.print(t)
    q = c.ours.quality
    console.print(f"station: drift resolved accel {np.isfinite(c.ours.accel.correlation_time_s).tolist()}, "
                  f"gyro {np.isfinite(c.ours.gyro.correlation_time_s).tolist()}; residual RMS accel "
                  f"{q['accel']['rms']} m/s^2, gyro {np.degrees(q['gyro']['rms']).round(4).tolist()} deg/s")


if __name__ == "__main__":
    main(sys.argv[1:])
