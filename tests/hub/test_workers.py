"""``[hub] workers``: devices run and are processed in worker processes; the hub serves the same."""

from __future__ import annotations

import asyncio
import json
import os
import time

import httpx

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, SkinArrays
from wott_hub.plugins import DeviceConfig
from wott_hub.runtime.messages import Ended
from wott_hub.td.validate import validate_td


def test_devices_in_a_worker_process_stream_and_record_like_local_ones(tmp_path, hub_thread, scene,
                                                                       sse_events):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), workers=1,
                    devices=(scene("pad", "flat"), scene("cyl", "cylinder"),
                             DeviceConfig("broken", "scene", {"shape": "flat"})))  # no scene: fails
    ht = hub_thread(cfg).start()
    try:
        hub = ht.hub
        assert set(hub.devices) == {"pad", "cyl"} and "broken" in hub.describe()["failed"]
        assert hub.devices["pad"].processor is None  # processed in the worker
        td = httpx.get(hub.td_url("pad")).json()
        assert validate_td(td) == [] and td["properties"]["skinNodes"]
        assert httpx.get(f"{hub.td_url('pad')}/properties/skinNodes").json()["numOfNodes"] == 256
        got = [(int(ev.id), ev.data) for ev in sse_events(f"{hub.td_url('pad')}/events", 30, timeout=20)]
        assert ht.call(lambda: hub._history.writer.flush())
        recs, _ = hub._history.reader.rows("pad", 0, 1 << 62, (KIND_EVENT, None), limit=10**6)
        recorded = {r.seq: r.data for r in recs}
        assert all(recorded[i] == d for i, d in got)
        ids = [i for i, _ in got]
        assert ids == [s for s in sorted(recorded) if ids[0] <= s <= ids[-1]]
        skins = ht.call(lambda: [r for r in hub._plane.stream("pad").ring
                                 if r.name == "skinDeformedDetection"])
        assert skins and all(isinstance(r.skin, SkinArrays) for r in skins)  # its arrays crossed the pipe
        for r in skins[-5:]:
            nodes = json.loads(r.data)["arrayOfDeformedNodes"]
            assert r.skin.ids.tolist() == [n["deformedNodeID"] for n in nodes]
            assert r.skin.intensity.tolist() == [n["deformedNodeIntensity"] for n in nodes]
        health = httpx.get(f"{hub.td_url('hub')}/properties/health").json()
        assert health["devices"]["pad"]["frames"] > 0
        # below the hub's CPU priority by [hub] worker_nice (default 10): its loop runs first
        own = os.getpriority(os.PRIO_PROCESS, 0)
        assert [os.getpriority(os.PRIO_PROCESS, p.pid) for p in hub._fleet.pool.procs] == [min(own + 10, 19)]
    finally:
        ht.stop()
    assert not any(p.is_alive() for p in hub._fleet.pool.procs)  # the workers are gone


# --- the pipe: records batched in the worker (Outbox), unpacked by the hub (WorkerPool) ----------------

END = Ended("-", "end")
"""A message after the records: the tests' end marker."""

def _skin_record(sink, t_ns: int, ids: list[int], mm: list[float]) -> None:
    import numpy as np

    data = json.dumps({"timeStamp": t_ns, "numOfDeformedNodes": len(ids), "arrayOfDeformedNodes": [
        {"deformedNodeID": i, "deformedNodeIntensity": v} for i, v in zip(ids, mm, strict=True)]},
        separators=(",", ":"))
    sink.put(Record(sink.thing, 0, KIND_EVENT, "skinDeformedDetection", t_ns, data, None,
                    SkinArrays(np.array(ids, np.intp), np.array(mm))))


def _fields(rec: Record) -> tuple:
    """A record as it crossed the pipe: (kind, name, t_ns, data, trace, skin)."""
    return rec.kind, rec.name, rec.t_ns, rec.data, rec.trace, rec.skin


def _through_the_pipe(work, flush_s: float = 0.05):
    """Run ``work(outbox, sinks)`` in a loop whose pipe ends in a ``WorkerPool`` reader: the messages
    the hub's loop hands on (``("recs", thing, records)`` per frame; ``END`` as ``("end",)``), the number
    of pipe messages they came in, each batch's frame times."""
    import multiprocessing as mp

    from wott_hub.runtime.messages import Batch
    from wott_hub.runtime.outbox import Outbox, PipeSink
    from wott_hub.runtime.pool import WorkerPool

    got: list[tuple] = []
    batches: list[list[int]] = []  # the t_ns of each batch's frames
    sent = [0]

    class Counted:
        """The worker's end of the pipe, counting the messages that cross it."""

        def __init__(self, conn) -> None:
            self.conn = conn

        def send(self, msg) -> None:
            sent[0] += 1
            if isinstance(msg, Batch):
                batches.append([recs[0].t_ns for recs in msg.frames])
            self.conn.send(msg)

    class Heard:
        """The hub's side (``WorkerEvents``): what the pool hands on."""

        def on_records(self, recs) -> None:
            got.append(("recs", recs[0].thing, [_fields(r) for r in recs]))

        def on_ended(self, device_id, reason) -> None:
            got.append((reason,))  # END

    async def main() -> None:
        hub_end, worker_end = mp.Pipe(duplex=True)
        pool = WorkerPool(0, Heard())  # no process: this test's pipe stands for its worker
        pool.conns.append(hub_end)
        loop = asyncio.get_running_loop()
        loop.add_reader(hub_end.fileno(), pool._readable, 0)
        outbox = Outbox(Counted(worker_end), flush_s)
        await work(outbox, {t: PipeSink(t, outbox) for t in ("a", "b")})
        outbox.flush()
        deadline = time.monotonic() + 5
        while (not got or got[-1][0] != "end") and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        loop.remove_reader(hub_end.fileno())
        hub_end.close()
        worker_end.close()

    asyncio.run(main())
    return got, sent[0], batches


def test_frames_of_all_devices_go_out_as_one_message_and_keep_their_order_and_arrays():
    async def work(outbox, sinks):
        for k in range(6):
            sink = sinks["ab"[k % 2]]
            _skin_record(sink, 1000 + k, [3, 7 + k], [0.5, 1.25])
            sink.put(Record(sink.thing, 0, KIND_PROPERTY, "contactInformation", 1000 + k, f'{{"k":{k}}}',
                            {"in": k}))
            sink.frame_done()
        outbox.send(END)

    got, messages, _ = _through_the_pipe(work)
    assert messages == 2  # six frames in one batch, flushed ahead of "end"
    assert [m[:2] for m in got] == [("recs", "ab"[k % 2]) for k in range(6)] + [("end",)]
    for k, (_, _, recs) in enumerate(got[:6]):
        (kind, name, t_ns, data, trace, skin), contacts = recs
        assert (kind, name, t_ns, trace) == (KIND_EVENT, "skinDeformedDetection", 1000 + k, None)
        nodes = json.loads(data)["arrayOfDeformedNodes"]
        assert skin.ids.tolist() == [n["deformedNodeID"] for n in nodes] == [3, 7 + k]
        assert skin.intensity.tolist() == [n["deformedNodeIntensity"] for n in nodes]
        assert contacts == (KIND_PROPERTY, "contactInformation", 1000 + k, f'{{"k":{k}}}', {"in": k}, None)


def test_a_batch_waits_at_most_flush_s_even_while_the_loop_is_busy(monkeypatch):
    """A loop tick that never yields (one running many devices): the batch goes out when a frame
    finds its first one ``flush_s`` old, not when the tick ends. The outbox reads its clock through
    its module's ``time``; here that clock is the frames' own (1/1024 s apart: exact in binary), so
    the batches are exactly those the rule makes, however late the machine runs the test."""
    import types

    from wott_hub.runtime import outbox as outbox_module

    flush_s = 0.01
    clock = [1000.0]  # s
    monkeypatch.setattr(outbox_module, "time", types.SimpleNamespace(monotonic=lambda: clock[0]))

    async def work(outbox, sinks):
        sink = sinks["a"]
        for _ in range(100):  # never yields: the next-tick flush cannot run
            clock[0] += 1 / 1024
            sink.put(Record("a", 0, KIND_PROPERTY, "contactInformation", round(clock[0] * 1e9), "{}"))
            sink.frame_done()
        outbox.send(END)

    got, messages, batches = _through_the_pipe(work, flush_s)
    assert len(got) - 1 == sum(map(len, batches)) == 100 and len(batches) == 9  # 8 x 12 and 4
    for t in batches[:-1]:  # each went out with the first frame at flush_s or more after its first
        assert len(t) == 12 and t[-2] - t[0] < flush_s * 1e9 <= t[-1] - t[0]


def test_a_lone_frame_goes_out_on_the_next_loop_tick_not_after_flush_s():
    async def work(outbox, sinks):
        sink = sinks["b"]
        sink.put(Record("b", 0, KIND_PROPERTY, "contactInformation", 1, "{}"))
        sink.frame_done()
        ticks = 0
        while outbox._frames and ticks < 1000:
            await asyncio.sleep(0)
            ticks += 1
        assert ticks <= 2  # out on the next loop tick (flush_s here is 5 s: counted in ticks, not time)
        outbox.send(END)

    got, messages, _ = _through_the_pipe(work, flush_s=5.0)
    assert messages == 2
    assert got[0] == ("recs", "b", [(KIND_PROPERTY, "contactInformation", 1, "{}", None, None)])


def test_an_open_never_waits_for_a_worker_that_exited():
    """A worker process that exits while a device is opening in it fails that open (``WorkerDied``:
    it used to wait for ever); later opens go to a worker still running, and fail at once when
    none is."""
    import pytest

    from wott_hub.errors import DriverError, WorkerDied
    from wott_hub.runtime.pool import WorkerPool

    class Heard:
        def __init__(self) -> None:
            self.exited: list[int] = []

        def on_worker_exit(self, worker) -> None:
            self.exited.append(worker)

    async def main() -> None:
        heard = Heard()
        pool = WorkerPool(2, heard)
        try:
            opening = asyncio.create_task(pool.open(DeviceConfig("pad", "scene", {"shape": "flat"})))
            await asyncio.sleep(0)  # sent to worker 0, which is still starting (a spawned interpreter)
            pool.procs[0].kill()
            with pytest.raises(WorkerDied):
                await asyncio.wait_for(opening, 30)
            assert heard.exited == [0] and not pool._pending
            # the next opens go to worker 1: it answers (here: the scene has no steps, a DriverError)
            for _ in range(2):
                with pytest.raises(DriverError, match="step") as e:
                    await asyncio.wait_for(pool.open(DeviceConfig("x", "scene", {"shape": "flat"})), 60)
                assert not isinstance(e.value, WorkerDied)
            pool.procs[1].kill()
            deadline = time.monotonic() + 30
            while heard.exited != [0, 1] and time.monotonic() < deadline:
                await asyncio.sleep(0.02)
            with pytest.raises(WorkerDied, match="every worker process has exited"):
                await asyncio.wait_for(pool.open(DeviceConfig("y", "scene", {"shape": "flat"})), 1)
        finally:
            await pool.close()

    asyncio.run(main())
