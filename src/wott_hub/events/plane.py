"""The event plane: sequence numbers, fan-out, in-memory resume buffer.

Every record of a Thing gets the next number of that Thing's sequence, goes to
history (if the Thing is recorded) and to the subscribers interested in it,
in one synchronous call on the event loop: no queue hop, no task switch.

Sequence numbers are never reused, even across a crash. For a recorded Thing
the history database keeps a reservation ``seq_reserved`` ahead of what it has
committed; after SIGKILL the hub continues above it, so the numbers handed to
clients but never committed show up as one gap, not as different events with
old numbers. For a Thing that is not recorded the sequence starts at the
current time in microseconds, which a restart never goes below.

Durability (``durability``, the ``[history] durability`` setting):
- ``"fast"`` (the default): a record goes to subscribers at once and to history
  in the next batch (~50 ms later). A crash (SIGKILL, power) in between loses
  from history records some subscriber already saw; latency is the lowest.
- ``"committed"``: a recorded Thing's records are held on the plane until the
  writer's ``on_commit`` watermark passes them, then delivered: anything a
  subscriber ever saw is in history, and a record the database refused is never
  delivered. The cost is the batch interval plus a commit added to every
  record's latency. Things that are not recorded are delivered at once in both.
  The held queue is bounded per Thing in records (``max_held``) and in bytes
  (``held_max_bytes``, the writer's queue budget: a record held beyond what the
  writer can hold is one it gave up on, or soon will): beyond either the oldest
  held records are not delivered live (``held_dropped``, in health and the log);
  history still has the ones it commits, for a resume.

Resume (SSE ``Last-Event-ID``): records after the client's last id are served
from the in-memory ring of recent records when they are still there, else from
history (waiting, if needed, until the writer has committed them), then the
live stream continues. The subscriber is registered before the backlog is read,
so nothing published in between is missed, and seq de-duplicates the overlap.
A recorded Thing's ring is short (``RING_RECORDED``): history serves what it no
longer holds, and records that die young never reach the collector's oldest
generation (docs/hub.md, "Garbage collection").
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import defaultdict, deque
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Protocol

from wott_hub.errors import HistoryError

from .record import Record, SkinArrays, record_bytes
from .subscriber import Interest, Subscriber

__all__ = ["DURABILITY", "RING_RECORDED", "RING_UNRECORDED", "EventPlane", "HistorySink", "HistorySource",
           "Stream", "Tap"]

DURABILITY = ("fast", "committed")

RING_RECORDED = 512
"""Records a recorded Thing keeps in memory by default (~1.4 s of a 120 Hz skin's three records a
frame): resumes further back read history. Kept short so that a frame's records die before the
collector's middle generation is next collected (~3 s at 32 devices x 120 Hz): 4,096 kept them
~11 s, long enough to fill the oldest generation, whose full collections then took 170 ms."""
RING_UNRECORDED = 4096
"""Records a Thing that is not recorded keeps in memory by default: nothing else can serve its resumes."""

log = logging.getLogger(__name__)


class HistorySink(Protocol):
    """The history writer. ``failed_seqs``: per Thing, the seqs it gave up on (refused by the
    database, or dropped); the plane discards each once its watermark has passed."""

    failed_seqs: dict[str, set[int]]

    def submit(self, rec: Record) -> None: ...


class Tap(Protocol):
    """An in-process observer of every record of a Thing (e.g. wotpy's reactive streams).

    ``active`` False means it has nobody to tell: the record is not even built for it."""

    @property
    def active(self) -> bool: ...

    def __call__(self, rec: Record) -> None: ...


class HistorySource(Protocol):
    """History read back for resumes. ``failure``: why it cannot be trusted now (e.g. the
    database is corrupted), else "" (then a resume that needs it is refused up front)."""

    @property
    def failure(self) -> str: ...

    async def fetch(self, thing: str, after: int, upto: int, interest: Interest,
                    limit: int) -> tuple[list[Record], int]:
        """Records of ``thing`` with after < seq <= upto matching ``interest``, ascending, at most
        ``limit``; and the seq the scan reached (``upto`` when the range is exhausted)."""
        ...


@dataclass(eq=False)
class Stream:
    """One Thing's sequence, ring of recent records, subscribers and counters."""

    thing: str
    record: bool
    seq: int = 0
    committed: int = 0  # everything <= this is in history (or will never be)
    ring: deque[Record] = field(default_factory=deque)
    ring_max: int = RING_UNRECORDED  # the plane's ring size for this Thing (it trims down to it)
    ring_bytes: int = 0  # the ring's records' data, in characters (its hard cap in bytes)
    held: deque[Record] = field(default_factory=deque)  # durability "committed": not yet delivered
    held_bytes: int = 0  # the held records' ``record_bytes``
    held_dropped: int = 0  # held records let go past the bounds: never delivered live
    subs: dict[Interest, list[Subscriber]] = field(default_factory=dict)
    taps: list[Tap] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    _commit_waiters: list[tuple[int, asyncio.Future[None]]] = field(default_factory=list)

    def interested(self, kind: int, name: str) -> bool:
        return bool(self.subs.get((kind, name)) or self.subs.get((kind, None)))


class EventPlane:
    fetch_chunk = 5000  # records per history read of a resume backlog
    commit_wait_s = 10.0  # how long a resume waits for history to commit its backlog

    max_held = 1_000_000  # per Thing, "committed" mode: beyond, the oldest held are not delivered live
    held_max_bytes = 256_000_000
    """Per Thing, "committed" mode: the held records' bytes (``record_bytes``) at most; beyond, the oldest
    are not delivered live. The hub sets the writer's queue budget (``history_queue_mb``): on a full disk
    the writer drops what it cannot queue but the watermark does not move, so the held queue kept every
    record up to ``max_held`` (a raw camera's: +7.5 MB/s, 250 GB at the cap)."""
    held_log_every_s = 10.0  # at most one WARNING this often while held records are let go
    ring_hold_bytes = 32_000_000
    """Per Thing, what the ring keeps beyond ``ring_max`` while history has not committed it, at most
    (and at most 16 x ``ring_max`` records): a raw camera's records on a full disk (never committed)
    kept 65,536 images, ~16 GB (issue 48, item 4)."""

    def __init__(self, *, ring_size: int | None = None, max_pending: int = 100_000,
                 durability: str = "fast", held_max_bytes: int | None = None) -> None:
        """``ring_size``: records per Thing kept in memory; None: ``RING_RECORDED`` for a recorded
        Thing, ``RING_UNRECORDED`` for one that is not. ``held_max_bytes``: see the attribute."""
        self.set_durability(durability)
        if held_max_bytes is not None:
            self.held_max_bytes = held_max_bytes
        self.held_overflow = 0  # held records let go, all Things
        self._held_logged = (-1e9, 0)  # time.monotonic() and held_overflow of the last WARNING
        self.ring_size = ring_size
        self.max_pending = max_pending
        # set by the hub once the history database is open
        self.history_sink: HistorySink | None = None
        self.history_source: HistorySource | None = None
        self.streams: dict[str, Stream] = {}
        self.overflow_disconnects = 0
        self.trace = False  # benchmarks: stamp perf_counter_ns per stage

    def set_durability(self, durability: str) -> None:
        """``"fast"`` or ``"committed"`` (see the module docstring); set before records flow."""
        if durability not in DURABILITY:
            raise ValueError(f"durability must be one of {', '.join(DURABILITY)}, got {durability!r}")
        self.durability = durability
        self.hold = durability == "committed"

    # --- Things -----------------------------------------------------------------

    def add_stream(self, thing: str, *, record: bool, start_after: int | None = None) -> Stream:
        """Register a Thing. ``start_after``: the last seq that may have been used (from history)."""
        if thing in self.streams:
            raise ValueError(f"duplicate Thing {thing!r} on the event plane")
        seq = start_after if start_after is not None else time.time_ns() // 1000
        st = Stream(thing, record, seq=seq, committed=seq, ring_max=self._ring_max(record))
        self.streams[thing] = st
        return st

    def continue_after(self, thing: str, seq: int | None, *, record: bool) -> Stream:
        """Before ``thing`` publishes: whether its records go to history (``record``) and, if ``seq``
        is given, that its sequence continues after it (the last seq history may have handed out)."""
        st = self.stream(thing)
        st.record = record
        st.ring_max = self._ring_max(record)
        if seq is not None:
            st.seq = st.committed = seq
        return st

    def _ring_max(self, record: bool) -> int:
        if self.ring_size is not None:
            return self.ring_size
        return RING_RECORDED if record else RING_UNRECORDED

    def remove_stream(self, thing: str) -> None:
        st = self.streams.pop(thing, None)
        if st is None:
            return
        for subs in list(st.subs.values()):
            for s in list(subs):
                s.close()

    def add_tap(self, thing: str, tap: Tap) -> None:
        """Let ``tap`` observe every record of ``thing`` from now on, until the Thing's stream is removed:
        the one way a binding (wotpy's bridge, the MQTT publisher) follows a Thing in process."""
        self.stream(thing).taps.append(tap)

    def stream(self, thing: str) -> Stream:
        try:
            return self.streams[thing]
        except KeyError:
            raise KeyError(f"unknown Thing {thing!r}") from None

    # --- publishing ---------------------------------------------------------------

    def wants(self, thing: str, kind: int, name: str) -> bool:
        """Does anyone (history, a subscriber, a tap) need this record? If not, don't build it."""
        st = self.streams[thing]
        return st.record or st.interested(kind, name) or any(t.active for t in st.taps)

    def publish(self, thing: str, kind: int, name: str, t_ns: int, data: str,
                trace: dict[str, int] | None = None, skin: SkinArrays | None = None) -> Record:
        """Make the record of these fields and ``put`` it: the next of ``thing``'s sequence."""
        rec = Record(thing, 0, kind, name, t_ns, data, trace, skin)
        self.put(rec)
        return rec

    def put(self, rec: Record) -> None:
        """Number ``rec`` (made elsewhere, ``seq`` 0: a device pipeline's, here or from a worker's pipe)
        and hand it on: ring, history, subscribers. The plane is the hub's ``types.RecordSink``."""
        st = self.streams[rec.thing]
        st.seq += 1
        rec.seq = st.seq
        st.counts[rec.name] += 1
        ring = st.ring
        ring.append(rec)
        st.ring_bytes += len(rec.data)
        if len(ring) > st.ring_max:
            self._trim(st)
        if st.record and self.history_sink is not None:
            self.history_sink.submit(rec)
            if self.hold:  # delivered by on_committed once the writer has committed it
                st.held.append(rec)
                st.held_bytes += record_bytes(rec)
                if len(st.held) > self.max_held or st.held_bytes > self.held_max_bytes:
                    self._shed(st)
                return
        elif not st.record:
            st.committed = rec.seq
        self._deliver(st, rec)

    def _shed(self, st: Stream) -> None:
        """The oldest held records let go until ``st`` is within both bounds (the newest is always kept):
        counted, and said at most every ``held_log_every_s``."""
        held = st.held
        n = 0
        while len(held) > 1 and (len(held) > self.max_held or st.held_bytes > self.held_max_bytes):
            st.held_bytes -= record_bytes(held.popleft())
            n += 1
        st.held_dropped += n
        self.held_overflow += n
        now = time.monotonic()
        at, before = self._held_logged
        if now - at >= self.held_log_every_s:
            self._held_logged = (now, self.held_overflow)
            log.warning("history has not committed %s's records: %d held records over the bound "
                        "(%d records, %.1f MB a Thing; %.1f MB held) were not delivered live (%d in all); "
                        "history keeps the ones it commits", st.thing, self.held_overflow - before,
                        self.max_held, self.held_max_bytes / 1e6, st.held_bytes / 1e6, self.held_overflow)

    def held_health(self) -> dict[str, int]:
        """"committed" mode: what waits for history to commit it, and what was let go past the bounds
        (``notDelivered``): the hub's ``health.history.held``."""
        streams = self.streams.values()
        return {"records": sum(len(st.held) for st in streams),
                "bytes": sum(st.held_bytes for st in streams),
                "maxBytesPerThing": self.held_max_bytes,
                "notDelivered": self.held_overflow}

    @staticmethod
    def _deliver(st: Stream, rec: Record) -> None:
        subs = st.subs
        if subs:
            for s in subs.get((rec.kind, rec.name), ()):
                s.push(rec)
            for s in subs.get((rec.kind, None), ()):
                s.push(rec)
        for tap in st.taps:
            if tap.active:
                tap(rec)

    def _trim(self, st: Stream) -> None:
        """Down to ``ring_max``, keeping what history has not committed (up to a hard cap, in records
        and in bytes)."""
        ring, committed, size = st.ring, st.committed, st.ring_max
        while len(ring) > size and (ring[0].seq <= committed or len(ring) > max(size * 16, 65536)
                                    or st.ring_bytes > self.ring_hold_bytes):
            st.ring_bytes -= len(ring.popleft().data)

    def on_committed(self, watermarks: dict[str, int]) -> None:
        """History has written (or given up on) every record up to these seqs."""
        failed_all = self.history_sink.failed_seqs if self.history_sink is not None else None
        for thing, seq in watermarks.items():
            st = self.streams.get(thing)
            if st is None or seq <= st.committed:
                continue
            st.committed = seq
            failed = failed_all.get(thing) if failed_all else None
            if st.held:
                held = st.held
                while held and held[0].seq <= seq:
                    rec = held.popleft()
                    st.held_bytes -= record_bytes(rec)
                    if not (failed and rec.seq in failed):
                        self._deliver(st, rec)
            if failed:
                for s in [s for s in list(failed) if s <= seq]:
                    failed.discard(s)
            if len(st.ring) > st.ring_max:
                self._trim(st)
            if st._commit_waiters:
                keep = []
                for need, fut in st._commit_waiters:
                    if need <= seq:
                        if not fut.done():
                            fut.set_result(None)
                    else:
                        keep.append((need, fut))
                st._commit_waiters = keep

    async def _wait_committed(self, st: Stream, seq: int) -> None:
        if st.committed >= seq:
            return
        fut = asyncio.get_running_loop().create_future()
        st._commit_waiters.append((seq, fut))
        try:
            await asyncio.wait_for(fut, self.commit_wait_s)
        except TimeoutError:
            log.warning("history has not committed %s up to %d after %.0f s; resuming anyway",
                        st.thing, seq, self.commit_wait_s)

    # --- subscribing --------------------------------------------------------------

    def subscribe(self, thing: str, interest: Interest, after: int | None = None) -> Subscriber:
        """A new consumer of ``thing``'s records matching ``interest``.

        ``after`` (a Last-Event-ID) asks for every matching record with a greater
        seq first; None means live records only.

        A resume that needs history while history is known to be broken raises
        ``HistoryError`` before anything is sent (an HTTP route answers 503): never
        a stream that silently lacks the records asked for.
        """
        st = self.stream(thing)
        # in "committed" mode a subscriber sees only committed records: held ones come live
        head = min(st.seq, st.committed) if self.hold and st.record else st.seq
        if after is not None and 0 <= after < head and st.record and self.history_source is not None:
            ring_first = st.ring[0].seq if st.ring else head + 1
            failure = self.history_source.failure
            if after + 1 < ring_first and failure:
                raise HistoryError(f"cannot resume {thing!r} after {after}: {failure}")
        sub = Subscriber(thing, interest, self.max_pending, self._unsubscribe)
        st.subs.setdefault(interest, []).append(sub)
        if after is None or after >= head:
            sub.last_seq = head  # live only (an id from the future: a reset database)
            return sub
        after = max(after, 0)
        sub.last_seq = after
        snapshot = [r for r in st.ring if after < r.seq <= head and sub.wants(r)]
        ring_first = st.ring[0].seq if st.ring else head + 1
        sub._backfill = self._backfill(st, sub, after, ring_first, snapshot)
        return sub

    def _unsubscribe(self, sub: Subscriber) -> None:
        st = self.streams.get(sub.thing)
        if st is None:
            return
        subs = st.subs.get(sub.interest)
        if subs and sub in subs:
            subs.remove(sub)
            if not subs:
                del st.subs[sub.interest]
        if sub.overflowed:
            self.overflow_disconnects += 1

    async def _backfill(self, st: Stream, sub: Subscriber, after: int, ring_first: int,
                        snapshot: list[Record]) -> AsyncIterator[list[Record]]:
        if after + 1 < ring_first:
            if st.record and self.history_source is not None:
                upto = ring_first - 1
                await self._wait_committed(st, upto)
                cursor = after
                while cursor < upto and not sub.closed:
                    rows, cursor = await self.history_source.fetch(
                        st.thing, cursor, upto, sub.interest, self.fetch_chunk)
                    if rows:
                        yield rows
            else:
                sub.gap = (after, ring_first)
        if snapshot:
            yield snapshot

    # --- introspection ------------------------------------------------------------

    def counters(self) -> dict[str, dict[str, object]]:
        return {
            thing: {
                "seq": st.seq,
                "published": sum(st.counts.values()),
                "byName": dict(st.counts),
                "subscribers": sum(len(v) for v in st.subs.values()),
                "recorded": st.record,
            }
            for thing, st in self.streams.items()
        }
