"""The history writer's thread: wakes, keeps the lease, forwards the spool, writes the queue.

It wakes every ``interval_s`` (or as soon as a batch is full, or for a stop, a hurry, a flush).
Each round: refresh the lease when due (``Lease.keep``; lost: the queue is given up on, nothing
more is written); forward the spool if it holds anything, since it is older than anything queued
(``StoreAndForward.forward``); write the queue only once the spool is empty (``BatchWriter``),
or, while forwarding takes a while, move a full batch's worth of queue to the spool to keep memory
bounded; apply retention when due.

A round that fails (locked, disk full, connection lost) is logged and retried with backoff
(0.1 s doubling to 5 s; a stop or a hurry cuts the wait short). Health is "degraded" meanwhile
(``Tally.failing``). What is queued moves to the spool once batches have failed for
``spill_after_s``, at once when stopping or hurried, and at once when the queue holds half its
byte budget (a raw camera fills memory fast). A stop ends the thread once the queue is written
(or spooled), or after three failures in a row: ``stop`` reports the rest.
"""

from __future__ import annotations

import logging
import threading
import time

from wott_hub.errors import HistoryError

from .batch_writer import BatchWriter
from .db_errors import driver_message
from .forward import StoreAndForward
from .lease import Lease
from .record_queue import RecordQueue
from .retention import Retention, RetentionClock
from .state import DatabaseState
from .storage import StorageWriter
from .tally import Tally

__all__ = ["HURRY_S", "WriterLoop"]

log = logging.getLogger("wott_hub.history.writer")  # the writer's log, as before it was in pieces

HURRY_S = 1.0
"""After ``hurry``, how long ``stop`` still waits for the database before it spools and returns."""


class WriterLoop:
    def __init__(self, storage: StorageWriter, queue: RecordQueue, tally: Tally, batches: BatchWriter,
                 forward: StoreAndForward, db: DatabaseState, *, interval_s: float,
                 spill_after_s: float, retention: Retention, retention_clock: RetentionClock) -> None:
        self.storage = storage
        self.queue = queue
        self.tally = tally
        self.batches = batches
        self.forward = forward
        self.db = db
        self.lease: Lease = storage.lease
        self.interval_s = interval_s
        self.spill_after_s = spill_after_s
        self.retention = retention
        self.retention_clock = retention_clock  # when the next pass is due: by time and by bytes written
        self.stopping = False  # stop() asked: write what is queued, then end
        self.hurried = False  # hurry() asked: stop waiting for the database
        self.thread: threading.Thread | None = None

    def start(self) -> None:
        if self.thread is not None:
            return
        self.stopping = False
        self.thread = threading.Thread(target=self.run, name="history-writer", daemon=True)
        self.thread.start()

    def urgent(self) -> bool:
        """A stop or a hurry is asked for: what is queued is written now, not at the next wake."""
        return self.stopping or self.hurried

    def join(self, timeout_s: float) -> float | None:
        """Ask the thread to stop and wait for it, at most ``timeout_s`` (``HURRY_S`` more once
        hurried); None once it ended, else how long it was waited for (it is left behind)."""
        thread = self.thread
        assert thread is not None
        self.stopping = True
        self.queue.wake.set()
        t0 = time.monotonic()
        deadline = t0 + timeout_s
        hurried = False
        while thread.is_alive() and time.monotonic() < deadline:
            thread.join(0.05)
            if self.hurried and not hurried:
                hurried, deadline = True, min(deadline, time.monotonic() + HURRY_S)
        self.thread = None
        return time.monotonic() - t0 if thread.is_alive() else None

    def run(self) -> None:
        backoff = 0.1
        failures_at_stop = 0
        process = self.batches.process
        if process is not None:
            try:
                process.start()
            except HistoryError as e:  # the first batch starts it again, or reports why not
                log.warning("%s", e)
        q, t, fwd = self.queue, self.tally, self.forward
        while not q.abandoned:
            stopping = self.stopping
            try:
                self.keep_lease()
                if fwd.waiting:  # older than anything queued: first
                    fwd.forward()
                if not fwd.waiting:
                    self.batches.write_pending(self.urgent)
                elif len(q) >= self.batches.batch_max:  # forwarding takes a while: keep memory bounded
                    fwd.spill()
                t.failing, t.failing_since = False, None
                backoff = 0.1
                if self.retention_clock.due():  # by time, and by the bytes written (retention.py)
                    self.storage.apply_retention(self.retention)  # the audit trail's bound even when off
                    self.retention_clock.done()
            except Exception as e:  # keep recording: a failed batch is logged, the rest retried
                if q.abandoned:
                    return
                now = time.monotonic()
                t.errors += 1
                t.last_error = driver_message(e)
                t.failing = True
                t.failing_since = t.failing_since or now
                if "database disk image is malformed" in t.last_error:
                    self.db.read_failed(t.last_error)
                spill = fwd.spool is not None and (stopping or self.hurried
                                                   or now - t.failing_since >= self.spill_after_s
                                                   or 2 * q.bytes >= q.max_bytes)
                log.error("history batch failed (%s): %s", "moving what is queued to the spool" if spill
                          else f"retrying in {backoff:.1f} s", t.last_error)
                if spill:
                    fwd.spill()
                if stopping:
                    failures_at_stop += 1
                    if not len(q) or failures_at_stop >= 3:  # stop() must end: the rest is reported
                        return
                # a stop or a hurry cuts it short; stopping, the three tries are not spaced out: each
                # fails at once on a full disk, and their backoff (0.1 + 5 + 5 s) outlasted stop's 10 s
                q.wake.wait(min(backoff, 0.5) if stopping else backoff)
                q.wake.clear()
                backoff = min(backoff * 2, 5.0)
                continue
            if stopping:
                if len(q) and fwd.waiting:  # the spool is forwarded at the next start
                    fwd.spill()
                if not len(q):
                    return
            q.wake.wait(self.interval_s)
            q.wake.clear()

    def keep_lease(self) -> None:
        """Refresh the lease when due; lost: nothing more is written, the queue is given up on."""
        if not self.lease.keep():
            log.error("%s", self.lease.lost)
            with self.queue.lock:
                records = self.queue.drain()
                self.queue.settle(records)
            self.tally.drop(records)
