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
    "correct": {"kernel", "session"},
    "physics": {"kernel", "session"},
    "diagnose": {"kernel", "session", "fit", "correct", "physics"},
    # measurement system analysis (Gage R&R by ANOVA): numbers in, a frozen study out
    "msa": {"kernel"},
    # what the Modbus devices share: URL parsing, the pymodbus transport, the heartbeat
    "modbus": {"kernel"},
    # hardware behind protocols, selected by URL scheme
    "rig": {"kernel", "modbus"},
    "chamber": {"kernel", "modbus"},
    "rack": {"kernel", "modbus"},
    "sensor": {"kernel"},
    "eeprom": {"kernel", "sensor"},
    # a virtual clock served across processes (simulator <-> station): time-advance request and grant
    "timelink": {"kernel"},
    # the sequence: steps, runner, records, limits, gates, provisioning, on-rig verification
    "sequence": {"kernel", "session", "fit", "correct", "rig", "chamber", "sensor", "eeprom"},
    # subscribers to the records
    "store": {"kernel", "eeprom", "sequence"},
    "terminal": {"kernel", "sequence"},
    "web": NUMERICS | {"eeprom", "sequence", "store"},
    # the calibration line's roles: the soak rack's logging and recordings, the rig role's joint fit
    "line": {"kernel", "session", "fit", "sensor", "rack", "sequence", "store"},
    # the composition root, its one-run-per-rig lock, and the command line
    "rig_lock": {"kernel", "store"},
    "compose": {"kernel", "session", "fit", "rig", "chamber", "sensor", "sequence", "store", "rig_lock", "line",
                "timelink"},
    "commands": NUMERICS | {"rig", "chamber", "rack", "sensor", "eeprom", "sequence", "store", "compose", "rig_lock",
                            "line"},
    "cli": NUMERICS | {"rig", "chamber", "sensor", "eeprom", "sequence", "store", "terminal", "web", "compose",
                       "commands", "rig_lock"},
    "__main__": {"cli"},  # ``python -m station``: the command line, nothing else
    # simulated peers: the kernel, the physics and the wire formats they speak; never the station above
    "sim": NUMERICS | {"rig", "chamber", "rack", "sensor", "eeprom"},
    "__init__": set(),
}
# the simulator's own applications (the demo and its commands) sit on top of everything
SIM_APPS = {"station.sim.demo", "station.sim.cli", "station.sim.msa_study", "station.sim.golden_study",
            "station.sim.line_station"}
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


# --- inside a package: no module-level import cycle, no private name imported across modules ---------------------

#: Known cycles still present, each as the set of modules of one strongly connected component, with why (none
#: left: the diagnosis's two went with its typed rewrite); nothing may be added without a reason.
KNOWN_CYCLES: list[frozenset[str]] = []


def _resolve(target: str, names: Iterable[str], modules: set[str]) -> Iterator[str]:
    """The station modules an import of ``target`` (``from target import names``) depends on: ``target.name``
    where that is a module, and ``target`` itself for a name defined in it (or in its ``__init__``). (Importing a
    submodule runs its package's ``__init__`` first either way, which is no dependency on what it defines.)"""
    for name in names:
        sub = f"{target}.{name}"
        yield sub if sub in modules else target


def _module_edges(modules: Iterable[tuple[str, str, bool]]) -> dict[str, set[str]]:
    """Module -> the station modules it imports (anywhere in its source: functions and TYPE_CHECKING included)."""
    mods = list(modules)
    names = {m for m, _, _ in mods}
    graph: dict[str, set[str]] = {m: set() for m in names}
    for module, source, is_package in mods:
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
                graph[module].update(t for t in targets if t in names)
            elif isinstance(node, ast.ImportFrom):
                target = next(iter(_imports(module, ast.unparse(ast.Module([node], [])), is_package)), "")
                if target.startswith("station"):
                    graph[module].update(t for t in _resolve(target, [a.name for a in node.names], names)
                                         if t in names and t != module)
    return graph


def module_cycles(modules: Iterable[tuple[str, str, bool]]) -> list[frozenset[str]]:
    """Every import cycle between modules (its strongly connected component, Tarjan's algorithm). A package's
    ``__init__`` importing its own modules is no cycle unless one of them imports the package back."""
    graph = _module_edges(modules)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[frozenset[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(frozenset(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return sorted(out, key=sorted)


def private_imports(modules: Iterable[tuple[str, str, bool]]) -> list[str]:
    """``'a imports b._name'`` for every ``_private`` name one station module takes from another (anywhere in
    its source). Dunder names (``__version__``) are public."""
    out = []
    for module, source, is_package in modules:
        for node in ast.walk(ast.parse(source)):
            if not isinstance(node, ast.ImportFrom):
                continue
            target = next(iter(_imports(module, ast.unparse(ast.Module([node], [])), is_package)), "")
            if not target.startswith("station") or target == module:
                continue
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    out.append(f"{module} imports {target}.{alias.name}")
    return sorted(out)


def test_no_import_cycle_between_modules() -> None:
    found = module_cycles(_station_modules())
    new = [sorted(c) for c in found if c not in KNOWN_CYCLES]
    assert new == [], f"import cycles between modules: {new}"
    gone = [sorted(c) for c in KNOWN_CYCLES if c not in found]
    assert gone == [], f"known cycles no longer present: remove them from KNOWN_CYCLES: {gone}"


def test_no_private_name_is_imported_across_modules() -> None:
    bad = private_imports(_station_modules())
    assert bad == [], "private names imported across modules (make them public where they are defined):\n" + \
        "\n".join(bad)


@pytest.mark.parametrize(
    ("sources", "expected"),
    [
        # a plain two-module cycle, one side inside a function
        ({"station.fit.a": "from station.fit.b import f", "station.fit.b": "def g():\n    from station.fit import a"},
         [{"station.fit.a", "station.fit.b"}]),
        # three modules through relative imports and TYPE_CHECKING
        ({"station.diagnose.a": "from .b import x", "station.diagnose.b": "from . import c",
          "station.diagnose.c": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import station.diagnose.a"},
         [{"station.diagnose.a", "station.diagnose.b", "station.diagnose.c"}]),
        # a package's __init__ re-exporting its modules, and a module importing a sibling: no cycle
        ({"station.session": "from station.session.csv_v1 import read", "station.session.csv_v1":
          "from station.session.model import Session\nfrom station.session import model", "station.session.model":
          "import numpy"}, []),
        # ... but a module importing the name from its own package's __init__ that imports it back is one
        ({"station.session": "from station.session.csv_v1 import read", "station.session.csv_v1":
          "from station.session import Session"}, [{"station.session", "station.session.csv_v1"}]),
    ],
)
def test_the_cycle_checker_on_made_up_modules(sources: dict[str, str], expected: list[set[str]]) -> None:
    modules = [(m, src, m.count(".") == 1 and m == "station.session") for m, src in sources.items()]
    assert module_cycles(modules) == sorted((frozenset(e) for e in expected), key=sorted)


@pytest.mark.parametrize(
    ("module", "source", "expected"),
    [
        ("station.fit.rigfree_fit", "from station.fit.calibrate import _allan, _noise, fit_session",
         ["station.fit.rigfree_fit imports station.fit.calibrate._allan",
          "station.fit.rigfree_fit imports station.fit.calibrate._noise"]),
        ("station.fit.x", "def f():\n    from .axis_ml import _Problem",
         ["station.fit.x imports station.fit.axis_ml._Problem"]),
        ("station.fit.x", "from station import __version__\nfrom station.fit.axis_ml import AxisFit", []),
        ("station.fit.x", "from numpy import _private_of_numpy", []),
    ],
)
def test_the_private_import_checker_on_made_up_modules(module: str, source: str, expected: list[str]) -> None:
    assert private_imports([(module, source, False)]) == expected
