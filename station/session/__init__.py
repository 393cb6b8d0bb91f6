"""Session recordings: the in-memory model and the CSV v1 file format."""

from station.session.csv_v1 import check_session_file, format_session, parse_session, read_session, write_session
from station.session.model import KIND_LABELS, Kind, Segment, Session

__all__ = [
    "KIND_LABELS",
    "Kind",
    "Segment",
    "Session",
    "check_session_file",
    "format_session",
    "parse_session",
    "read_session",
    "write_session",
]
