"""The accelerometer's scale polynomial: how often a term is kept, how close it is, and what it buys.

Recordings of the independent generator (``tests/indepgen.py``) with its four corner poses added (each axis sees
+-g/sqrt(3) besides +-g: two magnitudes, so the gyro's rule fits k2 and k3), each fitted by ``station fit``'s fit
(``FitOptions(scale_nonlinearity="auto")``):

* ``indep k2``: an even scale term of ``--size`` (relative scale error at 1 g) on every accelerometer axis;
  z = (fitted - truth) / stated std (the generator bends each element's input before its misalignment, the fit's
  model after it: they differ by cross-axis terms times k2, about 1 % of k2);
* ``indep k3``: an odd term of ``--size`` (relative at 1 g) instead;
* ``indep null``: linear accelerometers (false terms per axis);

and, for the planted sets, the RMS of the corrected specific force over the poses' settled second halves with the
fitted set and with the same set less its accelerometer polynomial (in-sample: the recording the fit saw).

    PYTHONPATH=. python benchmarks/bench_accel_polynomial.py --base 405000 --units 20 --size 5e-4
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from station.fit.calibrate import FitOptions, fit_session
from tests.test_fit_accel_polynomial import pose_error_rms, with_corners

AUTO = FitOptions(scale_nonlinearity="auto")
SETS = (("indep k2", "scale_nonlinearity_even", 0), ("indep k3", "scale_nonlinearity_odd", 1), ("indep null", "", -1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", type=int, required=True, help="first seed (each set takes --units seeds from it)")
    ap.add_argument("--units", type=int, default=20, help="recordings per set")
    ap.add_argument("--size", type=float, default=5e-4, help="the planted term as a relative scale error at 1 g")
    args = ap.parse_args()
    cpu0 = time.process_time()
    print(f"accelerometer scale polynomial, corner poses added; seeds {args.base}.. (--units {args.units} per set, "
          f"size {args.size:g} at 1 g)")
    print("| set | recordings | k2 kept (axes) | k3 kept (axes) | planted term within 3 std | z mean / sd | "
          "pose RMS with / without the polynomial (mm/s^2, median) |")
    print("| --- | ---: | ---: | ---: | ---: | --- | --- |")
    for s_i, (label, effect, term) in enumerate(SETS):
        kept = [0, 0]
        zs: list[float] = []
        rms_with: list[float] = []
        rms_without: list[float] = []
        for seed in range(args.base + 1000 * s_i, args.base + 1000 * s_i + args.units):
            rec = with_corners(seed, {effect: args.size} if effect else None)
            p = fit_session(rec.session, AUTO)
            a = p.accel
            kept[0] += int(np.count_nonzero(a.scale_quadratic))
            kept[1] += int(np.count_nonzero(a.scale_cubic))
            if term < 0:
                continue
            name = "scale_quadratic" if term == 0 else "scale_cubic"
            value, std = getattr(a, name), getattr(a, f"{name}_std")
            truth = np.asarray(rec.truth[f"{effect} accel"])
            zs += [float((value[i] - truth[i]) / std[i]) for i in range(3) if value[i] != 0.0]
            rms_with.append(pose_error_rms(rec.session, p))
            linear = replace(a, scale_quadratic=np.zeros(3), scale_cubic=np.zeros(3))
            rms_without.append(pose_error_rms(rec.session, replace(p, accel=linear)))
        n = args.units
        if term < 0:
            print(f"| {label} | {n} | {kept[0]} ({3 * n}) | {kept[1]} ({3 * n}) | | | |")
            continue
        within = sum(abs(z) < 3 for z in zs)
        print(f"| {label} | {n} | {kept[0]} ({3 * n}) | {kept[1]} ({3 * n}) | {within}/{3 * n} | "
              f"{statistics.mean(zs):+.2f} / {statistics.pstdev(zs):.2f} | "
              f"{1e3 * statistics.median(rms_with):.3f} / {1e3 * statistics.median(rms_without):.3f} |")
    print(f"CPU {time.process_time() - cpu0:.0f} s")


if __name__ == "__main__":
    main()
