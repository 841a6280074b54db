"""Client processes (``python -m bench_client.clients SPEC``): wott-client or wotpy's ConsumedThing.

Protocol: the process prints ``ready`` once it has consumed every TD and subscribed; the hub
side then publishes and writes how many records it published (one line on stdin); the client
waits until it has them all (or ``idle_s`` pass without a new one, or ``drain_s`` in all)
and prints one JSON line: per record (thing index, event id or -1, wall clock ns when its
field was built, its timeStamp), and the CPU seconds it used meanwhile.
Latency is the client's wall clock when the NumPy field is built minus the packet's
``timeStamp`` (the hub side's wall clock at publication; same machine).
"""

from __future__ import annotations

import asyncio
import json
import sys
import time

__all__ = ["client_main"]


async def _wait_expected(got: list, idle_s: float, drain_s: float) -> float:
    """Until every published record is in, ``idle_s`` pass without one, or ``drain_s`` after publishing."""
    expected = int(await asyncio.to_thread(sys.stdin.readline))
    last, seen = time.monotonic(), len(got)
    end = last + drain_s
    while len(got) < expected and time.monotonic() - last < idle_s and time.monotonic() < end:
        await asyncio.sleep(0.05)
        if len(got) != seen:
            last, seen = time.monotonic(), len(got)
    return time.monotonic()


async def ours(urls: list[str], idle_s: float, drain_s: float) -> dict:
    from contextlib import aclosing

    from wott_client import AsyncClient

    got: list[tuple[int, int, int, int]] = []
    async with AsyncClient() as c:
        things = [await c.async_thing(u) for u in urls]
        for t in things:
            await t.async_mesh()

        async def one(i: int, thing) -> None:
            append = got.append
            async with aclosing(thing.async_batches(contacts=False, actions=False)) as batches:
                async for batch in batches:
                    now = time.time_ns()
                    for f in batch:
                        append((i, int(f.event_id), now, f.timestamp_ns))

        tasks = [asyncio.ensure_future(one(i, t)) for i, t in enumerate(things)]
        await asyncio.sleep(0.5)
        print("ready", flush=True)
        cpu0, t0 = time.process_time(), time.monotonic()
        await _wait_expected(got, idle_s, drain_s)
        cpu, wall = time.process_time() - cpu0, time.monotonic() - t0
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    return {"events": got, "cpu_s": cpu, "wall_s": wall}


async def wotpy(urls: list[str], idle_s: float, drain_s: float) -> dict:
    import numpy as np
    from wotpy.wot.servient import Servient
    from wotpy.wot.wot import WoT

    got: list[tuple[int, int, int, int]] = []
    wot = WoT(servient=Servient(catalogue_port=None))
    subs = []
    for i, url in enumerate(urls):
        thing = await wot.consume_from_url(url)
        n = len((await thing.read_property("skinNodes"))["arrayOfNodes"])

        def on_next(ev, i=i, n=n) -> None:  # the same work as wott-client's: a dense field per packet
            nodes = ev.data["arrayOfDeformedNodes"]
            field = np.zeros(n)
            field[[d["deformedNodeID"] for d in nodes]] = [d["deformedNodeIntensity"] for d in nodes]
            got.append((i, -1, time.time_ns(), ev.data["timeStamp"]))

        subs.append(thing.events["skinDeformedDetection"].subscribe(on_next=on_next))
    await asyncio.sleep(0.5)  # each subscription opens its own connection
    print("ready", flush=True)
    cpu0, t0 = time.process_time(), time.monotonic()
    await _wait_expected(got, idle_s, drain_s)
    cpu, wall = time.process_time() - cpu0, time.monotonic() - t0
    for s in subs:
        s.dispose()
    return {"events": got, "cpu_s": cpu, "wall_s": wall}


def client_main(spec: dict) -> None:
    run = {"ours": ours, "wotpy": wotpy}[spec["kind"]]
    print(json.dumps(asyncio.run(run(spec["urls"], spec["idle_s"], spec["drain_s"]))), flush=True)


if __name__ == "__main__":
    client_main(json.loads(sys.argv[1]))
