"""Stale per-axis gyro reads (station.fit.readtiming) in the rig-free fit.

A simulated hand-held recording read by a logger whose clock beats against the gyro's ODR: each axis
repeats a sample once per ``P`` reads, the axes a read or two apart (the OpenAXES logger's pattern). The
model must find the beat (P within its stated uncertainty), and the fit integrating the sensor's own
samples must recover the gyro's M within its (much smaller) uncertainties; on the
same recording without stale reads the model must not be selected. Seeds 330.. (other tests use 300..).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.fit.readtiming import detect_stale_reads
from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free
from station.kernel.sensor_class import TABLE1
from station.session.multipos_import import import_imu_tk
from station.sim.handheld import HandheldResult, counts_with_offsets, simulate_handheld

TC_PRIOR = {"accel": TABLE1.accel_correlation_time_s, "gyro": TABLE1.gyro_correlation_time_s}
SEED = 330
BEAT = 77.3  # reads per beat: the ODR is (P - 1) / P of the read rate
LAG = (0.0, 1.6 / BEAT, 3.1 / BEAT)  # each axis read this fraction of a read period after x: 1.6, 3.1 reads of beat


def _stale_read_counts(res: HandheldResult, g_counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The gyro counts a logger reads at the recording's rate from a sensor sampling at ``(P - 1) / P`` of it.

    Read k of axis i (at ``k + lag_i`` read periods) returns the sensor's latest sample
    ``m = floor((k + lag_i) (P - 1) / P)``, taken at
    ``m P / (P - 1)`` read periods: the simulated counts interpolated there (the sensor's own time base).
    Returns (counts read, stale mask (n, 3): read k repeats read k - 1)."""
    n = len(g_counts)
    k = np.arange(n, dtype=float)
    out = np.empty_like(g_counts, dtype=float)
    stale = np.zeros((n, 3), dtype=bool)
    for i in range(3):
        m = np.floor((k + LAG[i]) * (BEAT - 1.0) / BEAT)
        out[:, i] = np.round(np.interp(m * BEAT / (BEAT - 1.0), k, g_counts[:, i]))
        stale[1:, i] = m[1:] == m[:-1]
    return out, stale


def _session(folder: Path, stale: bool):  # type: ignore[no-untyped-def]
    res = simulate_handheld(SEED)
    a_cnt, g_cnt, _, g_off, a_sens, g_sens = counts_with_offsets(res, np.random.default_rng(SEED + 10**6))
    g_float = res.gyro_radps * g_sens + g_off  # before the ADC's rounding, so the interpolation is the sensor's
    if stale:
        g_cnt, mask = _stale_read_counts(res, g_float)
    else:
        mask = np.zeros_like(g_cnt, dtype=bool)
    acc, gyr = folder / f"acc_{stale}.txt", folder / f"gyro_{stale}.txt"
    np.savetxt(acc, np.column_stack([res.t_s, a_cnt]), fmt=["%.6f", "%.0f", "%.0f", "%.0f"])
    np.savetxt(gyr, np.column_stack([res.t_s, g_cnt]), fmt=["%.6f", "%.0f", "%.0f", "%.0f"])
    session = import_imu_tk(acc, gyr, accel_lsb_per_mps2=a_sens, gyro_lsb_per_radps=g_sens, gravity_mps2=9.8128)
    return session, res, mask


def _truth_gyro(res: HandheldResult) -> np.ndarray:
    q, r = np.linalg.qr(np.linalg.inv(res.truth.accel.misalignment))
    return res.truth.gyro.misalignment @ (q * np.sign(np.diag(r)))


@pytest.fixture(scope="module")
def planted(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    return _session(tmp_path_factory.mktemp("stale"), stale=True)


def test_the_beat_is_found_with_an_honest_uncertainty(planted) -> None:  # type: ignore[no-untyped-def]
    session, _, mask = planted
    sigma = np.std(np.diff(session.gyro_radps[:2000], axis=0), axis=0) / np.sqrt(2.0)  # the initial still's
    t = detect_stale_reads(session.gyro_radps, sigma)
    assert t.selected, t.reason
    assert abs(t.period_reads - BEAT) <= 3.0 * t.period_std, (t.period_reads, t.period_std)
    assert t.period_std < 0.05
    assert abs(t.drift_reads) <= 3.0 * t.drift_std + 1e-6  # no drift planted
    assert np.allclose(np.diff(t.offsets), np.diff(LAG) * BEAT, atol=0.6)  # a later-read axis repeats later
    # the stale reads placed by the model are the planted ones (up to a read where the axis hardly moves)
    agree = np.mean(t.stale[mask])
    assert agree > 0.9 and abs(int(t.stale.sum()) - int(mask.sum())) <= 6


def test_fit_on_the_sensor_samples_recovers_gyro_m(planted) -> None:  # type: ignore[no-untyped-def]
    session, res, _ = planted
    m_w = _truth_gyro(res)
    on = fit_rig_free(session, RigFreeOptions(cv_folds=0, tc_range_s=TC_PRIOR))
    off = fit_rig_free(session, RigFreeOptions(cv_folds=0, tc_range_s=TC_PRIOR, read_timing=False))
    assert on.quality.rig_free["read_timing"]["selected"]
    assert not off.quality.rig_free["read_timing"]["selected"]
    z_on = ((on.gyro.misalignment - m_w) / on.gyro.misalignment_std).ravel()
    z_off = ((off.gyro.misalignment - m_w) / off.gyro.misalignment_std).ravel()
    assert np.max(np.abs(z_on)) <= 3.5, np.round(z_on, 2)
    # integrating the reads (stale ones included) at the read period gets the scale right on average (P reads
    # hold P - 1 samples of P / (P - 1) read periods each) but each move wrong by the extra sample it holds:
    # unbiased, only much less precise
    assert np.max(np.abs(z_off)) <= 3.5, np.round(z_off, 2)
    ratio = np.median(off.gyro.misalignment_std / on.gyro.misalignment_std)
    assert ratio > 2.0, ratio
    rms_on = on.quality.rig_free["gyro_direction_rms_deg"]
    rms_off = off.quality.rig_free["gyro_direction_rms_deg"]
    assert rms_on < 0.5 * rms_off, (rms_on, rms_off)


def test_not_selected_without_stale_reads(tmp_path: Path) -> None:
    session, _, _ = _session(tmp_path, stale=False)
    sigma = np.std(np.diff(session.gyro_radps[:2000], axis=0), axis=0) / np.sqrt(2.0)
    t = detect_stale_reads(session.gyro_radps, sigma)
    assert not t.selected and not t.stale.any(), t.reason
    p = fit_rig_free(session, RigFreeOptions(cv_folds=0, tc_range_s=TC_PRIOR))
    q = p.quality.rig_free["read_timing"]
    assert not q["selected"] and q["stale_reads"] == [0, 0, 0]


def test_sensor_samples_drop_the_stale_reads_and_align_the_axes() -> None:
    # a ramp per axis read with one stale read per axis at reads 10, 12, 14: the sensor samples are the ramp
    n = 30
    truth = np.column_stack([np.arange(n), 100 + np.arange(n), 200 + np.arange(n)]).astype(float)
    reads = np.empty_like(truth)
    stale = np.zeros((n, 3), dtype=bool)
    for i, k in enumerate((10, 12, 14)):
        m = np.arange(n) - (np.arange(n) >= k)
        reads[:, i] = truth[m, i]
        stale[k, i] = True
    t = detect_stale_reads(reads, np.ones(3))  # too few repeats: not selected
    assert not t.selected
    from dataclasses import replace

    t = replace(t, selected=True, stale=stale, period_reads=1000.0, drift_reads=0.0, offsets=np.array([10.0, 12, 14]))
    s = t.sensor_samples(reads, 0, n)
    assert np.array_equal(s, truth[: n - 1])
    assert t.odr_ratio(0.0) == pytest.approx(1000.0 / 999.0)
