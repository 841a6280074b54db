"""The history writer's batches written by a process of their own, off the event loop's GIL.

Why: the writer thread encodes each batch (``codec.py``) and has the driver bind its rows, in
Python, holding the GIL it shares with the event loop; the loop waits for it each time (up to
the interpreter's 5 ms switch interval). Measured at 32 devices x 120 Hz on 2 cores: 2,730 of
3,840 frames/s processed and SSE p50 5.3 ms with the thread, 3,530-3,620 and 1.4-1.7 ms with no
history at all (docs/history.md, "The writer's process"). Here the writer's thread only hands
each batch's records over, as they are, and waits (GIL released) while this process has the
same storage engine (``engines.open_storage``) encode and commit them; the writer keeps
everything else (queue, lease, reservations, isolation of refused records, health, retention).
A backlog (``batch_writer.CATCH_UP``) the thread writes itself: handing over costs ~8 µs a record,
more than catching up can spare.

Protocol: two pipes of pickled messages (``multiprocessing.connection`` framing), strictly
request then answer. Writer -> process: ``("open", url, compact)`` once, then per batch any number of
``("part", records)`` (no answer: the process keeps them) and one ``("write", records, keys,
reserve)`` (``records``: the batch's ``Record``s, the parts' first, as tuples of their fields
(``Fields``), which the process makes ``Record``s again; ``keys``: the database key of each of
their Things; ``reserve``: Thing -> ``seq_reserved`` to set in the same transaction).
Process -> writer: ``("ok",)``, ``("refused", message)`` (``RecordRefused``: the writer
isolates the records as it does its own), ``("error", message)`` (anything else: a
``HistoryError``, the writer retries the batch with backoff).

The writer's thread starts the process when it starts (its imports take ~0.5 s: the first batch
would wait for them). The process runs in its own session (a Ctrl-C or a SIGTERM to the hub's
process group does not reach it) and ends when its input closes: the hub stopping, or dying
(even SIGKILL), after the batch in hand. A process that exits (killed, crashed) fails the batch
in hand; the writer retries it and the next batch starts a new process.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from collections.abc import Mapping, Sequence
from multiprocessing.connection import Connection
from typing import Any

from wott_hub.errors import HistoryError, RecordRefused
from wott_hub.events.fields import FieldRecord, Wire
from wott_hub.events.record import Record, SkinArrays

__all__ = ["BatchProcess", "Fields", "fields_of", "main", "records_of"]

log = logging.getLogger(__name__)

Fields = tuple[str, int, int, str, int, "str | None", "tuple[bytes, bytes] | Wire | None"]
"""A ``Record`` as it crosses: its fields in ``Record``'s order, the skin arrays as bytes
(``SkinArrays.to_wire``). Pickled so, a batch costs the writer's side ~1.1 µs a record; as
``Record``s (their ``__reduce__``) ~1.7 µs, and that side is the hub's process (measured).
A ``skinDisplacement`` record (``events.fields.FieldRecord``) crosses as its numbers
(``FieldRecord.wire``, mm as the pipeline made them: quantised in this process, not the hub's)
with ``data`` None unless its text was already written: history packs the numbers and never
needs the text."""


_SLICE = 32
"""Records a message carries: a batch crosses as "part" messages and a last "write". The writer's
thread holds the GIL while it makes and pickles a message (~1.5 µs a record) and lets it go at each
send, so the event loop waits ~50 µs for it at most, not the whole batch's ~1.5 ms (or the
interpreter's 5 ms switch interval). Measured at 32 devices: the SSE fan-out's p99 0.23-0.25 ms
with 32 records a message, 0.31-0.34 with 128 (0.22-0.27 before batches grew to a whole interval)."""


class BatchProcess:
    """The writer thread's handle on the process: started when the thread starts, again after it exits.
    ``url``: the database (sent over the pipe, never in argv); ``compact``: as the writer's storage."""

    def __init__(self, url: str, compact: bool) -> None:
        self._url = url
        self._compact = compact
        self._proc: subprocess.Popen[bytes] | None = None
        self._to: Connection | None = None
        self._from: Connection | None = None

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    def write(self, records: Sequence[Record], keys: Mapping[str, int], reserve: Mapping[str, int]) -> None:
        """Write ``records`` and move ``reserve`` in one transaction, as ``StorageWriter.write``
        does: ``RecordRefused``, or ``HistoryError`` for anything else (the process gone too)."""
        last = max(0, len(records) - 1) // _SLICE * _SLICE
        for i in range(0, last, _SLICE):  # the GIL is let go at each send: the event loop runs between
            self._tell(("part", fields_of(records[i:i + _SLICE])))
        answer = self._ask(("write", fields_of(records[last:]), dict(keys), dict(reserve)))
        if answer[0] == "refused":
            raise RecordRefused(answer[1])
        if answer[0] != "ok":
            raise HistoryError(answer[1])

    def _tell(self, msg: tuple[Any, ...]) -> None:
        """Send ``msg``, which has no answer."""
        if self._to is None:
            self.start()
        assert self._to is not None
        try:
            self._to.send(msg)
        except OSError as e:
            raise self._gone(e) from None

    def _ask(self, msg: tuple[Any, ...]) -> tuple[Any, ...]:
        self._tell(msg)
        assert self._from is not None
        try:
            answer: tuple[Any, ...] = self._from.recv()
        except (EOFError, OSError) as e:
            raise self._gone(e) from None
        return answer

    def _gone(self, e: BaseException) -> HistoryError:
        """The process, whose pipe failed with ``e``, reaped: the error to raise."""
        return HistoryError(f"the history process exited ({self._reap()}) before answering: {e!r}")

    def start(self) -> None:
        """Start the process and have it open the database (the writer thread does, before its first
        batch: the process takes ~0.5 s to import what it needs); nothing if it runs."""
        if self._to is not None:
            return
        from_hub, to_child = os.pipe()  # (read end, write end)
        from_child, to_hub = os.pipe()
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", __name__, str(from_hub), str(to_hub)], pass_fds=(from_hub, to_hub),
                stdin=subprocess.DEVNULL, start_new_session=True)
        except OSError as e:
            os.close(to_child)
            os.close(from_child)
            raise HistoryError(f"cannot start the history process: {e}") from None
        finally:
            os.close(from_hub)
            os.close(to_hub)
        self._to = Connection(to_child, readable=False)
        self._from = Connection(from_child, writable=False)
        answer = self._ask(("open", self._url, self._compact))
        if answer[0] != "ok":
            self.close()
            raise HistoryError(answer[1])
        log.debug("history process %d started", self._proc.pid)

    def _reap(self) -> int | None:
        """Close the pipes and wait for the process (killed if it does not end): its exit code."""
        for conn in (self._to, self._from):
            if conn is not None:
                conn.close()
        self._to = self._from = None
        proc, self._proc = self._proc, None
        if proc is None:
            return None
        try:
            return proc.wait(10.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait()

    def close(self) -> None:
        """End the process: its input closes, it finishes and exits."""
        self._reap()


def fields_of(records: Sequence[Record]) -> list[Fields]:
    return [(r.thing, r.seq, r.kind, r.name, r.t_ns, r.data, None if r.skin is None else r.skin.to_wire())
            if type(r) is not FieldRecord else
            (r.thing, r.seq, r.kind, r.name, r.t_ns, r.data if r.text_built else None, r.wire())
            for r in records]


def records_of(fields: list[Fields]) -> list[Record]:
    return [_record(*f) for f in fields]


def _record(thing: str, seq: int, kind: int, name: str, t_ns: int, data: str | None,
            skin: tuple[bytes, bytes] | Wire | None) -> Record:
    if skin is not None and len(skin) == 3:  # a FieldRecord's numbers
        return FieldRecord.revive(thing, seq, t_ns, skin, None, data)
    if data is None:
        raise ValueError(f"record {seq} of {thing!r} crossed without its payload")
    arrays = None if skin is None else SkinArrays.from_wire(skin)
    return Record(thing, seq, kind, name, t_ns, data, None, arrays)


# --- the process ------------------------------------------------------------------------

def main(read_fd: int, write_fd: int) -> None:
    """Answer the writer's requests until its pipe closes."""
    inbox, outbox = Connection(read_fd, writable=False), Connection(write_fd, readable=False)
    from .db import create_engine
    from .db_errors import driver_message
    from .engines import open_storage

    try:
        _, url, compact = inbox.recv()
    except EOFError:
        return
    try:
        engine = create_engine(url)
        storage = open_storage(engine, compact=compact)
    except Exception as e:
        outbox.send(("error", f"the history process cannot open the database: {driver_message(e)}"))
        return
    outbox.send(("ok",))
    parts: list[Fields] = []
    while True:
        try:
            msg = inbox.recv()
        except EOFError:  # the writer stopped, or the hub is gone
            break
        if msg[0] == "part":
            parts += msg[1]
            continue
        _, fields, keys, reserve = msg
        fields, parts = parts + fields, []
        storage.keys.update(keys)
        try:
            storage.write(storage.prepare(records_of(fields)), reserve)
        except RecordRefused as e:
            outbox.send(("refused", str(e)))
        except Exception as e:
            outbox.send(("error", driver_message(e)))
        else:
            outbox.send(("ok",))
    engine.dispose()


if __name__ == "__main__":
    logging.basicConfig(format="wott-hub history process: %(levelname)s %(message)s")
    main(int(sys.argv[1]), int(sys.argv[2]))
