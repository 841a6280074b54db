"""Replay like ``ros2 bag play``: an affordance filter, several devices on one time base, a start
offset (functional tolerance, not a benchmark)."""

from __future__ import annotations

import asyncio

import pytest

from wott_hub.history import Replayer

from .skin_records import register_device, skin_records


@pytest.fixture
def recorded(writer):
    """pad-a at 120 Hz and pad-b at 60 Hz, interleaved in time, 1 s each."""
    recs = []
    t0 = 1_700_000_000 * 10**9
    a, n = register_device(writer, "pad-a")
    recs += skin_records("pad-a", a, 120, n, t0_ns=t0, seed=1)
    b, n = register_device(writer, "pad-b")
    recs += skin_records("pad-b", b, 60, n, t0_ns=t0 + 3_000_000, period_ns=16_666_667, seed=2)
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    return recs


def _play(rp: Replayer, timed: bool = False):
    got = []

    async def main():
        loop = asyncio.get_running_loop()
        await rp.run(lambda r: got.append((loop.time(), r.thing, r.name, r.data)))

    asyncio.run(main())
    return got


def test_two_devices_replay_on_one_time_base_in_recorded_order(reader, recorded):
    got = _play(Replayer(reader, ["pad-a", "pad-b"], speed=1.0, page=37))
    expected = sorted(recorded, key=lambda r: r.t_ns)  # stable: pad-a first at equal times
    assert [(th, n, d) for _, th, n, d in got] == [(r.thing, r.name, r.data) for r in expected]
    # one clock for both: each record is emitted at its recorded time after the first one (at speed 1 a
    # loaded machine's backlog does not accumulate over records 8 ms apart as it did 2 ms apart)
    t0 = got[0][0]
    late = [(t - t0) - (r.t_ns - expected[0].t_ns) / 1e9 for (t, *_), r in zip(got, expected, strict=True)]
    assert min(late) > -0.003 and sorted(late)[len(late) // 2] < 0.1  # loose: a shared machine


def test_a_name_filter_keeps_only_those_affordances(reader, recorded):
    got = _play(Replayer(reader, ["pad-a", "pad-b"], speed=0, names=["contactInformation"]))
    want = sorted((r for r in recorded if r.name == "contactInformation"), key=lambda r: r.t_ns)
    assert [(th, d) for _, th, _, d in got] == [(r.thing, r.data) for r in want] and want


def test_an_offset_starts_into_the_range(reader, recorded):
    t0 = min(r.t_ns for r in recorded)
    got = _play(Replayer(reader, ["pad-a", "pad-b"], speed=0, offset_s=0.5))
    want = sorted((r for r in recorded if r.t_ns >= t0 + 500_000_000), key=lambda r: r.t_ns)
    assert [d for *_, d in got] == [r.data for r in want] and 0 < len(want) < len(recorded)
    # with an explicit start, the offset counts from it; one device alone too
    lo = t0 + 200_000_000
    got = _play(Replayer(reader, "pad-b", t_from_ns=lo, speed=0, offset_s=0.25))
    assert [d for *_, d in got] == [r.data for r in recorded
                                    if r.thing == "pad-b" and r.t_ns >= lo + 250_000_000]


def test_a_negative_offset_or_no_device_is_refused(reader):
    with pytest.raises(ValueError, match="offset"):
        Replayer(reader, "pad-a", offset_s=-1)
    with pytest.raises(ValueError, match="at least one"):
        Replayer(reader, [])
