"""The wire formats of two open piezoresistive matrices (docs/taxel-protocol.md, docs/skins.md).

FlexiTac (PyPI ``flexitac`` 0.3.1, ``flexitac/sensor.py`` and ``firmware/template.ino``): per frame
``0xAA 0x55`` then ``rows * cols`` uint8 ADC values, row-major, default 12 x 32 at 2,000,000 baud, no
length, sequence number or checksum. A payload may hold ``0xAA 0x55`` itself, so a marker alone says
little: a frame is taken when the next frame's marker follows it exactly ``rows * cols`` bytes on, which
confirms its length (one frame of latency; PyPI's reader takes the bytes after any marker). A frame that
the next marker does not confirm (cut short, or followed by noise) is ``truncated``; the bytes before
the next confirmed frame are garbage (one ``resync``).

3D-ViTac (binghao-huang/3D-ViTac_Tactile_Hardware, ``arduino_code/MatrixArray.ino``, MIT): each row
``v v ... v \\r\\n`` (decimal 0-255, each followed by a space), a blank line after the last row,
16 x 16 at 2,000,000 baud. A frame is exactly ``rows`` lines of ``cols`` values followed by a blank
line; a line that is no row makes its frame garbage (and the bytes of the line are counted), a frame of
fewer rows is ``truncated``, of more ``wrong_shape``; the blank line resynchronises.

Neither carries a sequence number: frames are counted, not numbered (``RawFrame.seq`` None).
"""

from __future__ import annotations

import numpy as np

from .protocol import Counters, DecoderBase, LineDecoder, RawFrame

__all__ = ["MARKER", "FlexiTacDecoder", "VitacDecoder", "encode_3dvitac", "encode_flexitac"]

MARKER = b"\xaa\x55"


class FlexiTacDecoder(DecoderBase):
    """FlexiTac frames out of a byte stream: each confirmed by the marker of the frame after it."""

    expect: tuple[int, int]

    def __init__(self, expect: tuple[int, int], counters: Counters | None = None,
                 joining: bool = False) -> None:
        super().__init__(expect, counters, joining)
        self.size = len(MARKER) + expect[0] * expect[1]
        self._locked = False

    def _confirmed(self, buf: bytearray, at: int) -> bool | None:
        """Is there a frame at ``at`` followed by the next marker (None: not enough bytes yet)?"""
        end = at + self.size
        if len(buf) < end + len(MARKER):
            return None
        return buf[at : at + 2] == MARKER and buf[end : end + 2] == MARKER

    def feed(self, data: bytes | bytearray) -> list[RawFrame]:
        buf = self._buf
        buf += data
        out: list[RawFrame] = []
        pos, size = 0, self.size
        while True:
            if self._locked:
                ok = self._confirmed(buf, pos)
                if ok is None:
                    break
                if ok:
                    self._deliver_at(buf, pos, out)
                    pos += size
                    continue
                self._locked = False  # this frame's length is not confirmed: it is lost
                self._framed()
                self.counters.truncated += 1
                pos += 1
            j, ready = self._find(buf, pos)
            if not ready:  # keep a marker still to be confirmed, or a last byte that may begin one
                keep = max(pos, len(buf) - 1) if j < 0 else j
                self._garbage(keep - pos)
                pos = keep
                break
            self._garbage(j - pos)
            self._framed()
            self._locked, pos = True, j
        del buf[:pos]
        return out

    def _find(self, buf: bytearray, start: int) -> tuple[int, bool]:
        """The first marker at or after ``start`` not yet ruled out (-1: none), and whether a complete
        frame and the next marker confirm it (False: more bytes are needed to tell)."""
        j = buf.find(MARKER, start)
        while j >= 0:
            ok = self._confirmed(buf, j)
            if ok is None or ok:
                return j, bool(ok)
            j = buf.find(MARKER, j + 1)
        return -1, False

    def _deliver_at(self, buf: bytearray, at: int, out: list[RawFrame]) -> None:
        rows, cols = self.expect
        values = np.frombuffer(bytes(buf[at + 2 : at + self.size]), dtype=np.uint8).astype(np.uint16)
        self._deliver(RawFrame(None, rows, cols, values), out)

    def reset(self) -> None:
        """The link was lost: a frame in progress is truncated; join the stream again."""
        if self._locked and self._buf:
            self.counters.truncated += 1
        elif self._buf:
            self._garbage(len(self._buf))
        self._buf.clear()
        self._in_garbage = False
        self._locked = False
        self._joining = True


class VitacDecoder(LineDecoder):
    """3D-ViTac frames: ``rows`` lines of ``cols`` decimal values, then a blank line (the line splitting,
    a line too long and joining are ``LineDecoder``'s)."""

    def __init__(self, expect: tuple[int, int], counters: Counters | None = None,
                 joining: bool = False) -> None:
        super().__init__(expect, counters, joining)
        self.max_line = 4 * expect[1] + 8  # "255 " per value and the line end, with room
        self._rows: list[list[int]] = []
        self._row_bytes = 0
        self._bad = False  # a line of this frame was no row

    def _discard(self, line: bytes) -> None:
        super()._discard(line)
        if line.strip():  # a row's piece: the frame it was part of is incomplete (a blank line is none)
            self._bad = True

    def _line(self, line: bytes, out: list[RawFrame]) -> None:
        text = line.strip()
        if not text:
            self._end_frame(out)
            return
        tokens = text.split()
        if len(tokens) == self.expect[1] and all(t.isdigit() and len(t) <= 3 for t in tokens):
            row = [int(t) for t in tokens]
            if max(row) <= 255:
                self._rows.append(row)
                self._row_bytes += len(line) + 1
                return
        self._garbage(len(line) + 1)
        self._bad = True

    def _end_frame(self, out: list[RawFrame]) -> None:
        rows, cols = self.expect
        got, bad, n_bytes = self._rows, self._bad, self._row_bytes
        self._rows, self._bad, self._row_bytes = [], False, 0
        if not got:
            return
        if self._joining and (bad or len(got) < rows):  # the end of a frame sent before we listened
            self.counters.skipped_bytes += n_bytes
            self._framed()
            return
        self._framed()
        if bad or len(got) < rows:  # a line was noise, or rows are missing: the frame is lost
            self.counters.truncated += 1
        elif len(got) > rows:
            self.counters.wrong_shape += 1
        else:
            self._deliver(RawFrame(None, rows, cols, np.array(got, dtype=np.uint16).ravel()), out)

    def reset(self) -> None:
        """The link was lost: a frame in progress is truncated; resync on the next blank line."""
        if self._rows and not self._buf.strip():
            self.counters.truncated += 1
        super().reset()
        self._rows, self._bad, self._row_bytes = [], False, 0


def _bytes(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values)
    if v.ndim != 2 or v.size == 0 or v.min() < 0 or v.max() > 255:
        raise ValueError(f"values must be a (rows, cols) array of 0..255, got shape {v.shape}")
    return v.astype(np.uint8)


def encode_flexitac(values: np.ndarray) -> bytes:
    """One FlexiTac frame of a (rows, cols) array of 0..255."""
    return MARKER + _bytes(values).tobytes()


def encode_3dvitac(values: np.ndarray) -> bytes:
    """One 3D-ViTac frame as its firmware prints it (``Serial.print(v); Serial.print(" ")`` per value,
    ``Serial.println()`` per row and once more after the last)."""
    rows = [" ".join(map(str, row)) + " \r\n" for row in _bytes(values).tolist()]
    return ("".join(rows) + "\r\n").encode("ascii")
