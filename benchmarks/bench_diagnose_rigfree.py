"""The diagnosis on simulated hand-held (rig-free) recordings: what it names, per planted effect.

    python benchmarks/bench_diagnose_rigfree.py [--per N] [--seed0 S]

Each recording: :func:`station.sim.handheld.simulate_handheld` (a 120 s rest, 20..40 random orientations,
hand moves, Table 1 unit), the Earth rate at 52 deg latitude in the data and NO latitude in the metadata
(the vertical part then looks like a g-sensitivity c I and must not be named), segments from the still
detector, diagnosed with :func:`station.diagnose.report.diagnose` (which takes the rig-free path by itself).

Rows: no effect; g-sensitivity 0.02 and 0.01 deg/s per g; a bias random walk (accelerometer 0.0005
m/s^2/sqrt(s), the gyro's GYRO_PER_ACCEL times it); extra outliers (0.1 % of the samples). Per row: recordings,
planted effect named (on the gyro for the g-sensitivity and the random walk, on either sensor for outliers;
the random walk and the outliers are planted on both sensors), recordings with a false finding (any effect on
a sensor where it was not planted), refused by the fit; ``-v`` prints every recording with its time.

Seeds: ``--seed0`` (default 7000, the report seeds) + row * 100 + k. The development seeds were 30..85 and the
tests use 620..629: keep them apart.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import numpy as np

from station.diagnose.report import diagnose
from station.kernel.errors import StationError
from station.physics.effects import Effects
from station.session.model import Session
from station.session.still import detect_still, label_segments
from station.sim.handheld import HandheldResult, simulate_handheld

LATITUDE_DEG = 52.0

_BOTH = ("accel", "gyro")
#: (label, effects, the (effect, sensor) pairs planted, the pairs that count as found: any one of them)
ROWS: tuple[tuple[str, Effects, frozenset[tuple[str, str]], frozenset[tuple[str, str]]], ...] = (
    ("none", Effects(earth_rotation=1.0), frozenset(), frozenset()),
    ("g_sensitivity 0.02 deg/s/g", Effects(g_sensitivity=0.02, earth_rotation=1.0),
     frozenset({("g_sensitivity", "gyro")}), frozenset({("g_sensitivity", "gyro")})),
    ("g_sensitivity 0.01 deg/s/g", Effects(g_sensitivity=0.01, earth_rotation=1.0),
     frozenset({("g_sensitivity", "gyro")}), frozenset({("g_sensitivity", "gyro")})),
    # planted on both sensors; the accelerometer's is rarely detectable from 20-40 stills
    ("bias_random_walk", Effects(bias_random_walk=0.0005, earth_rotation=1.0),
     frozenset(("bias_random_walk", s) for s in _BOTH), frozenset({("bias_random_walk", "gyro")})),
    ("outliers 0.1 %", Effects(outliers=0.001, earth_rotation=1.0),
     frozenset(("outliers", s) for s in _BOTH), frozenset(("outliers", s) for s in _BOTH)),
)


def session_of(res: HandheldResult) -> Session:
    """The recording as a session without references, segments from the still detector."""
    n = len(res.t_s)
    segment, kind = label_segments(n, detect_still(res.accel_mps2, res.plan.sample_rate_hz,
                                                   gyro_radps=res.gyro_radps))
    return Session(
        metadata={"serial": f"hand-{res.seed}", "sample_rate_hz": repr(res.plan.sample_rate_hz),
                  "gravity_mps2": repr(res.plan.gravity_mps2)},
        t_s=res.t_s, segment=segment, kind=kind, accel_mps2=res.accel_mps2, gyro_radps=res.gyro_radps,
        temp_degc=np.full(n, np.nan), ref_accel_mps2=np.full((n, 3), np.nan), ref_gyro_radps=np.full((n, 3), np.nan),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per", type=int, default=10, help="recordings per row")
    ap.add_argument("--seed0", type=int, default=7000, help="first seed (report seeds 7000..)")
    ap.add_argument("-v", "--verbose", action="store_true", help="one line per recording")
    args = ap.parse_args()
    print(f"rig-free diagnosis, {args.per} recordings per row, seeds {args.seed0}.. "
          f"(Earth rate at {LATITUDE_DEG:g} deg, latitude not given)")
    print(f"{'row':28s} {'n':>3s} {'found':>6s} {'false':>6s} {'refused':>8s}  named instead / in addition")
    times: list[float] = []
    total_false = total_n = 0
    for r, (label, effects, planted, wanted) in enumerate(ROWS):
        found = false = refused = n = 0
        extra: Counter[str] = Counter()
        for k in range(args.per):
            seed = args.seed0 + 100 * r + k
            res = simulate_handheld(seed, effects=effects, latitude_deg=LATITUDE_DEG)
            t0 = time.perf_counter()
            try:
                report = diagnose(session_of(res)).to_json()
            except StationError:
                refused += 1
                continue
            times.append(time.perf_counter() - t0)
            n += 1
            named = {(f["effect"], f["sensor"]) for f in report["findings"]}
            found += bool(named & wanted)
            others = named - planted
            if args.verbose:
                print(f"  {label:28s} seed {seed}: named {sorted(named) or '-'} ({times[-1]:.1f} s)", flush=True)
            false += bool(others)
            extra.update(f"{e}/{s}" for e, s in sorted(others))
        total_false += false
        total_n += n
        note = ", ".join(f"{k} x{v}" for k, v in extra.most_common()) or "-"
        shown = f"{found}" if wanted else "-"
        print(f"{label:28s} {n:3d} {shown:>6s} {false:6d} {refused:8d}  {note}", flush=True)
    print(f"\nrecordings with a false finding: {total_false} of {total_n}")
    if times:
        print(f"diagnosis time: median {np.median(times):.1f} s, max {max(times):.1f} s")


if __name__ == "__main__":
    main()
