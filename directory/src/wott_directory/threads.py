"""A thread of the directory's own for work that grows with its input, with a bound on who waits.

Validating a 2 MiB TD, applying a merge patch, running a JSONPath query over 10,000 TDs: each
takes long enough to hold up every other request if run on the IOLoop (which the hub shares
with its devices). Each kind of work gets one thread (writes stay in the order they were
decided; a search cannot starve a write); at most ``max_pending`` calls wait for it, and a
client's call past that gets 503 with ``Retry-After`` at once rather than a growing queue.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from .errors import DirectoryError

__all__ = ["WorkThread"]

_R = TypeVar("_R")


class WorkThread:
    """``what``: the calls' name in the 503 ("searches"); ``setting``: the bound's name in it."""

    def __init__(self, name: str, max_pending: int, what: str, setting: str) -> None:
        self.max_pending = max_pending
        self.what = what
        self.setting = setting
        self.pending = 0
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)

    async def run(self, fn: Callable[..., _R], *args: Any, bounded: bool = True,
                  timeout_s: float | None = None) -> _R:
        """``fn(*args)`` on the thread; ``bounded`` (a client's call): 503 at once when ``max_pending``
        already wait; ``timeout_s``: ``TimeoutError`` past it (the thread's work is not interrupted)."""
        if bounded and self.pending >= self.max_pending:
            raise DirectoryError(503, f"{self.max_pending} {self.what} are already waiting "
                                      f"({self.setting}); try again shortly", [], {"Retry-After": "1"})
        self.pending += 1
        try:
            done = asyncio.get_running_loop().run_in_executor(self._executor, fn, *args)
            return await (done if timeout_s is None else asyncio.wait_for(done, timeout_s))
        finally:
            self.pending -= 1

    def shutdown(self) -> None:
        self._executor.shutdown(wait=True)
