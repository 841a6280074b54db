"""Reconnect pacing for drivers whose transport comes and goes.

A device that was unplugged must not be hammered with open() calls, yet it
should be picked up again quickly once it is back; and a fleet of devices that
all lost their link at the same moment (a USB hub reset, a Wi-Fi drop) must not
retry in lock-step. So: exponential growth from ``initial_s`` by ``factor`` per
failed attempt, capped at ``cap_s``, each delay shortened by a random fraction
of up to ``jitter`` of itself, and back to ``initial_s`` after a success.

Usable from a thread (``wait``, interruptible by a ``threading.Event``) and
from asyncio (``sleep``).
"""

from __future__ import annotations

import asyncio
import random
import threading
from dataclasses import dataclass, field

__all__ = ["Backoff"]


@dataclass
class Backoff:
    initial_s: float = 0.05
    cap_s: float = 5.0
    factor: float = 2.0
    jitter: float = 0.5  # each delay is drawn from [base * (1 - jitter), base]
    rng: random.Random = field(default_factory=random.Random, repr=False)
    attempts: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        if not (self.initial_s > 0 and self.cap_s >= self.initial_s and self.factor >= 1.0):
            raise ValueError("need 0 < initial_s <= cap_s and factor >= 1")
        if not 0.0 <= self.jitter <= 1.0:
            raise ValueError("jitter must lie in [0, 1]")

    def base_delay(self, attempt: int) -> float:
        """The un-jittered delay before retry number ``attempt`` (0-based)."""
        # Cap the exponent too, so a device that stays away for days cannot overflow the float.
        exponent = min(attempt, 64)
        return min(self.cap_s, self.initial_s * self.factor**exponent)

    def next_delay(self) -> float:
        """The delay to wait before the next attempt; counts the attempt."""
        base = self.base_delay(self.attempts)
        self.attempts += 1
        return base * (1.0 - self.jitter * self.rng.random())

    def reset(self) -> None:
        """The transport works again: the next failure starts from ``initial_s``."""
        self.attempts = 0

    def wait(self, stop: threading.Event | None = None) -> bool:
        """Block for the next delay; return True early if ``stop`` is set meanwhile."""
        delay = self.next_delay()
        if stop is None:
            threading.Event().wait(delay)
            return False
        return stop.wait(delay)

    async def sleep(self) -> None:
        await asyncio.sleep(self.next_delay())
