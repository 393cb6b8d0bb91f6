"""Test-wide hooks: the real-data switch (see tests/realdata.py) and a rig-lock directory per test session."""

from __future__ import annotations

import pytest
import realdata


@pytest.fixture(autouse=True)
def _own_rig_lock_dir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """Rig locks (flock files named after the rig URL) in this test session's own directory: two test runs on
    one machine (or a station running beside them) never hold each other's rigs. A test may set its own."""
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path_factory.getbasetemp() / "rig-locks"))


_skipped: dict[str, int] = {}  # data set -> tests skipped for it
REASON = "real recordings absent"


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "real(*paths): needs these files of the real recordings ($STATION_REAL, default ../shared/real)")


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    needed = tuple(p for m in item.iter_markers("real") for p in m.args)
    if not needed:
        return
    absent = realdata.missing(needed)
    if not absent:
        return
    where = realdata.real_dir()
    if realdata.in_ci():
        pytest.fail(f"CI=true and the real recordings are missing: {', '.join(absent)} under {where} "
                    f"(${realdata.ENV_VAR}); CI lays shared/ beside the repository", pytrace=False)
    for name in sorted({p.split('/', 1)[0] for p in absent}):
        _skipped[name] = _skipped.get(name, 0) + 1
    pytest.skip(f"{REASON} under {where}")


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if not _skipped:
        return
    _fold_into_one_line(terminalreporter)
    sets = ", ".join(f"{name} ({n} test{'s' if n != 1 else ''})" for name, n in sorted(_skipped.items()))
    terminalreporter.write_line(
        f"real data: skipped the tests of {sets}: the recordings are not under {realdata.real_dir()}; set "
        f"{realdata.ENV_VAR}=/path/to/shared/real (the project's read-only shared/real folder) to run them",
        yellow=True)


def _fold_into_one_line(tr: pytest.TerminalReporter) -> None:
    """Keep these skips out of the per-reason skip list of ``-ra``: the 'real data' line says it all. They stay
    counted in the closing line ('N skipped')."""
    original = tr.short_test_summary

    def short_test_summary() -> None:
        skipped = tr.stats.get("skipped", [])
        ours = [r for r in skipped if REASON in str(getattr(r, "longrepr", ""))]
        tr.stats["skipped"] = [r for r in skipped if r not in ours]
        try:
            original()
        finally:
            tr.stats["skipped"] = skipped

    tr.short_test_summary = short_test_summary  # type: ignore[method-assign]  # pytest offers no hook after it
