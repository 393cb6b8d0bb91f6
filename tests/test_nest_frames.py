"""Nest mounting errors: the rotation helpers, the versioned JSON, and the estimate from a reference unit."""

from __future__ import annotations

import numpy as np
import pytest

from station.fit.nest_estimate import NestFits, TriadFit, estimate_nest_calibration
from station.kernel.errors import FitError, UnsupportedVersionError
from station.kernel.nest_frames import (
    NestCalibration,
    nest_calibration_from_json,
    rotation_matrix,
    rotation_vector,
)


def test_rotation_vector_round_trip() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        v = rng.normal(0, 0.5, 3)
        r = rotation_matrix(v)
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(r) == pytest.approx(1.0)
        assert np.allclose(rotation_vector(r), v, atol=1e-12)
    assert np.allclose(rotation_matrix(np.zeros(3)), np.eye(3))
    # a right-hand rotation about z by 90 deg takes x to y
    assert np.allclose(rotation_matrix(np.array([0, 0, np.pi / 2])) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def _cal(rot: tuple[tuple[float, float, float], ...]) -> NestCalibration:
    return NestCalibration("rig-a", 3, "REF-1", "2026-11-28T00:00:00+00:00", rot,
                           tuple((0.001, 0.001, 0.001) for _ in rot), tuple(0.0 for _ in rot))


def test_references_go_into_the_sensor_frame() -> None:
    cal = _cal(((0.0, 0.0, 90.0), (0.0, 0.0, 0.0)))
    ref = np.array([[1.0, 0.0, 0.0], [np.nan, np.nan, np.nan]])
    out = cal.to_sensor_frame(0, ref)
    # R maps the sensor's x to the nest's y: a nest x reference is the sensor's -y
    assert np.allclose(out[0], [0.0, -1.0, 0.0], atol=1e-15)
    assert np.all(np.isnan(out[1]))
    assert np.array_equal(cal.to_sensor_frame(5, ref[:1]), ref[:1])  # a nest it does not cover: unchanged


def test_json_round_trip_and_refusals() -> None:
    cal = _cal(((0.1, -0.2, 0.05), (-0.1, 0.2, -0.05)))
    back = nest_calibration_from_json(cal.to_json())
    assert back == cal
    assert back.sha256 == cal.sha256
    assert cal.label.startswith("rig-a v3 (")
    with pytest.raises(UnsupportedVersionError):
        nest_calibration_from_json({**cal.to_json(), "format": "station-nests/2"})


def test_estimate_recovers_relative_nest_rotations() -> None:
    rng = np.random.default_rng(11)
    theta = np.radians(rng.normal(0, 0.3, (4, 3)))
    theta -= theta.mean(axis=0)
    m_a = np.eye(3) + rng.normal(0, 0.01, (3, 3))
    m_w = np.eye(3) + rng.normal(0, 0.003, (3, 3))
    std = np.full((3, 3), 1e-5)
    # A_j = M R_j^T, a common tilt of every nest added: it is not observable and must not matter
    common = rotation_matrix(np.radians([0.2, -0.1, 0.3]))
    per = {j: NestFits(TriadFit(m_a @ (rotation_matrix(theta[j]) @ common).T, std),
                       TriadFit(m_w @ (rotation_matrix(theta[j]) @ common).T, std)) for j in range(4)}
    cal = estimate_nest_calibration("rig", "REF", per)
    # first order in the tilts: ~1e-3 of 0.3 deg
    assert np.allclose(np.array(cal.rotations_deg), np.degrees(theta), atol=2e-3)
    assert max(cal.agreement_deg) < 1e-9  # the same mount seen by both triads, no noise
    with pytest.raises(FitError, match="nest 2"):
        estimate_nest_calibration("rig", "REF", {0: per[0], 2: per[2]})


def test_estimate_is_exact_for_large_tilts_and_absolute_with_a_reference() -> None:
    rng = np.random.default_rng(12)
    theta = np.radians(rng.normal(0, 0.7, (4, 3)))  # tilts up to ~1.5 deg, a common part included
    m_a = np.eye(3) + rng.normal(0, 0.01, (3, 3))
    m_w = np.eye(3) + rng.normal(0, 0.003, (3, 3))
    std = np.full((3, 3), 1e-5)
    per = {j: NestFits(TriadFit(m_a @ rotation_matrix(theta[j]).T, std),
                       TriadFit(m_w @ rotation_matrix(theta[j]).T, std)) for j in range(4)}
    absolute = estimate_nest_calibration("rig", "REF", per, NestFits(TriadFit(m_a, std), TriadFit(m_w, std)))
    assert absolute.datum == "reference"
    assert np.allclose(np.array(absolute.rotations_deg), np.degrees(theta), atol=1e-9)
    relative = estimate_nest_calibration("rig", "REF", per)
    assert relative.datum == "mean nest"
    rel = np.array(relative.rotations_deg)
    assert np.allclose(rel.sum(axis=0), 0.0, atol=1e-9)
    # the relative rotations between nests are exact: R_j R_k^T from the estimate equals the truth's
    for j in range(1, 4):
        est = rotation_matrix(np.radians(rel[j])) @ rotation_matrix(np.radians(rel[0])).T
        true = rotation_matrix(theta[j]) @ rotation_matrix(theta[0]).T
        assert np.allclose(est, true, atol=1e-12)
