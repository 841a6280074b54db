"""A progress bar on stderr for the history commands that read long ranges (export, replay's start).

Why by sequence number: a range's records are read in seq order, page by page, and the span of
seqs each device has in the range is known before reading (two index lookups); the last seq
of each page read says how far along that device is, with or without a name filter (which
only skips records). ``Tracked`` wraps a reader so that every page a consumer takes (JSON
Lines, MCAP, several devices merged) moves the bar, without those consumers knowing.

The bar is drawn only when stderr is a terminal (a script's stderr stays clean), by rich,
already a dependency of the command; ``--no-progress`` turns it off.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.progress import Progress, TaskID

    from wott_hub.events.record import Record
    from wott_hub.history.reader import HistoryReader
    from wott_hub.history.storage import Columns

__all__ = ["Bar", "Tracked", "wanted"]


def wanted(enabled: bool) -> bool:
    """A bar is drawn when asked for and stderr is a terminal."""
    return enabled and sys.stderr.isatty()


class Bar:
    """A bar over ``total`` steps on stderr, or nothing when not ``shown``; a context manager."""

    def __init__(self, what: str, total: int, shown: bool) -> None:
        self._progress: Progress | None = None
        self._task: TaskID | None = None
        if shown and total > 0:
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeRemainingColumn

            self._progress = Progress(TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
                                      TimeRemainingColumn(), console=Console(stderr=True), transient=True)
            self._task = self._progress.add_task(what, total=total)

    def __enter__(self) -> Bar:
        if self._progress is not None:
            self._progress.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._progress is not None:
            self._progress.stop()

    def update(self, done: int, total: int | None = None) -> None:
        """``done`` steps (of ``total``, when it is known only now)."""
        if self._progress is not None and self._task is not None:
            if total:
                self._progress.update(self._task, completed=done, total=total)
            else:
                self._progress.update(self._task, completed=done)


class Tracked:
    """``reader`` whose ``pages`` and ``columns`` move ``bar`` by the seqs they have reached; every
    other attribute is the reader's own."""

    def __init__(self, reader: HistoryReader, spans: dict[str, tuple[int, int]], bar: Bar) -> None:
        self._reader = reader
        self._spans = spans
        self._at = dict.fromkeys(spans, 0)
        self._bar = bar

    @staticmethod
    def spans(reader: HistoryReader, things: Sequence[str], t_from_ns: int | None,
              t_to_ns: int | None) -> dict[str, tuple[int, int]]:
        """Each Thing's first and last seq in the range (the bar's total is the sum of the spans)."""
        out = {}
        for thing in things:
            span = reader.seq_range(thing, t_from_ns, t_to_ns)
            if span is not None:
                out[thing] = span
        return out

    @staticmethod
    def total(spans: dict[str, tuple[int, int]]) -> int:
        return sum(hi - lo + 1 for lo, hi in spans.values())

    def __getattr__(self, name: str) -> Any:
        return getattr(self._reader, name)

    def _reached(self, thing: str, seq: int) -> None:
        lo, hi = self._spans.get(thing, (seq, seq))
        self._at[thing] = min(seq, hi) - lo + 1
        self._bar.update(sum(self._at.values()))

    def pages(self, thing: str, *args: Any, **kwargs: Any) -> Iterator[list[Record]]:
        for page in self._reader.pages(thing, *args, **kwargs):
            self._reached(thing, page[-1].seq)
            yield page

    def columns(self, thing: str, *args: Any, **kwargs: Any) -> Iterator[Columns]:
        for cols in self._reader.columns(thing, *args, **kwargs):
            self._reached(thing, cols.seqs[-1])
            yield cols
