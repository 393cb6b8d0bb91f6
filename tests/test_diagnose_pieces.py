"""The diagnosis a piece of samples at a time: block means, regressors and the findings do not depend on the pieces.

The candidates' regressors are asked for a piece of samples at a time (``candidates.Rows``) and block-averaged
piece by piece (``SensorData.block_mean_of``), so that a long recording's (n, 3, p) arrays are never held. Here the
pieces are made small (``residuals.PIECE_ROWS``) so that a short recording is cut into many of them, and every
number is compared with the whole-recording computation: the sparse 0/1 block-sum matrix the block means were
taken with before, each candidate's whole array, and a diagnosis with a single piece.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import sparse

from station.diagnose import diagnose, residuals
from station.diagnose.candidates import delay_regressor, delay_rows
from station.diagnose.effect_registry import LIBRARY
from station.diagnose.residuals import Baseline, SensorData, fit_baseline
from station.fit.calibrate import mean_model
from station.kernel.plan import RigPlan
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

#: A short plan (~4 min at 100 Hz): rest, the six poses, rate steps about every axis.
PLAN = RigPlan(rest_s=60.0, pose_hold_s=10.0, rate_steps=tuple((a, s * 100.0) for a in "xyz" for s in (1.0, -1.0)),
               rate_hold_s=5.0)
SMALL_PIECE = 3_001


@pytest.fixture(scope="module")
def baseline() -> Baseline:
    res = simulate_session(7, plan=PLAN, effects=Effects.parse("lever_arm=20,pose_tilt=0.1,g_sensitivity=0.05"))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(residuals, "PIECE_ROWS", SMALL_PIECE)
        b = fit_baseline(res.session)
        for sd in (b.accel, b.gyro):
            assert len(sd.pieces) > 5  # cut while the small piece size holds (cached per triad)
    return b


def _block_mean_sparse(sd: SensorData, values: np.ndarray) -> np.ndarray:
    """Block means as they were taken before: one product with a sparse (blocks x samples) 0/1 matrix."""
    idx = np.flatnonzero(sd.label >= 0)
    m = sparse.csr_array((np.ones(idx.size), (sd.label[idx], idx)), shape=(len(sd.t_s), len(sd.label)))
    flat = np.asarray(values, dtype=float).reshape(len(values), -1)
    return ((m @ flat) / sd.count[:, None]).reshape((len(sd.t_s), *values.shape[1:]))


def test_pieces_cover_the_samples_and_cut_no_block(baseline: Baseline) -> None:
    for sd in (baseline.accel, baseline.gyro):
        edges = [lo for lo, _ in sd.pieces] + [sd.pieces[-1][1]]
        assert edges[0] == 0 and edges[-1] == len(sd.label)
        assert all(a < b for a, b in itertools.pairwise(edges))
        for cut in edges[1:-1]:  # no block has samples on both sides of a cut
            before, after = sd.label[:cut], sd.label[cut:]
            assert not set(before[before >= 0]) & set(after[after >= 0])


def test_block_means_by_pieces_are_the_sparse_products_bit_for_bit(baseline: Baseline) -> None:
    for sd in (baseline.accel, baseline.gyro):
        for values in (sd.ref, sd.u, sd.residual, baseline.d_temp):  # the residual: rows made when asked
            assert np.array_equal(sd.block_mean(values), _block_mean_sparse(sd, values[:]))


def test_residual_rows_are_the_whole_residual_bit_for_bit(baseline: Baseline) -> None:
    """The residual made a piece (or a segment) at a time is the measurement minus the mean model of the whole
    recording, as it was computed and kept before; its block means are the one-pass sums of that array."""
    session = baseline.session
    for sd, data in ((baseline.accel, session.accel_mps2), (baseline.gyro, session.gyro_radps)):
        whole = data - mean_model(residuals._triad_dict(sd.params), session.t_s, sd.ref, session.ref_accel_mps2)
        assert np.array_equal(sd.residual[:], whole)
        assert np.array_equal(np.concatenate([sd.residual[lo:hi] for lo, hi in sd.pieces]), whole)
        segs = [s for s in session.segments() if len(s)]
        assert np.array_equal(np.concatenate([sd.residual[s.start:s.stop] for s in segs]),
                              whole[segs[0].start:segs[-1].stop])
        sel = sd.label >= 0
        one_pass = np.stack([np.bincount(sd.label[sel], weights=whole[sel, j], minlength=len(sd.t_s))
                             for j in range(3)], axis=1) / sd.count[:, None]
        assert np.array_equal(sd.y, one_pass)


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_each_candidates_rows_are_its_whole_array(baseline: Baseline, name: str) -> None:
    effect = LIBRARY[name]
    for sd in (baseline.accel, baseline.gyro):
        if sd.sensor not in effect.sensors:
            continue
        z = effect.regressors(baseline, sd)
        rows = effect.regressor_rows(baseline, sd)
        assert (z is None) == (rows is None)
        if z is None or rows is None:
            continue
        assert np.any(z)  # the recording excites it: the comparison is not one of zeros
        pieces = np.concatenate([rows.of(lo, hi) for lo, hi in sd.pieces])
        assert np.array_equal(pieces, z)
        assert np.array_equal(sd.block_mean_of(rows.of), _block_mean_sparse(sd, z))


@pytest.mark.parametrize("tau_s", [0.0, 0.004, -0.02])
def test_delay_rows_are_the_whole_delay_regressor(baseline: Baseline, tau_s: float) -> None:
    sd = baseline.accel
    rows = delay_rows(baseline, sd, tau_s)
    whole = delay_regressor(baseline, sd, tau_s)
    assert np.any(whole)
    assert np.array_equal(np.concatenate([rows.of(lo, hi) for lo, hi in sd.pieces]), whole)


def test_findings_do_not_depend_on_the_pieces(monkeypatch: pytest.MonkeyPatch) -> None:
    """One small case's diagnosis with many pieces and with one: the same JSON (findings and every number)."""
    session = simulate_session(8, plan=PLAN, effects=Effects.parse("lever_arm=30,pose_tilt=0.1")).session
    one = diagnose(session, resamples=0).to_json()
    monkeypatch.setattr(residuals, "PIECE_ROWS", SMALL_PIECE)
    many = diagnose(session, resamples=0).to_json()
    assert {(f["effect"], f["sensor"]) for f in one["findings"]} >= {("lever_arm", "accel")}
    assert many == one
