"""Lifecycle events and their fan-out to SSE subscribers, with replay for ``Last-Event-ID``.

The replay log is bounded twice: ``retention`` events and ``max_bytes`` bytes of their
data's JSON (``Event.size``: a created TD or an update's diff may be megabytes); the
oldest events go first.

Publishing happens on the event loop, synchronously: the event goes into the
replay log and into every subscriber's queue in one step, so a subscriber that
snapshots the log and registers in the same step can neither miss an event nor
see one twice. Each event renders its SSE text at most twice (with and without
``diff``), whatever the number of subscribers.
"""

from __future__ import annotations

import asyncio
import json
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["EVENT_TYPES", "Event", "EventHub", "Subscription"]

EVENT_TYPES = ("thing_created", "thing_updated", "thing_deleted")


@dataclass
class Event:
    id: int
    type: str
    thing_id: str
    data: dict[str, Any] | None = None
    """The full TD (created) or the merge patch including ``id`` (updated); None for deleted."""
    size: int = 0
    """Bytes of ``data``'s JSON (what the event costs the replay log's byte budget)."""
    _text: dict[bool, bytes] = field(default_factory=dict, repr=False)

    def payload(self, diff: bool) -> dict[str, Any]:
        """The event data: the id only, or with ``diff`` the TD/patch (never for deletions)."""
        if diff and self.data is not None and self.type != "thing_deleted":
            return self.data
        return {"id": self.thing_id}

    def sse(self, diff: bool) -> bytes:
        text = self._text.get(diff)
        if text is None:
            data = json.dumps(self.payload(diff), ensure_ascii=False, separators=(",", ":"))
            text = f"id: {self.id}\nevent: {self.type}\ndata: {data}\n\n".encode()
            self._text[diff] = text
        return text


class Subscription:
    """One SSE client: the event types it wants and its queue of events not yet written."""

    def __init__(self, types: Iterable[str], diff: bool, maxsize: int) -> None:
        self.types = frozenset(types)
        self.diff = diff
        self.queue: asyncio.Queue[Event | None] = asyncio.Queue(maxsize)
        self.overflowed = False
        self.closed = False

    def offer(self, event: Event) -> None:
        if event.type not in self.types or self.overflowed:
            return
        try:
            self.queue.put_nowait(event)
        except asyncio.QueueFull:
            # too slow: the writer sees the flag once it drains the (full) queue and ends the
            # stream; the client reconnects with Last-Event-ID and replays what it missed
            self.overflowed = True

    def close(self) -> None:
        self.closed = True
        try:
            self.queue.put_nowait(None)
        except asyncio.QueueFull:
            pass  # the writer is busy draining and checks ``closed`` next


class EventHub:
    def __init__(self, retention: int, queue_size: int, max_bytes: int | None = None) -> None:
        self.log: deque[Event] = deque()
        self.retention = retention
        self.max_bytes = max_bytes
        self.log_bytes = 0  # sum of the logged events' ``size``
        self.subscribers: set[Subscription] = set()
        self.queue_size = queue_size
        self.last_id = 0
        self.trimmed_to = 0  # storage holds no event of this id or older

    def restore(self, events: Iterable[Event]) -> None:
        """Events loaded from storage at start, oldest first (it loads ``retention`` at most)."""
        for ev in events:
            self._log(ev)
            self.last_id = max(self.last_id, ev.id)
        self.trimmed_to = max(0, self.last_id - self.retention)

    def to_trim(self) -> int | None:
        """The id up to which storage may now delete events: it keeps what this log keeps (count and
        bytes), no older one; None when nothing more may go. Tell ``trimmed_to`` once it did."""
        keep_after = max(self.last_id - self.retention, self.first_kept - 1)
        return keep_after if keep_after > self.trimmed_to else None

    def next_id(self) -> int:
        self.last_id += 1
        return self.last_id

    def _log(self, event: Event) -> None:
        log = self.log
        log.append(event)
        self.log_bytes += event.size
        while log and (len(log) > self.retention
                       or (self.max_bytes is not None and self.log_bytes > self.max_bytes)):
            self.log_bytes -= log.popleft().size

    @property
    def first_kept(self) -> int:
        """The id of the oldest event kept (``last_id + 1`` when none is): storage keeps no older one."""
        return self.log[0].id if self.log else self.last_id + 1

    def publish(self, event: Event) -> None:
        self._log(event)
        for sub in self.subscribers:
            sub.offer(event)

    def subscribe(self, types: Iterable[str], diff: bool,
                  last_event_id: int | None) -> tuple[Subscription, list[Event]]:
        """Register a subscriber and return the events it missed after ``last_event_id``."""
        sub = Subscription(types, diff, self.queue_size)
        missed: list[Event] = []
        if last_event_id is not None:
            missed = [ev for ev in self.log if ev.id > last_event_id and ev.type in sub.types]
        self.subscribers.add(sub)
        return sub, missed

    def unsubscribe(self, sub: Subscription) -> None:
        self.subscribers.discard(sub)

    def close_all(self) -> None:
        for sub in list(self.subscribers):
            sub.close()
