"""Operator status page, engineer's unit and population pages and the JSON API (FastAPI, see :mod:`.app`)."""

from station.web.app import create_app
from station.web.diagnosis_worker import DiagnosisService
from station.web.serve import ServerThread, serve
from station.web.state import LiveStatus, ShiftStats, shift_stats

__all__ = ["DiagnosisService", "LiveStatus", "ServerThread", "ShiftStats", "create_app", "serve", "shift_stats"]
