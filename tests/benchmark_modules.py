"""A benchmark script loaded by the tests as a module (``benchmarks/`` is no package): once per process, under its
own name, so a second test file that loads it gets the same module."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_benchmark(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` as the module ``name``."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def run_outside_bench_undiagnosed(monkeypatch: Any, argv: list[str]) -> None:
    """``benchmarks/bench_diagnose_outside.py`` run with ``argv``, its diagnosis replaced by an empty report (a
    sealed generator's kinds are not diagnosed before the final check): what it draws and prints, not what the
    diagnosis says. ``monkeypatch`` is pytest's fixture; the benchmark's module state is restored after the test."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import bench_diagnose_outside as bench

    class _Empty:
        class report:
            @staticmethod
            def to_json() -> dict[str, list[object]]:
                return {"findings": [], "unexplained": []}

    monkeypatch.setattr(bench, "diagnose", lambda session, warmup_tc_s=None: _Empty)
    monkeypatch.setattr(bench, "GEN", bench.gen_outside)  # main() sets it
    monkeypatch.setattr(sys, "argv", ["bench", *argv])
    bench.main()
