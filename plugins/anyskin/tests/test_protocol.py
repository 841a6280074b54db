"""The burst stream without a port: exact floats, split reads, a ``\\r\\n`` inside a payload, garbage,
repeats, frames cut short, and the board layouts."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wott_driver_anyskin.boards import BOARDS
from wott_driver_anyskin.protocol import FRAME_SIZE, AnySkinDecoder

RNG = np.random.default_rng(7)
CRLF_FLOAT = struct.unpack("<f", b"\r\n\x41\x43")[0]  # 193.04 µT: its bytes hold "\r\n"
TINY_CRLF_FLOAT = struct.unpack("<f", b"\x00\x10\r\n")[0]  # a tiny field whose last two bytes are "\r\n"


def raw_frame(values: np.ndarray) -> bytes:
    """The firmware's bytes, packed here (not by the plugin): 20 float32 little-endian, then CRLF."""
    return struct.pack("<20f", *values.ravel()) + b"\r\n"


def values(k: int, crlf: bool = False) -> np.ndarray:
    v = np.column_stack([np.full(5, 25.0 + k / 100), RNG.normal(0, 300, (5, 3))]).astype(np.float32)
    if crlf:
        v[2, 2], v[4, 1] = CRLF_FLOAT, TINY_CRLF_FLOAT
    return v


def stream(n: int, crlf_every: int = 4) -> tuple[bytes, list[np.ndarray]]:
    vs = [values(k, crlf=k % crlf_every == 1) for k in range(n)]
    return b"".join(raw_frame(v) for v in vs), vs


def decode(data: bytes, chunks: list[int] | None = None, joining: bool = False):
    d = AnySkinDecoder(joining=joining)
    out, pos = [], 0
    for size in chunks or [len(data)]:
        out += d.feed(data[pos : pos + size])
        pos += size
    out += d.feed(data[pos:])
    return out, d.counters


def check(samples, vs) -> None:
    assert len(samples) == len(vs)
    for s, v in zip(samples, vs, strict=True):
        np.testing.assert_array_equal(s.temperature, v[:, 0].astype(np.float64))
        np.testing.assert_array_equal(s.field, v[:, 1:].astype(np.float64))


def test_frames_with_crlf_inside_their_payload_decode_exactly():
    data, vs = stream(40)
    assert sum(b"\r\n" in raw_frame(v)[:80] for v in vs) == 10
    samples, c = decode(data)
    check(samples, vs)
    assert [s.number for s in samples] == list(range(40))
    assert (c.frames, c.resyncs, c.garbage_bytes, c.short_frames) == (40, 0, 0, 0)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 200), min_size=1, max_size=40))
def test_any_split_of_the_reads_gives_the_same_samples(chunks):
    data, vs = stream(30)
    samples, c = decode(data, chunks)
    check(samples, vs)
    assert c.resyncs == 0 and c.garbage_bytes == 0


@pytest.mark.parametrize("where", ["between frames", "inside a frame"])
def test_a_kib_of_garbage_costs_at_most_one_frame(where):
    data, vs = stream(60)
    junk = RNG.integers(0, 256, 1024, dtype=np.uint8).tobytes().replace(b"\r\n", b"\r\r") + b"\r\n" * 3
    cut = 30 * FRAME_SIZE + (0 if where == "between frames" else 37)
    samples, c = decode(data[:cut] + junk + data[cut:], chunks=[97] * 900)
    got = [s.number for s in samples]
    lost = 60 - len(samples)
    assert lost <= 1 and c.resyncs == 1
    if where == "between frames":
        check(samples, vs)
        assert c.garbage_bytes == len(junk) and c.short_frames == 0
    else:
        check(samples, vs[:30] + vs[31:])  # the frame the garbage went into, and only it
        assert got == list(range(59))  # numbers count the frames read, not those sent


def test_joining_mid_frame_skips_without_a_fault_and_a_cut_frame_is_short():
    data, vs = stream(20)
    samples, c = decode(data[50:], joining=True)
    check(samples, vs[1:])
    assert c.skipped_bytes == FRAME_SIZE - 50 and c.resyncs == 0 and c.garbage_bytes == 0
    cut = data[: 5 * FRAME_SIZE] + data[5 * FRAME_SIZE : 6 * FRAME_SIZE - 30] + data[6 * FRAME_SIZE :]
    samples, c = decode(cut)
    check(samples, vs[:5] + vs[6:])
    assert (c.short_frames, c.resyncs) == (1, 1)


def test_repeated_samples_are_counted_not_delivered():
    v = [values(k) for k in range(6)]
    data = b"".join(raw_frame(x) for x in (v[0], v[1], v[1], v[1], v[2], v[3], v[3], v[4], v[5]))
    samples, c = decode(data)
    check(samples, v)
    assert c.duplicates == 3 and [s.number for s in samples] == [0, 1, 4, 5, 7, 8]


def test_implausible_floats_never_become_a_sample():
    bad = values(0)
    bad[1, 0] = 400.0  # no chip is at 400 °C
    nan = values(1)
    nan[3, 2] = np.nan
    data = b"".join(raw_frame(v) for v in (values(2), values(3), bad, nan, values(4), values(5)))
    samples, c = decode(data)
    assert len(samples) == 4 and c.resyncs == 1 and c.garbage_bytes == 2 * FRAME_SIZE


def test_a_lost_link_counts_the_frame_in_progress_and_joins_again():
    data, vs = stream(5)
    d = AnySkinDecoder()
    assert len(d.feed(data + data[:40])) == 5
    d.reset()
    assert d.counters.short_frames == 1 and d.pending == 0
    assert len(d.feed(data[10:])) == 4 and d.counters.skipped_bytes == FRAME_SIZE - 10


@pytest.mark.parametrize("name", ["anyskin", "reskin"])
def test_each_board_is_a_plus_of_rotations_into_a_right_handed_frame(name):
    board = BOARDS[name]
    p = board.positions_mm
    assert sorted(np.linalg.norm(p, axis=1).round(6).tolist()) == [0.0, 7.0, 7.0, 7.0, 7.0]
    r = board.rotations
    np.testing.assert_allclose(np.linalg.det(r), 1.0)
    np.testing.assert_allclose(r @ np.transpose(r, (0, 2, 1)), np.broadcast_to(np.eye(3), r.shape), atol=1e-9)
    mesh = board.mesh()
    assert mesh.n_nodes == 5 and (mesh.normals[:, 2] > 0.99).all() and (mesh.node_areas > 0).all()


def test_the_makers_visualisers_chip_axes():
    # AnySkin's anyskin_viz.py draws chip k's (x, y) as R(angle_k) (x, y) on a screen whose y points down
    r = BOARDS["anyskin"].rotations
    np.testing.assert_allclose(r[0] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)  # -pi/2: x drawn up
    np.testing.assert_allclose(r[4] @ [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], atol=1e-12)  # 0: x drawn right
    # ReSkin's pygame_demo.py draws the right chip's (x, y) as is, the left's as (-y, x); the board's y is
    # the screen's, up
    r = BOARDS["reskin"].rotations
    np.testing.assert_allclose(r[2][:2, :2], [[1.0, 0.0], [0.0, -1.0]], atol=1e-12)
    np.testing.assert_allclose(r[4][:2, :2], [[0.0, -1.0], [-1.0, 0.0]], atol=1e-12)
