"""A synthetic production history for the quality statistics at factory scale (benchmarks and tests).

:func:`fill` writes N units into a station database through the store's tables (stations, units, runs, run
units, product-limit checks) and then builds the quality tables with :func:`station.store.quality_index.rebuild`,
the same SQL the migration runs. Deterministic: the same seed gives the same rows.

What it draws (SI, the default limits file's parameters and limits): every parameter normal with a
capability Cp between 1.6 and 2.6 and a small offset from the middle of its limits (fit-quality figures
one-sided, folded at 0); four-unit runs on several stations round the clock over ``days`` days; lots of
``units / lots`` consecutive units; station faults (ERROR) and aborts in a few runs; failed, errored and
aborted units retested once; ``defect_rate`` of the units have one value far above its upper limit (a gross
defect, so the first-pass yield is near 98.5 %). Two findings are planted: :data:`DRIFTING` drifts linearly by
:data:`DRIFT_SIGMAS` sigma over the whole period, and in lot :data:`SHIFTED_LOT` the parameter
:data:`SHIFTED` is moved by :data:`SHIFT_SIGMAS` sigma (its Cpk there is about 0.8).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
from sqlalchemy import func, insert, select, text

from station.kernel.limits_file import load_limits
from station.store.db import Database
from station.store.models import Run, RunUnit, Unit
from station.store.models import Station as StationRow
from station.store.quality_index import rebuild

DRIFTING = "accel.bias_static.z"
DRIFT_SIGMAS = 2.5
SHIFTED = "gyro.bias_static.y"
SHIFT_SIGMAS = 3.0
SHIFTED_LOT = "LOT-07"
LIMITS_VERSIONS = ("table1-default 2.0.0", "table1-default 2.1.0")  # the newer from 80 % of the period on
AXES = "xyz"


@dataclass(frozen=True)
class SyntheticParameter:
    name: str
    unit: str
    low: float | None  # None: one-sided (>= 0 by nature)
    high: float
    mean: float
    sigma: float


def parameters(seed: int = 0) -> list[SyntheticParameter]:
    """The product-limit parameters of the default limits file with their drawn distributions."""
    lim = load_limits().product
    rng = np.random.default_rng(seed + 1000)
    out: list[SyntheticParameter] = []
    for prefix, tri, unit in (("accel", lim.accel, "m/s^2"), ("gyro", lim.gyro, "rad/s")):
        ranges: list[tuple[str, tuple[float, float], str]] = []
        for i in range(3):
            for j in range(3):
                ranges.append((f"{prefix}.M.{AXES[i]}{AXES[j]}", tri.scale if i == j else tri.cross_axis, "1"))
        for fam in ("bias_static", "bias_drift", "noise_std"):
            ranges += [(f"{prefix}.{fam}.{a}", getattr(tri, fam), unit) for a in AXES]
        for name, (lo, hi), u in ranges:
            w = hi - lo
            cp = 1.8 if name in (DRIFTING, SHIFTED) else float(rng.uniform(1.6, 2.6))
            off = 0.0 if name in (DRIFTING, SHIFTED) else float(rng.uniform(-0.05, 0.05)) * w
            out.append(SyntheticParameter(name, u, lo, hi, (lo + hi) / 2 + off, w / (6 * cp)))
    fq = lim.fit_quality
    if fq is not None:
        one_sided = [("fit.accel.residual_rms", fq.accel_residual_rms_mps2, "m/s^2", 3),
                     ("fit.gyro.residual_rms", fq.gyro_residual_rms_radps, "rad/s", 3),
                     ("fit.accel.M_std", fq.accel_misalignment_std, "1", 9),
                     ("fit.gyro.M_std", fq.gyro_misalignment_std, "1", 9),
                     ("fit.accel.bias_static_std", fq.accel_bias_static_std_mps2, "m/s^2", 3),
                     ("fit.gyro.bias_static_std", fq.gyro_bias_static_std_radps, "rad/s", 3)]
        for base, top, u, k in one_sided:
            if top is None:
                continue
            suffixes = [f"{AXES[i]}{AXES[j]}" for i in range(3) for j in range(3)] if k == 9 else list(AXES)
            for sfx in suffixes:
                mean = top * float(rng.uniform(0.25, 0.45))
                out.append(SyntheticParameter(f"{base}.{sfx}", u, None, top, mean,
                                              (top - mean) / (3 * float(rng.uniform(1.6, 2.6)))))
    return out


@dataclass(frozen=True)
class FillSummary:
    units: int
    runs: int
    results: int
    checks: int
    seconds: float


def fill(db: Database, units: int, *, seed: int = 1, days: int = 30, stations: int = 4, slots: int = 4,
         lots: int = 10, start: datetime = datetime(2026, 9, 1, tzinfo=UTC), error_rate: float = 0.004,
         abort_rate: float = 0.003, retest_fraction: float = 0.8, defect_rate: float = 0.015) -> FillSummary:
    """Write ``units`` synthetic units with their runs into the empty history of ``db`` (see the module)."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    params = parameters(seed)
    names = [p.name for p in params]
    drift_k = names.index(DRIFTING) if DRIFTING in names else -1
    shift_k = names.index(SHIFTED) if SHIFTED in names else -1
    with db.transaction() as s:
        if s.scalar(select(func.count()).select_from(Run)):
            raise ValueError("fill() writes into a database without runs")
    period_s = days * 86400.0
    lot_size = max(units // lots, 1)
    lot_of_unit = np.minimum(np.arange(units) // lot_size, lots - 1)

    def draw(unit_idx: np.ndarray, t_frac: np.ndarray) -> np.ndarray:
        v = np.empty((len(unit_idx), len(params)))
        for k, p in enumerate(params):
            x = p.mean + p.sigma * rng.standard_normal(len(unit_idx))
            if k == drift_k:
                x += DRIFT_SIGMAS * p.sigma * t_frac
            if k == shift_k:
                x += np.where(lot_of_unit[unit_idx] == int(SHIFTED_LOT[-2:]), SHIFT_SIGMAS * p.sigma, 0.0)
            if p.low is None:
                x = np.abs(x)
            v[:, k] = x
        bad = np.flatnonzero(rng.uniform(size=len(unit_idx)) < defect_rate)  # a gross defect: one value far out
        for i, k in zip(bad, rng.integers(0, len(params), len(bad)), strict=True):
            p = params[k]
            v[i, k] = p.high + abs(p.high - (p.low if p.low is not None else 0.0)) * float(rng.uniform(0.05, 0.5))
        return v

    lows = np.array([p.low if p.low is not None else -np.inf for p in params])
    highs = np.array([p.high for p in params])
    # first tests: consecutive units in runs of `slots`, evenly over the period, stations round robin
    n_runs1 = -(-units // slots)
    run_t = np.sort(rng.uniform(0, period_s, n_runs1))
    runs: list[dict[str, Any]] = []
    results: list[tuple[int, int, int, np.ndarray | None, str]] = []  # run index, slot, unit, values, outcome

    def add_runs(unit_list: np.ndarray, times: np.ndarray) -> list[int]:
        retest: list[int] = []
        for r, t in enumerate(times):
            members = unit_list[r * slots:(r + 1) * slots]
            u = rng.uniform()
            fault = "ERROR" if u < error_rate else "ABORTED" if u < error_rate + abort_rate else None
            vals = draw(members, np.full(len(members), t / period_s))
            outs = []
            for k, unit in enumerate(members):
                if fault is not None:
                    out, v = fault, None
                else:
                    ok = bool(np.all((vals[k] >= lows) & (vals[k] <= highs)))
                    out, v = ("PASS" if ok else "FAIL"), vals[k]
                outs.append(out)
                results.append((len(runs), k, int(unit), v, out))
                if out != "PASS" and (fault is not None or rng.uniform() < retest_fraction):
                    retest.append(int(unit))
            worst = fault or ("FAIL" if "FAIL" in outs else "PASS")
            station = len(runs) % stations
            lot = f"LOT-{int(lot_of_unit[members[0]]):02d}"
            runs.append({"t": float(t), "outcome": worst, "station": station, "lot": lot})
        return retest

    retest = add_runs(np.arange(units), run_t)  # in the order of their first run
    if retest:
        order = np.array(retest)
        first_t = run_t[np.minimum(order // slots, n_runs1 - 1)]
        n2 = -(-len(order) // slots)
        group_t = np.array([first_t[r * slots:(r + 1) * slots].max() for r in range(n2)])
        add_runs(order, np.minimum(group_t + rng.uniform(1800, 14400, n2), period_s + 3600))
    return _write(db, params, runs, results, units, start, stations, period_s, t0)


def _write(db: Database, params: list[SyntheticParameter], runs: list[dict[str, Any]],
           results: list[tuple[int, int, int, np.ndarray | None, str]], units: int, start: datetime,
           stations: int, period_s: float, t0: float) -> FillSummary:
    with db.transaction() as s:
        st_ids = []
        for k in range(stations):
            row = StationRow(name=f"EOL-{k + 1}", created_at=start)
            s.add(row)
            s.flush()
            st_ids.append(row.id)
        base_unit = int(s.scalar(select(func.coalesce(func.max(Unit.id), 0))) or 0)
        base_run = int(s.scalar(select(func.coalesce(func.max(Run.id), 0))) or 0)
        base_ru = int(s.scalar(select(func.coalesce(func.max(RunUnit.id), 0))) or 0)
        s.execute(insert(Unit), [{"id": base_unit + i + 1, "serial": f"IMU-{i:07d}", "created_at": start}
                                 for i in range(units)])
        run_rows = []
        for i, r in enumerate(runs):
            t = start + timedelta(seconds=r["t"])
            version = LIMITS_VERSIONS[1] if r["t"] > 0.8 * period_s else LIMITS_VERSIONS[0]
            run_rows.append({"id": base_run + i + 1, "run_uid": f"syn-{i:08d}", "station_id": st_ids[r["station"]],
                             "outcome": r["outcome"], "started_at": t, "finished_at": t + timedelta(seconds=410),
                             "duration_s": 400.0, "wall_s": 410.0, "software_version": "synthetic",
                             "sequence_version": "plan/25 steps", "sequence_hash": "", "limits_version": version,
                             "limits_hash": "", "operator": "synthetic", "lot": r["lot"], "rig": "fake-rig://",
                             "host": "synthetic", "pid": 0, "rig_at_rest": True,
                             "message": "" if r["outcome"] in ("PASS", "FAIL") else "synthetic fault"})
        for i in range(0, len(run_rows), 20000):
            s.execute(insert(Run), run_rows[i:i + 20000])
        ru_rows = [{"id": base_ru + i + 1, "run_id": base_run + ri + 1, "slot": slot, "sensor_url": "",
                    "unit_id": base_unit + u + 1, "outcome": out, "message": ""}
                   for i, (ri, slot, u, _v, out) in enumerate(results)]
        for i in range(0, len(ru_rows), 20000):
            s.execute(insert(RunUnit), ru_rows[i:i + 20000])
        conn = s.connection()
        checks = _write_checks(conn, params, results, base_ru)
        if conn.dialect.name == "postgresql":
            for table in ("units", "runs", "run_units"):
                conn.execute(text(f"SELECT setval(pg_get_serial_sequence('{table}', 'id'), "
                                  f"(SELECT MAX(id) FROM {table}))"))
        rebuild(conn)
    return FillSummary(units, len(runs), len(results), checks, time.perf_counter() - t0)


def _write_checks(conn: Any, params: list[SyntheticParameter], results: list[tuple[int, int, int, Any, str]],
                  base_ru: int) -> int:
    names = [p.name for p in params]
    units = [p.unit for p in params]
    lows = [p.low if p.low is not None else 0.0 for p in params]
    highs = [p.high for p in params]
    dbapi = conn.connection.driver_connection
    count = 0
    if conn.dialect.name == "postgresql":
        with dbapi.cursor() as cur, cur.copy(
                "COPY limit_checks (run_unit_id, step, name, value, low, high, unit, passed, verdict) FROM STDIN") \
                as cp:
            for i, (_ri, _slot, _u, v, _out) in enumerate(results):
                if v is None:
                    continue
                for k in range(len(names)):
                    x = float(v[k])
                    ok = lows[k] <= x <= highs[k]
                    cp.write_row((base_ru + i + 1, "limits", names[k], x, lows[k], highs[k], units[k], ok,
                                  "PASS" if ok else "FAIL"))
                    count += 1
        return count
    cur = dbapi.cursor()
    batch: list[tuple[Any, ...]] = []
    for i, (_ri, _slot, _u, v, _out) in enumerate(results):
        if v is None:
            continue
        for k in range(len(names)):
            x = float(v[k])
            ok = lows[k] <= x <= highs[k]
            batch.append((base_ru + i + 1, "limits", names[k], x, lows[k], highs[k], units[k], int(ok),
                          "PASS" if ok else "FAIL"))
        if len(batch) > 200000:
            cur.executemany("INSERT INTO limit_checks (run_unit_id, step, name, value, low, high, unit, passed, "
                            "verdict) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", batch)
            count += len(batch)
            batch.clear()
    if batch:
        cur.executemany("INSERT INTO limit_checks (run_unit_id, step, name, value, low, high, unit, passed, verdict) "
                        "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", batch)
        count += len(batch)
    return count


__all__ = ["DRIFTING", "DRIFT_SIGMAS", "SHIFTED", "SHIFTED_LOT", "SHIFT_SIGMAS", "FillSummary", "fill",
           "parameters"]
