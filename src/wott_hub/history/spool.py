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
- Crash-safe: each ``append`` is written and ``fsync``-ed before it returns, as frames of at most
  ``FRAME_RECORDS`` records and about ``FRAME_BYTES`` (a sync mark, the body's length, its record
  count, its CRC-32 and the header's own CRC-32, then msgpack of the rows). A frame torn by a crash
  (the file's last, cut short) ends the segment's reading quietly: its records were never
  acknowledged. Spooled records count as durable: in ``committed`` mode subscribers get them once
  they are on disk.
- Damage never empties the spool silently (issue 48): a frame whose body fails its CRC is skipped
  (its header says how many records it held), a broken header is passed by finding the next sync
  mark, so one flipped byte costs one frame (at most ``FRAME_RECORDS`` records), not the segment.
  A damaged segment is renamed ``<n>.seg.damaged`` (kept, never deleted: what could be read is
  still forwarded from it), and named in the log and in ``damage()`` (health) with the count of
  records it lost (estimated from the bytes lost where no header survived).
- Only regular files are read (issue 48): a segment or ``lock`` is opened ``O_NOFOLLOW |
  O_NONBLOCK`` and checked with ``fstat``, so a FIFO never blocks the hub and a symlink to
  ``/dev/zero`` is never read; such an entry is renamed ``<name>.notfile`` and named likewise. A
  segment larger than ``max_bytes`` cannot be one the spool wrote: set aside as damaged, unread.
  Frames are read one at a time (a sync mark searched in 64 KiB steps): memory is bounded by a
  segment's rows, whatever the file holds.
- One process per spool: an exclusive ``flock`` on ``lock`` in the folder, taken by ``open`` if
  the folder exists and by the first ``append`` otherwise (``Conflict`` naming the folder if
  another holds it); the database's writer lease keeps two hubs off one database in the same
  way. A hub whose database never failed leaves no folder behind.

Layout: a folder of segments ``<n>.seg`` (n ascending: the order they were written), each
``MAGIC`` then frames (a segment of the first format, ``MAGIC_V1``, whose frames are a length and a
CRC-32, is still read). A segment is written only while it is the last one ("the tail"); it is
sealed (a new tail begun) before it is read for forwarding.
"""

from __future__ import annotations

import errno
import logging
import os
import stat
import struct
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import msgspec

from wott_hub.errors import Conflict, HistoryError

from .spool_damage import NotRegular, SetAside, kind, open_lock

__all__ = ["FRAME_BYTES", "FRAME_RECORDS", "MAGIC", "SEGMENT_BYTES", "Segment", "Spool", "SpoolRow"]

log = logging.getLogger(__name__)

MAGIC = b"WOTTSPL2"
MAGIC_V1 = b"WOTTSPL1"
SEGMENT_BYTES = 4 << 20
"""A segment is sealed past this size: what one forwarding step reads at once (a few MB)."""
FRAME_BYTES = 64 << 10
"""A frame holds about this many bytes of rows at most (one row larger than it is a frame alone)."""
FRAME_RECORDS = 64
"""A frame holds at most this many records: what one flipped byte can cost."""

SpoolRow = tuple[str, int, int, str, int, bytes]
"""A spooled record: (thing, seq, kind, name, t_ns, payload as the database stores it)."""

_SYNC = b"\xd7WsF"
_HEAD = struct.Struct("<4sIIII")  # sync, body length, records, CRC-32 of the body, CRC-32 of the 16 before
_V1 = struct.Struct("<II")  # the first format's frame: payload length, CRC-32 of the payload
_MAX_FRAME = 1 << 30
_SCAN = 1 << 16
_ROW_OVERHEAD = 24  # what a row costs in msgpack beside its strings and payload (an estimate)


@dataclass
class Segment:
    """One segment file and what it holds (kept in memory: counts, times, the last seqs)."""

    number: int
    path: Path
    records: int = 0
    size: int = 0
    first_t_ns: int | None = None
    damaged: bool = False
    """Renamed aside (``.damaged``) when found damaged: forwarded from there, never deleted."""


@dataclass
class Read:
    rows: list[SpoolRow]
    lost: int = 0  # records of frames whose body failed (their header says how many)
    lost_bytes: int = 0  # bytes of those frames and of stretches without a readable header
    unknown_bytes: int = 0  # bytes without a readable header: their records are estimated
    header: bool = True  # the segment's MAGIC was intact


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
        self.aside = SetAside()  # what could not be read (``damage()``), renamed out of the way
        self._segments: list[Segment] = []
        self._forwarding: Segment | None = None  # the segment ``head`` gave out, not yet consumed
        self._tail: IO[bytes] | None = None
        self._lock_file: IO[bytes] | None = None
        self._top = 0  # the highest segment number found in the folder (set aside or not)
        self._encoder = msgspec.msgpack.Encoder()
        self._decoder = msgspec.msgpack.Decoder(list[tuple[str, int, int, str, int, bytes]])

    # --- opening ------------------------------------------------------------------------

    def open(self) -> None:
        """Read what a previous run left, if anything (the folder taken: ``Conflict`` if another
        process has it); a folder that does not exist is made by the first ``append``. Entries
        that are not regular files are set aside, damaged segments renamed and named (``damage``)."""
        if not self.folder.is_dir():
            return
        self._take_folder()
        for path in sorted(self.folder.glob("*.seg"), key=_number):
            self._top = max(self._top, _number(path))
            seg = Segment(_number(path), path)
            try:
                rows = self._read(seg)
            except NotRegular as e:
                self.aside.entry(path, str(e))
                continue
            if not rows:
                if not seg.damaged:
                    path.unlink(missing_ok=True)  # empty: a crash right after it was begun
                continue
            self._count(seg, rows)
            self._segments.append(seg)

    def _take_folder(self) -> None:
        if self._lock_file is not None:
            return
        import fcntl

        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            lock = open_lock(self.folder / "lock", self.aside)
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
        """Never fails: a tail the disk refused was cut back when it refused (``_undo``), so nothing
        of ours is lost here; a full disk must not turn a stop into an error (issue 48)."""
        if self._tail is not None:
            try:
                self._tail.close()
            except OSError as e:
                log.warning("history: closing the spool %s: %s", self.folder, e.strerror or e)
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

    def damage(self) -> list[dict[str, Any]]:
        """What could not be read and is still set aside (``keptAs`` exists): deleting that file says
        it has been seen to. Each: ``path``, ``keptAs``, ``records`` (lost), ``estimated`` (the
        count guessed from the bytes), ``bytes`` (lost), ``reason``."""
        return self.aside.current()

    # --- writing ------------------------------------------------------------------------

    def append(self, rows: Sequence[SpoolRow]) -> int:
        """Add ``rows`` (in order) at the tail, on disk before this returns; returns how many older
        records were dropped to stay within ``max_bytes``. ``HistoryError`` if the disk refuses
        (nothing of ``rows`` is then kept)."""
        if not rows:
            return 0
        self._take_folder()
        frames = [(_frame(self._encoder, chunk), chunk) for chunk in _chunks(rows)]
        tail = self._segments[-1] if self._segments and self._tail is not None else None
        start = tail.size if tail is not None else 0
        begun: list[Segment] = []
        placed: list[tuple[Segment, Sequence[SpoolRow]]] = []
        try:
            for frame, chunk in frames:
                if tail is None or tail.size + len(frame) > self.segment_bytes and tail.size > len(MAGIC):
                    if self._tail is not None:
                        self._sync()
                    tail = self._begin()
                    begun.append(tail)
                assert self._tail is not None
                self._tail.write(frame)
                tail.size += len(frame)
                placed.append((tail, chunk))
            self._sync()
        except OSError as e:
            self._undo(placed, begun, start)
            raise HistoryError(f"cannot write the history spool {str(self.folder)!r}: "
                               f"{e.strerror or e}") from None
        for seg, chunk in placed:
            self._count(seg, chunk)
        return self._trim()

    def _sync(self) -> None:
        assert self._tail is not None
        self._tail.flush()
        os.fsync(self._tail.fileno())

    def _undo(self, placed: list[tuple[Segment, Sequence[SpoolRow]]], begun: list[Segment],
              start: int) -> None:
        """A failed append leaves nothing of its rows: the old tail cut back, segments it began removed
        (the tail sealed: the next append begins a new one)."""
        if self._tail is not None:
            try:
                self._tail.close()
            except OSError:
                pass
            self._tail = None
        first = placed[0][0] if placed else None
        if first is not None and first not in begun:
            try:
                os.truncate(first.path, start)
            except OSError:
                pass
            first.size = start
        for seg in begun:
            if seg in self._segments:
                self._segments.remove(seg)
            seg.path.unlink(missing_ok=True)

    def _begin(self) -> Segment:
        if self._tail is not None:
            self._tail.close()
            self._tail = None
        number = max(self._top, self._segments[-1].number if self._segments else 0) + 1
        for _ in range(100):  # a name taken by something set aside in place: the next one
            path = self.folder / f"{number:010d}.seg"
            try:
                f = path.open("xb")
                break
            except FileExistsError:
                number += 1
        else:
            raise OSError(errno.EEXIST, f"no free segment name in {self.folder}")
        self._top = number
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
            if not seg.damaged:
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
        try:
            return seg, self._read(seg)
        except NotRegular as e:  # replaced under us: nothing of it can be read
            self.aside.entry(seg.path, str(e), records=seg.records)
            seg.damaged = True
            return seg, []

    def consumed(self, seg: Segment) -> None:
        """Every row of ``seg`` is in the database: the segment goes (a damaged one stays set aside)."""
        if seg in self._segments:
            self._segments.remove(seg)
        if self._forwarding is seg:
            self._forwarding = None
        if not seg.damaged:
            seg.path.unlink(missing_ok=True)

    # --- reading a segment --------------------------------------------------------------

    def _read(self, seg: Segment) -> list[SpoolRow]:
        """The rows of ``seg`` that can be read. ``NotRegular``: not a regular file (unread);
        damage found the first time renames the segment and names it (``damage``)."""
        try:
            fd = os.open(seg.path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError as e:
            if e.errno in (errno.ELOOP, errno.ENXIO):
                raise NotRegular(kind(seg.path)) from None
            raise HistoryError(f"cannot read the history spool segment {str(seg.path)!r}: "
                               f"{e.strerror or e}") from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise NotRegular(kind(seg.path))
            if st.st_size > self.max_bytes:
                got = Read([], unknown_bytes=st.st_size, lost_bytes=st.st_size)
                reason = f"larger than the spool's bound ({st.st_size} > {self.max_bytes} bytes): not read"
            else:
                with open(fd, "rb", buffering=_SCAN, closefd=False) as f:
                    got = _parse(f, st.st_size, self._decoder)
                reason = ""
        except OSError as e:
            raise HistoryError(f"cannot read the history spool segment {str(seg.path)!r}: "
                               f"{e.strerror or e}") from None
        finally:
            os.close(fd)
        seg.size = max(seg.size, st.st_size)
        if (got.lost or got.unknown_bytes or not got.header) and not seg.damaged:
            seg.path, seg.damaged = self.aside.segment(seg.path, seg.size, got, reason), True
        return got.rows

    def _count(self, seg: Segment, rows: Sequence[SpoolRow]) -> None:
        seg.records += len(rows)
        if seg.first_t_ns is None:
            seg.first_t_ns = rows[0][4]
        top = self.max_seq
        for thing, seq, *_ in rows:
            if seq > top.get(thing, -1):
                top[thing] = seq


def _chunks(rows: Sequence[SpoolRow]) -> Iterator[Sequence[SpoolRow]]:
    """``rows`` cut into frames of at most ``FRAME_RECORDS`` and about ``FRAME_BYTES``."""
    start, size = 0, 0
    for i, r in enumerate(rows):
        n = len(r[5]) + len(r[0]) + len(r[3]) + _ROW_OVERHEAD
        if i > start and (size + n > FRAME_BYTES or i - start >= FRAME_RECORDS):
            yield rows[start:i]
            start, size = i, 0
        size += n
    yield rows[start:]


def _frame(encoder: msgspec.msgpack.Encoder, rows: Sequence[SpoolRow]) -> bytes:
    body = encoder.encode(list(rows))
    head = _HEAD.pack(_SYNC, len(body), len(rows), zlib.crc32(body), 0)[:16]
    return head + struct.pack("<I", zlib.crc32(head)) + body


def _parse(f: IO[bytes], size: int, decoder: msgspec.msgpack.Decoder[Any]) -> Read:
    """Every frame of a segment that can be read, one frame at a time, and what could not."""
    magic = f.read(len(MAGIC))
    if magic == MAGIC:
        return _parse_frames(f, size, len(MAGIC), decoder, Read([]))
    if magic == MAGIC_V1:
        return _parse_v1(f, size, decoder, Read([]))
    got = Read([], header=False)  # a broken header: the frames are found by their sync marks
    got = _parse_frames(f, size, 0, decoder, got)
    if not got.rows and size > len(MAGIC_V1):  # none: perhaps the first format's frames
        got = _parse_v1(f, size, decoder, Read([], header=False))
    return got


def _parse_frames(f: IO[bytes], size: int, at: int, decoder: msgspec.msgpack.Decoder[Any],
                  got: Read) -> Read:
    f.seek(at)
    while at < size:
        head = f.read(_HEAD.size)
        if len(head) < _HEAD.size:
            break  # a header cut short by a crash: what came before is whole
        sync, length, count, crc, head_crc = _HEAD.unpack(head)
        if sync != _SYNC or zlib.crc32(head[:16]) != head_crc:
            found = _resync(f, at + 1, size)
            skipped = (size if found is None else found) - at
            if at != 0 or got.header:  # the bytes before the first frame of a broken header are its MAGIC
                got.unknown_bytes += skipped
                got.lost_bytes += skipped
            elif skipped > len(MAGIC):
                got.unknown_bytes += skipped - len(MAGIC)
                got.lost_bytes += skipped - len(MAGIC)
            if found is None:
                break
            at = found
            f.seek(at)
            continue
        if at + _HEAD.size + length > size:
            break  # the last frame cut short by a crash: never acknowledged
        body = f.read(length)
        at += _HEAD.size + length
        if zlib.crc32(body) != crc:
            got.lost += count
            got.lost_bytes += _HEAD.size + length
            continue
        try:
            got.rows.extend(decoder.decode(body))
        except msgspec.DecodeError:
            got.lost += count
            got.lost_bytes += _HEAD.size + length
    return got


def _resync(f: IO[bytes], at: int, size: int) -> int | None:
    """The offset of the next frame header (its sync mark and CRC) at or after ``at``; None: none."""
    f.seek(at)
    carry = b""
    pos = at
    while pos < size:
        chunk = f.read(_SCAN)
        if not chunk:
            return None
        buf = carry + chunk
        base = pos - len(carry)
        i = buf.find(_SYNC)
        while 0 <= i <= len(buf) - _HEAD.size:
            head = buf[i:i + _HEAD.size]
            if zlib.crc32(head[:16]) == _HEAD.unpack(head)[4]:
                return base + i
            i = buf.find(_SYNC, i + 1)
        pos += len(chunk)
        carry = buf[-(_HEAD.size - 1):]
    return None


def _parse_v1(f: IO[bytes], size: int, decoder: msgspec.msgpack.Decoder[Any], got: Read) -> Read:
    """The first format: a frame is a length and a CRC-32; a body failing its CRC is skipped by its
    length (a flipped byte costs that frame), an impossible length ends the reading (counted)."""
    at = len(MAGIC_V1)
    f.seek(at)
    bad = 0
    while at + _V1.size <= size:
        length, crc = _V1.unpack(f.read(_V1.size))
        if length == 0 or bad >= 2 or (at + _V1.size + length > size and length > _MAX_FRAME):
            got.unknown_bytes += size - at  # never written so (no empty frame; two bad in a row: no
            got.lost_bytes += size - at  # frame boundary left to trust): the rest is not read
            break
        if at + _V1.size + length > size:
            break  # the last frame cut short by a crash
        body = f.read(length)
        at += _V1.size + length
        try:
            if zlib.crc32(body) != crc:
                raise msgspec.DecodeError
            got.rows.extend(decoder.decode(body))
            bad = 0
        except msgspec.DecodeError:
            bad += 1
            got.unknown_bytes += _V1.size + length
            got.lost_bytes += _V1.size + length
    return got


def _number(path: Path) -> int:
    try:
        return int(path.stem)
    except ValueError:
        return -1
