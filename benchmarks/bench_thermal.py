"""The thermal terms of the fit, on simulated units at climate-chamber temperature plateaus.

Every unit runs the default plan (rest, six poses, +-50/100/200 deg/s about each axis) at four chamber plateaus,
25 -> 45 -> 5 -> 25 degC (a 600 s soak before each later plateau, the unit lagging the chamber by 150 s, its own
self-heating on top), with Table 1 parameters plus temperature coefficients of data-sheet size:
``--effect temperature_bias=0.004,temperature_scale=200`` gives 0.2-0.4 mg/K and 0.01-0.02 deg/s/K bias and
100-200 ppm/K scale per axis (random signs).

1. Recovery: ``--units`` units (report seeds from ``--seed``; the tests and development used seeds < 100 and
   5001), fitted with :func:`station.fit.calibrate.fit_session`; per coefficient family the fraction of
   |estimate - truth| within 1, 2 and 3 of its stated standard uncertainties (Gaussian: 68.3 / 95.4 / 99.7 %).
2. Correction at every plateau, through the command line: ``station simulate --temperature-plateaus``,
   ``station fit --json`` (and ``--thermal off`` for contrast), ``station correct``; per plateau the worst pose
   error (|mean corrected specific force - reference|, mg, largest axis, second half of each pose) and the worst
   rate error (|mean corrected rate - commanded|, % of the rate, second half of each rate step), against the same
   unit without temperature effects (same seed and plateaus, ``station fit`` as well).

    python benchmarks/bench_thermal.py --units 50 --seed 7000 --table-units 3
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from station.fit.calibrate import FitOptions, fit_session
from station.physics.effects import Effects
from station.session import read_session
from station.session.model import Kind, Session
from station.sim.session_sim import simulate_session

PLATEAUS = (25.0, 45.0, 5.0, 25.0)
EFFECT = "temperature_bias=0.004,temperature_scale=200"
MG = 9.80665e-3


def recovery(units: int, seed: int, effect: str = EFFECT) -> None:
    z: dict[str, list[np.ndarray]] = {}
    rel: dict[str, list[np.ndarray]] = {}
    orders = {"accel": np.zeros(4, dtype=int), "gyro": np.zeros(4, dtype=int)}
    status: dict[str, int] = {}
    times = []
    for i in range(units):
        res = simulate_session(seed + i, effects=Effects.parse(effect), temperature_plateaus_degc=PLATEAUS)
        t0 = time.perf_counter()
        p = fit_session(res.session, FitOptions(thermal="auto"))  # what `station fit` does
        times.append(time.perf_counter() - t0)
        status[p.thermal.status] = status.get(p.thermal.status, 0) + 1
        if not p.thermal.fitted:
            continue
        et = res.effect_truth
        # the fit's M and b_stat hold at its T_ref, the simulator's at the power-on temperature (the first plateau):
        # the truth at T_ref is (1 + s dT) M and b_stat + c dT, dT = T_ref - T_power-on
        d_ref = p.reference_temperature_degc - res.environment.ambient_degc
        for tri_name, tri, truth in (("accel", p.accel, res.truth.accel), ("gyro", p.gyro, res.truth.gyro)):
            m_ref = (1.0 + getattr(et, f"{tri_name}_temp_scale") * d_ref)[:, None] * truth.misalignment
            b_ref = truth.bias_static + getattr(et, f"{tri_name}_temp_bias") * d_ref
            for fam, est, std, true in (
                ("temp bias c1", tri.temp_bias_coeff[:, 0], tri.temp_bias_coeff_std[:, 0],
                 getattr(et, f"{tri_name}_temp_bias")),
                ("temp scale s1", tri.temp_scale_coeff[:, 0], tri.temp_scale_coeff_std[:, 0],
                 getattr(et, f"{tri_name}_temp_scale")),
                ("b_stat at T_ref", tri.bias_static, tri.bias_static_std, b_ref),
                ("M at T_ref (9 per unit)", tri.misalignment.ravel(), tri.misalignment_std.ravel(), m_ref.ravel()),
            ):
                key = f"{tri_name} {fam}"
                if not np.any(true) and fam.startswith("temp"):  # a unit without temperature effects
                    key += " (truth 0)"
                z.setdefault(key, []).append((est - true) / std)
                rel.setdefault(key, []).append(std / np.maximum(np.abs(true), 1e-300))
            for term in ("bias", "scale"):
                for o in p.thermal.orders[tri_name][term]:
                    orders[tri_name][o] += 1
    print(f"## Recovery over {units} units (seeds {seed}..{seed + units - 1}, --effect {effect}); "
          f"thermal status: {status}; "
          f"median fit time {np.median(times):.1f} s")
    print()
    print("| parameter | values | within 1 sigma | within 2 sigma | within 3 sigma | median std / |truth| |")
    print("|---|---:|---:|---:|---:|---:|")
    for key, zs in z.items():
        a = np.abs(np.concatenate(zs))
        r = np.concatenate(rel[key])
        print(f"| {key} | {a.size} | {np.mean(a <= 1):.1%} | {np.mean(a <= 2):.1%} | {np.mean(a <= 3):.1%} | "
              f"{np.median(r):.2e} |")
    print()
    for tri_name, counts in orders.items():
        print(f"{tri_name}: polynomial orders chosen (bias and scale, per axis): "
              + ", ".join(f"order {o}: {counts[o]}" for o in (1, 2, 3)))
    print()


def _station(*args: str) -> subprocess.CompletedProcess[str]:
    exe = Path(sys.executable).with_name("station")  # the console script of this environment
    return subprocess.run([str(exe), *args], capture_output=True, text=True, check=False)


def plateau_errors(s: Session) -> list[tuple[float, float, float]]:
    """Per plateau block (each starts with a rest): (worst pose error mg, worst rate error %, deg/s)."""
    out: list[list[float]] = []
    for seg in s.segments():
        if seg.kind == Kind.REST:
            out.append([0.0, 0.0, 0.0])
        if seg.kind not in (Kind.POSE, Kind.RATE):
            continue
        a = seg.start + (seg.stop - seg.start) // 2
        if seg.kind == Kind.POSE:
            e = np.abs(s.accel_mps2[a:seg.stop].mean(0) - s.ref_accel_mps2[a:seg.stop].mean(0)).max() / MG
            out[-1][0] = max(out[-1][0], float(e))
        else:
            ref = s.ref_gyro_radps[a:seg.stop].mean(0)
            k = int(np.argmax(np.abs(ref)))
            e = abs(float(s.gyro_radps[a:seg.stop, k].mean() - ref[k]))
            out[-1][1] = max(out[-1][1], 100.0 * e / abs(float(ref[k])))
            out[-1][2] = max(out[-1][2], float(np.degrees(e)))
    return [tuple(v) for v in out]  # type: ignore[misc]


def table(units: int, seed: int) -> None:
    print(f"## `station fit` + `station correct` at every plateau ({units} units, seeds {seed}..{seed + units - 1})")
    print()
    print("Commands per unit (`-` = without temperature effects, same seed):")
    print(f"`station simulate -o s.csv --seed N --effect {EFFECT} --temperature-plateaus 25,45,5,25`, "
          "`station fit s.csv --json > p.json` (and `--thermal off`), `station correct s.csv --params p.json -o c.csv`")
    print()
    print("| unit | plateau (degC) | pose err mg: thermal fit | no thermal model | unit w/o temp. effects "
          "| rate err % (deg/s): thermal fit | no thermal model | unit w/o temp. effects |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    worst = np.zeros((3, 2))
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for i in range(units):
            n = seed + i
            rows = {}
            for label, effect, thermal in (("thermal", EFFECT, "auto"), ("off", EFFECT, "off"), ("plain", "none",
                                                                                                  "auto")):
                s_csv, p_json, c_csv = d / f"{label}-{n}.csv", d / f"{label}-{n}.json", d / f"{label}-{n}-c.csv"
                r = _station("simulate", "-o", str(s_csv), "--seed", str(n), "--effect", effect,
                             "--temperature-plateaus", ",".join(f"{p:g}" for p in PLATEAUS))
                assert r.returncode == 0, r.stderr
                r = _station("fit", str(s_csv), "--json", "--thermal", thermal)
                assert r.returncode in (0, 3), r.stderr
                if r.returncode == 3:
                    print(f"<!-- {label} {n}: {r.stderr.strip()} -->")
                p_json.write_text(r.stdout)
                r = _station("correct", str(s_csv), "--params", str(p_json), "-o", str(c_csv))
                assert r.returncode == 0, r.stderr
                rows[label] = plateau_errors(read_session(c_csv))
            for k, temp in enumerate(PLATEAUS):
                t, o, p = rows["thermal"][k], rows["off"][k], rows["plain"][k]
                for j, v in enumerate((t, o, p)):
                    worst[j] = np.maximum(worst[j], [v[0], v[1]])
                print(f"| {n} | {temp:g} | {t[0]:.2f} | {o[0]:.2f} | {p[0]:.2f} | {t[1]:.4f} ({t[2]:.4f}) | "
                      f"{o[1]:.4f} ({o[2]:.4f}) | {p[1]:.4f} ({p[2]:.4f}) |")
    print()
    print(f"worst over all plateaus: pose {worst[0, 0]:.2f} / {worst[1, 0]:.2f} / {worst[2, 0]:.2f} mg, "
          f"rate {worst[0, 1]:.4f} / {worst[1, 1]:.4f} / {worst[2, 1]:.4f} % "
          "(thermal fit / no thermal model / unit without temperature effects)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=50)
    ap.add_argument("--seed", type=int, default=7000)
    ap.add_argument("--table-units", type=int, default=3)
    ap.add_argument("--effect", default=EFFECT, help="effects of the recovery units (none: no temperature effects)")
    args = ap.parse_args()
    if args.units:
        recovery(args.units, args.seed, args.effect)
    if args.table_units:
        table(args.table_units, args.seed)


if __name__ == "__main__":
    main()
