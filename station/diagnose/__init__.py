"""Diagnosis: where a recording and the base model (eq. 1 + eq. 3) disagree, and which physics is missing."""


# Lazy (PEP 562): importing the package, e.g. for its CLI commands, loads no heavy dependency.
_EXPORTS = {
    "NAMES": "station.diagnose.effect_registry",
    "Progress": "station.diagnose.diagnosis_progress",
    "Stage": "station.diagnose.diagnosis_progress",
    "FORMAT": "station.diagnose.results",
    "Diagnosis": "station.diagnose.outcome",
    "DiagnosisReport": "station.diagnose.results",
    "load_report": "station.diagnose.results",
    "diagnose": "station.diagnose.report",
    "save_figure": "station.diagnose.report",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> object:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
