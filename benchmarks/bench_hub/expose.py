"""Expose group: time to expose N Tactile Things on one servient, and TD GET latency.

Each Thing a 16x16 pad's Tactile TD on the servient's HTTP and WebSocket bindings; TD GETs
for random Things from another process. Plain wotpy: ``wot.produce(...).expose()`` of the
same TD and its ``TDHandler`` route.
"""

from __future__ import annotations

import time

from report import pct  # benchmarks/report.py (this package's report is `from . import report`)

from . import report
from .clients import Client

__all__ = ["expose_ours", "expose_plain", "run"]


async def expose_ours(n: int, gets: int) -> dict:
    from dataclasses import replace

    from wott_hub.td.builder import build_tactile_td, static_property_values

    from ._hub_internals import EventPlane, HubServer, ServedThing, clean_td, example_device

    base = example_device("flat")
    plane = EventPlane()
    server = HubServer(plane, http_port=0, ws_port=0)
    layout = server.bind()
    await server.start()
    t0 = time.perf_counter()
    for i in range(n):
        tid = f"pad-{i}"
        desc = replace(base, id=tid, title=tid)
        td = build_tactile_td(desc, base=f"{layout.http_base}/", forms=layout.factory(tid),
                              context_url=layout.context_url)
        td["forms"] = layout.thing_forms(tid)
        clean_td(td)
        plane.add_stream(tid, record=False)
        server.expose(ServedThing.create(tid, td, static_property_values(desc)))
    expose_s = time.perf_counter() - t0
    c = Client({"kind": "td-get", "n": gets, "urls": [server.td_url(f"pad-{i}") for i in range(n)]})
    await c.ready()
    lat = (await c.result())["lat_ns"]
    await server.stop()
    return {"n": n, "expose_s": expose_s, "get_p50": pct(lat, 50), "get_p99": pct(lat, 99)}


async def expose_plain(n: int, gets: int, budget_s: float) -> dict:
    """Plain wotpy with the full Tactile affordances; stops exposing after ``budget_s``."""
    from wotpy.wot.dictionaries.thing import ThingFragment
    from wotpy.wot.servient import TDHandler

    from wott_hub.td.builder import build_tactile_td

    from ._hub_internals import example_device
    from .plain_wotpy import plain_servient

    servient, wot, http, ws = await plain_servient(n)
    td = build_tactile_td(example_device("flat"))
    td.pop("base")
    for aff in [*td["properties"].values(), *td["events"].values()]:
        aff.pop("forms")
    t0 = time.perf_counter()
    done = 0
    for i in range(n):
        doc = dict(td, title=f"pad-{i}", id=f"urn:plain:pad-{i}")
        wot.produce(ThingFragment(doc)).expose()
        done += 1
        if time.perf_counter() - t0 > budget_s:
            break
    expose_s = time.perf_counter() - t0
    # wotpy's TD route (its catalogue's handler), mounted on its HTTP server's port
    http.app.add_handlers(r".*", [(r"/td/(?P<thing_url_name>[^/]+)", TDHandler, {"servient": servient})])
    c = Client({"kind": "td-get", "n": gets,
                "urls": [f"http://127.0.0.1:{http.port}/td/pad-{i}" for i in range(done)]})
    await c.ready(timeout=300)
    lat = (await c.result(timeout=600))["lat_ns"]
    await servient.shutdown()
    return {"n": n, "exposed": done, "expose_s": expose_s, "get_p50": pct(lat, 50), "get_p99": pct(lat, 99)}


async def run(*, quick: bool) -> dict:
    """N = 10, 100, 500 Things on the hub's servient, 10 on plain wotpy; the report's rows."""
    ms = report.ms
    rows = []
    gets = 200 if quick else 1000
    for n in (10, 100) if quick else (10, 100, 500):
        print(f"expose: {n} ...", flush=True)
        r = await expose_ours(n, gets)
        rows.append(["hub", n, n, f"{r['expose_s']:.2f}", ms(r["get_p50"]), ms(r["get_p99"])])
        print(rows[-1], flush=True)
    for n in (3,) if quick else (10,):
        print(f"expose plain wotpy: {n} ...", flush=True)
        r = await expose_plain(n, 20 if quick else 50, budget_s=60)
        rows.append(["plain wotpy", n, r["exposed"], f"{r['expose_s']:.2f}", ms(r["get_p50"]),
                     ms(r["get_p99"])])
        print(rows[-1], flush=True)
    return {"rows": rows}
