"""The event plane: numbering, fan-out by interest, lazy work, resume from ring and history."""

from __future__ import annotations

import asyncio

from wott_hub.events import KIND_EVENT, KIND_PROPERTY, EventPlane, Record


async def _drain(sub, n, timeout=30.0):  # a hang's bound: records already published come at once
    out = []

    async def take():
        async for batch in sub.batches():
            out.extend(batch)
            if len(out) >= n:
                return

    await asyncio.wait_for(take(), timeout)
    return out


class ListHistory:
    """A history that keeps committed records in a list (the real one is tested in tests/history); the
    plane's ``HistorySink`` and ``HistorySource`` both: it refuses nothing and is never broken."""

    failure = ""

    def __init__(self, plane):
        self.plane = plane
        self.queue: list[Record] = []
        self.rows: list[Record] = []
        self.failed_seqs: dict[str, set[int]] = {}

    def submit(self, rec):
        self.queue.append(rec)

    def commit(self):
        self.rows += self.queue
        if self.queue:
            self.plane.on_committed({self.queue[-1].thing: self.queue[-1].seq})
        self.queue = []

    async def fetch(self, thing, after, upto, interest, limit):
        kind, name = interest
        rows = [r for r in self.rows if r.thing == thing and after < r.seq <= upto][:limit]
        reached = rows[-1].seq if len(rows) == limit else upto
        return [r for r in rows if r.kind == kind and (name is None or r.name == name)], reached


def test_each_thing_has_its_own_increasing_sequence():
    plane = EventPlane()
    plane.add_stream("a", record=True, start_after=41)
    plane.add_stream("b", record=True, start_after=0)
    seqs = [plane.publish(t, KIND_EVENT, "e", 0, "1").seq for t in "abab"]
    assert seqs == [42, 1, 43, 2]


def test_unrecorded_streams_start_above_any_earlier_run():
    plane = EventPlane()
    st = plane.add_stream("x", record=False)
    assert st.seq > 1_600_000_000_000_000  # microseconds since the epoch: a restart never goes below


def test_records_nobody_wants_are_not_wanted():
    plane = EventPlane()
    plane.add_stream("a", record=False)
    assert not plane.wants("a", KIND_EVENT, "skinDeformedDetection")
    sub = plane.subscribe("a", (KIND_EVENT, "skinDeformedDetection"))
    assert plane.wants("a", KIND_EVENT, "skinDeformedDetection")
    assert not plane.wants("a", KIND_EVENT, "actionDetection")
    sub.close()
    assert not plane.wants("a", KIND_EVENT, "skinDeformedDetection")
    plane.add_stream("r", record=True, start_after=0)
    assert plane.wants("r", KIND_PROPERTY, "contactInformation")  # history wants everything


def test_fan_out_by_interest():
    async def main():
        plane = EventPlane()
        plane.add_stream("a", record=False)
        one = plane.subscribe("a", (KIND_EVENT, "x"))
        every = plane.subscribe("a", (KIND_EVENT, None))
        props = plane.subscribe("a", (KIND_PROPERTY, "p"))
        for name, kind in (("x", KIND_EVENT), ("y", KIND_EVENT), ("p", KIND_PROPERTY)):
            plane.publish("a", kind, name, 0, "0")
        assert [r.name for r in await _drain(one, 1)] == ["x"]
        assert [r.name for r in await _drain(every, 2)] == ["x", "y"]
        assert [r.name for r in await _drain(props, 1)] == ["p"]

    asyncio.run(main())


def test_resume_serves_the_ring_then_live_without_gap_or_duplicate():
    async def main():
        plane = EventPlane(ring_size=100)
        plane.add_stream("a", record=False)
        first = [plane.publish("a", KIND_EVENT, "x", 0, str(i)).seq for i in range(10)]
        sub = plane.subscribe("a", (KIND_EVENT, "x"), after=first[3])
        later = [plane.publish("a", KIND_EVENT, "x", 0, str(i)).seq for i in range(5)]
        got = [r.seq for r in await _drain(sub, 11)]
        assert got == first[4:] + later

    asyncio.run(main())


def test_resume_older_than_the_ring_reads_history_after_it_is_committed():
    async def main():
        plane = EventPlane(ring_size=10)
        hist = ListHistory(plane)
        plane.history_sink = plane.history_source = hist
        plane.add_stream("a", record=True, start_after=0)
        for i in range(50):
            plane.publish("a", KIND_EVENT, "x" if i % 2 else "y", 0, str(i))
            if i == 30:
                hist.commit()
        # the ring holds 10 + what is not committed yet; the oldest records are only in history
        sub = plane.subscribe("a", (KIND_EVENT, "x"), after=5)
        asyncio.get_running_loop().call_later(0.05, hist.commit)  # the rest commits a bit later
        plane.publish("a", KIND_EVENT, "x", 0, "live")
        got = [r.seq for r in await _drain(sub, 24)]
        assert got == [s for s in range(6, 51) if s % 2 == 0] + [51]

    asyncio.run(main())


def test_unrecorded_resume_past_the_ring_reports_the_gap():
    async def main():
        plane = EventPlane(ring_size=5)
        plane.add_stream("a", record=False, start_after=0)
        for i in range(20):
            plane.publish("a", KIND_EVENT, "x", 0, str(i))
        sub = plane.subscribe("a", (KIND_EVENT, "x"), after=2)
        got = [r.seq for r in await _drain(sub, 5)]
        assert got == [16, 17, 18, 19, 20] and sub.gap == (2, 16)

    asyncio.run(main())


def test_a_recorded_thing_keeps_a_short_ring_and_one_that_is_not_a_long_one():
    """By default (docs/hub.md, "Garbage collection"): history serves a recorded Thing's older records,
    nothing serves those of a Thing that is not recorded; a configured size is every Thing's."""
    from wott_hub.events.plane import RING_RECORDED, RING_UNRECORDED

    plane = EventPlane()
    hist = ListHistory(plane)
    plane.history_sink = plane.history_source = hist
    plane.add_stream("rec", record=True, start_after=0)
    plane.add_stream("live", record=False, start_after=0)
    plane.add_stream("later", record=False, start_after=0)
    plane.continue_after("later", None, record=True)  # told once history is open
    for i in range(RING_UNRECORDED + 10):
        for thing in ("rec", "live", "later"):
            plane.publish(thing, KIND_EVENT, "x", 0, str(i))
    assert len(plane.stream("rec").ring) == RING_UNRECORDED + 10  # nothing trimmed before history has it
    plane.on_committed({"rec": RING_UNRECORDED + 10, "later": RING_UNRECORDED + 10})
    assert RING_RECORDED < RING_UNRECORDED
    assert len(plane.stream("rec").ring) == len(plane.stream("later").ring) == RING_RECORDED
    assert len(plane.stream("live").ring) == RING_UNRECORDED
    assert plane.stream("rec").ring[-1].seq == RING_UNRECORDED + 10  # the newest kept

    sized = EventPlane(ring_size=7)
    sized.add_stream("rec", record=True)
    sized.add_stream("live", record=False)
    assert sized.stream("rec").ring_max == sized.stream("live").ring_max == 7


def test_a_subscriber_that_falls_too_far_behind_is_cut_off():
    plane = EventPlane(max_pending=10)
    plane.add_stream("a", record=False)
    sub = plane.subscribe("a", (KIND_EVENT, None))
    for i in range(11):
        plane.publish("a", KIND_EVENT, "x", 0, str(i))
    assert sub.closed and sub.overflowed and plane.overflow_disconnects == 1
    assert not plane.stream("a").subs  # and costs nothing any more


def test_the_hub_writes_skin_deformed_packets_exactly_as_the_processor_describes_them():
    import numpy as np

    from wott_hub.events.record import encode
    from wott_hub.examples import example_device
    from wott_hub.runtime.payloads import skin_deformed_json
    from wott_hub.tactile import FrameProcessor, TactileFrame
    from wott_hub.tactile.indentation import Indenter, indent

    desc = example_device("flat")
    proc = FrameProcessor(desc.mesh)
    centre = desc.mesh.nodes[desc.mesh.free_indices[100]]
    d = indent(desc.mesh, [Indenter(centre, 1.3, 5.0, np.array([0.2, -0.1, 0.0]))])
    for t, disp in ((1, d), (2, d * 0.37), (3, np.zeros_like(d))):  # contact, smaller, release
        res = proc.process(TactileFrame(t, disp))
        assert skin_deformed_json(res) == encode(res.skin_deformed_detection())


class _Sink:
    """A record sink asking ``wants``; each record put lands in ``out`` as its fields
    (thing, kind, name, t_ns, data, trace, skin)."""

    def __init__(self, wants, out: list) -> None:
        self.wants = wants
        self.out = out

    def put(self, rec) -> None:
        self.out.append((rec.thing, rec.kind, rec.name, rec.t_ns, rec.data, rec.trace, rec.skin))


def test_frame_records_builds_only_what_is_wanted_and_the_worker_builds_everything():
    """The same rules in the hub (asks the plane) and in a worker (wants everything), runtime/pipeline.py."""
    import json

    import numpy as np

    from wott_hub.examples import example_device
    from wott_hub.runtime.payloads import skin_deformed_json
    from wott_hub.runtime.pipeline import ACTION, CONTACTS, SKIN_DEFORMED, DevicePipeline
    from wott_hub.tactile import FrameProcessor, TactileFrame
    from wott_hub.tactile.indentation import Indenter, indent

    def State():
        return DevicePipeline("p", None, None, contacts_json=None)

    desc = example_device("flat")
    proc = FrameProcessor(desc.mesh)
    centre = desc.mesh.nodes[desc.mesh.free_indices[100]]
    d = indent(desc.mesh, [Indenter(centre, 1.3, 5.0, np.array([0.2, -0.1, 0.0]))])
    frames = ((1, d), (2, d * 0.37), (3, 0 * d), (4, 0 * d))  # contact, smaller, release, at rest
    results = [proc.process(TactileFrame(t, disp)) for t, disp in frames]
    assert [bool(r.contacts) for r in results] == [True, True, False, False]

    everything, nothing, asked = [], [], []
    all_state, none_state = State(), State()

    def never(thing, kind, name):
        asked.append(name)
        return False

    for res in results:
        all_state.records(res, 0, _Sink(lambda *_: True, everything))
        everything.append("frame end")
        none_state.records(res, 0, _Sink(never, nothing))
    by_frame = [[]]
    for rec in everything:
        if rec == "frame end":
            by_frame.append([])
        else:
            by_frame[-1].append(rec)
    assert nothing == [] and none_state.contacts_json is None and none_state.contacts is results[-2]
    # contacts while touched and once at rest; never again at rest
    assert [any(rec[2] == CONTACTS for rec in recs) for recs in by_frame[:4]] == [True, True, True, False]
    assert all_state.contacts_json == json.dumps(results[2].contact_information(), separators=(",", ":"))
    for res, recs in zip(results, by_frame, strict=False):
        assert all(rec[0] == "p" and rec[3] == res.t_ns and rec[5] is None for rec in recs)
        assert [rec[4] for rec in recs if rec[2] == SKIN_DEFORMED] == ([skin_deformed_json(res)]
                                                                       if res.packet_due else [])
        assert sum(1 for rec in recs if rec[2] == ACTION) == len(res.actions)
    assert sum(len(r.actions) for r in results) > 0
    # the plane is asked about actions once per frame that has any, not once per action
    assert asked.count(ACTION) == sum(1 for r in results if r.actions)


def test_frame_records_stamps_the_skin_packet_when_tracing():
    import numpy as np

    from wott_hub.examples import example_device
    from wott_hub.runtime.pipeline import SKIN_DEFORMED, DevicePipeline
    from wott_hub.tactile import FrameProcessor, TactileFrame
    from wott_hub.tactile.indentation import Indenter, indent

    desc = example_device("flat")
    centre = desc.mesh.nodes[desc.mesh.free_indices[100]]
    d = indent(desc.mesh, [Indenter(centre, 1.3, 5.0, np.array([0.0, 0.0, 0.0]))])
    res = FrameProcessor(desc.mesh).process(TactileFrame(1, d))
    out = []
    DevicePipeline("p", None, None).records(res, 123, _Sink(lambda *_: True, out))
    traces = {rec[2]: rec[5] for rec in out}
    assert set(traces[SKIN_DEFORMED]) == {"in", "proc", "enc"} and traces[SKIN_DEFORMED]["in"] == 123
    assert all(trace is None for name, trace in traces.items() if name != SKIN_DEFORMED)


def _consume_with(sub, direct):
    """Run ``sub``'s consumer with the writer ``direct``; its batches' seqs land in the list returned."""
    batches: list[list[int]] = []

    async def consume():
        async for batch in sub.batches(direct):
            batches.append([r.seq for r in batch])

    return asyncio.create_task(consume()), batches


def test_an_idle_consumer_is_written_to_by_push_itself_up_to_the_burst_then_in_one_batch():
    from wott_hub.events.subscriber import DIRECT_BURST

    async def main():
        plane = EventPlane()
        plane.add_stream("a", record=False)
        sub = plane.subscribe("a", (KIND_EVENT, "x"))
        written: list[int] = []
        task, batches = _consume_with(sub, lambda rec: written.append(rec.seq) is None)
        await asyncio.sleep(0)  # the consumer waits, nothing pending
        seqs = [plane.publish("a", KIND_EVENT, "x", 0, str(i)).seq for i in range(20)]
        burst = int(DIRECT_BURST)
        assert written == seqs[:burst]  # inside publish: no loop turn in between
        await asyncio.sleep(0.02)  # the rest went to the consumer's task, in one write; credit is back
        assert batches == [seqs[burst:]]
        later = plane.publish("a", KIND_EVENT, "x", 0, "later").seq
        assert written[-1] == later and sub.last_seq == later
        task.cancel()

    asyncio.run(main())


def test_a_record_the_writer_refuses_or_fails_on_is_queued_and_none_overtakes_it():
    async def main():
        plane = EventPlane()
        plane.add_stream("a", record=False)
        sub = plane.subscribe("a", (KIND_EVENT, "x"))
        written: list[int] = []

        def direct(rec):
            if rec.data == "busy":  # the socket is backed up
                return False
            if rec.data == "bug":
                raise RuntimeError("a consumer's bug")
            written.append(rec.seq)
            return True

        task, batches = _consume_with(sub, direct)
        await asyncio.sleep(0)
        first = plane.publish("a", KIND_EVENT, "x", 0, "ok").seq
        busy = [plane.publish("a", KIND_EVENT, "x", 0, d).seq for d in ("busy", "ok", "ok")]
        await asyncio.sleep(0)
        bug = [plane.publish("a", KIND_EVENT, "x", 0, d).seq for d in ("bug", "ok")]  # publisher unharmed
        await asyncio.sleep(0)
        assert written == [first] and batches == [busy, bug]
        last = plane.publish("a", KIND_EVENT, "x", 0, "ok").seq  # idle again: written at once
        assert written == [first, last]
        task.cancel()

    asyncio.run(main())


def test_what_history_has_not_committed_is_kept_beyond_the_ring_up_to_a_byte_cap():
    """Issue 48, item 4: a raw camera's images on a full disk are never committed; the ring kept 65,536
    of them (~16 GB). Beyond ``ring_max`` it keeps uncommitted records up to ``ring_hold_bytes``, never
    fewer than ``ring_max``, the newest."""
    plane = EventPlane(ring_size=4)
    plane.ring_hold_bytes = 10_000
    hist = ListHistory(plane)
    plane.history_sink = plane.history_source = hist
    plane.add_stream("cam", record=True, start_after=0)
    image = "x" * 1_000
    for _ in range(8):
        plane.publish("cam", KIND_EVENT, "image", 0, image)
    st = plane.stream("cam")
    assert len(st.ring) == 8 and st.ring_bytes == 8_000  # under the cap: all kept for resumes
    for _ in range(100):
        plane.publish("cam", KIND_EVENT, "image", 0, image)
    assert len(st.ring) == 10 and st.ring_bytes == 10_000 and st.ring[-1].seq == 108
    big = "y" * 50_000
    for _ in range(6):
        plane.publish("cam", KIND_EVENT, "image", 0, big)
    assert len(st.ring) == 4 and st.ring_bytes == 4 * 50_000  # over the cap, never under ring_max
    hist.commit()
    assert len(st.ring) == 4 and st.ring_bytes == sum(len(r.data) for r in st.ring)


def test_the_held_queue_of_committed_mode_is_bounded_in_bytes_dropping_the_oldest_with_a_count(caplog):
    """Issue 48: on a full disk the writer drops what it cannot queue and the watermark stands still, so
    "committed" mode held every record up to ``max_held`` (1,000,000 raw images: 250 GB). Beyond
    ``held_max_bytes`` the oldest held are let go, counted (``held_health``) and said in the log; what is
    committed afterwards is delivered, in order."""
    plane = EventPlane(durability="committed", held_max_bytes=10_000)
    hist = ListHistory(plane)
    plane.history_sink = plane.history_source = hist
    plane.add_stream("cam", record=True, start_after=0)
    sub = plane.subscribe("cam", (KIND_EVENT, None))
    image = "x" * 1_800  # 2,000 bytes a record with its objects (record_bytes)
    with caplog.at_level("WARNING", logger="wott_hub.events.plane"):
        for _ in range(100):
            plane.publish("cam", KIND_EVENT, "image", 0, image)
    st = plane.stream("cam")
    assert len(st.held) == 5 and st.held_bytes == 10_000 and st.held[0].seq == 96
    assert plane.held_health() == {"records": 5, "bytes": 10_000, "maxBytesPerThing": 10_000,
                                   "notDelivered": 95}
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1, said  # once, not per record
    assert "not delivered live" in said[0] and "cam" in said[0], said
    big = "y" * 50_000  # one record over the bound on its own: the newest is always kept
    plane.publish("cam", KIND_EVENT, "image", 0, big)
    assert [r.seq for r in st.held] == [101] and st.held_dropped == 100
    hist.commit()
    assert st.held_bytes == 0 and not st.held

    async def main():
        got = await _drain(sub, 1)
        assert [r.seq for r in got] == [101]

    asyncio.run(main())
