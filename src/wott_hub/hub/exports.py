"""History reads for the hub Thing's actions, in threads of their own: exports and pages.

An MCAP export of an hour reads and writes hundreds of MB for seconds to minutes. Run in the
event loop's default executor (as it was), eight of them took every thread that the camera
devices' frames also need: a device delivered one event in 46 s, memory grew by a GB, they ran on
after their clients left and the hub took a minute to stop. So (issue 33):

- an export runs in a daemon thread of its own, at most ``MAX_EXPORTS`` at a time; one more is
  ``Busy`` (503) at once, never queued;
- it streams: the MCAP writer writes into a ``_Pipe`` whose chunks (``CHUNK`` bytes, at most
  ``IN_FLIGHT`` waiting for the client) go out as they come, so memory is bounded and a client
  that reads slowly slows its export, no one else;
- it is cancelled (``Export.cancel``) when its client leaves (the response's generator is closed
  or cancelled: ``actions.ActionHandler``), when the hub stops (``Exports.cancel_all``), and
  checked between pages and every few thousand records (``check``);
- ``historyDevices`` and ``historyRecords`` pages (short, bounded reads) run in a pool of
  ``READ_THREADS`` threads of their own (``Exports.read``), queued, not refused;
- ``health`` says how many run, the limit, how many were refused and cancelled.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import threading
from collections.abc import AsyncGenerator, Callable
from concurrent.futures import ThreadPoolExecutor
from typing import IO, Any, TypeVar, cast

from wott_hub.errors import Busy

__all__ = ["CHUNK", "IN_FLIGHT", "MAX_EXPORTS", "READ_THREADS", "Export", "Exports"]

log = logging.getLogger(__name__)
T = TypeVar("T")

MAX_EXPORTS = 2
"""Exports running at once: each keeps a core busy; more only slow them all and the devices."""
READ_THREADS = 2
CHUNK = 1 << 20
IN_FLIGHT = 4


class _Cancelled(Exception):
    """Raised inside an export's thread once it is cancelled: it unwinds the export, nothing more."""


class Export:
    """One running export: its cancel flag and, while it runs, the thread writing it."""

    def __init__(self) -> None:
        self.cancelled = threading.Event()

    def cancel(self) -> None:
        self.cancelled.set()

    def check(self) -> None:
        """For the export's own code, now and then: ``_Cancelled`` once it is cancelled."""
        if self.cancelled.is_set():
            raise _Cancelled


class _Pipe:
    """What the export's writer writes to: chunks of ``CHUNK`` bytes handed to the event loop, at
    most ``IN_FLIGHT`` not yet sent (the writer waits for room, and gives up when cancelled)."""

    def __init__(self, export: Export, send: Callable[[bytes], object], room: threading.Semaphore) -> None:
        self._export = export
        self._send = send
        self._room = room
        self._buf = bytearray()
        self._written = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        self._export.check()
        self._buf += data
        self._written += len(data)
        if len(self._buf) >= CHUNK:
            self._hand_over()
        return len(data)

    def tell(self) -> int:
        return self._written

    def flush(self) -> None:
        """The MCAP writer flushes after every chunk; sending waits for a full one (or the end)."""

    def close(self) -> None:
        if self._buf:
            self._hand_over()

    def _hand_over(self) -> None:
        while not self._room.acquire(timeout=0.5):
            self._export.check()
        self._export.check()
        data, self._buf = bytes(self._buf), bytearray()
        self._send(data)


class Exports:
    def __init__(self, max_exports: int = MAX_EXPORTS, read_threads: int = READ_THREADS) -> None:
        self.max_exports = max_exports
        self.running: set[Export] = set()
        self.refused = 0
        self.cancelled = 0
        self.finished = 0
        self._reads: ThreadPoolExecutor | None = None
        self._read_threads = read_threads

    def begin(self) -> Export:
        """A new export, or ``Busy`` when ``max_exports`` run already."""
        if len(self.running) >= self.max_exports:
            self.refused += 1
            raise Busy(f"{len(self.running)} history exports are running already (at most {self.max_exports} "
                       "at a time); try again when one has ended")
        export = Export()
        self.running.add(export)
        return export

    def _ended(self, export: Export) -> None:
        """On the event loop, when the export's thread has ended."""
        if export in self.running:
            self.running.discard(export)
            if export.cancelled.is_set():
                self.cancelled += 1
            self.finished += 1

    async def stream(self, write: Callable[[IO[bytes], Export], Any]) -> AsyncGenerator[bytes, None]:
        """A new export (``Busy`` at the first step when ``max_exports`` run already): ``write(out,
        export)`` in a thread of its own; the bytes it writes to ``out``, as they come. Closing or
        cancelling the generator cancels the export; its errors are raised here."""
        export = self.begin()
        loop = asyncio.get_running_loop()
        chunks: asyncio.Queue[bytes | BaseException | None] = asyncio.Queue()
        room = threading.Semaphore(IN_FLIGHT)
        pipe = _Pipe(export, lambda b: loop.call_soon_threadsafe(chunks.put_nowait, b), room)

        def run() -> None:
            end: BaseException | None = None
            try:
                write(cast("IO[bytes]", pipe), export)  # what the MCAP writer uses of a file: write, tell
                pipe.close()
            except BaseException as e:  # handed to the event loop, raised there
                end = e
            with contextlib.suppress(RuntimeError):  # the loop is closed: nobody listens any more
                loop.call_soon_threadsafe(chunks.put_nowait, end)
                loop.call_soon_threadsafe(self._ended, export)  # its place is free once its thread ends

        thread = threading.Thread(target=run, name="history-export", daemon=True)
        thread.start()
        complete = False
        try:
            while (item := await chunks.get()) is not None:
                if isinstance(item, BaseException):
                    if isinstance(item, _Cancelled):
                        return
                    raise item
                yield item
                room.release()
            complete = True
        finally:
            if not complete:
                export.cancel()
                room.release()  # a thread waiting for room sees the cancel at once

    async def read(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """``fn(*args, **kwargs)`` (a bounded read of history) in the reads' own threads."""
        if self._reads is None:
            self._reads = ThreadPoolExecutor(self._read_threads, thread_name_prefix="history-api")
        return await asyncio.get_running_loop().run_in_executor(self._reads, functools.partial(fn, *args,
                                                                                              **kwargs))

    def cancel_all(self) -> None:
        """The hub stops: every export ends at its next check (its thread is a daemon: never waited for)."""
        for export in list(self.running):
            export.cancel()
        if self._reads is not None:
            self._reads.shutdown(wait=False, cancel_futures=True)
            self._reads = None

    def health(self) -> dict[str, Any]:
        return {"running": len(self.running), "limit": self.max_exports, "refused": self.refused,
                "cancelled": self.cancelled, "finished": self.finished}
