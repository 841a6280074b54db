"""Zero-order hold: every recorded stream of an episode onto one grid of frame times, never a future sample.

Frame ``k`` of an episode that starts at ``start_ns`` is at ``t_k = start_ns + (k * 10**9) // fps`` (ns,
floored). A stream's value at ``t_k`` is its last sample with ``t_ns <= t_k`` (of two at the same
time, the later-numbered one), its age ``(t_k - t_ns) / 1e9`` seconds; before its first sample it has
none (index -1, age -1). The sample held when an episode starts is looked up before it
(``StorageReader.last_at``): a press that began before the episode is there in its first frame.

Streams are read once per Thing (``ThingReader``: its records of the episode in seq order, handed to
each stream by ``Stream.accepts``) a block of frames at a time, so memory holds a block and a page, not
an episode. A page is bounded in bytes as well as in records (``PAGE_BYTES``): a stream of large
records (camera images, ~0.5 MB each) is read in pages of its own, a few dozen records each, the
small ones together 20,000 at a time. (One page of 20,000 records of a camera's Thing was ~120 MB of
images, three copies of it in memory while SQLite joined it and the next one was read ahead: the
export's peak memory.) Within a Thing seq order is time order except for records published after
later ones (a camera image, published once encoded, ~100 ms late): a block is held only once each
of the Thing's page streams has reached ``LATE_NS`` past its last frame, and each stream's samples
are put in time order first.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from itertools import compress
from operator import attrgetter
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np

if TYPE_CHECKING:
    from wott_hub.events.record import Record

    from ..storage import StorageReader

__all__ = ["LATE_NS", "PAGE_BYTES", "Held", "Stream", "ThingReader", "frame_times", "page_groups"]

LATE_NS = 2_000_000_000
"""How far past a block's last frame a Thing's records are read before the block is held."""
PAGE_BYTES = 8 << 20
"""About the payload bytes a page holds at most (a page is read ahead while the one before is used)."""
_TIME_NS = 10**9
_T_NS = attrgetter("t_ns")
_NAME = attrgetter("name")


def frame_times(start_ns: int, fps: int, k0: int, k1: int) -> np.ndarray:
    """The times (ns, int64) of frames k0..k1-1 of an episode starting at ``start_ns``."""
    k = np.arange(k0, k1, dtype=np.int64)
    return start_ns + (k * _TIME_NS) // fps


class Held(NamedTuple):
    """A block of frames of one stream: ``samples`` in time order, and per frame ``which`` sample is held
    (its index, -1: none yet) and its ``age_s`` (float32 seconds, -1 with none)."""

    samples: list[Record]
    which: np.ndarray
    age_s: np.ndarray


class Stream(Protocol):
    """What a ``ThingReader`` hands records to: one recorded affordance (or one camera of it)."""

    name: str
    """The affordance its records have."""

    picky: bool
    """False: every record of ``name`` is this stream's (``accepts`` is not asked)."""

    def accepts(self, rec: Record) -> bool:
        """Whether a record of ``name`` is this stream's (a camera picks its own images)."""
        ...


class _Samples:
    """One stream's samples not yet past the frames held, and the one held last."""

    def __init__(self, before: Record | None) -> None:
        self.last = before
        self.waiting: list[Record] = []

    def hold(self, times: np.ndarray) -> Held:
        w = self.waiting
        t = np.fromiter(map(_T_NS, w), np.int64, len(w))
        if len(t) > 1 and (t[1:] < t[:-1]).any():
            order = np.argsort(t, kind="stable")  # stable: equal times keep seq order
            w, t = [w[i] for i in order.tolist()], t[order]
        n = int(np.searchsorted(t, times[-1], side="right"))  # those at or before the last frame
        fresh, self.waiting = w[:n], w[n:]
        samples = ([self.last] if self.last is not None else []) + fresh
        if not samples:
            return Held(samples, np.full(len(times), -1, np.int64), np.full(len(times), -1.0, np.float32))
        if self.last is not None:
            t = np.concatenate([[self.last.t_ns], t[:n]])
        else:
            t = t[:n]
        index = np.searchsorted(t, times, side="right") - 1
        age = np.where(index >= 0, (times - t[np.maximum(index, 0)]) / 1e9, -1.0).astype(np.float32)
        self.last = samples[-1]
        return Held(samples, index, age)


def page_groups(sizes: dict[str, int], page: int) -> list[tuple[list[str], int]]:
    """The names read together and their page (records): those of records no larger than
    ``PAGE_BYTES / page`` together in pages of ``page``, each other one alone in pages of
    ``PAGE_BYTES`` (at least 4 records). ``sizes``: a record's typical payload length per name."""
    small = sorted(n for n, size in sizes.items() if size * page <= PAGE_BYTES)
    large = sorted(n for n in sizes if n not in small)
    groups = [(small, page)] if small else []
    return groups + [([n], max(4, min(page, PAGE_BYTES // max(sizes[n], 1)))) for n in large]


class _Pages:
    """Pages of some of a Thing's streams, and the time the last one read reached."""

    def __init__(self, pages: Iterator[list[Record]], start_ns: int) -> None:
        self.pages: Iterator[list[Record]] | None = pages
        self.reached = start_ns


class ThingReader:
    """One Thing's records in [start_ns, end_ns], read once, held block by block for each stream."""

    def __init__(
        self,
        reader: StorageReader,
        thing: str,
        streams: Sequence[Stream],
        start_ns: int,
        end_ns: int,
        page: int = 20_000,
    ) -> None:
        self.streams = list(streams)
        names = sorted({s.name for s in self.streams})
        self._by_name: dict[str, list[tuple[Stream, _Samples]]] = {}
        self._samples: dict[int, _Samples] = {}
        sizes: dict[str, int] = {}
        for s in self.streams:
            last = reader.last_at(thing, s.name, start_ns, limit=8)
            before = next((r for r in last if s.accepts(r)), None)
            samples = self._samples[id(s)] = _Samples(before)
            self._by_name.setdefault(s.name, []).append((s, samples))
            last = last or reader.last_at(thing, s.name, end_ns)
            sizes[s.name] = max([sizes.get(s.name, 0), *(len(r.data) for r in last)])
        self._groups = (
            [
                _Pages(reader.pages(thing, start_ns + 1, end_ns, group, size, numbers=True), start_ns)
                for group, size in page_groups({n: sizes[n] for n in names}, page)
            ]
            if names and end_ns > start_ns
            else []
        )
        self.records = 0

    def _read_until(self, t_ns: int) -> None:
        by_name = self._by_name
        for group in self._groups:
            while group.pages is not None and group.reached < t_ns:
                page = next(group.pages, None)
                if page is None:
                    group.pages = None
                    break
                self.records += len(page)
                names = list(map(_NAME, page))
                for name, takers in by_name.items():  # each name's records picked by C-level iterators
                    of_name = list(compress(page, map(name.__eq__, names)))
                    for stream, samples in takers:
                        samples.waiting.extend(filter(stream.accepts, of_name) if stream.picky else of_name)
                group.reached = max(group.reached, page[-1].t_ns)

    def hold(self, times: np.ndarray) -> list[Held]:
        """Each stream's block at ``times`` (ascending), in the order of ``streams``."""
        self._read_until(int(times[-1]) + LATE_NS)
        return [self._samples[id(s)].hold(times) for s in self.streams]
