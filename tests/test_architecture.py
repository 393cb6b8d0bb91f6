"""The layers of ``station/`` import downward only (docs/architecture.md).

An AST walk over every module of the package, counting every ``import`` and ``from ... import``
(inside functions and ``TYPE_CHECKING`` blocks too: a type is a dependency), checked against the
table of what each package may import. The checker itself is tested on made-up modules, so this
test fails when an import runs the wrong way.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Iterator
from pathlib import Path

import pytest

import station

ROOT = Path(station.__file__).resolve().parent

# what each top-level package (or module) of station/ may import, besides itself
NUMERICS = {"kernel", "session", "fit", "correct", "physics", "diagnose", "msa"}
ALLOWED: dict[str, set[str]] = {
    # the kernel: clock, geometry, plan, sensor class, limits, errors; no I/O, no simulation
    "kernel": set(),
    # pure numerics and physics: arrays in, frozen results out
    "session": {"kernel"},
    "fit": {"kernel", "session"},
    "correct": {"kernel", "session", "fit"},
    "physics": {"kernel", "session", "fit"},
    "diagnose": {"kernel", "session", "fit", "correct", "physics"},
    # measurement system analysis (Gage R&R by ANOVA): numbers in, a frozen study out
    "msa": {"kernel"},
    # what the Modbus devices share: URL parsing, the pymodbus transport, the heartbeat
    "modbus": {"kernel"},
    # hardware behind protocols, selected by URL scheme
    "rig": {"kernel", "modbus"},
    "chamber": {"kernel", "modbus"},
    "sensor": {"kernel"},
    "eeprom": {"kernel", "fit", "sensor"},
    # the sequence: steps, runner, records, limits, gates, provisioning, on-rig verification
    "sequence": {"kernel", "session", "fit", "correct", "rig", "chamber", "sensor", "eeprom"},
    # subscribers to the records
    "store": {"kernel", "fit", "eeprom", "sequence"},
    "terminal": {"kernel", "fit", "sequence"},
    "web": NUMERICS | {"eeprom", "sequence", "store"},
    # the composition root, its one-run-per-rig lock, and the command line
    "rig_lock": {"kernel", "store"},
    "compose": {"kernel", "session", "fit", "rig", "chamber", "sensor", "sequence", "store", "rig_lock"},
    "commands": NUMERICS | {"rig", "chamber", "sensor", "eeprom", "sequence", "store", "compose", "rig_lock"},
    "cli": NUMERICS | {"rig", "chamber", "sensor", "eeprom", "sequence", "store", "terminal", "web", "compose",
                       "commands", "rig_lock"},
    # simulated peers: the kernel, the physics and the wire formats they speak; never the station above
    "sim": NUMERICS | {"rig", "chamber", "sensor", "eeprom"},
    "__init__": set(),
}
# the simulator's own applications (the demo and its commands) sit on top of everything
SIM_APPS = {"station.sim.demo", "station.sim.cli", "station.sim.msa_study", "station.sim.golden_study"}
EVERYTHING = set(ALLOWED)


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(module: str, source: str, is_package: bool) -> Iterator[str]:
    """Every station module ``module`` imports (absolute names), from anywhere in its source."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            yield target
            if target == "station":  # `from station import sim` imports station.sim
                for alias in node.names:
                    yield f"station.{alias.name}"


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def violations(modules: Iterable[tuple[str, str, bool]]) -> list[str]:
    """``'a -> b'`` for every import that breaks the table, over (module name, source, is package)."""
    known = EVERYTHING
    out = []
    for module, source, is_package in modules:
        own = _package(module)
        allowed = EVERYTHING if module in SIM_APPS else ALLOWED[own]
        for target in _imports(module, source, is_package):
            if not target.startswith("station.") and target != "station":
                continue
            other = _package(target)
            if other == own or other not in known or (target == "station" and module != "station"):
                continue
            if other not in allowed:
                out.append(f"{module} -> {target}")
    return sorted(set(out))


def _station_modules() -> list[tuple[str, str, bool]]:
    return [(_module_name(p), p.read_text(encoding="utf-8"), p.name == "__init__.py") for p in ROOT.rglob("*.py")]


def test_every_package_is_in_the_table() -> None:
    tops = {p.stem if p.is_file() else p.name for p in ROOT.iterdir()
            if (p.is_dir() and (p / "__init__.py").exists()) or p.suffix == ".py"}
    assert tops <= set(ALLOWED), f"packages missing from the layer table: {sorted(tops - set(ALLOWED))}"


def test_imports_point_downward_only() -> None:
    bad = violations(_station_modules())
    assert bad == [], "imports against the layers (docs/architecture.md):\n" + "\n".join(bad)


def test_nothing_outside_sim_imports_the_simulator() -> None:
    users = [f"{m} -> {t}" for m, src, pkg in _station_modules() if _package(m) != "sim"
             for t in _imports(m, src, pkg) if t == "station.sim" or t.startswith("station.sim.")]
    assert users == []


def test_eeprom_does_not_import_the_sequence() -> None:
    users = [f"{m} -> {t}" for m, src, pkg in _station_modules() if _package(m) == "eeprom"
             for t in _imports(m, src, pkg) if t.startswith("station.sequence")]
    assert users == []


def test_the_package_graph_has_no_cycle() -> None:
    graph: dict[str, set[str]] = {}
    for m, src, pkg in _station_modules():
        own = _package(m)
        if m in SIM_APPS:
            continue
        graph.setdefault(own, set()).update(
            _package(t) for t in _imports(m, src, pkg) if t.startswith("station.") and _package(t) != own
        )
    seen: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        if seen.get(node) == 1:
            raise AssertionError("import cycle: " + " -> ".join([*path, node]))
        if seen.get(node) == 2:
            return
        seen[node] = 1
        for nxt in sorted(graph.get(node, ())):
            visit(nxt, [*path, node])
        seen[node] = 2

    for node in sorted(graph):
        visit(node, [])


@pytest.mark.parametrize(
    ("module", "source", "expected"),
    [
        ("station.rig.modbus", "from station.sim.clock import SimClock", ["station.rig.modbus -> station.sim.clock"]),
        ("station.eeprom.verify", "import station.sequence.steps", ["station.eeprom.verify -> station.sequence.steps"]),
        ("station.kernel.plan", "def f():\n    from station.physics import motion",
         ["station.kernel.plan -> station.physics"]),
        ("station.fit.x", "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import station.sequence.runner",
         ["station.fit.x -> station.sequence.runner"]),
        ("station.sim.rig_server", "from station import compose", ["station.sim.rig_server -> station.compose"]),
        ("station.sequence.steps", "from ..rig import protocol\nfrom ..kernel.plan import RigPlan", []),
        ("station.sequence.steps", "from ..store import db", ["station.sequence.steps -> station.store"]),
        ("station.sim.demo", "from station.compose import Station", []),
        ("station.compose", "from station.sim.station_sim import SimStation",
         ["station.compose -> station.sim.station_sim"]),
    ],
)
def test_the_checker_finds_imports_the_wrong_way(module: str, source: str, expected: list[str]) -> None:
    assert violations([(module, source, False)]) == sorted(expected)
