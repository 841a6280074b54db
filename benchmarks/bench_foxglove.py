"""Live Foxglove at 8 devices x 120 Hz (issue 30; target: frame in -> message at a Foxglove client
p99 ≤ 10 ms, none lost on the event channels), and what the endpoint costs with no client.

    uv run wott-hub bench foxglove [--devices 8] [--seconds 10] [--runs 3] [--quick] [--no-write]

1. latency: N precomputed-frame drivers at 120 Hz through the hub's real pipeline (processing,
   plane, history on SQLite, the Foxglove endpoint); one client of the protocol in its own process
   (Python ``websockets``, subprotocol ``foxglove.sdk.v1``) subscribed to every device's
   ``skinDeformedDetection`` and ``contactInformation`` channels (the event channels: every record)
   and to their deformation and contact scenes (30 Hz). Frame in (the hub's trace stamp) -> the
   client's receipt of the skin packet (``time.perf_counter_ns``, CLOCK_MONOTONIC on both sides);
   lost = processed in the window and not received. The same drivers as ``bench hub`` and
   ``bench mqtt``.
2. idle: the same hub with no client, ``[foxglove]`` off and on alternated: frames processed and
   the plane's delivery latency (frame in -> a tap) and the hub's CPU, so that an endpoint nobody
   uses is seen to cost nothing.

Without ``--quick`` or ``--no-write`` the section ``foxglove`` of docs/benchmarks.md is rewritten.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from report import markdown_table, pct, write_section

EVENT = "skinDeformedDetection"

CLIENT = r"""
import asyncio, json, struct, sys, time
import websockets
spec = json.loads(sys.argv[1])
now = time.perf_counter_ns
got = []
async def main():
    async with websockets.connect(spec["url"], subprotocols=["foxglove.sdk.v1"], max_size=2**26) as ws:
        chans = {}
        want = set(spec["topics"])
        while not want <= set(chans):
            m = json.loads(await ws.recv())
            if m.get("op") == "advertise":
                chans.update({c["topic"]: c["id"] for c in m["channels"]})
        subs = {i + 1: t for i, t in enumerate(sorted(want))}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i, "channelId": chans[t]} for i, t in subs.items()]}))
        print("ready", flush=True)
        seen, flowing = set(), False
        loop = asyncio.get_running_loop()
        stop = loop.run_in_executor(None, sys.stdin.readline)
        waiting, deadline, quiet = None, None, None
        while True:
            if waiting is None and stop.done():
                waiting = json.loads(stop.result())
                deadline, quiet = time.monotonic() + 60, time.monotonic() + 5
            if waiting is not None and (not waiting or time.monotonic() > min(deadline, quiet)):
                break
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.2)
            except asyncio.TimeoutError:
                continue
            if not isinstance(frame, bytes) or frame[0] != 1:
                continue
            t = now()
            topic = subs[struct.unpack_from("<I", frame, 1)[0]]
            if not topic.endswith("/events/skinDeformedDetection"):
                continue
            thing = topic.split("/")[1]
            p = frame[13:]
            ts = int(p[13:p.index(b",", 13)])  # '{"timeStamp":123,...'
            got.append((thing, ts, t))
            if not flowing:
                seen.add(thing)
                if len(seen) >= spec["expect"]:
                    flowing = True
                    print("flowing", flush=True)
            if waiting is not None:
                quiet = time.monotonic() + 5
                if ts >= waiting.get(thing, ts + 1):
                    del waiting[thing]
asyncio.run(main())
print(json.dumps(got), flush=True)
"""


def relay_cpu_s(live) -> float:
    """The CPU seconds of the hub's Foxglove relay process (``robotics/relay.py``: the SDK's server and
    its per-client fan-out), counted in the hub's CPU beside ``time.process_time()``."""
    if live is None or live.relay is None:
        return 0.0
    fields = Path(f"/proc/{live.relay.pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Client:
    def __init__(self, url: str, topics: list[str], expect: int) -> None:
        spec = {"url": url, "topics": topics, "expect": expect}
        self.proc = subprocess.Popen([sys.executable, "-c", CLIENT, json.dumps(spec)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    async def expect(self, word: str) -> None:
        line = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), 90)
        if line.strip() != word:
            raise RuntimeError(f"client not {word}: {line}{self.proc.stderr.read()[-2000:]}")

    async def result(self, until: dict[str, int]) -> list[tuple[str, int, int]]:
        self.proc.stdin.write(json.dumps(until) + "\n")
        self.proc.stdin.flush()
        out = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), 120)
        self.proc.wait(30)
        if not out:
            raise RuntimeError(f"the client ended with no result: {self.proc.stderr.read()[-2000:]}")
        return json.loads(out)


def hub_config(tmp: Path, *, foxglove: bool):
    from wott_hub.config import HubConfig
    from wott_hub.robotics.config import FoxgloveConfig

    return HubConfig(id="bench", http_port=0, ws_port=None, history=True, database=str(tmp / "bench.db"),
                     foxglove=FoxgloveConfig(port=0 if foxglove else None, backlog=100_000))


async def _fleet(hub, n_dev: int, stamps: dict, delivered: dict | None = None):
    """``n_dev`` precomputed 120 Hz drivers; a tap keeping each skin record's frame-in stamp (and, with
    ``delivered``, the stamp of its delivery to taps)."""
    from bench_hub.latency import make_driver_class, press_frames

    from wott_hub.examples import example_device

    base = example_device("flat")
    frames = press_frames(base, 240)
    Driver = make_driver_class()

    class Keep:
        active = True

        def __init__(self, thing: str) -> None:
            self.thing = thing

        def __call__(self, rec) -> None:
            if rec.trace is not None and rec.name == EVENT:
                stamps[(self.thing, rec.t_ns)] = rec.trace["in"]
                if delivered is not None:
                    delivered[(self.thing, rec.t_ns)] = time.perf_counter_ns()

    ids = [f"pad-{i}" for i in range(n_dev)]
    for did in ids:
        desc = replace(base, id=did, title=did)
        await hub.add_driver(Driver(desc, frames, 120.0, phase_s=random.random() / 120))
        hub._plane.add_tap(did, Keep(did))
    return ids


async def latency(tmp: Path, n_dev: int, seconds: float) -> dict:
    from wott_hub.hub import Hub, tune_for_hub

    hub = Hub(hub_config(tmp, foxglove=True))
    hub._plane.trace = True
    await hub.start()
    tune_for_hub()  # what `wott-hub run` does after start-up
    try:
        stamps: dict[tuple[str, int], int] = {}
        ids = await _fleet(hub, n_dev, stamps)
        topics = [f"/{d}/{kind}" for d in ids for kind in (
            f"events/{EVENT}", "properties/contactInformation", "scene/deformation", "scene/contacts")]
        client = Client(hub.describe()["foxglove"], topics, n_dev)
        await client.expect("ready")
        await client.expect("flowing")
        await asyncio.sleep(1.0)  # warm-up
        live = hub._foxglove
        sent0, cpu0 = live.sent, time.process_time() + relay_cpu_s(live)
        t0 = time.perf_counter_ns()
        await asyncio.sleep(seconds)
        t1 = time.perf_counter_ns()
        sent1, cpu1 = live.sent, time.process_time() + relay_cpu_s(live)
        last: dict[str, int] = {}
        for (thing, ts), t_in in list(stamps.items()):
            if t0 <= t_in < t1:
                last[thing] = max(ts, last.get(thing, ts))
        got = await client.result(last)
        errors = live.errors
    finally:
        await hub.stop()
    window_s = (t1 - t0) / 1e9
    processed = sum(1 for t in stamps.values() if t0 <= t < t1)
    lat = [t_recv - stamps[(thing, ts)] for thing, ts, t_recv in got
           if (thing, ts) in stamps and t0 <= stamps[(thing, ts)] < t1]
    return {"offered": round(n_dev * 120 * window_s), "processed": processed, "received": len(lat),
            "lost": processed - len(lat), "sent_per_s": (sent1 - sent0) / window_s, "errors": errors,
            "hub_cpu": 100 * (cpu1 - cpu0) / window_s, "p50_ms": pct(lat, 50) / 1e6,
            "p99_ms": pct(lat, 99) / 1e6, "max_ms": max(lat, default=0) / 1e6}


async def idle(tmp: Path, n_dev: int, seconds: float, foxglove: bool) -> dict:
    from wott_hub.hub import Hub, tune_for_hub

    hub = Hub(hub_config(tmp, foxglove=foxglove))
    hub._plane.trace = True
    await hub.start()
    tune_for_hub()
    try:
        stamps: dict[tuple[str, int], int] = {}
        delivered: dict[tuple[str, int], int] = {}
        await _fleet(hub, n_dev, stamps, delivered)
        await asyncio.sleep(1.0)
        cpu0, t0 = time.process_time() + relay_cpu_s(hub._foxglove), time.perf_counter_ns()
        await asyncio.sleep(seconds)
        cpu1, t1 = time.process_time() + relay_cpu_s(hub._foxglove), time.perf_counter_ns()
    finally:
        await hub.stop()
    window_s = (t1 - t0) / 1e9
    lat = [delivered[k] - t for k, t in stamps.items() if t0 <= t < t1 and k in delivered]
    return {"processed_per_s": len(lat) / window_s, "p50_ms": pct(lat, 50) / 1e6,
            "p99_ms": pct(lat, 99) / 1e6, "hub_cpu": 100 * (cpu1 - cpu0) / window_s}


async def main(args: argparse.Namespace) -> None:
    tmp = Path(tempfile.mkdtemp(prefix="bench-foxglove-"))
    load = os.getloadavg()
    body = []
    try:
        rows = []
        for run in range(1, args.runs + 1):
            res = await latency(tmp / f"l{run}", args.devices, args.seconds)
            print(f"latency run {run}: {res}", flush=True)
            rows.append([run, res["offered"], res["processed"], res["received"], res["lost"],
                         f"{res['p50_ms']:.2f}", f"{res['p99_ms']:.2f}", f"{res['max_ms']:.1f}",
                         f"{res['sent_per_s']:,.0f}", f"{res['hub_cpu']:.0f}", res["errors"]])
        p99 = statistics.median(float(r[6]) for r in rows)
        body.append(
            f"Frame in -> Foxglove client, {args.devices} devices x 120 Hz (history on, SQLite), "
            f"{args.seconds:g} s a run; the client subscribed to every device's skinDeformedDetection and "
            "contactInformation channels and its deformation and contact scenes. Target: p99 ≤ 10 ms, "
            "none lost on the event channels. Lost: skin packets processed in the window and not at the "
            "client.\n\n"
            + markdown_table(["run", "frames offered", "processed", "received", "lost", "p50 ms", "p99 ms",
                              "max ms", "messages/s sent", "hub CPU %", "mapping errors"], rows)
            + f"\n\nMedian p99 of {args.runs}: {p99:.2f} ms.")
        rows = []
        for run in range(1, args.runs + 1):
            for on in (False, True):  # alternated: this machine drifts
                res = await idle(tmp / f"i{run}{int(on)}", args.devices, args.seconds, on)
                print(f"idle run {run}, foxglove {'on' if on else 'off'}: {res}", flush=True)
                rows.append(["on" if on else "off", run, f"{res['processed_per_s']:,.0f}",
                             f"{res['p50_ms']:.2f}", f"{res['p99_ms']:.2f}", f"{res['hub_cpu']:.0f}"])
        med = {k: statistics.median(float(r[4]) for r in rows if r[0] == k) for k in ("off", "on")}
        body.append(
            f"No client connected, {args.devices} devices x 120 Hz, `[foxglove]` off and on alternated: "
            "frames processed, frame in -> the plane's taps (delivery), hub CPU.\n\n"
            + markdown_table(["[foxglove]", "run", "frames/s processed", "p50 ms", "p99 ms", "hub CPU %"],
                             rows)
            + f"\n\nMedian p99: off {med['off']:.2f} ms, on {med['on']:.2f} ms.")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    text = "\n\n".join(body) + f"\n\nLoad average at the start: {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}."
    print(text)
    if not (args.quick or args.no_write):
        cmd = "uv run wott-hub bench foxglove"
        print(f"written to {write_section('foxglove', 'Live Foxglove (issue 30)', text, cmd)}")


def parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="wott-hub bench foxglove", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one short run; docs untouched")
    ap.add_argument("--no-write", action="store_true", help="print only; leave docs/benchmarks.md alone")
    ap.add_argument("--devices", type=int, default=8, help="devices at 120 Hz")
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds measured per run")
    ap.add_argument("--runs", type=int, default=3, help="runs of each measurement")
    args = ap.parse_args()
    if args.quick:
        args.runs, args.seconds = 1, min(args.seconds, 3.0)
    if args.devices < 1 or args.runs < 1 or not args.seconds > 0:
        ap.error("--devices and --runs at least 1, --seconds positive")
    return args


if __name__ == "__main__":
    asyncio.run(main(parse_args()))
