"""The AnySkin / ReSkin binary burst stream, byte-exact, and how the hub finds its frames again.

The makers' firmware (raunaqbhirangi/anyskin and raunaqbhirangi/reskin_sensor,
``arduino/5X_binary_burst_stream/5X_binary_burst_stream.ino``) writes, per sample, for each of the 5
MLX90393 chips its ``MLX90393::txyz`` struct (4 float32: temperature °C, then x, y, z µT), little-endian
(the QT Py's and Trinket's SAMD21 is), then ``Serial.println()``: ``\\r\\n``. 82 bytes, with no header,
sequence number or checksum; a payload may itself hold ``\\r\\n``, and the loop outruns the chips, so
the same reading is often sent twice in a row. The makers' reader (PyPI ``anyskin`` 1.0.0,
``AnySkinBase.get_sample``) reads 82 bytes and, when they do not end in ``\\r\\n``, reads on to the next
``\\r\\n`` and tries again.

The hub's decoder: a frame is 82 bytes ending in ``\\r\\n`` whose floats are plausible (finite, each
temperature in [-50, 150] °C, each field component within ±100 mT: random bytes pass that with a
probability of order 1e-9 per frame). Locked on the stream, each frame is checked and delivered as its
82nd byte arrives. A frame that fails the check unlocks it (one ``resync``); the decoder then looks for
the first position where two consecutive frames pass (the second confirms the alignment, so a ``\\r\\n``
inside a payload cannot misplace it: a wrong alignment would have to pass twice), counts the bytes
before it as garbage, and locks there. A frame the stream realigned inside (less than a frame from its
start) was cut short (``short_frames``); so is one in progress when the link is lost. A sample equal to
the one before it is counted (``duplicates``) and not delivered: it is no new reading. Every good frame,
repeated or not, advances ``Sample.number``, the board's own cadence (its frames' times).
"""

from __future__ import annotations

import struct
from dataclasses import asdict, dataclass
from typing import ClassVar, NamedTuple

import numpy as np

__all__ = ["END", "FRAME_SIZE", "N_MAGS", "AnySkinDecoder", "Counters", "Sample", "encode_sample"]

N_MAGS = 5
PAYLOAD = 4 * 4 * N_MAGS  # (t, x, y, z) float32 per chip
END = b"\r\n"
FRAME_SIZE = PAYLOAD + len(END)  # 82
MAX_FIELD_UT = 1e5  # 100 mT: beyond any MLX90393 range setting
TEMPERATURE_C = (-50.0, 150.0)
INDEX_MODULO = 1 << 16


class Sample(NamedTuple):
    number: int  # the good frames read before it, repeats included, modulo 65536 (the board's cadence)
    temperature: np.ndarray  # (5,) °C, one per chip
    field: np.ndarray  # (5, 3) µT, each chip's x, y, z in its own axes, in the firmware's order


@dataclass
class Counters:
    """What went right and wrong on one link (docs/skins.md)."""

    frames: int = 0  # samples delivered
    duplicates: int = 0  # good frames equal to the one before: not delivered
    short_frames: int = 0  # frames cut short: the stream realigned inside them, or the link was lost
    resyncs: int = 0  # times the decoder lost the stream and found it again
    garbage_bytes: int = 0  # bytes that belonged to no frame
    skipped_bytes: int = 0  # bytes before the first frame after opening the port (joined mid-stream)
    reconnects: int = 0  # successful re-opens of the port after losing it
    dropped: int = 0  # decoded samples discarded because the consumer fell behind

    FAULTS: ClassVar[tuple[str, ...]] = ("short_frames", "resyncs")

    def as_dict(self) -> dict[str, int]:
        return asdict(self)

    @property
    def faults(self) -> int:
        return self.short_frames + self.resyncs


def plausible(buf: bytes | bytearray, at: int) -> bool:
    """Is there a frame at ``at``: 82 bytes ending in ``\\r\\n`` whose floats a board can send?"""
    if buf[at + PAYLOAD : at + FRAME_SIZE] != END:
        return False
    v = np.frombuffer(buf, "<f4", 4 * N_MAGS, at).reshape(N_MAGS, 4)
    with np.errstate(invalid="ignore", over="ignore"):
        t, b = v[:, 0], v[:, 1:]
        return bool(np.isfinite(v).all() and (t >= TEMPERATURE_C[0]).all() and (t <= TEMPERATURE_C[1]).all()
                    and (np.abs(b) <= MAX_FIELD_UT).all())


class AnySkinDecoder:
    """Samples out of an arbitrary byte stream (the module doc says how it finds them)."""

    def __init__(self, counters: Counters | None = None, *, joining: bool = False) -> None:
        self.counters = counters if counters is not None else Counters()
        self._buf = bytearray()
        self._locked = False
        self._joining = joining  # bytes before the first frame are skipped, not garbage
        self._consumed = 0  # bytes of the stream before the buffer's first
        self._lost_at: int | None = None  # where (in the stream) the frame that lost the lock began
        self._last = b""  # the payload of the last good frame (repeats)
        self._index = -1

    @property
    def pending(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes | bytearray) -> list[Sample]:
        buf = self._buf
        buf += data
        out: list[Sample] = []
        pos = 0
        while True:
            if self._locked:
                if len(buf) - pos < FRAME_SIZE:
                    break
                if plausible(buf, pos):
                    self._take(buf, pos, out)
                    pos += FRAME_SIZE
                    continue
                self._locked, self._lost_at = False, self._consumed + pos
                self.counters.resyncs += 1
            at, ready = self._find(buf, pos)
            if not ready:  # keep what may still begin a frame; what cannot is garbage
                keep = max(pos, len(buf) - FRAME_SIZE - 1) if at < 0 else at
                self._garbage(keep - pos)
                pos = keep
                break
            lost = self._lost_at
            if lost is not None and 0 < self._consumed + at - lost < FRAME_SIZE:
                self.counters.short_frames += 1  # realigned inside the frame that lost the lock
            self._garbage(at - pos)
            self._locked, self._joining, self._lost_at, pos = True, False, None, at
        del buf[:pos]
        self._consumed += pos
        return out

    def _find(self, buf: bytearray, start: int) -> tuple[int, bool]:
        """The first frame at or after ``start`` that the next one confirms (-1: none yet), and whether
        it is confirmed (False: more bytes are needed to tell)."""
        end = buf.find(END, start + PAYLOAD)
        while end >= 0:
            at = end - PAYLOAD
            if plausible(buf, at):
                if len(buf) < at + 2 * FRAME_SIZE:
                    return at, False
                if plausible(buf, at + FRAME_SIZE):
                    return at, True
            end = buf.find(END, end + 1)
        return -1, False

    def _garbage(self, n: int) -> None:
        if n > 0:
            if self._joining:
                self.counters.skipped_bytes += n
            else:
                self.counters.garbage_bytes += n

    def _take(self, buf: bytearray, at: int, out: list[Sample]) -> None:
        payload = bytes(buf[at : at + PAYLOAD])
        self._index = (self._index + 1) % INDEX_MODULO
        if payload == self._last:
            self.counters.duplicates += 1
            return
        self._last = payload
        v = np.frombuffer(payload, "<f4").astype(np.float64).reshape(N_MAGS, 4)
        self.counters.frames += 1
        out.append(Sample(self._index, v[:, 0].copy(), v[:, 1:].copy()))

    def reset(self) -> None:
        """The link was lost: a frame in progress was cut short; join the stream again."""
        if self._locked and self._buf:
            self.counters.short_frames += 1
        elif self._buf:
            self._garbage(len(self._buf))
        self._buf.clear()
        self._locked, self._joining, self._lost_at = False, True, None


def encode_sample(temperature: np.ndarray, field: np.ndarray) -> bytes:
    """One frame as the firmware writes it: per chip (t, x, y, z) float32 little-endian, then ``\\r\\n``."""
    t = np.asarray(temperature, np.float64).reshape(N_MAGS, 1)
    b = np.asarray(field, np.float64).reshape(N_MAGS, 3)
    return struct.pack(f"<{4 * N_MAGS}f", *np.hstack([t, b]).ravel()) + END
