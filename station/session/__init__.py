"""Session recordings: the in-memory model and the CSV v1 file format."""

from station.session.model import KIND_LABELS, Kind, Segment, Session

__all__ = ["KIND_LABELS", "Kind", "Segment", "Session"]
