"""Issue 16, item 9: with ``durability = "committed"``, SIGKILL under load loses nothing any
subscriber saw.

A real hub process publishes as fast as it can into a recorded Thing; a real SSE client reads
the stream; the hub is SIGKILLed mid-stream, restarted on the same database (its lease is taken
over at once: the holder's pid is gone), stopped cleanly; every id the client saw is in history.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import threading
import time

import httpx

from wott_hub.history import HistoryReader, create_engine, database_url

_HUB = textwrap.dedent("""
    import asyncio, json, signal, sys, time
    from wott_hub.config import HubConfig
    from wott_hub.events.record import KIND_EVENT
    from wott_hub.hub import Hub
    from wott_hub.network import DirectoryConfig

    TD = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "title": "load", "id": "urn:test:load",
          "securityDefinitions": {"n": {"scheme": "nosec"}}, "security": "n",
          "events": {"tick": {"data": {"type": "object"}}}}

    async def main():
        cfg = HubConfig(name="load", host="127.0.0.1", http_port=0, ws_port=0, database=sys.argv[1],
                        directory=DirectoryConfig(enabled=False))
        hub = Hub(cfg)
        hub._plane.set_durability(sys.argv[2])
        await hub.start()
        await hub.expose_thing("load", TD, record=True)
        stop = asyncio.Event()
        asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
        print(json.dumps({"events": hub.td_url("load") + "/events/tick"}), flush=True)
        if sys.argv[3] == "idle":  # until SIGTERM, then a clean stop
            await stop.wait()
            await hub.stop()
            return
        i = 0
        while True:  # under load: bursts of 50 records, as fast as the loop allows
            for _ in range(50):
                i += 1
                hub._plane.publish("load", KIND_EVENT, "tick", time.time_ns(), json.dumps({"i": i}))
            await asyncio.sleep(0.001)

    asyncio.run(main())
""")


def _start(db: str, mode: str, load: str) -> tuple[subprocess.Popen, str]:
    p = subprocess.Popen([sys.executable, "-c", _HUB, db, mode, load], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    assert line, p.stderr.read()
    return p, json.loads(line)["events"]


def _read_ids(url: str, seen: list[int], stop: threading.Event) -> None:
    """The ids of the stream until ``stop`` or its end. A first connection that times out before any id
    (the hub's loop busy publishing, on a loaded machine) is made again: only the stream that saw ids
    is the one whose ids must be in history."""
    while not stop.is_set():
        try:
            with httpx.Client(timeout=httpx.Timeout(10, read=5)) as c, c.stream(
                    "GET", url, headers={"Accept": "text/event-stream"}) as r:
                for line in r.iter_lines():
                    if line.startswith("id:"):
                        seen.append(int(line[3:]))
                    if stop.is_set():
                        return
        except httpx.HTTPError:  # the hub was killed under us: what was seen is seen
            if seen:
                return
            time.sleep(0.1)


def test_sigkill_under_load_in_committed_mode_loses_nothing_a_subscriber_saw(tmp_path):
    db = str(tmp_path / "h.db")
    hub, url = _start(db, "committed", "load")
    seen: list[int] = []
    stop = threading.Event()
    reader = threading.Thread(target=_read_ids, args=(url, seen, stop), daemon=True)
    try:
        reader.start()
        deadline = time.monotonic() + 60  # a wait, not a bound: a loaded machine starts streaming later
        while len(seen) < 3000 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(seen) >= 3000, "the hub did not stream under load"
        hub.send_signal(signal.SIGKILL)  # mid-stream, mid-batch
        hub.wait(10)
    finally:
        stop.set()
        if hub.poll() is None:
            hub.kill()
            hub.wait(10)
    reader.join(10)
    assert seen == sorted(seen) and len(set(seen)) == len(seen)

    again, _ = _start(db, "committed", "idle")  # the dead hub's lease is taken over at once
    again.send_signal(signal.SIGTERM)
    assert again.wait(20) == 0, again.stderr.read()

    eng = create_engine(database_url(db))
    try:
        recorded = {r.seq for page in HistoryReader(eng).pages("load") for r in page}
    finally:
        eng.dispose()
    missing = sorted(set(seen) - recorded)
    assert missing == [], f"{len(missing)} of {len(seen)} ids seen over SSE not in history: {missing[:10]}"


def test_committed_mode_delivers_only_after_the_commit_and_never_a_refused_record(tmp_path):
    """The plane's side of it, in one process: a real writer on a real file, with one row refused."""
    import asyncio

    from wott_hub.events.plane import EventPlane
    from wott_hub.history import HistoryWriter, upgrade

    async def scenario() -> tuple[list[int], list[int], set[int]]:
        loop = asyncio.get_running_loop()
        eng = create_engine(database_url(tmp_path / "h.db"))
        upgrade(eng)
        plane = EventPlane(durability="committed")
        writer = HistoryWriter(eng, interval_s=0.01,
                               on_commit=lambda wm: loop.call_soon_threadsafe(plane.on_committed, wm))
        start = writer.register_thing("d")
        with eng.begin() as conn:  # the row seq start+3 is taken already: the database refuses ours
            conn.exec_driver_sql("INSERT INTO events (thing_key, seq, t_ns, kind, name, data) "
                                 f"VALUES ({writer.storage.keys['d']}, {start + 3}, 3, 0, 'tick', '0')")
        plane.history_sink = writer
        plane.add_stream("d", record=True, start_after=start)
        sub = plane.subscribe("d", (0, None))
        writer.start()
        for i in range(10):
            plane.publish("d", 0, "tick", i + 1, json.dumps({"i": i}))
        before = [r.seq - start for r in sub.pending]  # nothing committed yet: nothing delivered
        got: list[int] = []
        async with asyncio.timeout(10):
            async for batch in sub.batches():
                got += [r.seq - start for r in batch]
                if got and got[-1] == 10:
                    break
        await asyncio.to_thread(writer.stop)
        recorded = {r.seq - start for page in HistoryReader(eng).pages("d") for r in page}
        eng.dispose()
        return before, got, recorded

    before, got, recorded = asyncio.run(scenario())
    assert before == []
    assert got == [1, 2, 4, 5, 6, 7, 8, 9, 10]  # 3 was refused: never shown to anyone
    assert set(got) <= recorded
