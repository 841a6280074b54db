"""One background task per device id: the retry loops of devices that could not be opened.

Both the restarts (``restart.Restarts``: a device whose ``restart`` could not re-open it,
in the hub's process or a worker's) and the hub's fleet management (a configured device
that failed to open at start) keep such a loop per device; a loop removes itself when it
ends, and removing, restarting or stopping cancels it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any

__all__ = ["TasksById"]


class TasksById:
    def __init__(self, kind: str) -> None:
        self.kind = kind  # the tasks' name prefix: "reopen", "retry"
        self._tasks: dict[str, asyncio.Task[None]] = {}

    def __contains__(self, key: str) -> bool:
        return key in self._tasks

    def start(self, key: str, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as ``key``'s task; it forgets itself when it ends."""
        task = asyncio.create_task(coro, name=f"{self.kind}:{key}")
        self._tasks[key] = task
        task.add_done_callback(lambda t: self._tasks.pop(key) if self._tasks.get(key) is t else None)

    def cancel(self, key: str) -> None:
        task = self._tasks.pop(key, None)
        if task is not None:
            task.cancel()

    async def stop(self) -> None:
        """Cancel every task and wait until they are done."""
        tasks = list(self._tasks.values())
        self._tasks.clear()
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
