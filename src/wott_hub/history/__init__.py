"""Event history: SQLAlchemy models, batched writer, retention, reader, export, replay."""

from .db import HistoryError, create_engine, database_url, upgrade
from .export import export_jsonl
from .models import Base, EventRow, ThingRow
from .reader import HistoryReader, ThingSummary
from .replay import Replayer
from .retention import Retention, apply_retention
from .times import format_ns, parse_time
from .writer import RESERVE, HistoryWriter

__all__ = [
    "RESERVE", "Base", "EventRow", "HistoryError", "HistoryReader", "HistoryWriter", "Replayer",
    "Retention", "ThingRow", "ThingSummary", "apply_retention", "create_engine", "database_url",
    "export_jsonl", "format_ns", "parse_time", "upgrade",
]
