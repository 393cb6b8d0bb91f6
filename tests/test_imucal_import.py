"""Importing the real imucal recordings (shared/real/imucal, read-only) into Sessions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from realdata import DATA_SETS, real_path

from station.kernel.errors import FormatError
from station.session import Kind, Session, format_session, parse_session
from station.session.imucal_import import import_imucal_annotated, import_imucal_ferraris

REAL = real_path("imucal")
FERRARIS_CSV = REAL / "example_ferraris_session.csv"
FERRARIS_JSON = REAL / "example_ferraris_session_list.json"
ANNOTATED_CSV = REAL / "annotated_session.csv"
G = 9.81

needs_real = pytest.mark.real(*DATA_SETS["imucal"])

POSE_UP = {"x_p": (0, 1.0), "x_a": (0, -1.0), "y_p": (1, 1.0), "y_a": (1, -1.0), "z_p": (2, 1.0), "z_a": (2, -1.0)}
ROT_AXIS = {"x_rot": 0, "y_rot": 1, "z_rot": 2}


@pytest.fixture(scope="module")
def ferraris() -> Session:
    return import_imucal_ferraris(FERRARIS_CSV, FERRARIS_JSON)


@pytest.fixture(scope="module")
def annotated() -> Session:
    return import_imucal_annotated(ANNOTATED_CSV)


def check_pose(session: Session, index: int, label: str) -> np.ndarray:
    """The segment is a pose with +-g on the right axis, zero gyro reference; returns its mean accel."""
    seg = next(s for s in session.segments() if s.index == index)
    assert seg.kind is Kind.POSE
    axis, sign = POSE_UP[label]
    expected = np.zeros(3)
    expected[axis] = sign * G
    np.testing.assert_array_equal(session.ref_accel_mps2[seg.slice], np.tile(expected, (len(seg), 1)))
    np.testing.assert_array_equal(session.ref_gyro_radps[seg.slice], 0.0)
    mean = session.accel_mps2[seg.slice].mean(axis=0)
    # the measured specific force lies along the reference axis with the reference's sign (uncalibrated
    # sensors: off-axis components are biases/misalignment of a few percent of g)
    assert int(np.argmax(np.abs(mean))) == axis and np.sign(mean[axis]) == sign, (label, mean)
    return mean


def check_pose_norms(means: list[np.ndarray]) -> None:
    norms = np.linalg.norm(means, axis=1)
    assert np.all(np.abs(norms / G - 1.0) < 0.08), norms  # single uncalibrated poses: bias + scale errors
    assert abs(norms.mean() / G - 1.0) < 0.02, norms  # biases largely cancel over the six poses


def check_round_trip(session: Session) -> None:
    text = format_session(session)
    back = parse_session(text)
    assert format_session(back) == text
    assert dict(back.angles_deg) == dict(session.angles_deg)
    np.testing.assert_allclose(back.accel_mps2, session.accel_mps2, rtol=0, atol=5.1e-7)
    np.testing.assert_allclose(np.rad2deg(back.gyro_radps), np.rad2deg(session.gyro_radps), rtol=0, atol=5.1e-7)
    np.testing.assert_array_equal(np.isnan(back.ref_accel_mps2), np.isnan(session.ref_accel_mps2))


@needs_real
def test_ferraris_segments_follow_the_section_list(ferraris: Session) -> None:
    sections = json.loads(FERRARIS_JSON.read_text())
    ordered = sorted(sections.items(), key=lambda item: item[1]["start"])
    segments = ferraris.segments()
    # leading gap + 9 labelled parts + 8 gaps between them + trailing gap
    assert len(segments) == 19
    assert [s.index for s in segments] == list(range(19))
    for k, (label, bounds) in enumerate(ordered):
        seg = segments[2 * k + 1]
        assert (seg.start, seg.stop) == (bounds["start"], bounds["end"])
        assert seg.kind is (Kind.POSE if label in POSE_UP else Kind.MOVE)
    for seg in segments[::2]:  # unlabelled stretches
        assert seg.kind is Kind.MOVE
        assert np.isnan(ferraris.ref_accel_mps2[seg.slice]).all()
        assert np.isnan(ferraris.ref_gyro_radps[seg.slice]).all()
    assert len(ferraris) == 10376 and segments[-1].stop == 10376


@needs_real
def test_ferraris_units_time_and_metadata(ferraris: Session) -> None:
    raw = pd.read_csv(FERRARIS_CSV)
    np.testing.assert_allclose(ferraris.t_s, raw["n_samples"].to_numpy() / 102.4, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ferraris.accel_mps2[123], raw.loc[123, ["acc_x", "acc_y", "acc_z"]].to_numpy(float))
    np.testing.assert_allclose(
        ferraris.gyro_radps[123], np.deg2rad(raw.loc[123, ["gyr_x", "gyr_y", "gyr_z"]].to_numpy(float))
    )
    assert np.isnan(ferraris.temp_degc).all()
    assert ferraris.serial == "imucal-example"
    assert ferraris.sample_rate_hz == 102.4 and ferraris.gravity_mps2 == 9.81
    assert ferraris.metadata["source"] == "imucal"
    assert ferraris.metadata["source_file"] == "example_ferraris_session.csv"


@needs_real
def test_ferraris_pose_references_and_gravity(ferraris: Session) -> None:
    sections = json.loads(FERRARIS_JSON.read_text())
    ordered = [label for label, _ in sorted(sections.items(), key=lambda item: item[1]["start"])]
    means = [check_pose(ferraris, 2 * k + 1, label) for k, label in enumerate(ordered) if label in POSE_UP]
    assert len(means) == 6
    check_pose_norms(means)


@needs_real
def test_ferraris_rotations_carry_angles(ferraris: Session) -> None:
    assert dict(ferraris.angles_deg) == {13: (-360.0, 0.0, 0.0), 15: (0.0, -360.0, 0.0), 17: (0.0, 0.0, -360.0)}
    for index, axis in ((13, 0), (15, 1), (17, 2)):
        seg = next(s for s in ferraris.segments() if s.index == index)
        assert seg.kind is Kind.MOVE
        assert np.isnan(ferraris.ref_gyro_radps[seg.slice]).all()
        turned_deg = np.rad2deg(ferraris.gyro_radps[seg.slice, axis]).sum() / 102.4
        assert turned_deg == pytest.approx(-360.0, rel=0.05)  # the data agrees with imucal's default angle


@needs_real
def test_ferraris_round_trip(ferraris: Session) -> None:
    check_round_trip(ferraris)


@needs_real
def test_annotated_segments_in_time_order(annotated: Session) -> None:
    segments = annotated.segments()
    order = ["x_p", "x_a", "y_p", "y_a", "z_p", "z_a", "x_rot", "y_rot", "z_rot"]
    raw = pd.read_csv(ANNOTATED_CSV)
    counts = raw["part"].value_counts()
    assert [s.index for s in segments] == list(range(9))
    assert [len(s) for s in segments] == [int(counts[label]) for label in order]
    assert [s.kind for s in segments] == [Kind.POSE] * 6 + [Kind.MOVE] * 3
    assert dict(annotated.angles_deg) == {6: (-360.0, 0.0, 0.0), 7: (0.0, -360.0, 0.0), 8: (0.0, 0.0, -360.0)}
    for seg in segments[6:]:
        assert np.isnan(annotated.ref_accel_mps2[seg.slice]).all()
        assert np.isnan(annotated.ref_gyro_radps[seg.slice]).all()
    means = [check_pose(annotated, k, label) for k, label in enumerate(order[:6])]
    check_pose_norms(means)
    for seg, label in zip(segments[6:], order[6:], strict=True):
        turned_deg = np.rad2deg(annotated.gyro_radps[seg.slice, ROT_AXIS[label]]).sum() / 204.8
        # this sensor's gyro reports about +360 deg for the turn (opposite to imucal's default -360)
        assert abs(turned_deg) == pytest.approx(360.0, rel=0.05)


@needs_real
def test_annotated_units_and_time(annotated: Session) -> None:
    raw = pd.read_csv(ANNOTATED_CSV).sort_values("samples")
    np.testing.assert_allclose(annotated.t_s, raw["samples"].to_numpy() / 204.8, rtol=0, atol=1e-12)
    first = raw.iloc[0]
    assert first["part"] == "x_p"
    np.testing.assert_allclose(
        annotated.accel_mps2[0], first[["acc_x", "acc_y", "acc_z"]].to_numpy(float) / 2048.0 * 9.80665
    )
    np.testing.assert_allclose(
        annotated.gyro_radps[0], np.deg2rad(first[["gyr_x", "gyr_y", "gyr_z"]].to_numpy(float) / 16.4)
    )
    assert annotated.sample_rate_hz == 204.8 and annotated.metadata["source"] == "imucal"
    assert annotated.metadata["source_file"] == "annotated_session.csv"


@needs_real
def test_annotated_round_trip(annotated: Session) -> None:
    check_round_trip(annotated)


# --------------------------------------------------------------------------- malformed imucal inputs (synthetic)


def write_ferraris(tmp_path: Path, sections: object, n: int = 50) -> tuple[Path, Path]:
    csv_path = tmp_path / "s.csv"
    frame = pd.DataFrame({"n_samples": np.arange(n)})
    for column in ("gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y"):
        frame[column] = 0.0
    frame["acc_z"] = G
    frame.to_csv(csv_path, index=False)
    json_path = tmp_path / "s.json"
    json_path.write_text(json.dumps(sections))
    return csv_path, json_path


def test_synthetic_ferraris_minimal(tmp_path: Path) -> None:
    csv_path, json_path = write_ferraris(tmp_path, {"z_p": {"start": 10, "end": 20}, "z_rot": {"start": 30, "end": 40}})
    s = import_imucal_ferraris(csv_path, json_path, serial="U1")
    assert [(g.index, g.kind, g.start, g.stop) for g in s.segments()] == [
        (0, Kind.MOVE, 0, 10),
        (1, Kind.POSE, 10, 20),
        (2, Kind.MOVE, 20, 30),
        (3, Kind.MOVE, 30, 40),
        (4, Kind.MOVE, 40, 50),
    ]
    np.testing.assert_array_equal(s.ref_accel_mps2[15], [0.0, 0.0, G])
    assert dict(s.angles_deg) == {3: (0.0, 0.0, -360.0)}
    assert s.serial == "U1"


@pytest.mark.parametrize(
    ("sections", "fragment"),
    [
        ({"x_p": {"start": 0, "end": 20}, "x_a": {"start": 10, "end": 30}}, "overlaps"),
        ({"w_p": {"start": 0, "end": 20}}, "unknown section"),
        ({"x_p": {"start": 0, "end": 500}}, "outside"),
        ({"x_p": {"start": 5}}, "'start' and 'end'"),
        (["x_p"], "expected an object"),
    ],
)
def test_bad_section_lists(tmp_path: Path, sections: object, fragment: str) -> None:
    csv_path, json_path = write_ferraris(tmp_path, sections)
    with pytest.raises(FormatError, match=fragment):
        import_imucal_ferraris(csv_path, json_path)


def test_bad_imucal_csv(tmp_path: Path) -> None:
    path = tmp_path / "a.csv"
    path.write_text("part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y\nx_p,0,1,2,3,4,5\n")
    with pytest.raises(FormatError, match="missing column"):
        import_imucal_annotated(path)
    path.write_text("part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\nx_p,0,1,2,3,4,5,6\nspin,1,1,2,3,4,5,6\n")
    with pytest.raises(FormatError, match="unknown part"):
        import_imucal_annotated(path)
    path.write_text("part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\nx_p,0,1,2,3,4,5,6\nx_a,0,1,2,3,4,5,6\n")
    with pytest.raises(FormatError, match="more than once"):
        import_imucal_annotated(path)
    with pytest.raises(FormatError, match="cannot read"):
        import_imucal_annotated(tmp_path / "missing.csv")
