"""The store-backed commands through the real `station` app: parameters, EEPROM image, Kalibr, dispositions."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from station.cli import app
from station.eeprom.image import decode_image
from station.fit.calibrate import fit_session
from station.kernel.parameters import ParameterSet
from station.sequence.records import Outcome
from station.sim.session_sim import simulate_session
from station.store.db import open_database
from station.store.queries import attempt_count, show_unit
from station.store.recorder import Recorder
from tests.test_store import synthetic_run


def test_parameters_image_kalibr_and_disposition_from_the_store(tmp_path: Path) -> None:
    sim = simulate_session(21)
    params = fit_session(sim.session)
    serial = params.serial
    url = f"sqlite:///{tmp_path / 'station.sqlite'}"
    records = synthetic_run("run-1", [serial], [Outcome.PASS], out_dir=tmp_path)
    (tmp_path / f"{serial}_run-1.params.json").write_text(params.to_json())
    with open_database(url) as db:
        rec = Recorder(db)
        for r in records:
            rec(r)
    cli = CliRunner()

    out = cli.invoke(app, ["units", "params", serial, "--db", url])
    assert out.exit_code == 0, out.output
    assert ParameterSet.from_json(out.output).to_json() == params.to_json()

    image = tmp_path / "image.bin"
    out = cli.invoke(app, ["eeprom", "image", serial, "-o", str(image), "--db", url])
    assert out.exit_code == 0, out.output
    img = decode_image(image.read_bytes())
    assert img.serial == serial
    assert img.to_params().accel.bias_static.tolist() == params.accel.bias_static.tolist()

    out = cli.invoke(app, ["eeprom", "kalibr", serial, "--db", url])
    assert out.exit_code == 0, out.output
    assert "gyroscope_noise_density" in out.output and "update_rate:" in out.output

    out = cli.invoke(app, ["eeprom", "image", "NOT-THERE", "-o", str(tmp_path / "x.bin"), "--db", url])
    assert out.exit_code == 2 and "no PASS parameter set" in out.output

    out = cli.invoke(app, ["units", "disposition", serial, "retest", "--reason", "re-seated", "--db", url])
    assert out.exit_code == 2 and "needs the operator" in out.output  # who decided is required
    out = cli.invoke(app, ["units", "disposition", "NOPE", "retest", "--operator", "qa", "--reason", "x",
                           "--db", url])
    assert out.exit_code == 2 and "no unit with serial 'NOPE'" in out.output  # no phantom unit
    out = cli.invoke(app, ["units", "disposition", serial, "maybe", "--operator", "qa", "--reason", "x", "--db", url])
    assert out.exit_code == 2 and "unknown decision 'maybe'" in out.output
    out = cli.invoke(app, ["units", "disposition", serial, "retest", "--operator", "qa", "--note", "re-seated",
                           "--db", url])
    assert out.exit_code == 0, out.output
    with open_database(url) as db:
        assert attempt_count(db, serial) == 0
        assert attempt_count(db, serial, since_disposition=False) == 0  # a PASS is no failed attempt
        assert show_unit(db, "NOPE") is None
    shown = json.loads(cli.invoke(app, ["units", "show", serial, "--json", "--db", url]).output)
    assert shown["runs"][0]["outcome"] == "PASS"
    listed = json.loads(cli.invoke(app, ["units", "list", "--json", "--db", url]).output)
    assert [u["serial"] for u in listed] == [serial]
    assert (listed[0]["runs"], listed[0]["last_outcome"], listed[0]["attempts"]) == (1, "PASS", 0)


def test_read_only_commands_never_create_a_database(tmp_path: Path) -> None:
    cli = CliRunner()
    missing = tmp_path / "nowhere.sqlite"
    for args in (["units", "list"], ["units", "show", "SN1"], ["units", "params", "SN1"],
                 ["eeprom", "image", "SN1", "-o", str(tmp_path / "x.bin")], ["eeprom", "kalibr", "SN1"]):
        out = cli.invoke(app, [*args, "--db", f"sqlite:///{missing}"])
        assert out.exit_code == 2, (args, out.output)
        assert "no station database at" in out.output and str(missing) in out.output, (args, out.output)
        assert not missing.exists(), args


def test_serve_refuses_a_corrupt_database_in_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "corrupt.sqlite"
    bad.write_bytes(b"this is not a database" * 100)
    out = CliRunner().invoke(app, ["serve", "--db", f"sqlite:///{bad}", "--port", "1"])
    assert out.exit_code == 2 and "Traceback" not in out.output
    assert "is not a SQLite database" in out.output and out.output.strip().count("\n") == 0, out.output
    assert bad.read_bytes() == b"this is not a database" * 100  # nothing written into it
