"""The taxel array's wire protocols: framed binary and an ASCII line variant (docs/taxel-protocol.md).

Binary frame, all integers little-endian::

    SYNC   2   0xA5 0x5A
    LEN    2   uint16, bytes from SEQ to the last value = 4 + 2 * ROWS * COLS
    SEQ    2   uint16, +1 per frame, wraps at 65536
    ROWS   1   uint8, 1..255
    COLS   1   uint8, 1..255
    VALUES 2*ROWS*COLS  uint16 pressure counts, row-major: taxel (r, c) at r * COLS + c
    CRC    2   uint16, CRC-16/CCITT-FALSE over LEN .. VALUES

ASCII line: ``[SEQ:]V0,V1,...,VN-1[*CCCC]`` then ``\\n`` (``\\r\\n`` accepted);
values separated by commas and/or blanks, CCCC the same CRC in hex over the
bytes before ``*``; lines starting with ``#`` are comments.

The decoders are pure (bytes in, frames out, counters updated), so they are
tested without any port, and the reader only moves bytes.
"""

from __future__ import annotations

import binascii
import re
import struct
from dataclasses import asdict, dataclass
from typing import ClassVar, NamedTuple

import numpy as np

__all__ = [
    "Counters", "DecoderBase", "FrameDecoder", "LineDecoder", "RawFrame", "SYNC", "crc16", "encode_frame",
    "encode_line",
]

SYNC = b"\xa5\x5a"
_HEADER = struct.Struct("<HHBB")  # LEN, SEQ, ROWS, COLS (after SYNC)
HEADER_SIZE = len(SYNC) + _HEADER.size  # 8
CRC_SIZE = 2
SEQ_MODULO = 1 << 16
MAX_VALUES = (0xFFFF - 4) // 2  # LEN is a uint16


def crc16(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor; "123456789" -> 0x29B1).

    ``binascii.crc_hqx`` is exactly this CRC when seeded with 0xFFFF, in C.
    """
    return binascii.crc_hqx(data, 0xFFFF)


@dataclass
class Counters:
    """What went right and wrong on one link since the driver started (docs/taxel-protocol.md)."""

    frames: int = 0  # good frames delivered
    bad_crc: int = 0  # complete frames whose CRC did not match: skipped
    truncated: int = 0  # frames cut short by the next frame's start or by a disconnect
    resyncs: int = 0  # runs of bytes that belonged to no frame (each run counts once)
    garbage_bytes: int = 0  # the bytes of those runs
    skipped_bytes: int = 0  # bytes before the first frame after opening the port (joined mid-stream)
    gaps: int = 0  # times the sequence number jumped forward
    lost: int = 0  # sequence numbers skipped by those jumps (frames the hub never saw)
    seq_resets: int = 0  # times the sequence number went backwards (device restart)
    wrong_shape: int = 0  # good frames whose rows x cols differ from the configured array
    reconnects: int = 0  # successful re-opens of the port after losing it
    dropped: int = 0  # decoded frames discarded because the consumer fell behind

    FAULTS: ClassVar[tuple[str, ...]] = ("bad_crc", "truncated", "resyncs", "gaps", "wrong_shape")
    """Everything that makes the link ``degraded`` while it keeps happening (the reader names them)."""

    def as_dict(self) -> dict[str, int]:
        return asdict(self)

    @property
    def faults(self) -> int:
        return self.bad_crc + self.truncated + self.resyncs + self.gaps + self.wrong_shape


class RawFrame(NamedTuple):
    seq: int | None  # None when the ASCII variant sends no sequence number
    rows: int
    cols: int
    values: np.ndarray  # (rows * cols,) uint16 counts, row-major


class _Tracker:
    """Sequence gaps: a forward jump of k counts k - 1 lost frames; a backward one a restart."""

    def __init__(self, counters: Counters) -> None:
        self.counters = counters
        self.expected: int | None = None

    def see(self, seq: int | None) -> None:
        if seq is None:
            return
        seq %= SEQ_MODULO
        if self.expected is not None and seq != self.expected:
            missing = (seq - self.expected) % SEQ_MODULO
            if missing < SEQ_MODULO // 2:
                self.counters.gaps += 1
                self.counters.lost += missing
            else:
                self.counters.seq_resets += 1
        self.expected = (seq + 1) % SEQ_MODULO

    def reset(self) -> None:
        self.expected = None


class DecoderBase:
    """Shared state: the buffer, the sequence tracker, and whether we are still joining.

    ``joining`` (the reader's setting, and the state after ``reset``): the link
    was just opened, most likely in the middle of a frame, so the bytes before
    the first frame are ``skipped_bytes``, not a fault.
    """

    def __init__(self, expect: tuple[int, int] | None, counters: Counters | None, joining: bool) -> None:
        self.expect = expect
        self.counters = counters if counters is not None else Counters()
        self.seq = _Tracker(self.counters)
        self._buf = bytearray()
        self._in_garbage = False
        self._joining = joining

    def _framed(self) -> None:
        """A frame boundary was found (good frame, bad CRC or truncation): back in sync."""
        self._in_garbage = False
        self._joining = False

    def _garbage(self, n: int) -> None:
        if n <= 0:
            return
        if self._joining:
            self.counters.skipped_bytes += n
            return
        self.counters.garbage_bytes += n
        if not self._in_garbage:
            self.counters.resyncs += 1
            self._in_garbage = True

    def _deliver(self, frame: RawFrame, out: list[RawFrame]) -> None:
        self._framed()
        if self.expect is not None and (frame.rows, frame.cols) != self.expect:
            self.counters.wrong_shape += 1
            return
        self.seq.see(frame.seq)
        self.counters.frames += 1
        out.append(frame)

    @property
    def pending(self) -> int:
        """Bytes waiting for the rest of their frame or line."""
        return len(self._buf)


class FrameDecoder(DecoderBase):
    """Binary frames out of an arbitrary byte stream, resynchronising on SYNC.

    ``expect`` (rows, cols) is the configured array: larger headers are
    rejected at once (so a corrupt header cannot make the decoder wait for
    up to 64 KiB), frames of another shape are counted in ``wrong_shape``.
    """

    def __init__(
        self, expect: tuple[int, int] | None = None, counters: Counters | None = None, joining: bool = False
    ) -> None:
        super().__init__(expect, counters, joining)
        self.max_values = MAX_VALUES if expect is None else expect[0] * expect[1]

    def _header_ok(self, length: int, rows: int, cols: int) -> bool:
        return rows > 0 and cols > 0 and rows * cols <= self.max_values and length == 4 + 2 * rows * cols

    def _frame_starts_at(self, buf: bytearray, start: int, end: int) -> int | None:
        """The first SYNC in [start, end) followed by a plausible header, if any."""
        j = buf.find(SYNC, start, end)
        while j >= 0:
            if len(buf) - j < HEADER_SIZE:
                return j  # too short to judge: a frame start is the likelier reading
            length, _, rows, cols = _HEADER.unpack_from(buf, j + 2)
            if self._header_ok(length, rows, cols):
                return j
            j = buf.find(SYNC, j + 1, end)
        return None

    def feed(self, data: bytes | bytearray) -> list[RawFrame]:
        buf = self._buf
        buf += data
        out: list[RawFrame] = []
        pos = 0
        c = self.counters
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                # A last 0xA5 not yet consumed may be the first half of the next SYNC.
                keep = 1 if len(buf) > pos and buf[-1] == SYNC[0] else 0
                self._garbage(len(buf) - keep - pos)
                pos = len(buf) - keep
                break
            self._garbage(i - pos)
            pos = i
            if len(buf) - pos < HEADER_SIZE:
                break
            length, seq, rows, cols = _HEADER.unpack_from(buf, pos + 2)
            if not self._header_ok(length, rows, cols):
                self._garbage(1)  # a SYNC look-alike in noise; look again one byte on
                pos += 1
                continue
            total = 4 + length + CRC_SIZE
            if len(buf) - pos < total:
                break
            end = pos + 4 + length
            (crc_rx,) = struct.unpack_from("<H", buf, end)
            if crc16(buf[pos + 2 : end]) == crc_rx:
                values = np.frombuffer(bytes(buf[pos + HEADER_SIZE : end]), dtype="<u2").astype(np.uint16)
                self._deliver(RawFrame(seq, rows, cols, values), out)
                pos += total
                continue
            self._framed()
            inner = self._frame_starts_at(buf, pos + 2, pos + total)
            if inner is not None:  # the next frame began before this one ended: this one was cut short
                c.truncated += 1
                pos = inner
            else:
                c.bad_crc += 1
                pos += total
        del buf[:pos]
        return out

    def reset(self) -> None:
        """The link was lost: a frame in progress is truncated; forget the sequence."""
        if self._buf.startswith(SYNC):
            self.counters.truncated += 1
        else:
            self._garbage(len(self._buf))
        self._buf.clear()
        self._in_garbage = False
        self._joining = True
        self.seq.reset()


_SEP = re.compile(rb"[,\s]+")
_HEX4 = re.compile(rb"^[0-9A-Fa-f]{4}$")


class LineDecoder(DecoderBase):
    """ASCII lines; the configured shape is required (a line does not carry one).

    When ``joining`` (the reader's setting) the bytes up to the first newline
    are discarded: most likely the tail of a line the device was already sending.
    """

    expect: tuple[int, int]  # required here: a line does not carry its shape

    def __init__(
        self, expect: tuple[int, int], counters: Counters | None = None, joining: bool = False
    ) -> None:
        super().__init__(expect, counters, joining)
        self.n_values = expect[0] * expect[1]
        self.max_line = 8 * self.n_values + 32  # "65535," per value, with room for a prefix and CRC
        self._first_line = joining  # still to be discarded
        self._skipping = False

    def feed(self, data: bytes | bytearray) -> list[RawFrame]:
        buf = self._buf
        buf += data
        out: list[RawFrame] = []
        pos = 0
        while True:
            nl = buf.find(b"\n", pos)
            if nl < 0:
                if len(buf) - pos > self.max_line:  # no newline for too long: noise, skip to the next one
                    self._garbage(len(buf) - pos)
                    pos = len(buf)
                    self._skipping = True
                break
            line = bytes(buf[pos:nl])
            pos = nl + 1
            if self._skipping or self._first_line:
                self._skipping = self._first_line = False
                self._discard(line)
                continue
            self._line(line, out)
        del buf[:pos]
        return out

    def _discard(self, line: bytes) -> None:
        """A line dropped unread: the rest of one too long, or the first after joining."""
        self._garbage(len(line) + 1)

    def _line(self, line: bytes, out: list[RawFrame]) -> None:
        text = line.rstrip(b"\r")
        stripped = text.strip()
        if not stripped or stripped.startswith(b"#"):
            return
        body = text
        if b"*" in text:
            body, _, tail = text.rpartition(b"*")
            if not _HEX4.match(tail.strip()):
                self._garbage(len(line) + 1)
                return
            if crc16(body) != int(tail.strip(), 16):
                self._framed()
                self.counters.bad_crc += 1
                return
        seq = None
        if b":" in body:
            head, _, body = body.partition(b":")
            try:
                seq = int(head)
            except ValueError:
                self._garbage(len(line) + 1)
                return
        tokens = [t for t in _SEP.split(body.strip()) if t]
        try:
            values = np.array([int(t) for t in tokens], dtype=np.int64)
        except ValueError:
            self._garbage(len(line) + 1)
            return
        if values.size and (values.min() < 0 or values.max() > 0xFFFF):
            self._garbage(len(line) + 1)
            return
        if values.size < self.n_values:
            self._framed()
            self.counters.truncated += 1
            return
        if values.size > self.n_values:
            self._framed()
            self.counters.wrong_shape += 1
            return
        rows, cols = self.expect
        self._deliver(RawFrame(seq, rows, cols, values.astype(np.uint16)), out)

    def reset(self) -> None:
        """The link was lost: a partial line is truncated; resync on the next newline."""
        if self._buf.strip():
            self.counters.truncated += 1
        self._buf.clear()
        self._in_garbage = False
        self._skipping = False
        self._joining = self._first_line = True
        self.seq.reset()


def _check_values(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values)
    if v.ndim != 2 or not (1 <= v.shape[0] <= 255 and 1 <= v.shape[1] <= 255):
        raise ValueError(f"values must be a (rows, cols) array with 1..255 each, got shape {v.shape}")
    if v.size > MAX_VALUES:
        raise ValueError(f"{v.size} values do not fit a frame (max {MAX_VALUES})")
    if v.size and (v.min() < 0 or v.max() > 0xFFFF):
        raise ValueError("values must lie in 0..65535")
    return v.astype("<u2")


def encode_frame(seq: int, values: np.ndarray) -> bytes:
    """One binary frame of a (rows, cols) array of counts."""
    v = _check_values(values)
    rows, cols = v.shape
    body = _HEADER.pack(4 + 2 * v.size, seq % SEQ_MODULO, rows, cols) + v.tobytes()
    return SYNC + body + struct.pack("<H", crc16(body))


def encode_line(seq: int | None, values: np.ndarray, *, with_crc: bool = True) -> bytes:
    """One ASCII line (``SEQ:`` prefix unless seq is None, ``*CRC`` suffix if asked)."""
    v = _check_values(values)
    body = ",".join(map(str, v.ravel().tolist())).encode()
    if seq is not None:
        body = f"{seq % SEQ_MODULO}:".encode() + body
    if with_crc:
        body += f"*{crc16(body):04X}".encode()
    return body + b"\n"
