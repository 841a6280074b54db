"""Throughput group: records/s to one subscriber with zero loss and every record in history.

Records published on one Thing at the offered rate; one SSE and one raw WebSocket client in
other processes at once. Plain wotpy: ``emit_event`` to the same raw WebSocket client.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

from .clients import Client
from .common import payload, payload_maker

__all__ = ["run", "throughput_ours", "throughput_plain"]


async def _publish_at(rate: float, duration: float, publish) -> int:
    """Publish ``rate`` records/s for ``duration`` s in 5 ms bursts; returns how many."""
    n = 0
    t0 = time.monotonic()
    while True:
        elapsed = time.monotonic() - t0
        if elapsed >= duration:
            return n
        due = int(rate * elapsed) + 1
        while n < due:
            publish(n)
            n += 1
        await asyncio.sleep(0.005)


async def throughput_ours(rate: float, duration: float, tmp: Path) -> dict:
    from wott_hub.config import HubConfig
    from wott_hub.events.record import KIND_EVENT
    from wott_hub.hub import Hub, tune_for_hub
    from wott_hub.td.builder import build_tactile_td

    from ._hub_internals import example_device, hub_plane, hub_writer

    hub = Hub(HubConfig(http_port=0, ws_port=0, database=str(tmp / f"tp{int(rate)}.db")))
    await hub.start()
    tune_for_hub()  # what `wott-hub run` does after start-up
    td = build_tactile_td(example_device("flat"))
    await hub.expose_thing("bench", td, record=True)
    url = f"{hub.td_url('bench')}/events/skinDeformedDetection"
    sse = Client({"kind": "sse", "duration": duration + 3.0, "urls": [url]})
    raw = Client({"kind": "ws-raw", "duration": duration + 3.0, "event": "skinDeformedDetection",
                  "url": f"{hub.ws_url}/bench"})
    await asyncio.gather(sse.ready(), raw.ready())
    plane = hub_plane(hub)
    first_seq = plane.stream("bench").seq + 1
    make = payload_maker()
    t0 = time.perf_counter()
    n = await _publish_at(rate, duration, lambda k: plane.publish(
        "bench", KIND_EVENT, "skinDeformedDetection", k, make(k)))
    achieved = n / (time.perf_counter() - t0)
    sse_res, raw_res = await asyncio.gather(sse.result(), raw.result())
    writer = hub_writer(hub)
    await asyncio.to_thread(writer.flush)
    written = writer.written
    overflow = plane.overflow_disconnects
    await hub.stop()
    seqs = [e[1] for e in sse_res["events"]]
    sse_ok = seqs == list(range(first_seq, first_seq + n))
    raw_ok = raw_res["n"] == n and raw_res["out_of_order"] == 0
    return {"rate": rate, "achieved": achieved, "published": n, "sse": len(seqs), "sse_lossless": sse_ok,
            "ws": raw_res["n"], "ws_lossless": raw_ok, "history": written, "history_ok": written == n,
            "overflow": overflow}


async def throughput_plain(rate: float, duration: float) -> dict:
    from wotpy.wot.dictionaries.thing import ThingFragment

    from .plain_wotpy import plain_servient, plain_td

    servient, wot, http, ws = await plain_servient(1)
    e = wot.produce(ThingFragment(plain_td("plain", http.port)))
    e.expose()
    raw = Client({"kind": "ws-raw", "duration": duration + 3.0, "event": "skinDeformedDetection",
                  "url": f"ws://127.0.0.1:{ws.port}/{e.thing.url_name}"})
    await raw.ready()
    payloads = [payload(20, k) for k in range(int(rate * duration) + 10)]  # built before timing
    t0 = time.perf_counter()

    def emit(k):
        try:
            e.emit_event("skinDeformedDetection", payloads[k])
        except Exception:  # wotpy raises into the emitter when its subscriber has gone
            pass

    n = await _publish_at(rate, duration, emit)
    achieved = n / (time.perf_counter() - t0)
    res = await raw.result()
    await servient.shutdown()
    return {"rate": rate, "achieved": achieved, "published": n, "ws": res["n"],
            "ws_lossless": res["n"] == n and res["out_of_order"] == 0}


async def run(tmp: Path, *, quick: bool) -> dict:
    """Rising offered rates until a subscriber loses records; the report's rows."""
    dur = 2.0 if quick else 5.0
    rows = []
    for rate in (10_000, 20_000, 40_000) if quick else (10_000, 20_000, 40_000, 80_000):
        print(f"throughput: {rate}/s ...", flush=True)
        r = await throughput_ours(rate, dur, tmp)
        rows.append(["hub", rate, f"{r['achieved']:.0f}", r["published"],
                     f"{r['sse']} ({'lossless' if r['sse_lossless'] else 'LOSS'})",
                     f"{r['ws']} ({'lossless' if r['ws_lossless'] else 'LOSS'})",
                     f"{r['history']} ({'all' if r['history_ok'] else 'MISSING'})"])
        print(rows[-1], flush=True)
        if not (r["sse_lossless"] and r["history_ok"]):
            break
    for rate in (100, 300, 1000) if quick else (100, 200, 400, 800, 1600):
        print(f"throughput plain wotpy: {rate}/s ...", flush=True)
        r = await throughput_plain(rate, dur)
        rows.append(["plain wotpy", rate, f"{r['achieved']:.0f}", r["published"], "-",
                     f"{r['ws']} ({'lossless' if r['ws_lossless'] else 'LOSS'})", "-"])
        print(rows[-1], flush=True)
        if not r["ws_lossless"]:
            break
    return {"duration": dur, "rows": rows}
