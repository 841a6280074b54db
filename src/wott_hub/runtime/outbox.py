"""The worker's end of the pipe: records of every device batched, everything else in order after them.

A worker batches its records: the frames its devices made in one loop tick go
out together, in one message the hub reads in one go; a tick longer than
``FLUSH_S`` sends its batch once its first frame has waited that long. One
message per frame cost each side a pickle, a write or read and a wake-up per
frame (~55 µs of the worker's time and ~70 µs of the hub's at 32 devices x
120 Hz; batched, ~30 µs each). Any other message flushes the waiting records
first: a device's records, and its ``Ended``, a health report or an ``Acted``
after them, keep their order.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import TYPE_CHECKING, Protocol

from .messages import Batch

if TYPE_CHECKING:
    from wott_hub.events.record import Record

    from .messages import ToHub

__all__ = ["FLUSH_S", "Outbox", "PipeSink", "Sender"]

FLUSH_S = 0.001
"""How long a frame's records wait at most for the others of their batch while the worker's loop is
busy (``Outbox``): the latency a batch adds, against the per-message cost it saves."""


class Sender(Protocol):
    """The worker's end of the pipe (a ``multiprocessing`` connection)."""

    def send(self, obj: ToHub) -> None: ...


class Outbox:
    """The messages a worker sends the hub, its devices' records batched.

    A batch goes out on the next loop tick, with the frames of every device that ran
    in this one, or as soon as a frame finds its first one ``flush_s`` old (a tick
    running many devices can take longer than that). No timer: a worker woken to send
    waits for a core on a loaded host. ``send`` flushes first.
    """

    __slots__ = ("_conn", "_first", "_frames", "_handle", "_loop", "flush_s")

    def __init__(self, conn: Sender, flush_s: float = FLUSH_S) -> None:
        self._conn = conn
        self._loop = asyncio.get_running_loop()
        self._frames: list[list[Record]] = []
        self._handle: asyncio.Handle | None = None
        self._first = 0.0  # when the first frame of the batch came
        self.flush_s = flush_s

    def frame(self, recs: list[Record]) -> None:
        """One frame's records (of one device), sent with the next batch."""
        self._frames.append(recs)
        if self._handle is None:
            self._first = time.monotonic()
            self._handle = self._loop.call_soon(self.flush)
        elif time.monotonic() - self._first >= self.flush_s:
            self.flush()

    def flush(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        if self._frames:
            frames, self._frames = self._frames, []
            self._put(Batch(frames))

    def send(self, msg: ToHub) -> None:
        self.flush()
        self._put(msg)

    def _put(self, msg: ToHub) -> None:
        with contextlib.suppress(OSError, ValueError):  # the hub has gone: it will tell us to close, or not
            self._conn.send(msg)


class PipeSink:
    """The record sink of a pipeline in a worker (a ``types.FrameSink``): it wants every record (only
    the hub knows who wants one) and hands each frame's records to the worker's ``Outbox``."""

    __slots__ = ("_outbox", "_recs", "thing")

    def __init__(self, thing: str, outbox: Outbox) -> None:
        self.thing = thing
        self._outbox = outbox
        self._recs: list[Record] = []

    def wants(self, _thing: str, _kind: int, _name: str) -> bool:
        return True

    def put(self, rec: Record) -> None:
        self._recs.append(rec)

    def frame_done(self) -> None:
        if self._recs:
            self._outbox.frame(self._recs)
            self._recs = []
