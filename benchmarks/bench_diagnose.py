"""Concealed-data study of ``station.diagnose``: is the missing physics found, and only then?

For every candidate effect, simulated recordings (random rig plans, sample rates and units,
``station.kernel.plan.random_plan``) with that effect at a magnitude below the white noise of a
single sample; recordings without missing physics; and pairs of effects hidden together.
Prints the confusion matrix (true effect x named effects), the detection and false-finding
rates, the median fit improvement (block chi^2 before/after on the affected axes), and the
time to diagnose a 15-minute 100 Hz recording.

With ``--sweep`` it also reports, per effect, the detection rate at 0.25x, 0.5x, 1x, 2x and 4x the
concealed magnitude, with the effect's size relative to the white noise of a single sample
(the largest |effect| over the recording divided by the sample noise std, median over the
recordings; the effect signal is the exact difference of the simulation with and without it).

Run: ``/work/venv/bin/python benchmarks/bench_diagnose.py [--seeds 10] [--clean 50] [--pairs 10]
[--effects a,b] [--sweep [--sweep-seeds 5] [--sweep-effects a,b]] [--chamber 10] [--information a,b]
[--detectable 10 [--detectable-effects a,b]] [--limits FILE|none]``

``--detectable N`` checks the sizes the report quotes for candidates it did not find (``detectable_from``):
N random recordings per effect, each diagnosed clean, then with the effect at the quoted size and at a
quarter of it (only this study).

The diagnosis gets the sensor class's T_c range of eq. 3 from the station's default limits file
(``fixtures/limits/default.toml``: Table 1, which is also the range the simulator draws from), as
``station diagnose --limits`` and the unit page do; ``--limits none`` runs it on the recordings alone.

``--information a,b`` prints, for the study's recordings of those effects, how much information each
recording holds about the effect (noncentrality of the exact effect signal against the decision threshold,
and the detection probability that implies): a miss where that probability is low is information-limited.
It runs only that study (``--seeds`` recordings per effect).

``--chamber N`` repeats the temperature_bias study (N recordings per row) from the recordings alone,
with the class's T_c range, and with the rig step the diagnosis names when it reports temperature and
warm-up as inseparable (a climate-chamber temperature cycle, without the range), and checks N clean
recordings made with that step for false findings.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from station.diagnose import NAMES, diagnose
from station.diagnose.effect_registry import LIBRARY
from station.kernel.limits_file import DEFAULT_LIMITS_PATH, load_limits
from station.kernel.plan import RigPlan, random_plan
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

#: Magnitudes (units of station.physics.effects.Effects) below the white noise of a single sample
#: (accel 0.017-0.028 m/s^2, gyro 0.010-0.013 deg/s) at typical inputs.
CONCEALED: dict[str, float] = {
    # accel 2 mm/s^2/K (0.2 mg/K, data-sheet typical), gyro 10 mdeg/s/K: ~10 mm/s^2 (below the accel's sample
    # noise) and ~50 mdeg/s over the self-heating, which the base fit absorbs as the warm-up of eq. 3
    "temperature_bias": 0.002,
    # 100 ppm/K = 0.01 %/K (data sheets list 0.005-0.026 %/K typical): 5e-4 relative after 5 K, RMS over the
    # recording ~0.8 single-sample sigma; the base fit takes most of it into M. At 50 ppm/K the recordings
    # carry too little of it for any test at ALPHA (--information: 8.4/10 expected).
    "temperature_scale": 100.0,
    "g_sensitivity": 0.005,  # deg/s per g
    "scale_nonlinearity": 2e-4,  # relative at 1 g / 200 deg/s
    "scale_asymmetry": 2e-4,
    "lever_arm": 2.0,  # mm
    "earth_rotation": 1.0,  # 15 deg/h = 4 mdeg/s
    "time_offset": 0.2,  # ms
    "bias_random_walk": 1e-4,  # m/s^2/sqrt(s)
    "outliers": 3e-4,  # extra probability per sample
    "pose_tilt": 0.05,  # deg rms per pose: ~8.6 mm/s^2 at 1 g, below the single-sample accel noise
}


#: The effects the station's simulator has (the library's names without the IEEE even/odd scale terms), in the
#: order the study's seeds and pairs were drawn from before those were added.
SIM_NAMES = tuple(n for n in NAMES if n in CONCEALED)


def study_seed(name: str, s: int) -> int:
    """Seed of the ``s``-th recording of effect ``name``'s study."""
    return 100 * (NAMES.index(name) + 1) + s


def plan_for(seed: int) -> RigPlan:
    """The random rig plan of recording ``seed`` (sequence, sample rate, durations)."""
    return random_plan(np.random.default_rng(10_000 + seed))


#: The sensor class's T_c range the study gives the diagnosis (``--limits``): the station's default limits file.
WARMUP_TC: dict[str, tuple[float, float]] | None = None


def run(
    effects: dict[str, float], seed: int, sensor_class: SensorClass = TABLE1, *, class_range: bool = True
) -> tuple[set[str], list[float], float, set[str]]:
    """(named effects, fit improvements of the findings, diagnosis time s, effects listed as inseparable)."""
    plan = plan_for(seed)
    res = simulate_session(seed, plan=plan, effects=Effects(**effects), sensor_class=sensor_class)
    t0 = time.perf_counter()
    d = diagnose(res.session, warmup_tc_s=WARMUP_TC if class_range else None)
    dt = time.perf_counter() - t0
    named = {f["effect"] for f in d.to_json()["findings"]}
    inseparable = {e for item in d.to_json()["inseparable"] for e in item["effects"]}
    gains = []
    for f in d.to_json()["findings"]:
        fit = f.get("fit") or {}
        if "before" in fit:
            b, a = np.array(fit["before"]["block_chi2"]), np.array(fit["after"]["block_chi2"])
            gains.append(float(np.max(b / a)))
    return named, gains, dt, inseparable


SWEEP_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0)


def effect_size(seed: int, effects: dict[str, float]) -> tuple[float, float]:
    """(largest |effect| over the recording, its RMS over the recording), both in single-sample noise
    sigmas, the larger of the two sensors' worst axes. Includes the ADC's +-1 LSB rounding jitter
    (accel 0.12 sigma, gyro ~0.35 sigma)."""
    plan = plan_for(seed)
    on = simulate_session(seed, plan=plan, effects=Effects(**effects))
    off = simulate_session(seed, plan=plan)
    peak, rms = [], []
    for data, sigma in ((lambda s: s.accel_mps2, on.truth.accel.noise_std),
                        (lambda s: s.gyro_radps, on.truth.gyro.noise_std)):
        diff = np.abs(data(on.session) - data(off.session))
        peak.append(float(np.max(np.nanmax(diff, axis=0) / sigma)))
        rms.append(float(np.max(np.sqrt(np.nanmean(diff**2, axis=0)) / sigma)))
    return max(peak), max(rms)


def sweep(names: list[str], seeds: int) -> None:
    """Detection rate against magnitude (multiples of CONCEALED) with the effect size in noise sigmas."""
    print(f"\ndetection rate against magnitude ({seeds} recordings per cell); effect size in single-sample noise "
          "sigmas: peak / RMS over the recording (median over the recordings)")
    print(f"{'effect':20s} " + " ".join(f"{f'{f:g}x found':>9s} {'peak/rms':>11s}" for f in SWEEP_FACTORS))
    for name in names:
        cells = []
        for factor in SWEEP_FACTORS:
            hits, peaks, rmss = 0, [], []
            for s in range(seeds):
                seed = study_seed(name, s)
                effects = {name: CONCEALED[name] * factor}
                named, *_ = run(effects, seed)
                hits += name in named
                peak, rms = effect_size(seed, effects)
                peaks.append(peak)
                rmss.append(rms)
            cells.append(f"{100.0 * hits / seeds:8.0f}% {np.median(peaks):5.2f}/{np.median(rmss):5.3f}")
            print(f"  {name} x{factor:g}: {hits}/{seeds}", flush=True)
        print(f"{name:20s} " + " ".join(cells), flush=True)


def _power_cells(name: str, seed: int, on: dict[str, float], off: dict[str, float]) -> tuple[list[str], float]:
    """Per sensor, the noncentrality of effect ``name``'s exact signal in recording ``seed`` (simulation with the
    effects ``on`` minus with ``off``), the part its regressors capture, the threshold and the test's power;
    and P(found on either sensor)."""
    from scipy import linalg, stats

    from station.diagnose.likelihood import RCOND, SensorProblem
    from station.diagnose.residuals import fit_baseline

    plan = plan_for(seed)
    sim_on = simulate_session(seed, plan=plan, effects=Effects(**on))
    sim_off = simulate_session(seed, plan=plan, effects=Effects(**off))
    baseline = fit_baseline(sim_on.session, warmup_tc_s=WARMUP_TC)
    cells, miss = [], 1.0
    for sensor, data in (("accel", lambda x: x.accel_mps2), ("gyro", lambda x: x.gyro_radps)):
        cand = LIBRARY.get(name)
        if cand is None or sensor not in cand.sensors:
            continue
        sd = baseline.sensor(sensor)
        z = cand.build(baseline, sd)
        if z is None:
            continue
        prob = SensorProblem(baseline, sd)
        chols, _ = prob.whitened()
        exact = sd.block_mean(data(sim_on.session) - data(sim_off.session))
        sw = np.concatenate([linalg.solve_triangular(chols[k], exact[:, k], lower=True) for k in range(3)])

        def left(x: np.ndarray, sw: np.ndarray = sw) -> float:
            beta, *_ = linalg.lstsq(x, sw, cond=RCOND)
            return float(np.sum((sw - x @ beta) ** 2))

        x0, _ = prob.design(chols, [])
        x1, _ = prob.design(chols, [sd.block_mean(z)])
        lam = left(x0)
        captured = lam - left(x1)
        test = prob.test_mean(name, sd.block_mean(z))
        thr = test.threshold
        power = float(stats.ncx2.sf(thr, max(test.params, 1), max(captured, 1e-12)))
        miss *= 1.0 - power
        absorbed = 1.0 - lam / max(float(sw @ sw), 1e-300)  # share of the signal's chi^2 the base terms take
        cells.append(f"{sensor} absorbed {100.0 * absorbed:5.1f} % lambda {lam:7.1f} captured {captured:7.1f} "
                     f"threshold {thr:5.1f} power {power:4.2f} gain {test.gain:7.1f}")
    return cells, 1.0 - miss


def information(names: list[str], seeds: int) -> None:
    """Whether a miss is information-limited: per recording of the study and sensor, the noncentrality
    ``lambda`` of the exact effect signal (simulation with minus without the effect, same seed; block means
    whitened by the diagnosis's block covariance, after the base model's terms), the part of it the
    candidate's regressors capture, the decision threshold (max of the chi^2 critical value and the BIC
    penalty) and the power ``P(chi^2_p(lambda) > threshold)`` of the test with the captured part.
    ``lambda`` includes the ADC's rounding jitter (a few units); T_c and q are held at the diagnosis's start.
    ``absorbed``: the share of the signal's whitened chi^2 that the base model's terms take (concealment).
    ``name@pairs`` does this for the pair study's recordings that hold ``name``, the other effect of the
    pair in the data (present in both simulations, so in the noise the test sees)."""
    print("\ninformation per recording (noncentrality lambda in chi^2 units; power = P(the test passes) given "
          "the captured part)")
    for spec in names:
        name, _, where = spec.partition("@")
        if name not in LIBRARY:
            print(f"{name}: not a mean candidate (a noise-model or outlier test): no noncentrality", flush=True)
            continue
        expected, count = 0.0, 0
        if where == "pairs":
            runs = [(f"pair {pair} seed {seed}", seed, {n: CONCEALED[n] for n in pair},
                     {n: CONCEALED[n] for n in pair if n != name})
                    for seed, pair in study_pairs(PAIRS) if name in pair]
        else:
            runs = [(f"seed {s}", study_seed(name, s), {name: CONCEALED[name]}, {}) for s in range(seeds)]
        for label, seed, on, off in runs:
            cells, p_found = _power_cells(name, seed, on, off)
            expected += p_found
            count += 1
            print(f"  {name} {label}: " + " | ".join(cells) + f" | P(found) {p_found:.2f}", flush=True)
            if len(on) > 1:  # the same recording without the other effect
                cells, p_alone = _power_cells(name, seed, {name: CONCEALED[name]}, {})
                print("    without the other effect: " + " | ".join(cells) + f" | P(found) {p_alone:.2f}", flush=True)
        print(f"{name}: expected detections from the powers {expected:.1f}/{count}", flush=True)


#: Recordings in the pair study.
PAIRS = 10


def study_pairs(n: int) -> list[tuple[int, tuple[str, str]]]:
    """The pair study's first ``n`` recordings: (seed, the two effects hidden together)."""
    rng = np.random.default_rng(7)
    out = []
    for s in range(n):
        a, b = rng.choice(len(SIM_NAMES), size=2, replace=False)
        out.append((9000 + s, (SIM_NAMES[a], SIM_NAMES[b])))
    return out


#: The rig step the diagnosis names for temperature_bias: a climate-chamber cycle, +-2 K with a 5 min period.
CHAMBER = replace(TABLE1, ambient_cycle_k=2.0, ambient_cycle_period_s=300.0)


def chamber(seeds: int) -> None:
    """temperature_bias (concealed magnitude) from the recording alone, with the sensor class's T_c range, with
    the separating rig step; and clean recordings with the step (false findings)."""
    print(f"\ntemperature_bias without and with what separates it from the warm-up (the sensor class's T_c range "
          f"from the limits file; the rig step the diagnosis names: climate chamber +-2 K, 300 s period), "
          f"{seeds} recordings each")
    mag = CONCEALED["temperature_bias"]
    for label, cls, effects, class_range in (
        ("recording alone", TABLE1, {"temperature_bias": mag}, False),
        ("class T_c range", TABLE1, {"temperature_bias": mag}, True),
        ("chamber step", CHAMBER, {"temperature_bias": mag}, False),
        ("chamber step, no effect", CHAMBER, {}, False),
    ):
        hits, other, listed = 0, 0, 0
        for s in range(seeds):
            named, _, _, insep = run(effects, study_seed("temperature_bias", s), cls, class_range=class_range)
            hits += "temperature_bias" in named
            listed += "temperature_bias" in insep
            other += bool(named - {"temperature_bias"})
            print(f"  {label} seed {s}: named {sorted(named)}, inseparable {sorted(insep)}", flush=True)
        print(f"{label:24s} temperature_bias named {hits}/{seeds}, listed as inseparable from the warm-up "
              f"{listed}/{seeds}, other findings in {other}/{seeds}", flush=True)


#: Effects whose reported parameters are the simulator's magnitude times a shape with the given smallest
#: magnitude (station.physics.effects.Effects): an effect of ``quoted / smallest shape`` has every parameter at or
#: above the size ``detectable_from`` quoted for it.
DETECTABLE_SHAPE_MIN = {"temperature_scale": 0.5, "g_sensitivity": 0.5, "time_offset": 1.0}


def detectable(names: list[str], seeds: int) -> None:
    """Is a rejected candidate's ``detectable_from`` a size at which the effect is found? Per random recording
    (plan, rate, unit; seeds 20000+): the sizes quoted on the clean recording (the sensor with the smallest
    largest quote), then the same recording with the effect at those sizes (every parameter at or above its
    quote: found in >= 90 % expected) and at a quarter of the smallest quote (rarely found)."""
    print("\ndetectable_from: found at the quoted size (every parameter >= its quote; expect >= 90 %) and at a "
          "quarter of the smallest quote")
    for name in names:
        hi_found = lo_found = tested = 0
        quotes = []
        for s in range(seeds):
            seed = 20_000 + s
            plan = plan_for(seed)
            clean = diagnose(simulate_session(seed, plan=plan).session, warmup_tc_s=WARMUP_TC).to_json()
            quoted = [r for r in clean["rejected"] if r["effect"] == name and r.get("detectable_from")]
            sizes = {r["sensor"]: np.abs(np.asarray(r["detectable_from"]["value"], dtype=float)).ravel()
                     for r in quoted}
            clean_gain = {r["sensor"]: r["gain"] for r in quoted}
            if not sizes:
                print(f"  {name} seed {s}: nothing quoted (not testable in full)", flush=True)
                continue
            sensor = min(sizes, key=lambda k: sizes[k].max())
            hi = float(sizes[sensor].max()) / DETECTABLE_SHAPE_MIN[name]
            lo = 0.25 * float(min(v.min() for v in sizes.values()))
            found = []
            for magnitude in (hi, lo):
                res = simulate_session(seed, plan=plan, effects=Effects(**{name: magnitude}))
                report = diagnose(res.session, warmup_tc_s=WARMUP_TC).to_json()
                found.append(name in {f["effect"] for f in report["findings"]})
            tested += 1
            hi_found += found[0]
            lo_found += found[1]
            quotes.append(hi * DETECTABLE_SHAPE_MIN[name])
            print(f"  {name} seed {s}: quoted on the {sensor} up to {hi * DETECTABLE_SHAPE_MIN[name]:.3g} (the clean "
                  f"recording's own chi^2 gain {clean_gain[sensor]:.2f}); at that size found {found[0]}, at a quarter "
                  f"of the smallest quote found {found[1]}", flush=True)
        print(f"{name:20s} at the quoted size found {hi_found}/{tested}, at a quarter {lo_found}/{tested}; "
              f"median largest quote {np.median(quotes) if quotes else math.nan:.3g}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--effects", default=",".join(SIM_NAMES), help="comma-separated effects of the per-effect study")
    ap.add_argument("--clean", type=int, default=50)
    ap.add_argument("--pairs", type=int, default=PAIRS)
    ap.add_argument("--chamber", type=int, default=0, help="recordings for the temperature rig-step study")
    ap.add_argument("--sweep", action="store_true", help="also the detection rate against magnitude")
    ap.add_argument("--sweep-seeds", type=int, default=5)
    ap.add_argument("--sweep-effects", default=",".join(SIM_NAMES), help="comma-separated effect names")
    ap.add_argument("--information", default="", help="comma-separated effect names: noncentrality and power per "
                    "recording of the study (is a miss information-limited?); name@pairs: the pair study's "
                    "recordings that hold it")
    ap.add_argument("--limits", default=str(DEFAULT_LIMITS_PATH),
                    help="limits file whose correlation_time_s ranges the diagnosis gets as the sensor class's T_c "
                    "(default: the station's default limits, Table 1); 'none': the recordings alone")
    ap.add_argument("--detectable", type=int, default=0, help="recordings per effect for the check of the "
                    "sizes rejected candidates quote (detectable_from); runs only that study")
    ap.add_argument("--detectable-effects", default=",".join(DETECTABLE_SHAPE_MIN))
    args = ap.parse_args()
    global WARMUP_TC
    WARMUP_TC = None if args.limits == "none" else load_limits(args.limits).correlation_time_s
    print(f"sensor class T_c range given to the diagnosis: {WARMUP_TC or 'none (the recordings alone)'}")
    if args.information:  # only this study
        information([n for n in args.information.split(",") if n], args.seeds)
        return
    if args.detectable:  # only this study
        detectable([n for n in args.detectable_effects.split(",") if n], args.detectable)
        return

    studied = [n for n in args.effects.split(",") if n]
    confusion = {name: dict.fromkeys(NAMES, 0) for name in (*studied, "none")}
    found = dict.fromkeys(NAMES, 0)
    improvements: list[float] = []
    times: list[float] = []
    for name in studied:
        for s in range(args.seeds):
            named, gains, dt, _ = run({name: CONCEALED[name]}, study_seed(name, s))
            times.append(dt)
            for n in named:
                confusion[name][n] += 1
            found[name] += name in named
            improvements.extend(gains)
            print(f"  {name:20s} seed {s}: named {sorted(named)} ({dt:.1f} s)", flush=True)
    false = 0
    for s in range(args.clean):
        named, _, dt, _ = run({}, 5000 + s)
        times.append(dt)
        for n in named:
            confusion["none"][n] += 1
        false += bool(named)
        print(f"  none                 seed {s}: named {sorted(named)} ({dt:.1f} s)", flush=True)
    pair_ok = 0
    pairs = []
    for seed, pair in study_pairs(args.pairs):
        named, _, dt, _ = run({pair[0]: CONCEALED[pair[0]], pair[1]: CONCEALED[pair[1]]}, seed)
        ok = set(pair) <= named
        pair_ok += ok
        pairs.append((pair, sorted(named), ok))
        print(f"  pair {pair}: named {sorted(named)} {'OK' if ok else 'MISSED'}", flush=True)

    short = {n: n[:9] if n not in SIM_NAMES[3:4] and not n.startswith("scale_nonlinearity_") else
             {"scale_nonlinearity": "scale_nl", "scale_nonlinearity_even": "s_nl_even",
              "scale_nonlinearity_odd": "s_nl_odd"}[n] for n in NAMES}
    print("\nconfusion matrix (rows: true effect, columns: named effect; counts of recordings)")
    print(f"{'true':20s} " + " ".join(f"{short[n]:>9s}" for n in NAMES))
    for row in (*studied, "none"):
        print(f"{row:20s} " + " ".join(f"{confusion[row][n]:9d}" for n in NAMES))
    print("\ndetection rate per effect (target >= 90 %)")
    for name in studied:
        print(f"  {name:20s} {found[name]}/{args.seeds} = {100.0 * found[name] / max(args.seeds, 1):.0f} %")
    print(f"false-finding rate: {false}/{args.clean} = {100.0 * false / max(args.clean, 1):.1f} % (target <= 2 %)")
    print(f"pairs both found: {pair_ok}/{args.pairs}")
    if improvements:
        print(f"median fit improvement (block chi^2 before/after, worst axis): {np.median(improvements):.3f}")
    if times:
        print(f"diagnosis time per recording: median {np.median(times):.2f} s, max {np.max(times):.2f} s")

    plan = RigPlan(sample_rate_hz=100.0)  # default plan: ~14 min; stretch the rest to 15 min total
    plan = RigPlan(sample_rate_hz=100.0, rest_s=plan.rest_s + 85.0)
    res = simulate_session(1, plan=plan)
    t0 = time.perf_counter()
    diagnose(res.session)
    dt = time.perf_counter() - t0
    print(f"speed: {res.session.duration_s / 60:.1f}-minute {plan.sample_rate_hz:.0f} Hz recording "
          f"({len(res.session)} samples) diagnosed in {dt:.2f} s (target < 10 s)")
    if args.chamber:
        chamber(args.chamber)
    if args.sweep:
        sweep([n for n in args.sweep_effects.split(",") if n], args.sweep_seeds)


if __name__ == "__main__":
    main()
