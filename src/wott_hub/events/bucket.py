"""How often a publisher may write a record itself instead of handing it to a consumer's task.

A write made inside ``publish`` reaches the socket at once but costs a syscall per record; a
queued record waits for the consumer's loop turn and goes with the rest of that turn's in one
write. The bucket keeps the first for an idle consumer and the second for a busy one.
"""

from __future__ import annotations

import time

__all__ = ["Bucket"]


class Bucket:
    """A token bucket: ``rate`` takes a second on average, up to ``burst`` back to back."""

    __slots__ = ("_at", "_credit", "burst", "rate")

    def __init__(self, rate: float, burst: float) -> None:
        self.rate = rate
        self.burst = burst
        self._credit = burst
        self._at = 0.0

    def take(self) -> bool:
        now = time.monotonic()
        credit = min(self._credit + (now - self._at) * self.rate, self.burst)
        self._at = now
        if credit >= 1.0:
            self._credit = credit - 1.0
            return True
        self._credit = credit
        return False
