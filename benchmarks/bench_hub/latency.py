"""Latency group: a frame enters the pipeline -> its skinDeformedDetection event at a client.

120 Hz per device, every frame deformed; each client (SSE, hub WebSocket, wotpy) in its own
process, one at a time; stages from the hub's trace stamps. Plain wotpy:
``ExposedThing.emit_event`` -> wotpy client. ``--devices N`` measures one point alone;
``--workers W[,W...]`` chooses the worker counts of the variant rows (the issue's 64-device point
is to be stated with whichever of ``workers = 0`` and ``workers = W`` does best).
"""

from __future__ import annotations

import asyncio
import json
import random
import statistics
import tempfile
import time
from pathlib import Path

from report import pct  # benchmarks/report.py (this package's report is `from . import report`)

from . import report
from .clients import Client
from .common import cpu_s, descendants, now_ns, payload

__all__ = ["DEFAULT_DEVICES", "DEFAULT_WORKERS", "QUICK_DEVICES", "REPEATED", "latency_ours", "latency_plain",
           "run"]

DEFAULT_DEVICES = (1, 8, 32, 64)
QUICK_DEVICES = (1, 8)
REPEATED = (32, 64)  # the targets' points: repeated, the median run shown (this machine is noisy)
DEFAULT_WORKERS = (1, 2)  # worker counts of the variant rows (workers = 0 is the main row)


def press_frames(desc, n: int):
    """A contact circling on the skin: every frame deformed, the contact moving (worst case)."""
    import numpy as np

    from wott_hub.tactile.indentation import Indenter, indent

    mesh = desc.mesh
    free = mesh.free_indices
    centre = mesh.nodes[free].mean(axis=0)
    span = float(np.ptp(mesh.nodes[free], axis=0).max())
    out = []
    for k in range(n):
        a = 2 * np.pi * k / n
        p = centre + 0.2 * span * np.array([np.cos(a), np.sin(a), 0.0])
        near = free[np.argmin(((mesh.nodes[free] - p) ** 2).sum(axis=1))]
        out.append(indent(mesh, [Indenter(mesh.nodes[near], 1.0, max(span / 10, 3.0))]))
    return out


def _lookup_processor(processor, frames):
    """A stand-in for ``processor.process`` returning results computed in advance (same payloads)."""
    from dataclasses import replace

    from wott_hub.tactile import TactileFrame

    results = [processor.process(TactileFrame(10**9 + i, f)) for i, f in enumerate(frames)]
    by_id = {id(f): r for f, r in zip(frames, results, strict=True)}

    def process(frame):
        return replace(by_id[id(frame.displacement)] if id(frame.displacement) in by_id else results[0],
                       t_ns=frame.t_ns)

    return process


def cpu_cell(r: dict) -> str:
    """Hub process / client process CPU in the SSE and the WS phase, % of one core."""
    return " · ".join(f"{kind}: {r['cpu'][key][0]:.0f} / {r['cpu'][key][1]:.0f}"
                      for kind, key in (("SSE", "sse-lean"), ("WS", "ws-lat")) if key in r["cpu"])


def cpu_per_frame(r: dict) -> float:
    """The hub's CPU per frame processed, µs: its process, its history process and its workers in the
    SSE phase over the frames processed in that window (issue 35's figure, the simulated devices' own
    work included: ``devices_own``)."""
    return 1e4 * r["cpu"]["sse-lean"][0] / max(1.0, r["sse"][0] / r["duration"])


def own_per_frame(r: dict) -> float:
    """``cpu_per_frame`` less what the benchmark's devices cost by themselves (``devices_own``, NaN
    with workers): the hub's own CPU per frame."""
    return cpu_per_frame(r) - r.get("devices_us", float("nan"))


def per_frame_cell(r: dict) -> str:
    return f"{cpu_per_frame(r):.0f} · {own_per_frame(r):.0f}"


_DEVICES_OWN: dict[int, float] = {}


async def devices_own(n_dev: int, seconds: float = 3.0) -> float:
    """The benchmark's simulated devices' own CPU per frame, µs: ``n_dev`` of its drivers at 120 Hz
    (``make_driver_class``: a timer each, a ``TactileFrame`` per frame), in this process's event loop
    with nothing but a counter taking their frames. A hub's own devices cost what their I/O costs (a
    camera read, a serial port); these cost their timers, which are not the hub's work (issue 35:
    "the simulated devices' own cost separated from the hub's"). Measured once per device count and
    process, before the hub starts; it includes the loop's wake-ups for the timers, which a hub
    shares with its own work, so the difference slightly understates the hub's own CPU."""
    if n_dev in _DEVICES_OWN:
        return _DEVICES_OWN[n_dev]
    from ._hub_internals import example_device

    base = example_device("flat")
    frames = press_frames(base, 240)
    driver_class = make_driver_class()
    drivers = [driver_class(base, frames, 120.0, random.random() / 120) for _ in range(n_dev)]
    count = 0

    async def take(driver) -> None:
        nonlocal count
        async for _ in driver.frames():
            count += 1

    tasks = [asyncio.create_task(take(d)) for d in drivers]
    await asyncio.sleep(0.5)  # warm-up
    cpu0, n0 = time.process_time(), count
    await asyncio.sleep(seconds)
    cpu1, n1 = time.process_time(), count
    for d in drivers:
        await d.close()
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    own = _DEVICES_OWN[n_dev] = 1e6 * (cpu1 - cpu0) / max(1, n1 - n0)
    return own


_HUB_CHILDREN = (b"wott_hub.history.batch_process", b"multiprocessing.spawn")
"""The hub's own child processes: its history process and its worker processes (not the clients)."""


def children_cpu_s() -> float:
    """CPU seconds of this process's history writer process (``history/batch_process.py``) and of its
    worker processes (``runtime/pool.py``): part of the hub's CPU, though not in its own process."""
    import os

    total = 0.0
    for pid in descendants(os.getpid()):
        try:
            if any(mark in Path(f"/proc/{pid}/cmdline").read_bytes() for mark in _HUB_CHILDREN):
                total += cpu_s(pid)
        except FileNotFoundError:  # a process that has just exited
            pass
    return total


def make_driver_class():
    from wott_hub.tactile import TactileFrame

    from ._hub_internals import Driver

    class PrecomputedDriver(Driver):
        """Yields precomputed frames at a fixed rate on the clock (the device side costs nothing)."""

        def __init__(self, desc, frames, rate_hz: float, phase_s: float) -> None:
            super().__init__(desc)
            self._frames = frames
            self.rate_hz = rate_hz
            self.phase_s = phase_s
            self._closed = False

        async def frames(self):
            period = 1 / self.rate_hz
            t0 = time.monotonic() + self.phase_s
            wall0 = time.time_ns()
            k = 0
            while not self._closed:
                due = t0 + k * period
                delay = due - time.monotonic()
                if delay > 0:
                    await asyncio.sleep(delay)
                elif delay < -period:  # behind (a camera drops frames): skip, let the loop run
                    k += int(-delay / period)
                    await asyncio.sleep(0)
                    continue
                yield TactileFrame(wall0 + int(k * period * 1e9), self._frames[k % len(self._frames)])
                k += 1

        async def close(self) -> None:
            self._closed = True

    return PrecomputedDriver


def scene_configs(n: int) -> list:
    """``scene``-family devices (opened by the plugin registry, in a worker when workers > 0):
    a contact sliding back and forth on a 16x16 pad, every frame deformed."""
    from ._hub_internals import DeviceConfig, example_device

    mesh = example_device("flat").mesh
    free = mesh.free_indices
    a = [float(v) for v in mesh.nodes[free[len(free) // 2 - 40]]]
    b = [float(v) for v in mesh.nodes[free[len(free) // 2 + 40]]]
    steps = [{"kind": "slide", "at": a, "to": b, "start_s": 0.0, "duration_s": 1.0, "depth_mm": 1.0,
              "radius_mm": 4.0, "ramp_s": 0.0},
             {"kind": "slide", "at": b, "to": a, "start_s": 1.0, "duration_s": 1.0, "depth_mm": 1.0,
              "radius_mm": 4.0, "ramp_s": 0.0}]
    return [DeviceConfig(f"pad-{i}", "scene", {"shape": "flat", "loop": True, "rate_hz": 120.0,
                                               "step": steps}) for i in range(n)]


async def latency_ours(n_dev: int, duration: float, tmp: Path, with_wotpy: bool = True,
                       workers: int = 0, precomputed: bool = False, durability: str = "fast",
                       worker_nice: int | None = None, history_process: bool = True,
                       displacement: bool = False) -> dict:
    """``precomputed``: each device's FrameProcessor is replaced by a lookup of results computed
    beforehand, to measure the hub's own path (plane, history, fan-out, sockets) alone.
    ``displacement``: one more subscriber per device, to ``skinDisplacement`` (SSE, its JSON text),
    through all the phases (a client process that reads and drops the bytes): the cost of the
    vectors for a hub whose every device has a reader of them (issue 29)."""
    from dataclasses import replace

    from wott_hub.config import HubConfig
    from wott_hub.hub import Hub, tune_for_hub

    from ._hub_internals import example_device, hub_plane, replace_processing

    devices = tuple(scene_configs(n_dev)) if workers else ()
    devices_us = float("nan") if workers else await devices_own(n_dev)
    hub = Hub(HubConfig(http_port=0, ws_port=0, database=str(tmp / f"lat{n_dev}-{workers}.db"),
                        workers=workers, devices=devices, history_durability=durability,
                        history_process=history_process,
                        **({} if worker_nice is None else {"worker_nice": worker_nice})))
    plane = hub_plane(hub)
    plane.trace = True
    await hub.start()
    tune_for_hub()  # what `wott-hub run` does after start-up
    base = example_device("flat")
    frames = press_frames(base, 240)
    Driver = make_driver_class()
    traces: dict[tuple[str, int], dict] = {}
    by_ts: dict[tuple[str, int], dict] = {}

    class Keep:
        active = True

        def __init__(self, thing):
            self.thing = thing

        def __call__(self, rec):
            if rec.trace is not None:
                traces[(self.thing, rec.seq)] = rec.trace
                by_ts[(self.thing, rec.t_ns)] = rec.trace

    ids = [f"pad-{i}" for i in range(n_dev)]
    for did in ids:
        if not workers:
            desc = replace(base, id=did, title=did)
            dev = await hub.add_driver(Driver(desc, frames, 120.0, phase_s=random.random() / 120))
            if precomputed:
                replace_processing(dev, _lookup_processor(dev.processor, frames))
        plane.add_tap(did, Keep(did))

    cpu: dict[str, tuple[float, float]] = {}  # client kind -> (hub, client) CPU, % of one core
    drain = None
    if displacement:  # subscribed before the phases, for all of them
        phases = 2 + bool(with_wotpy)
        drain = Client({"kind": "drain", "duration": phases * (duration + 2.0) + 2.0,
                        "urls": [f"{hub.td_url(d)}/events/skinDisplacement" for d in ids]})
        await drain.ready()

    async def phase(spec: dict) -> tuple[dict, int, int]:
        """One client at a time: the wotpy client alone can saturate a core of this machine."""
        c = Client({**spec, "duration": duration + 1.0})
        await c.ready()
        await asyncio.sleep(0.5)  # warm-up
        t0, cpu0 = now_ns(), time.process_time() + children_cpu_s()
        await asyncio.sleep(duration)
        t1, cpu1 = now_ns(), time.process_time() + children_cpu_s()
        res = await c.result()
        cpu[spec["kind"]] = (100 * (cpu1 - cpu0) / ((t1 - t0) / 1e9),
                             100 * res.get("cpu_s", float("nan")) / res.get("window_s", float("nan")))
        return res, t0, t1

    sse_res, s0, s1 = await phase({"kind": "sse-lean",
                                   "urls": [f"{hub.td_url(d)}/events/skinDeformedDetection" for d in ids]})
    raw_res, r0, r1 = await phase({"kind": "ws-lat", "event": "skinDeformedDetection",
                                   "urls": [f"{hub.ws_url}/{d}" for d in ids]})
    if with_wotpy:
        wot_res, w0, w1 = await phase({"kind": "wotpy", "event": "skinDeformedDetection",
                                       "urls": [hub.td_url(d) for d in ids]})
    else:  # the wotpy client cannot keep up with 8 devices already (its per-message validation)
        wot_res, w0, w1 = {"events": []}, 0, 0
    if drain is not None:
        drain.proc.kill()  # its window outlasts the phases: enough measured
        drain.proc.wait(30)
    await hub.stop()

    def window(t0, t1):
        return sum(1 for tr in traces.values() if t0 <= tr["in"] < t1)

    stages = {k: [] for k in ("processing", "encoding", "fanout", "transport", "decode")}
    sse_total = []
    for i, seq, t_recv, t_dec, _ts in sse_res["events"]:
        tr = traces.get((ids[i], seq))
        if tr is None or not s0 <= tr["in"] < s1 or "sse" not in tr:
            continue
        stages["processing"].append(tr["proc"] - tr["in"])
        stages["encoding"].append(tr["enc"] - tr["proc"])
        stages["fanout"].append(tr["sse"] - tr["enc"])
        stages["transport"].append(t_recv - tr["sse"])
        stages["decode"].append(t_dec - t_recv)
        sse_total.append(t_dec - tr["in"])
    raw_total, raw_fanout, raw_transport = [], [], []
    for i, ts, t_recv, t_dec in raw_res["events"]:
        tr = by_ts.get((ids[i], ts))
        if tr is None or not r0 <= tr["in"] < r1 or "ws" not in tr:
            continue
        raw_total.append(t_dec - tr["in"])
        raw_fanout.append(tr["ws"] - tr["enc"])
        raw_transport.append(t_recv - tr["ws"])
    wot_total, wot_after = [], []
    for i, ts, t_recv in wot_res["events"]:
        tr = by_ts.get((ids[i], ts))
        if tr is None or not w0 <= tr["in"] < w1 or "ws" not in tr:
            continue
        wot_total.append(t_recv - tr["in"])
        wot_after.append(t_recv - tr["ws"])
    return {"devices": n_dev,
            "sse": (window(s0, s1), len(sse_total), pct(sse_total, 50), pct(sse_total, 99)),
            "ws": (window(r0, r1), len(raw_total), pct(raw_total, 50), pct(raw_total, 99)),
            "wotpy": (window(w0, w1), len(wot_total), pct(wot_total, 50), pct(wot_total, 99)),
            "stages": {k: (pct(v, 50), pct(v, 99)) for k, v in stages.items()},
            "ws_stages": {"fanout": (pct(raw_fanout, 50), pct(raw_fanout, 99)),
                          "transport": (pct(raw_transport, 50), pct(raw_transport, 99))},
            "wotpy_after_write": (pct(wot_after, 50), pct(wot_after, 99)),
            "wotpy_decode": wot_res.get("decode_ns", float("nan")), "cpu": cpu, "duration": duration,
            "devices_us": devices_us}


async def latency_plain(n_dev: int, duration: float) -> dict:
    from wotpy.wot.dictionaries.thing import ThingFragment
    from wotpy.wot.td import ThingDescription

    from ._hub_internals import clean_td
    from .plain_wotpy import plain_servient, plain_td

    servient, wot, http, ws = await plain_servient(n_dev)
    things = []
    for i in range(n_dev):
        e = wot.produce(ThingFragment(plain_td(f"plain-{i}", http.port)))
        e.expose()
        things.append(e)
    # the wotpy client fetches TDs: serve them from files (wotpy has no TD route on its HTTP server)
    tmp = Path(tempfile.mkdtemp())
    urls = []
    for e in things:
        doc = clean_td(ThingDescription.from_thing(e.thing).to_dict())
        (tmp / f"{e.title}.json").write_text(json.dumps(doc))
        urls.append(f"file://{tmp / (e.title + '.json')}")
    import http.server
    import threading

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *a):
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0),
                                          lambda *a, **k: Quiet(*a, directory=str(tmp), **k))
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    urls = [f"http://127.0.0.1:{srv.server_address[1]}/{e.title}.json" for e in things]
    wsc = Client({"kind": "wotpy", "duration": duration + 2.0, "event": "skinDeformedDetection",
                  "urls": urls})
    await wsc.ready()
    emitted: dict[tuple[int, int], int] = {}
    stop = False

    async def emitter(i, e):
        period = 1 / 120
        t0 = time.monotonic() + random.random() * period
        k = 0
        while not stop:
            delay = t0 + k * period - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
            stamp = i * 10**9 + k
            emitted[(i, stamp)] = now_ns()
            try:
                e.emit_event("skinDeformedDetection", payload(20, stamp))
            except Exception:  # wotpy raises into the emitter when its subscriber has gone
                return
            k += 1

    tasks = [asyncio.create_task(emitter(i, e)) for i, e in enumerate(things)]
    await asyncio.sleep(0.5)
    t_start = now_ns()
    await asyncio.sleep(duration)
    t_end = now_ns()
    stop = True
    await asyncio.gather(*tasks)
    res = await wsc.result()
    srv.shutdown()
    await servient.shutdown()
    lat = [t - emitted[(i, ts)] for i, ts, t in res["events"]
           if (i, ts) in emitted and t_start <= emitted[(i, ts)] < t_end]
    sent = sum(1 for t in emitted.values() if t_start <= t < t_end)
    return {"devices": n_dev, "published": sent, "ws_received": len(lat), "ws_p50": pct(lat, 50),
            "ws_p99": pct(lat, 99)}


async def displacement_ab(n: int, dur: float, tmp: Path, pairs: int = 3) -> list:
    """Issue 29's cost rule at ``n`` devices: ``pairs`` alternated runs without and with one
    ``skinDisplacement`` subscriber per device; the row of medians (frames/s processed, SSE p99)
    and the drop in frames processed."""
    fps: dict[bool, list[float]] = {False: [], True: []}
    p99: dict[bool, list[float]] = {False: [], True: []}
    cpu: dict[bool, list[float]] = {False: [], True: []}  # hub CPU per frame processed, µs
    for k in range(pairs):
        for sub in (False, True):
            print(f"latency: {n} devices, skinDisplacement subscribers {sub}, pair {k + 1} ...", flush=True)
            r = await latency_ours(n, dur, tmp, with_wotpy=False, displacement=sub)
            fps[sub].append(r["sse"][0] / dur)
            p99[sub].append(r["sse"][3])
            cpu[sub].append(cpu_per_frame(r))
    med = statistics.median
    drop = 100 * (1 - med(fps[True]) / med(fps[False]))
    more = 100 * (med(cpu[True]) / med(cpu[False]) - 1)
    return [n, " · ".join(f"{x:.0f}" for x in fps[False]), " · ".join(f"{x:.0f}" for x in fps[True]),
            f"{med(fps[False]):.0f} → {med(fps[True]):.0f} ({drop:+.1f} % fewer)" if drop >= 0 else
            f"{med(fps[False]):.0f} → {med(fps[True]):.0f} ({-drop:.1f} % more)",
            f"{med(cpu[False]):.0f} → {med(cpu[True]):.0f} ({more:+.0f} %)",
            f"{report.ms(med(p99[False]))} → {report.ms(med(p99[True]))}"]


async def run(tmp: Path, *, quick: bool, devices: tuple[int, ...] | None = None,
              duration: float | None = None, workers: tuple[int, ...] | None = None,
              ab: bool = False) -> dict:
    """Every point of ``devices`` (default 1, 8, 32, 64; 1, 8 when quick); the report's rows.
    Points from 8 devices on also run once per count of ``workers`` (default 1 and 2), the
    most workers once more with ``worker_nice = 0`` (at the hub's CPU priority), with the
    processing precomputed, with ``history_durability = "committed"`` (its latency cost:
    a subscriber gets a record only once its batch is in history, docs/reliability.md), and with
    ``history_process = false`` (batches written by the writer's thread, docs/history.md)."""
    dur = duration if duration is not None else (2.0 if quick else 6.0)
    points = devices or (QUICK_DEVICES if quick else DEFAULT_DEVICES)
    rows, stage_rows, variant_rows, repeats, ab_rows = [], [], [], [], []
    cell, ms = report.cell, report.ms
    for n in points:
        print(f"latency: {n} devices ...", flush=True)
        r = await latency_ours(n, dur, tmp, with_wotpy=n <= 8)
        if n in REPEATED:
            runs = [r] + [await latency_ours(n, dur, tmp, with_wotpy=False) for _ in range(2)]
            runs.sort(key=lambda x: x["sse"][3])
            r = runs[1]
            repeats.append((n, [x["sse"][3] for x in runs], [x["ws"][3] for x in runs],
                            [x["sse"][0] / dur for x in runs], [cpu_per_frame(x) for x in runs],
                            [own_per_frame(x) for x in runs]))
        # plain wotpy saturates at 8 devices already (and exposing 32 there is O(N^3))
        p = await latency_plain(n, dur) if n <= 8 else None
        rows.append([n, f"{r['sse'][0] / dur:.0f} / {n * 120}", cell(r["sse"]), cell(r["ws"]),
                     cell(r["wotpy"]) if n <= 8 else "not run (saturated at 8)",
                     cell((p["published"], p["ws_received"], p["ws_p50"], p["ws_p99"])) if p
                     else "not run (saturated at 8)", cpu_cell(r), per_frame_cell(r)])
        if n >= 8 and not quick or n == 8:
            counts = workers or DEFAULT_WORKERS
            variants = [(f"workers = {w}", {"workers": w}) for w in counts]
            # the most workers again at the hub's own CPU priority: what [hub] worker_nice buys
            variants.append((f"workers = {max(counts)}, worker_nice = 0", {"workers": max(counts),
                                                                          "worker_nice": 0}))
            for label, kw in (*variants, ("processing precomputed", {"precomputed": True}),
                              ("history_durability = committed", {"durability": "committed"}),
                              ("history_process = false", {"history_process": False}),
                              ("1 skinDisplacement subscriber per device", {"displacement": True})):
                print(f"latency: {n} devices, {label} ...", flush=True)
                w = await latency_ours(n, dur, tmp, with_wotpy=False, **kw)
                variant_rows.append([n, label, f"{w['sse'][0] / dur:.0f} / {n * 120}", cell(w["sse"]),
                                     cell(w["ws"]),
                                     *(f"{ms(a)} / {ms(b)}" for a, b in (
                                         w["stages"]["processing"], w["stages"]["fanout"],
                                         w["stages"]["transport"])), cpu_cell(w), per_frame_cell(w)])
                print(variant_rows[-1], flush=True)
        if ab:
            ab_rows.append(await displacement_ab(n, dur, tmp))
            print(ab_rows[-1], flush=True)
        st, ws = r["stages"], r["ws_stages"]
        stage_rows.append([n, *(f"{ms(a)} / {ms(b)}" for a, b in (
            st["processing"], st["encoding"], st["fanout"], st["transport"], st["decode"],
            ws["fanout"], ws["transport"], r["wotpy_after_write"])), ms(r["wotpy_decode"])])
        print(rows[-1], stage_rows[-1], flush=True)
    return {"duration": dur, "rows": rows, "stage_rows": stage_rows, "variant_rows": variant_rows,
            "repeats": repeats, "ab_rows": ab_rows}
