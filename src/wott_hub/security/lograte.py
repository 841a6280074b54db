"""At most so many log lines a window for one kind of line, then one line saying how many were not.

Requests anyone can send (refused credentials, 4xx answers) each log a line; a flood of them must
not grow the hub's log without bound (600 refused requests with 60,000-character paths wrote
72 MB). ``LogRate.allow()`` says whether this line may be logged: the first ``burst`` of each
``window_s`` are, the rest are counted; the first call after the window (or ``flush``) logs
"N more <what> in the last 60 s were not logged". The audit trail still counts every request
(``audit.py``); only the log is sampled.
"""

from __future__ import annotations

import logging
import threading
import time

__all__ = ["LogRate"]


class LogRate:
    def __init__(self, logger: logging.Logger, burst: int, window_s: float, what: str,
                 level: int = logging.WARNING) -> None:
        self.logger = logger
        self.burst = burst
        self.window_s = window_s
        self.what = what
        self.level = level
        self.suppressed = 0  # in all
        self._lock = threading.Lock()
        self._start = time.monotonic()
        self._used = 0
        self._held = 0  # not logged in the current window

    def allow(self) -> bool:
        with self._lock:
            self._roll(time.monotonic())
            if self._used < self.burst:
                self._used += 1
                return True
            self._held += 1
            self.suppressed += 1
            return False

    def flush(self) -> None:
        """Say how many were not logged once their window has ended (called now and then)."""
        with self._lock:
            self._roll(time.monotonic())

    def _roll(self, now: float) -> None:
        if now - self._start < self.window_s:
            return
        if self._held:
            self.logger.log(self.level, "%d more %s in the last %.0f s were not logged", self._held,
                            self.what, now - self._start)
        self._start, self._used, self._held = now, 0, 0
