"""``station line rack`` against a simulated rack (relay board on 127.0.0.1, sensors on ptys): the recordings
land in the database where the rig role finds them by serial."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from station.cli import app
from station.line.recordings import DatabaseArchive
from station.sim.rack_sim import SimRack
from station.store.db import open_database


def test_line_rack_stores_every_slot_and_line_rig_explains_itself(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    with SimRack(2, scale=30.0, seed=4) as rack:
        args = ["line", "rack", "--board", rack.board_url, "--rack-s", "30", "--scale", "30", "--db", url,
                "--station", "rack-7"]
        for u in rack.sensor_urls:
            args += ["--sensor", u]
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        serials = [t.serial for t in rack.truths]
    with open_database(url) as db:
        archive = DatabaseArchive(db.sessions)
        for slot, serial in enumerate(serials):
            stored = archive.latest(serial)
            assert stored is not None and stored.slot == slot and stored.station == "rack-7"
            assert 29.9 <= stored.session.duration_s <= 30.0
            assert f"slot {slot}: {serial}: " in result.output
    help_text = CliRunner().invoke(app, ["line", "rig", "--help"]).output
    assert "--plan" in help_text and "--back-to-rack" in help_text
