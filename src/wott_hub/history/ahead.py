"""A batch whose payloads are encoded before it is written: the writer's pipelining.

With a storage that ``overlaps`` (PostgreSQL), while the server works through one batch's data
the writer's thread encodes the next batch a slice at a time (``Ahead.step``, called between its
socket writes), then prepares its rows: the two costs overlap instead of adding up. Records
forwarded from the spool were encoded when they were spooled (``Given``). Either is what
``BatchWriter.write_isolating`` takes as ``encoded``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from wott_hub.events.record import Record

from .storage import Prepared, StorageWriter

__all__ = ["ENCODE_SLICE", "Ahead", "Given"]

ENCODE_SLICE = 1_000
"""Records encoded per step of ``Ahead``: about 4 ms, well under the ~20 ms of work that a
socket's buffer of COPY data gives PostgreSQL (and no dearer per record than a whole batch)."""


class Given:
    """A batch's payloads encoded already (records forwarded from the spool): what ``Ahead`` gives."""

    prepared: Prepared | None = None

    def __init__(self, payloads: list[bytes]) -> None:
        self._payloads = payloads

    def result(self) -> list[bytes]:
        return self._payloads


class Ahead:
    """The next batch, its payloads encoded a slice at a time (``step``) while the current batch
    is written, then prepared (``prepared``); ``result`` encodes what is left. An error encoding
    is kept for ``result``: it belongs to this batch, not to the one being written; one preparing
    leaves ``prepared`` None (the batch writer prepares it again and raises it, for that batch)."""

    def __init__(self, storage: StorageWriter, batch: list[Record]) -> None:
        self.batch = batch
        self.prepared: Prepared | None = None
        self._encode: Callable[[Sequence[Record]], list[bytes]] = storage.encode
        self._prepare: Callable[[Sequence[Record], list[bytes]], Prepared] | None = storage.prepare
        self._parts: list[list[bytes]] = []
        self._done = 0
        self._error: Exception | None = None

    def step(self) -> bool:
        """Encode one more slice, or prepare the batch once all are; False once nothing is left."""
        if self._error is not None:
            return False
        if self._done >= len(self.batch):
            prepare, self._prepare = self._prepare, None
            if prepare is None:
                return False
            try:
                self.prepared = prepare(self.batch, self.result())
            except Exception:
                pass  # the batch writer prepares again, and raises it for this batch
            return False
        part = self.batch[self._done:self._done + ENCODE_SLICE]
        try:
            self._parts.append(self._encode(part))
        except Exception as e:
            self._error = e
            return False
        self._done += len(part)
        return True

    def result(self) -> list[bytes]:
        while self._error is None and self._done < len(self.batch):
            self.step()
        if self._error is not None:
            raise self._error
        return [d for part in self._parts for d in part]
