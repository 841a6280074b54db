"""Event history: SQLAlchemy models, batched writer, retention, reader, export, replay.

Names are imported on first use (PEP 562), so ``wott_hub.history.times`` and the
like do not pull SQLAlchemy into the hub's start-up before the TDs are served.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "HistoryError": "db", "check_integrity": "db", "create_engine": "db", "database_url": "db",
    "open_existing": "db", "upgrade": "db",
    "DEFAULT_HUB_ID": "lease", "Lease": "lease",
    "export_jsonl": "export",
    "Base": "models", "EventRow": "models", "ThingRow": "models",
    "HistoryReader": "reader", "ThingSummary": "reader",
    "Replayer": "replay",
    "Retention": "retention", "apply_retention": "retention",
    "format_ns": "times", "parse_time": "times",
    "RESERVE": "writer", "HistoryWriter": "writer",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
