"""A saturated (clipped) axis: ``station fit`` refuses it, the diagnosis censors and locates it.

The clipped recordings are made here, not by ``station.sim``: the rig, the sensor and the noise are
``tests/indepgen.py``'s (its own rotation code and sensor model), and the saturation is this file's own stage on
top, an output register that clips at a rail: every reading beyond ``+-L`` is written as the rail code ``+-L``
(``L`` on the generator's LSB grid, so the rail is one exact value). ``L`` is a fraction (85-97 %) of the axis's
output at the plan's top rate (the gyro), or of 1 g (the accelerometer: an output stage limiting below the class's
range), so the truth is known: the axis, the rail, the samples at it, the segments where they lie.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import indepgen
import numpy as np
import pytest
from typer.testing import CliRunner

from station.cli import app
from station.diagnose import diagnose
from station.diagnose.censoring import CURVE_POINTS, NEIGHBOURS_S, censor
from station.diagnose.results import FORMAT, FORMAT_CENSORED, ReportFormatError, load_report
from station.fit.calibrate import fit_session
from station.fit.checks import saturations
from station.kernel.errors import FitError
from station.sequence.runner import Outcome, refusal_outcome
from station.session import write_session
from station.session.model import Kind, Session

DEG = math.pi / 180.0
#: indepgen's converters (its ``generate``): gyro 2000 deg/s over 2^19 codes, accel 4 g over 2^17.
GYRO_LSB = 2000.0 * DEG / 2**19
ACCEL_LSB = 4.0 * indepgen.G0 / 2**17


def clip_axis(session: Session, sensor: str, axis: int, level: float) -> Session:
    """The output register at a rail: readings of ``axis`` beyond ``+-level`` are written as ``+-level``."""
    name = "gyro_radps" if sensor == "gyro" else "accel_mps2"
    data = np.array(getattr(session, name), dtype=float)
    data[:, axis] = np.clip(data[:, axis], -level, level)
    return session.replace(**{name: data})


def gyro_top_output(session: Session, axis: int) -> float:
    """The smaller of the axis's mean |output| in its top-rate holds of either sign (so both rails are hit)."""
    ref = np.nan_to_num(session.ref_gyro_radps[:, axis])
    rate = session.kind == int(Kind.RATE)
    top = np.abs(ref[rate]).max()
    outs = [np.abs(session.gyro_radps[rate & (sign * ref > 0.99 * top), axis]).mean() for sign in (1.0, -1.0)]
    return float(min(outs))


def clipped_gyro(seed: int) -> tuple[indepgen.Recording, Session, int, float]:
    """indepgen's recording of ``seed`` (no library effect) with one gyro axis (drawn) clipping at a rail of
    85-97 % (drawn) of its output at the plan's top rate."""
    rec = indepgen.generate(seed)
    rng = np.random.default_rng([seed, 0xC11])
    axis = int(rng.integers(3))
    level = math.floor(rng.uniform(0.85, 0.97) * gyro_top_output(rec.session, axis) / GYRO_LSB) * GYRO_LSB
    return rec, clip_axis(rec.session, "gyro", axis, level), axis, level


def _rate_kinds(session: Session, axis: int, level: float) -> set[int]:
    at = np.abs(session.gyro_radps[:, axis]) >= level
    return {int(k) for k in np.unique(session.kind[at])}


# --- dev seeds (320000-324999): three plans at 100, 200 and 400 Hz ---
SEEDS = (320003, 320000, 320001)


@pytest.fixture(scope="module", params=SEEDS)
def gyro_case(request: pytest.FixtureRequest) -> tuple[indepgen.Recording, Session, int, float, object]:
    rec, session, axis, level = clipped_gyro(request.param)
    return rec, session, axis, level, diagnose(session, resamples=0)


def test_seeds_cover_several_sample_rates() -> None:
    assert len({indepgen.generate(s).plan.rate_hz for s in SEEDS}) == 3


def test_fit_still_refuses_with_its_message() -> None:
    """``station fit``'s path: the same refusal (a FitError, one line, the segment and the rail) as before."""
    _, session, axis, level = clipped_gyro(SEEDS[0])
    with pytest.raises(FitError) as info:
        fit_session(session)
    msg = str(info.value)
    m = re.fullmatch(r"gyro ([xyz]) is saturated: (\d+) of (\d+) samples of rate segment (\d+) sit at its "
                     r"(maximum|minimum) (\S+)", msg)
    assert m is not None, msg
    assert m.group(1) == "xyz"[axis]
    assert abs(abs(float(m.group(6))) - level) <= 1e-5 * level  # printed to 6 digits
    first = saturations(session)[0]
    assert msg == first.reason
    # the production sequence's verdict on that refusal: a unit FAIL with the reason, not a station fault
    assert refusal_outcome(info.value) == (Outcome.FAIL, f"fit refused the recording: {msg}")


def test_clipped_gyro_located_not_a_finding(gyro_case: tuple) -> None:
    _, session, axis, level, d = gyro_case
    rep = d.report
    assert rep.to_json()["format"] == FORMAT_CENSORED
    assert rep.findings == ()  # the recording has no library effect; the clip is never a finding
    mine = [u for u in rep.unexplained if u.censored is not None]
    assert len(mine) == 1  # one entry for the axis, both rails in it
    for u in mine:
        c = u.censored
        assert (u.sensor, u.axes, c.axis) == ("gyro", ("xyz"[axis],), "xyz"[axis])
        assert "rate" in u.segment_kinds
        assert set(u.segment_kinds) <= {"rate", "move"}
        assert c.unit == "deg/s" and np.allclose(c.levels, (-level / DEG, level / DEG), atol=1e-3)
        assert "rate about" in u.covariate and "clips at" in u.covariate
        assert c.samples_at_level == int(np.count_nonzero(np.abs(session.gyro_radps[:, axis]) >= level))
        assert c.samples_excluded >= c.samples_at_level
        assert c.not_determined == ()
        assert "range is exceeded by the plan" in c.statement
        assert math.isnan(u.excess_chi2)
    # every sample at a rail lies in a censored segment (the gyro's reference taken away there, not the accel's)
    assert d.baseline is not None
    censored = d.baseline.session
    at = np.abs(session.gyro_radps[:, axis]) >= level
    assert np.all(np.isnan(censored.ref_gyro_radps[at])) and np.all(np.isfinite(censored.ref_accel_mps2[at]))
    assert {int(i) for i in np.unique(session.segment[at])} <= {i for u in mine for i in u.censored.segments}
    assert {"rate", "move"} >= {Kind(k).label for k in _rate_kinds(session, axis, level)}


def test_unclipped_axes_within_their_uncertainty(gyro_case: tuple) -> None:
    """The base fit on the censored recording: the other gyro axes' rows of M_w and every row of M_a within 4 of
    their stated standard uncertainties of indepgen's truth."""
    rec, _, axis, _, d = gyro_case
    assert d.baseline is not None
    p = d.baseline.params
    for sensor, rows in (("gyro", [k for k in range(3) if k != axis]), ("accel", [0, 1, 2])):
        tri = p.gyro if sensor == "gyro" else p.accel
        truth = np.asarray(rec.truth[f"{sensor}_m"])
        for k in rows:
            err = np.abs(tri.misalignment[k] - truth[k])
            assert np.all(err <= 4.0 * tri.misalignment_std[k] + 1e-9), (sensor, k, err, tri.misalignment_std[k])


def test_rest_of_the_diagnosis_unchanged(gyro_case: tuple) -> None:
    """The same recording without the clip: the same findings (none) and the same other unexplained entries."""
    rec, _, _, _, d = gyro_case
    plain = diagnose(rec.session, resamples=0).report
    others = {(u.sensor, u.axes, u.segment_kinds) for u in d.report.unexplained if u.censored is None}
    assert plain.effects == d.report.effects == []
    assert others == {(u.sensor, u.axes, u.segment_kinds) for u in plain.unexplained}
    assert plain.to_json()["format"] == FORMAT


def test_report_round_trip_and_versions(gyro_case: tuple) -> None:
    d = gyro_case[-1]
    out = d.report.to_json()
    assert load_report(out).to_json() == out
    with pytest.raises(ReportFormatError):
        load_report({**out, "format": "station-diagnosis/3"})


def test_every_hold_clipped_is_not_determined() -> None:
    """A rail below the lowest rate: every hold about the axis clips, its column of M_w has no data left: named
    not determined, no number printed for it, no base fit."""
    rec = indepgen.generate(SEEDS[0])
    ref = np.nan_to_num(rec.session.ref_gyro_radps[:, 1])
    low = np.abs(ref[(rec.session.kind == int(Kind.RATE)) & (np.abs(ref) > DEG)]).min()
    session = clip_axis(rec.session, "gyro", 1, math.floor(0.8 * low / GYRO_LSB) * GYRO_LSB)
    rep = diagnose(session, resamples=0).report
    assert rep.findings == () and rep.base_fit is None
    assert rep.unexplained and all(u.censored is not None for u in rep.unexplained)
    for u in rep.unexplained:
        assert u.censored.not_determined == ("M_w column y (gyro scale factor y and the cross-axis terms about y)",)
        assert "no rate step about y" in u.censored.reason
    out = rep.to_json()
    assert out["base_fit"] is None and out["format"] == FORMAT_CENSORED
    assert load_report(out).to_json() == out


def test_not_determined_plot_shows_the_recording_and_its_censored_part(tmp_path: Path) -> None:
    """No base fit, so no residual to draw: ``--plot`` draws the clipped sensor as recorded and what censoring
    leaves of it (NaN in every censored segment, the recording elsewhere), and the report is printed as well."""
    rec = indepgen.generate(SEEDS[0])
    ref = np.nan_to_num(rec.session.ref_gyro_radps[:, 1])
    low = np.abs(ref[(rec.session.kind == int(Kind.RATE)) & (np.abs(ref) > DEG)]).min()
    session = clip_axis(rec.session, "gyro", 1, math.floor(0.8 * low / GYRO_LSB) * GYRO_LSB)
    d = diagnose(session, resamples=0)
    (curve,) = d.curves
    assert curve.title == "gyro recording" and curve.labels == ("as recorded", "left after censoring")
    every = math.ceil(len(session) / CURVE_POINTS)
    assert len(curve.t_s) <= CURVE_POINTS and np.array_equal(curve.t_s, session.t_s[::every])
    assert np.array_equal(curve.before, session.gyro_radps[::every])
    (entry,) = [u.censored for u in d.report.unexplained if u.censored is not None]
    gone = np.zeros(len(session), dtype=bool)
    for g in session.segments():
        if g.index in entry.segments:
            gone[g.start:g.stop] = True
    gone = gone[::every]
    assert gone.any() and (~gone).any()
    assert np.isnan(curve.after[gone]).all() and np.array_equal(curve.after[~gone], curve.before[~gone])
    path, png = tmp_path / "clipped.csv", tmp_path / "clipped.png"
    write_session(session, path)
    out = CliRunner().invoke(app, ["diagnose", str(path), "--resamples", "0", "--plot", str(png)])
    assert out.exit_code == 0, out.output
    assert "UNEXPLAINED (gyro, axis y" in out.output and f"wrote {png}" in out.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_accel_output_stage_below_one_g() -> None:
    """An accelerometer axis limited at 0.93 g (below the class's +-4 g): every pose along it clips, so its row
    of M_a and its bias cannot be separated: located in the poses, not determined, no finding."""
    rec = indepgen.generate(SEEDS[1])
    level = math.floor(0.93 * indepgen.G0 / ACCEL_LSB) * ACCEL_LSB
    session = clip_axis(rec.session, "accel", 0, level)
    rep = diagnose(session, resamples=0).report
    mine = [u for u in rep.unexplained if u.censored is not None]
    assert mine and rep.findings == ()
    for u in mine:
        assert (u.sensor, u.axes) == ("accel", ("x",)) and "pose" in u.segment_kinds
        assert u.censored.unit == "mg"
        assert np.allclose(np.abs(u.censored.levels), level / (indepgen.G0 * 1e-3), atol=0.01)
        assert u.censored.not_determined and "M_a row x" in u.censored.not_determined[0]


def test_no_saturation_leaves_the_recording_alone() -> None:
    rec = indepgen.generate(SEEDS[2])
    c = censor(rec.session)
    assert c.entries == () and c.session is rec.session and c.determined


def test_neighbours_reach_into_the_segment_after() -> None:
    """A segment with a rail sample, or one within NEIGHBOURS_S of it (a filter's tail), is censored; no other."""
    _, session, axis, level = clipped_gyro(SEEDS[0])
    (entry,) = censor(session).entries
    at = np.flatnonzero(np.abs(session.gyro_radps[:, axis]) >= level)
    reach = math.ceil(NEIGHBOURS_S * session.sample_rate_hz)
    want = {g.index for g in session.segments() if np.any((at >= g.start - reach) & (at < g.stop + reach))}
    assert set(entry.segments) == want


def test_cli_fit_refuses_diagnose_reports(tmp_path: Path) -> None:
    """The same clipped file: ``station fit`` one line and a non-zero exit (as before), ``station diagnose`` a
    report (text and JSON) with the censored axis, exit 0."""
    _, session, axis, level = clipped_gyro(SEEDS[0])
    path = tmp_path / "clipped.csv"
    write_session(session, path)
    fit = CliRunner().invoke(app, ["fit", str(path)])
    lines = [ln for ln in fit.output.splitlines() if ln.strip()]
    assert fit.exit_code != 0 and len(lines) == 1
    assert lines[0].startswith(f"error: gyro {'xyz'[axis]} is saturated: "), fit.output
    text = CliRunner().invoke(app, ["diagnose", str(path), "--resamples", "0"])
    assert text.exit_code == 0, text.output
    assert f"UNEXPLAINED (gyro, axis {'xyz'[axis]}, in " in text.output and "censored" in text.output
    out = CliRunner().invoke(app, ["diagnose", str(path), "--json", "--resamples", "0"])
    assert out.exit_code == 0
    rep = json.loads(out.output)
    assert rep["format"] == FORMAT_CENSORED and rep["findings"] == []
    (entry,) = [u for u in rep["unexplained"] if "censored" in u]
    assert entry["excess_chi2"] is None and entry["censored"]["unit"] == "deg/s"
    assert np.allclose(entry["censored"]["levels"], [-level / DEG, level / DEG], atol=1e-3)
