"""The wire protocols without a port: layout, resync, CRC, truncation, sequence gaps, ASCII lines."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wott_driver_taxel.protocol import (
    SYNC,
    Counters,
    FrameDecoder,
    LineDecoder,
    crc16,
    encode_frame,
    encode_line,
)

SHAPE = (3, 4)


def values(k: int) -> np.ndarray:
    return (np.arange(12, dtype=np.int64).reshape(SHAPE) * 1000 + k) % 65536


def frames(seqs) -> list[bytes]:
    return [encode_frame(s, values(s)) for s in seqs]


def decode(stream: bytes, chunks: list[int] | None = None, expect=SHAPE) -> tuple[list, Counters]:
    d = FrameDecoder(expect)
    out, pos = [], 0
    for n in chunks or [len(stream)]:
        out += d.feed(stream[pos : pos + n])
        pos += n
    out += d.feed(stream[pos:])
    return out, d.counters


def counts(c: Counters, **expected) -> None:
    got = {k: v for k, v in c.as_dict().items() if v}
    assert got == {k: v for k, v in expected.items() if v}


def test_crc_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1
    assert crc16(b"") == 0xFFFF


def test_frame_layout_is_as_documented():
    f = encode_frame(0x1234, np.array([[1, 2], [3, 0xBEEF]]))
    assert f[:2] == SYNC == b"\xa5\x5a"
    assert struct.unpack_from("<HHBB", f, 2) == (4 + 2 * 4, 0x1234, 2, 2)
    assert struct.unpack_from("<4H", f, 8) == (1, 2, 3, 0xBEEF)
    assert struct.unpack_from("<H", f, 16)[0] == crc16(f[2:16])
    assert len(f) == 18


def test_round_trip():
    out, c = decode(b"".join(frames(range(5))))
    assert [f.seq for f in out] == [0, 1, 2, 3, 4]
    for f in out:
        assert (f.rows, f.cols) == SHAPE and f.values.dtype == np.uint16
        np.testing.assert_array_equal(f.values, values(f.seq).ravel())
    counts(c, frames=5)


def test_garbage_bit_flips_and_truncation_are_counted_and_skipped():
    f = frames(range(8))
    flipped = bytearray(f[2])
    flipped[12] ^= 0x10  # a value bit
    stream = (b"\x00\xa5noise" + f[0] + b"garbage!" + f[1] + bytes(flipped) + f[3] + f[4][:11] + f[5]
              + b"\xa5" + f[6] + f[7])
    out, c = decode(stream)
    assert [x.seq for x in out] == [0, 1, 3, 5, 6, 7]
    # three runs of noise (7 + 8 + 1 bytes); seq 2 and 4 missing -> two gaps of one frame each
    counts(c, frames=6, bad_crc=1, truncated=1, resyncs=3, garbage_bytes=16, gaps=2, lost=2)


@given(st.lists(st.integers(1, 40), max_size=60))
@settings(max_examples=60, deadline=None)
def test_any_split_of_the_stream_decodes_the_same(chunks):
    f = frames(range(6))
    bad = bytearray(f[3])
    bad[-1] ^= 1
    stream = b"xx" + f[0] + f[1] + b"\xa5\x5a\xff" + f[2] + bytes(bad) + f[4][:20] + f[5]
    reference, c_ref = decode(stream)
    out, c = decode(stream, chunks)
    assert [x.seq for x in out] == [x.seq for x in reference] == [0, 1, 2, 5]
    assert c == c_ref


def test_a_frame_ending_in_0xa5_at_the_end_of_a_read_is_not_kept_as_a_sync_byte():
    seq = next(k for k in range(1000) if frames([k])[0][-1] == 0xA5)
    d = FrameDecoder(SHAPE)
    for k in range(seq, seq + 3):  # one read per frame, the first ending in 0xA5
        assert [x.seq for x in d.feed(frames([k])[0])] == [k]
    counts(d.counters, frames=3)
    half = frames([seq + 3])[0]
    assert d.feed(half[:1]) == [] and d.pending == 1  # a real first SYNC byte is kept
    assert [x.seq for x in d.feed(half[1:])] == [seq + 3]
    counts(d.counters, frames=4)


def test_every_single_bit_flip_is_caught():
    f = frames(range(3))
    for byte in range(len(f[1])):
        for bit in range(8):
            bad = bytearray(f[1])
            bad[byte] ^= 1 << bit
            out, c = decode(f[0] + bytes(bad) + f[2])
            assert [x.seq for x in out] == [0, 2], (byte, bit)
            assert (c.gaps, c.lost) == (1, 1)
            if byte < 4 or 6 <= byte < 8:  # SYNC, LEN, ROWS/COLS: no frame starts here
                counts(c, frames=2, resyncs=1, garbage_bytes=len(f[1]), gaps=1, lost=1)
            else:  # SEQ, values, CRC: a frame with a bad CRC
                counts(c, frames=2, bad_crc=1, gaps=1, lost=1)


def test_a_frame_cut_by_a_disconnect_is_truncated_on_reset():
    d = FrameDecoder(SHAPE)
    f = frames(range(2))
    assert len(d.feed(f[0] + f[1][:9])) == 1 and d.pending == 9
    d.reset()
    counts(d.counters, frames=1, truncated=1)
    assert d.pending == 0
    d.feed(encode_frame(0, values(0)))  # the device restarted: no gap, no reset counted
    counts(d.counters, frames=2, truncated=1)


def test_joining_a_stream_mid_frame_is_not_a_fault_but_losing_sync_later_is():
    f = frames(range(4))
    d = FrameDecoder(SHAPE, joining=True)
    out = d.feed(f[0][9:] + b"boot\n" + f[1] + b"noise" + f[2] + f[3][:12])
    assert [x.seq for x in out] == [1, 2]
    d.reset()  # the port was lost: frame 3 is truncated, and the next open joins again
    out = d.feed(f[3][3:] + f[0])
    assert [x.seq for x in out] == [0]
    counts(d.counters, frames=3, skipped_bytes=len(f[0]) - 9 + 5 + len(f[3]) - 3, resyncs=1,
           garbage_bytes=5, truncated=1)


def test_sequence_wraps_jumps_and_restarts():
    out, c = decode(b"".join(frames([65534, 65535, 0, 1, 4, 5, 2])))
    assert len(out) == 7
    counts(c, frames=7, gaps=1, lost=2, seq_resets=1)


def test_frames_of_another_shape_are_counted_not_delivered():
    small = encode_frame(0, np.ones((2, 2)))
    out, c = decode(small + encode_frame(1, values(1)))
    assert [x.seq for x in out] == [1]
    counts(c, frames=1, wrong_shape=1)


def test_a_header_larger_than_the_array_does_not_stall_the_decoder():
    bogus = SYNC + struct.pack("<HHBB", 4 + 2 * 200 * 100, 0, 200, 100)  # 40 kB announced
    d = FrameDecoder(SHAPE)
    out = d.feed(bogus + encode_frame(7, values(7)))
    assert [x.seq for x in out] == [7]
    counts(d.counters, frames=1, resyncs=1, garbage_bytes=len(bogus))


def test_encoder_refuses_what_does_not_fit():
    for bad in (np.zeros(4), np.zeros((256, 2)), np.full((2, 2), 70000), np.full((2, 2), -1)):
        with pytest.raises(ValueError):
            encode_frame(0, bad)


# -- ASCII lines ------------------------------------------------------------------------------
def line_decode(data: bytes, joining: bool = False) -> tuple[list, Counters]:
    d = LineDecoder(SHAPE, joining=joining)
    return d.feed(data), d.counters


def test_line_format_is_as_documented():
    line = encode_line(7, np.array([[1, 2], [3, 4]]))
    body = b"7:1,2,3,4"
    assert line == body + f"*{crc16(body):04X}".encode() + b"\n"
    assert encode_line(None, np.array([[1, 2]]), with_crc=False) == b"1,2\n"


def test_lines_round_trip_with_and_without_seq_and_crc():
    data = (b"# taxel board v2 booting\r\n\n" + encode_line(0, values(0))
            + encode_line(1, values(1), with_crc=False) + b" 0 1 2 3\t4 5 6 7 8 9 10 11 \r\n")
    out, c = line_decode(data)
    assert [f.seq for f in out] == [0, 1, None]
    np.testing.assert_array_equal(out[0].values, values(0).ravel())
    np.testing.assert_array_equal(out[2].values, np.arange(12))
    counts(c, frames=3)


def test_line_faults_are_counted():
    bad_crc = bytearray(encode_line(2, values(2)))
    bad_crc[3] = ord("9") if bad_crc[3] != ord("9") else ord("8")
    data = (encode_line(0, values(0)) + b"hello world\n" + encode_line(1, values(1))[:15] + b"\n"
            + bytes(bad_crc) + b"1:2:3\n" + b"1,2,99999\n" + encode_line(4, np.ones((4, 4)))
            + encode_line(5, values(5)))
    out, c = line_decode(data)
    assert [f.seq for f in out] == [0, 5]
    counts(c, frames=2, truncated=1, bad_crc=1, wrong_shape=1, resyncs=2, garbage_bytes=12 + 6 + 10,
           gaps=1, lost=4)


def test_a_port_opened_mid_line_drops_the_partial_first_line_without_calling_it_a_fault():
    line = encode_line(3, values(3))
    out, c = line_decode(line[17:] + b"ERR\n" + encode_line(4, values(4)) + b"ERR\n", joining=True)
    assert [f.seq for f in out] == [4]
    counts(c, frames=1, skipped_bytes=len(line) - 17 + 4, resyncs=1, garbage_bytes=4)


def test_noise_without_newlines_is_bounded():
    d = LineDecoder(SHAPE)
    d.feed(b"\xff" * 500)
    assert d.pending == 0
    out = d.feed(b"\xff" * 20 + b"\n" + encode_line(0, values(0)))
    assert len(out) == 1
    counts(d.counters, frames=1, resyncs=1, garbage_bytes=521)
