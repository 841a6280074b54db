"""The history spool: records that cannot reach the database, kept on local disk in order.

Store and forward, as device gateways do: when the database is unreachable (PostgreSQL down,
SQLite locked or its disk full) for longer than the writer's patience, or when the hub stops
before it returns, the writer moves the records it holds into this spool instead of dropping
them; when the database answers again (or at the next start) it forwards them first, oldest
first, then carries on with what is new.

Contract:
- Everything in the spool is older than everything the writer holds in memory: the writer
  moves its whole queue to the spool's tail, and writes its queue only once the spool is empty.
  So records reach the database in the order they were made.
- A record is removed from the spool only after its batch is committed (a whole segment at a
  time): a crash in between forwards it again, and the writer leaves out the rows the database
  already has (``StorageWriter.existing``): no duplicates.
- Bounded: at most ``max_bytes`` on disk; beyond it the oldest segment is dropped, its records
  counted in ``dropped`` (they are lost; health and the stop report say so).
- Crash-safe: each ``append`` is one frame (length, CRC-32, msgpack of the rows), written and
  ``fsync``-ed before it returns. A frame torn by a crash fails its CRC and ends the segment's
  reading; what came before it is intact. Spooled records count as durable: in ``committed``
  mode subscribers get them once they are on disk.
- One process per spool: an exclusive ``flock`` on ``lock`` in the folder, taken by ``open`` if
  the folder exists and by the first ``append`` otherwise (``Conflict`` naming the folder if
  another holds it); the database's writer lease keeps two hubs off one database in the same
  way. A hub whose database never failed leaves no folder behind.

Layout: a folder of segments ``<n>.seg`` (n ascending: the order they were written), each
``MAGIC`` then frames. A segment is written only while it is the last one ("the tail"); it is
sealed (a new tail begun) before it is read for forwarding.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import msgspec

from wott_hub.errors import Conflict, HistoryError

__all__ = ["MAGIC", "SEGMENT_BYTES", "Segment", "Spool", "SpoolRow"]

MAGIC = b"WOTTSPL1"
SEGMENT_BYTES = 4 << 20
"""A segment is sealed past this size: what one forwarding step reads at once (a few MB)."""

SpoolRow = tuple[str, int, int, str, int, bytes]
"""A spooled record: (thing, seq, kind, name, t_ns, payload as the database stores it)."""

_FRAME = struct.Struct("<II")  # payload length, CRC-32 of the payload
_MAX_FRAME = 1 << 30


@dataclass
class Segment:
    """One segment file and what it holds (kept in memory: counts, times, the last seqs)."""

    number: int
    path: Path
    records: int = 0
    size: int = 0
    first_t_ns: int | None = None


class Spool:
    def __init__(self, folder: str | Path, max_bytes: int, *, segment_bytes: int = SEGMENT_BYTES) -> None:
        if max_bytes < 1 << 16:
            raise HistoryError(f"the history spool needs at least 64 KiB, got {max_bytes} bytes")
        self.folder = Path(folder)
        self.max_bytes = int(max_bytes)
        self.segment_bytes = max(1 << 12, min(segment_bytes, self.max_bytes // 8))
        self.dropped = 0
        """Records dropped because the spool was full (the oldest segment went)."""
        self.max_seq: dict[str, int] = {}
        """The highest seq ever spooled per Thing (this run or a previous one): a Thing registered
        while its records still wait here continues above them."""
        self._segments: list[Segment] = []
        self._forwarding: Segment | None = None  # the segment ``head`` gave out, not yet consumed
        self._tail: IO[bytes] | None = None
        self._lock_file: IO[bytes] | None = None
        self._encoder = msgspec.msgpack.Encoder()
        self._decoder = msgspec.msgpack.Decoder(list[tuple[str, int, int, str, int, bytes]])

    # --- opening ------------------------------------------------------------------------

    def open(self) -> None:
        """Read what a previous run left, if anything (the folder taken: ``Conflict`` if another
        process has it); a folder that does not exist is made by the first ``append``."""
        if not self.folder.is_dir():
            return
        self._take_folder()
        for path in sorted(self.folder.glob("*.seg"), key=_number):
            seg = Segment(_number(path), path)
            rows = self._read(seg)
            if not rows:
                path.unlink(missing_ok=True)
                continue
            self._count(seg, rows)
            self._segments.append(seg)

    def _take_folder(self) -> None:
        if self._lock_file is not None:
            return
        import fcntl

        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            lock = (self.folder / "lock").open("ab")
        except OSError as e:
            raise HistoryError(f"cannot use the history spool {str(self.folder)!r}: {e.strerror or e}") \
                from None
        try:
            fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            raise Conflict(f"the history spool {str(self.folder)!r} is in use by another process; "
                           "give each hub its own [hub] history_spool") from None
        self._lock_file = lock

    def close(self) -> None:
        if self._tail is not None:
            self._tail.close()
            self._tail = None
        if self._lock_file is not None:
            self._lock_file.close()  # releases the flock
            self._lock_file = None

    # --- what is in it ------------------------------------------------------------------

    @property
    def records(self) -> int:
        return sum(s.records for s in self._segments)

    @property
    def bytes(self) -> int:
        return sum(s.size for s in self._segments)

    @property
    def oldest_t_ns(self) -> int | None:
        """The record time of the oldest record waiting (None: empty)."""
        return self._segments[0].first_t_ns if self._segments else None

    # --- writing ------------------------------------------------------------------------

    def append(self, rows: Sequence[SpoolRow]) -> int:
        """Add ``rows`` (in order) at the tail, on disk before this returns; returns how many older
        records were dropped to stay within ``max_bytes``. ``HistoryError`` if the disk refuses
        (nothing of ``rows`` is then kept)."""
        if not rows:
            return 0
        self._take_folder()
        body = self._encoder.encode(list(rows))
        frame = _FRAME.pack(len(body), zlib.crc32(body)) + body
        tail = self._segments[-1] if self._segments and self._tail is not None else None
        try:
            if tail is None or tail.size + len(frame) > self.segment_bytes and tail.size > len(MAGIC):
                tail = self._begin()
            assert self._tail is not None
            start = self._tail.tell()
            try:
                self._tail.write(frame)
                self._tail.flush()
                os.fsync(self._tail.fileno())
            except OSError:
                self._tail.truncate(start)  # no half frame left behind for the next append
                raise
        except OSError as e:
            raise HistoryError(f"cannot write the history spool {str(self.folder)!r}: "
                               f"{e.strerror or e}") from None
        tail.size += len(frame)
        self._count(tail, rows)
        return self._trim()

    def _begin(self) -> Segment:
        if self._tail is not None:
            self._tail.close()
        number = self._segments[-1].number + 1 if self._segments else 1
        path = self.folder / f"{number:010d}.seg"
        f = path.open("xb")
        f.write(MAGIC)
        self._tail = f
        seg = Segment(number, path, size=len(MAGIC))
        self._segments.append(seg)
        return seg

    def _trim(self) -> int:
        """Drop the oldest segments (not the tail, not the one being forwarded) until within bounds."""
        dropped = 0
        while self.bytes > self.max_bytes:
            seg = next((s for s in self._segments[:-1] if s is not self._forwarding), None)
            if seg is None:
                break
            self._segments.remove(seg)
            seg.path.unlink(missing_ok=True)
            dropped += seg.records
        self.dropped += dropped
        return dropped

    # --- forwarding ---------------------------------------------------------------------

    def head(self) -> tuple[Segment, list[SpoolRow]] | None:
        """The oldest segment and its rows, in order (sealed first if it is the tail); None: empty."""
        if not self._segments:
            return None
        seg = self._segments[0]
        if len(self._segments) == 1 and self._tail is not None:
            self._tail.close()  # sealed: the next append begins a new segment
            self._tail = None
        self._forwarding = seg
        return seg, self._read(seg)

    def consumed(self, seg: Segment) -> None:
        """Every row of ``seg`` is in the database: the segment goes."""
        if seg in self._segments:
            self._segments.remove(seg)
        if self._forwarding is seg:
            self._forwarding = None
        seg.path.unlink(missing_ok=True)

    # --- reading a segment --------------------------------------------------------------

    def _read(self, seg: Segment) -> list[SpoolRow]:
        try:
            data = seg.path.read_bytes()
        except OSError as e:
            raise HistoryError(f"cannot read the history spool segment {str(seg.path)!r}: "
                               f"{e.strerror or e}") from None
        if not data.startswith(MAGIC):
            return []
        rows: list[SpoolRow] = []
        at = len(MAGIC)
        while at + _FRAME.size <= len(data):
            length, crc = _FRAME.unpack_from(data, at)
            body = data[at + _FRAME.size:at + _FRAME.size + length]
            if length > _MAX_FRAME or len(body) < length or zlib.crc32(body) != crc:
                break  # torn by a crash: what came before is whole
            try:
                rows.extend(self._decoder.decode(body))
            except msgspec.DecodeError:
                break
            at += _FRAME.size + length
        seg.size = max(seg.size, at)
        return rows

    def _count(self, seg: Segment, rows: Sequence[SpoolRow]) -> None:
        seg.records += len(rows)
        if seg.first_t_ns is None:
            seg.first_t_ns = rows[0][4]
        top = self.max_seq
        for thing, seq, *_ in rows:
            if seq > top.get(thing, -1):
                top[thing] = seq


def _number(path: Path) -> int:
    try:
        return int(path.stem)
    except ValueError:
        return -1
