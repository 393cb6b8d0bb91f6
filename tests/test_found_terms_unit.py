"""The found terms (gyro IEEE 952 polynomial, time offset) in the unit: their determinability, the JSON API, the
unit page and the certificate, and a production run that fits, writes and applies them."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from station.compose import Station, StationConfig
from station.eeprom.image import read_all_slots, select_image
from station.fit.calibrate import FitOptions, fit_session
from station.fit.export import left_out_notes
from station.kernel.found_terms import found_terms
from station.kernel.limits_file import load_limits
from station.kernel.parameters import ParameterSet
from station.kernel.virtual_clock import VirtualClock, acting
from station.physics.effects import Effects, EffectShapes
from station.sequence.limits import check_limits
from station.sequence.provision import ProvisionRecord
from station.sequence.records import Measured, Outcome
from station.session.csv_v1 import write_session
from station.session.model import Kind, Session
from station.sim.fakes import FakeStation
from station.sim.firmware import install_firmware
from station.sim.session_sim import simulate_session
from station.store import Recorder, open_database
from station.store.certificate import unit_certificate
from station.web.app import create_app
from tests.test_web_api import run_records

W200 = math.radians(200.0)
AUTO = FitOptions(scale_nonlinearity="auto", time_offset="auto", tc_range_s={"accel": (50.0, 167.0),
                                                                             "gyro": (1030.0, 3760.0)})
TAU_S = 4e-3
RUN = "run-found-1"


def _planted(seed: int) -> tuple[Session, np.ndarray]:
    """A simulated recording with a gyro k2 of 0.1 % at 200 deg/s per axis and a 4 ms time offset."""
    rng = np.random.default_rng(seed)
    k2 = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.5, 1.0, 3) * 1e-3 / W200
    et = Effects(time_offset=TAU_S * 1e3).realize(EffectShapes.draw(rng))
    return simulate_session(seed, effect_truth=replace(et, gyro_quadratic=k2)).session, k2


def _without_move_references(s: Session) -> Session:
    """The recording as the station's capture makes it: no reference in the moves."""
    move = s.kind == Kind.MOVE
    f, w = s.ref_accel_mps2.copy(), s.ref_gyro_radps.copy()
    f[move], w[move] = np.nan, np.nan
    return replace(s, ref_accel_mps2=f, ref_gyro_radps=w)


@pytest.fixture(scope="module")
def planted() -> tuple[Session, np.ndarray, ParameterSet]:
    session, k2 = _planted(341)
    return session, k2, fit_session(session, AUTO)


def test_found_terms_fitted_with_their_uncertainty(planted: tuple[Session, np.ndarray, ParameterSet]) -> None:
    _, k2, params = planted
    found = found_terms(params)
    t = found.time_offset
    assert t.status == "fitted" and t.applied
    assert abs(t.value - TAU_S) < 4 * t.std and 0 < t.std < 1e-3
    assert "ms" in t.shown() and "±" in t.shown()
    by_name = {f.name: f for f in found.polynomial}
    for k, a in enumerate("xyz"):
        f = by_name[f"gyro.k2.{a}"]
        assert f.status == "fitted" and abs(f.value - k2[k]) < 4 * f.std
        assert f.value == params.gyro.scale_quadratic[k]
        assert by_name[f"gyro.k3.{a}"].status == "not_significant"  # none planted: estimated, not kept
        assert math.isnan(by_name[f"gyro.k3.{a}"].value) and "not kept" in by_name[f"gyro.k3.{a}"].shown()
    notes = left_out_notes(params)  # an imu_tk / OpenAXES export says what it cannot carry
    assert any("k2, k3" in n for n in notes) and any("time offset" in n for n in notes)
    d = found.to_dict()
    assert d["time_offset"]["status"] == "fitted" and d["polynomial"][3]["value"] is None


def test_not_determined_and_not_fitted_are_flagged_not_numbers(
        planted: tuple[Session, np.ndarray, ParameterSet]) -> None:
    session, _, _ = planted
    params = fit_session(_without_move_references(session), AUTO)
    t = found_terms(params).time_offset
    assert t.status == "not_determined" and math.isnan(t.value) and t.shown() == "not determined"
    assert "transitions" in t.reason and params.time_offset_s == 0.0
    off_set = fit_session(session, replace(AUTO, time_offset="off", scale_nonlinearity="off"))
    off = found_terms(off_set)
    assert {f.status for f in off.terms} == {"not_fitted"} and "switched off" in off.time_offset.reason
    off_set.source["line"] = {"transfer_s": 30.0}  # what the line's rig role marks its joint fits with
    assert all("joint fit" in f.reason for f in found_terms(off_set).terms)
    # a rig plan without negative rates cannot separate k2 from the bias: not determined, with the rig step
    one_sign = replace(session, ref_gyro_radps=np.where(session.ref_gyro_radps < 0, np.nan, session.ref_gyro_radps))
    poly = found_terms(fit_session(one_sign, AUTO)).polynomial
    k2 = [f for f in poly if f.name.startswith("gyro.k2.")]
    assert all(f.status == "not_determined" and "other direction" in f.reason for f in k2)


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory,
          planted: tuple[Session, np.ndarray, ParameterSet]) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("found")
    session, _, params = planted
    session_path, params_path = tmp / "unit.csv", tmp / "unit.params.json"
    write_session(session, session_path)
    params_path.write_text(params.to_json(), encoding="utf-8")
    limits = load_limits()
    measured = [Measured(RUN, 0, params.serial, "limits", c) for c in check_limits(params, limits.product)]
    db = open_database(f"sqlite:///{tmp / 'station.sqlite'}")
    from station.store.recorder import RunContext

    recorder = Recorder(db, RunContext(limits_version=f"{limits.name} {limits.version}", limits_hash=limits.sha256))
    for r in run_records(RUN, "2026-11-28T10:00:00+00:00",
                         [(params.serial, Outcome.PASS, measured, str(session_path), str(params_path))]):
        recorder(r)
    assert recorder.errors == []
    yield {"db": db, "params": params}
    db.close()


def test_api_page_and_certificate_carry_the_found_terms(store: dict[str, Any]) -> None:
    params: ParameterSet = store["params"]
    assert params.to_dict()["format"] == "station-params/3"
    with TestClient(create_app(database=store["db"])) as client:
        body = client.get(f"/api/units/{params.serial}").json()
        page = client.get(f"/units/{params.serial}").text
    p = body["latest_params"]
    assert p["gyro"]["scale_quadratic"] == pytest.approx(list(params.gyro.scale_quadratic), rel=1e-12)
    assert p["gyro"]["scale_quadratic_std"] == pytest.approx(list(params.gyro.scale_quadratic_std), rel=1e-12)
    assert p["time_offset_std_s"] == pytest.approx(params.time_offset_std_s, rel=1e-12)
    ft = p["found_terms"]
    assert ft["time_offset"]["status"] == "fitted"
    assert ft["time_offset"]["value"] == pytest.approx(params.time_offset_s, rel=1e-12)
    # the gyro's planted k2 kept, its k3 estimated and not kept; the accelerometer on a 1 g rig of face poses:
    # neither term determined (one magnitude of specific force along each axis), the poses that would help named
    assert [t["status"] for t in ft["polynomial"]] == (["fitted"] * 3 + ["not_significant"] * 3
                                                       + ["not_determined"] * 6)
    assert all("tilted" in t["reason"] and t["value"] is None for t in ft["polynomial"][6:])
    assert ft["polynomial"][4]["value"] is None and ft["polynomial"][4]["z"] is not None
    assert 'id="found-terms"' in page and 'data-name="gyro.k2.x" data-status="fitted"' in page
    assert 'data-name="time_offset" data-status="fitted"' in page
    cert = unit_certificate(store["db"], params.serial)
    for k, a in enumerate("xyz"):
        row = cert.parameter(f"gyro.k2.{a}")
        assert row.value_si == params.gyro.scale_quadratic[k] and row.u_si == params.gyro.scale_quadratic_std[k]
        assert "ppm/(deg/s)" in row.shown()
        with pytest.raises(KeyError):  # estimated, not kept: no row
            cert.parameter(f"gyro.k3.{a}")
        for term in ("k2", "k3"):  # not determined: a row without a number
            accel_row = cert.parameter(f"accel.{term}.{a}")
            assert math.isnan(accel_row.value_si) and accel_row.group == "accelerometer"
    tau = cert.parameter("time_offset_s")
    assert tau.value_si == params.time_offset_s and tau.u_si == params.time_offset_std_s and "ms" in tau.shown()


def test_production_run_fits_writes_and_applies_k2() -> None:
    """The composition root's run on a simulated station: a unit with a planted gyro k2 is fitted with it
    (kept on every axis, within 4 sigma), its image is layout 3 holding k2, and the on-rig verification of the
    firmware's corrected output meets its limits; the time offset, which the station's capture (no references
    in the moves) cannot determine, is flagged not_determined and not written."""
    k2 = np.array([6e-4, -8e-4, 7e-4]) / W200
    clock = VirtualClock()
    records: dict[str, ProvisionRecord] = {}
    with acting(clock, name="test"), FakeStation(1, 30.0, 12, clock=clock, effects=Effects(time_offset=3.0),
                                                 effect_change=lambda _, et: replace(et, gyro_quadratic=k2)) as sim:
        install_firmware(sim.units[0].sensor, sim.clock)
        config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="found", record=False, out_dir=None,
                               plan=sim.plan, rig_options=sim.rig_client_options(), provision=True)
        station = Station(config, clock=sim.clock, on_provision=lambda r: records.__setitem__(r.serial, r))
        result = station.run()
        eeprom = sim.units[0].sensor.eeprom.image()
    unit = result.units[0]
    assert unit.outcome is Outcome.PASS, unit.message
    p = unit.params
    assert p is not None
    assert np.all(np.abs(p.gyro.scale_quadratic - k2) < 4 * p.gyro.scale_quadratic_std)
    assert p.quality.time_offset is not None and p.quality.time_offset.status == "not_determined"
    assert p.time_offset_s == 0.0
    slot = select_image(read_all_slots(eeprom), p.serial)
    assert slot is not None and slot.image is not None
    img = slot.image
    assert img.layout_version == 3
    assert img.effects is not None and np.array_equal(img.effects.quadratic[1], p.gyro.scale_quadratic)
    assert img.effects.time_offset_s == 0.0
    rec = records[p.serial]
    assert rec.verification is not None and rec.verification.passed
    rate_error = {c.name: c.value for c in rec.verification.checks}["verify.rate.rate_error"]
    assert abs(rate_error) < 2e-3 * math.pi / 180  # the planted k2 alone: 0.007-0.011 deg/s at 50 deg/s
