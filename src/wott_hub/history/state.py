"""What this process knows about the health of one history database.

The writer and the reader of a hub open the same engine; a read error the
reader meets (SSE resume, replay) and the integrity check the writer runs at
start both land here, so ``HistoryWriter.health()`` reports them in one place;
and the writer's spool says here that history lacks records for now.
"""

from __future__ import annotations

import logging
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy.engine import Engine

from wott_hub.errors import HistoryError

__all__ = ["DatabaseState", "is_corruption", "state_of"]

log = logging.getLogger("wott_hub.history.writer")  # the writer runs the check: its log, as before

_CORRUPT = ("malformed", "not a database", "corrupt", "disk i/o error")


def is_corruption(message: str) -> bool:
    """Does a driver's error text say the file itself is damaged (not a lock, not a bad query)?"""
    low = message.lower()
    return any(word in low for word in _CORRUPT)


@dataclass(eq=False)
class DatabaseState:
    integrity: str | None = None  # None: not checked yet; "ok"; else the problem found
    read_errors: int = 0
    last_read_error: str = ""
    last_read_error_at: float = 0.0  # time.monotonic()
    forwarding: str = ""
    """Set while records wait in the writer's spool (``spool.py``): history lacks them for now, so
    a resume that needs history is refused (503) rather than served with a silent gap."""

    def read_failed(self, message: str) -> None:
        self.read_errors += 1
        self.last_read_error = message
        self.last_read_error_at = time.monotonic()
        if is_corruption(message):
            self.integrity = message

    def check(self, scan: Callable[[], None]) -> None:
        """Run ``scan`` (the storage's integrity check: ``HistoryError`` naming the damage) and keep
        what it found in ``integrity``; a check that could not run is reported, not guessed."""
        try:
            scan()
        except HistoryError as e:
            self.integrity = str(e)
            log.error("%s", e)
        except Exception as e:  # the check itself could not run: report, do not guess
            log.warning("history integrity check did not run: %s", e)
        else:
            if self.integrity is None:
                self.integrity = "ok"

    @property
    def corrupted(self) -> str:
        """The problem if the database is known to be damaged, else ""."""
        return self.integrity if self.integrity not in (None, "ok") else ""


_STATES: weakref.WeakKeyDictionary[Engine, DatabaseState] = weakref.WeakKeyDictionary()
_LOCK = threading.Lock()


def state_of(engine: Engine) -> DatabaseState:
    with _LOCK:
        st = _STATES.get(engine)
        if st is None:
            st = _STATES[engine] = DatabaseState()
        return st
