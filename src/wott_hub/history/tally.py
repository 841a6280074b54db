"""What became of the records a history writer was given: the counters its pieces share.

The writer's pieces (the queue, the batches, store and forward, the thread) each move records
one step on; what they did is counted here, in one place, so that ``HistoryWriter.health()``
and ``outcome()`` read one account rather than ask every piece. ``on_commit`` is the event
plane's watermark callback: a record counts as durable once it is committed, spooled or given
up on, and the plane is told the highest seq per Thing.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from wott_hub.events.record import Record

__all__ = ["Tally"]


@dataclass(eq=False)
class Tally:
    on_commit: Callable[[dict[str, int]], None] | None = None
    committed: dict[str, int] = field(default_factory=dict)
    """The last seq per Thing that is durable (written, spooled, or given up on)."""
    failed_seqs: dict[str, set[int]] = field(default_factory=dict)
    """Seqs given up on per Thing (the plane drops them in ``committed`` mode, then discards them)."""
    started: dict[str, int] = field(default_factory=dict)
    """The seq each Thing registered this run started after (``mine``)."""
    submitted: int = 0
    written: int = 0
    dropped: int = 0
    batches: int = 0
    last_batch_s: float = 0.0
    errors: int = 0
    last_error: str = ""
    failed_records: int = 0
    last_refused: float = -1e9  # time.monotonic() of the last refused record
    failing: bool = False  # the last batch attempt failed and is being retried
    failing_since: float | None = None
    spooled: int = 0  # records moved to the spool (this run)
    forwarded: int = 0  # records written from the spool (any run's)

    def tell(self, tops: dict[str, int]) -> None:
        """``tops`` (the last seq per Thing) are durable now: tell the plane."""
        if self.on_commit is not None:
            self.on_commit(tops)

    def give_up(self, thing: str, seq: int) -> None:
        self.failed_seqs.setdefault(thing, set()).add(seq)

    def drop(self, records: Iterable[Record]) -> None:
        """``records`` will not be recorded (the lease was lost): counted, given up on, the plane told."""
        tops: dict[str, int] = {}
        for r in records:
            self.dropped += 1
            tops[r.thing] = r.seq
            self.give_up(r.thing, r.seq)
        if tops:
            self.tell(tops)

    def mine(self, thing: str, seq: int) -> int:
        """1 if the record was handed out in this run (``written`` and ``flush`` count those only)."""
        start = self.started.get(thing)
        return int(start is not None and seq > start)

    @property
    def accounted(self) -> int:
        """Records that are done with: written, dropped or refused (``flush`` waits for all)."""
        return self.written + self.dropped + self.failed_records
