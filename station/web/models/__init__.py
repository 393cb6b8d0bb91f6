"""The JSON API's typed answers and requests (pydantic), one module per area; ``/openapi.json`` is made from them.

Field names and values are those the API has always answered; SI units internally (m/s^2,
rad/s, s), and every field's description names its unit where it has one.
"""

from station.web.models.common import ErrorDetail, problem
from station.web.models.diagnosis_api import (
    DiagnosisFailed,
    DiagnosisPending,
    DiagnosisQueueFull,
    DiagnosisReady,
    DiagnosisSummary,
)
from station.web.models.params import AllanNoise, CalibrationParameters, TriadCalibration
from station.web.models.runs import (
    RunAbortAccepted,
    RunAccepted,
    RunFilter,
    RunSummary,
    RunUnitOutcome,
    StartRunRequest,
)
from station.web.models.status import PromptStatus, RigState, ShiftStats, SlotStatus, StationStatus, StepProgress
from station.web.models.units import (
    DispositionEntry,
    EepromWriteEntry,
    LimitCheckResult,
    UnitFilter,
    UnitOverview,
    UnitRecord,
    UnitRunResult,
)

__all__ = [
    "AllanNoise", "CalibrationParameters", "DiagnosisFailed", "DiagnosisPending", "DiagnosisQueueFull",
    "DiagnosisReady", "DiagnosisSummary", "DispositionEntry", "EepromWriteEntry", "ErrorDetail", "LimitCheckResult",
    "PromptStatus", "RigState",
    "RunAbortAccepted", "RunAccepted", "RunFilter", "RunSummary", "RunUnitOutcome", "ShiftStats", "SlotStatus",
    "StartRunRequest", "StationStatus", "StepProgress", "TriadCalibration", "UnitFilter", "UnitOverview",
    "UnitRecord", "UnitRunResult", "problem",
]
