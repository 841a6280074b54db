"""The FlexiTac and 3D-ViTac wire formats without a port: payloads holding the marker, split reads,
garbage, joining mid-stream, frames cut short; and their readings (baseline, tare, grids)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wott_driver_taxel.matrix import MARKER, FlexiTacDecoder, VitacDecoder
from wott_driver_taxel.readings import CountReadings

FLEXI, VITAC = (12, 32), (16, 16)


def grid(k: int, shape: tuple[int, int], marker_inside: bool = False) -> np.ndarray:
    v = np.random.default_rng(k).integers(10, 60, shape)
    if marker_inside:
        v.flat[7], v.flat[8] = 0xAA, 0x55  # the frame marker inside the payload
        v.flat[-2], v.flat[-1] = 0xAA, 0x55
    return v


def flexitac_bytes(values: np.ndarray) -> bytes:
    """What the firmware writes (flexitac firmware/template.ino): 0xAA 0x55, then the uint8 values."""
    return b"\xaa\x55" + values.astype(np.uint8).tobytes()


def vitac_bytes(values: np.ndarray) -> bytes:
    """What MatrixArray.ino prints: each value and a space, CRLF after each row and once more."""
    return b"".join(b"".join(b"%d " % v for v in row) + b"\r\n" for row in values.tolist()) + b"\r\n"


ENCODE = {"flexitac": (FlexiTacDecoder, FLEXI, flexitac_bytes), "3dvitac": (VitacDecoder, VITAC, vitac_bytes)}


def decode(protocol: str, data: bytes, chunks: list[int] | None = None, joining: bool = False):
    kind, shape, _ = ENCODE[protocol]
    d = kind(shape, joining=joining)
    out, pos = [], 0
    for size in chunks or [len(data)]:
        out += d.feed(data[pos : pos + size])
        pos += size
    out += d.feed(data[pos:])
    return out, d.counters, d


def stream(protocol: str, n: int) -> tuple[bytes, list[np.ndarray]]:
    _, shape, encode = ENCODE[protocol]
    vs = [grid(k, shape, marker_inside=k % 3 == 0) for k in range(n)]
    tail = MARKER if protocol == "flexitac" else b""  # the next frame's marker confirms the last one
    return b"".join(encode(v) for v in vs) + tail, vs


def check(frames, vs) -> None:
    assert len(frames) == len(vs)
    for f, v in zip(frames, vs, strict=True):
        assert f.seq is None and (f.rows, f.cols) == v.shape
        np.testing.assert_array_equal(f.values, v.ravel())


@pytest.mark.parametrize("protocol", ["flexitac", "3dvitac"])
def test_frames_decode_exactly_even_with_the_marker_inside(protocol):
    data, vs = stream(protocol, 20)
    frames, c, _ = decode(protocol, data)
    check(frames, vs)
    assert c.frames == 20 and c.resyncs == c.truncated == c.garbage_bytes == 0


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(["flexitac", "3dvitac"]), st.lists(st.integers(1, 700), min_size=1, max_size=30))
def test_any_split_of_the_reads_gives_the_same_frames(protocol, chunks):
    data, vs = stream(protocol, 12)
    frames, c, _ = decode(protocol, data, chunks)
    check(frames, vs)
    assert c.resyncs == 0


@pytest.mark.parametrize("protocol", ["flexitac", "3dvitac"])
@pytest.mark.parametrize("offset", [0, 101])
def test_a_kib_of_garbage_mid_stream_costs_at_most_one_frame(protocol, offset):
    data, vs = stream(protocol, 40)
    _, _, encode = ENCODE[protocol]
    junk = np.random.default_rng(9).integers(0, 256, 1024, dtype=np.uint8).tobytes()
    cut = sum(len(encode(v)) for v in vs[:20]) + offset
    frames, c, _ = decode(protocol, data[:cut] + junk + data[cut:], chunks=[257] * 400)
    seen = {f.values.tobytes() for f in frames}
    lost = [k for k, v in enumerate(vs) if v.astype(np.uint16).ravel().tobytes() not in seen]
    assert len(lost) <= 1 and len(frames) == 40 - len(lost) and c.resyncs >= 1
    assert set(lost) <= {19, 20}  # only the frame next to the garbage


@pytest.mark.parametrize("protocol", ["flexitac", "3dvitac"])
def test_joining_mid_frame_skips_and_a_frame_cut_short_is_counted(protocol):
    data, vs = stream(protocol, 10)
    frames, c, _ = decode(protocol, data[50:], joining=True)
    check(frames, vs[1:])
    assert c.skipped_bytes > 0 and c.resyncs == c.truncated == 0
    _, _, encode = ENCODE[protocol]
    sizes = np.cumsum([len(encode(v)) for v in vs])
    cut = data[: sizes[4] + 100] + data[sizes[4] + 120 :]  # frame 5 loses 20 bytes
    frames, c, _ = decode(protocol, cut)
    check(frames, vs[:5] + vs[6:])
    assert c.truncated == 1


def test_a_lost_link_counts_the_frame_in_progress():
    data, _ = stream("flexitac", 3)
    frames, c, d = decode("flexitac", data[:-2] + data[2:100])  # three frames and a piece
    d.reset()
    assert c.truncated == 1 and d.pending == 0


def test_the_baseline_is_the_median_of_its_frames_and_tare_takes_it_again():
    inward = np.tile([0.0, 0.0, -1.0], (4, 1))
    r = CountReadings(inward, (2, 2), 100.0, baseline_frames=3)
    rest = [np.array([10, 20, 30, 40]), np.array([12, 18, 30, 44]), np.array([11, 19, 31, 41])]
    assert r.frame(1, rest[0]) is None and r.frame(2, rest[1]) is None
    first = r.frame(3, rest[2])
    assert first is not None
    np.testing.assert_array_equal(r.baseline, [11, 19, 30, 41])
    pressed = r.frame(4, np.array([11, 19, 90, 30]))
    np.testing.assert_array_equal(pressed.displacement[:, 2], [0, 0, -60, 0])  # below the baseline: no press
    np.testing.assert_array_equal(r.raw_sample("change").array, [[0, 0], [60, -11]])
    np.testing.assert_array_equal(r.raw_sample("raw").array, [[11, 19], [90, 30]])
    r.tare()
    for t, v in enumerate([[20, 20, 20, 20]] * 3, start=5):
        assert r.frame(t, np.array(v)) is not None  # the old baseline stays in use meanwhile
    np.testing.assert_array_equal(r.baseline, [20, 20, 20, 20])
