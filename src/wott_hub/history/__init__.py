"""Event history: the writer over storage engines, the reader, replay, export, retention, migrations glue.

Layered as rosbag2 is: the interfaces (``storage.py``), the engines behind them (``sql.py``,
``sqlite.py``, ``postgres.py``; ``engines.py`` picks one), and above them the writer
(``writer.py``, its ``batch_process.py``), the reader (``reader.py``), play (``replay.py``,
``merge.py``) and export (``export.py``, ``mcap.py``); every stage carries ``Record``s.

Names are imported on first use (PEP 562), so ``wott_hub.history.times`` and the
like do not pull SQLAlchemy into the hub's start-up before the TDs are served.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "check_integrity": "db", "create_engine": "db", "database_url": "db", "open_existing": "db",
    "upgrade": "db",
    "open_storage": "engines",
    "DEFAULT_HUB_ID": "lease", "Lease": "lease",
    "export_jsonl": "export",
    "Base": "models", "EventRow": "models", "ThingRow": "models",
    "HistoryReader": "reader",
    "Replayer": "replay",
    "Retention": "retention", "apply_retention": "retention",
    "StorageReader": "storage", "StorageWriter": "storage", "ThingSummary": "storage",
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
