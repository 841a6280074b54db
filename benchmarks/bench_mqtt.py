"""MQTT event path: events/s from one hub to one MQTT subscriber with zero loss, and latency
frame -> MQTT subscriber at 32 devices x 120 Hz (issue 13; targets: >= 10,000/s, p99 <= 10 ms).

    uv run wott-hub bench mqtt [--quick] [--no-write] [--groups throughput,latency] [--devices 32]
                               [--seconds 5] [--runs 3]

A real Mosquitto (Debian's ``mosquitto``) on 127.0.0.1 and a free port, started here. The
subscriber is its own process (paho, one subscription, QoS 0 as the hub publishes
skinDeformedDetection), so it does not share the hub's event loop; stamps on both sides are
``time.perf_counter_ns`` (CLOCK_MONOTONIC, comparable across processes).

1. throughput: one Thing, events published on the hub's event plane at a fixed offered rate
   (paced every millisecond) for a few seconds, then as fast as the plane takes them; each
   payload carries a counter, the subscriber reports which arrived: lost = offered - received.
2. latency: N precomputed-frame drivers at 120 Hz through the hub's real pipeline (processing,
   plane, history on SQLite, MQTT tap); frame in (the hub's trace stamp) -> subscriber's
   on_message. The same drivers as ``bench hub``'s latency group. Measuring starts once the
   publisher is connected and the subscriber has had a message of every device (the queue
   never empties while they stream); frames offered (due from the drivers), processed (their
   events on the plane), received and lost (processed, not at the subscriber) are reported
   next to p50/p99.

After a run the hub tells the subscriber each Thing's last stamp sent; the subscriber stops once
those arrived (per topic in order), after 5 s without a message (the rest is lost) or after 60 s.

Without ``--quick`` or ``--no-write`` the section ``mqtt`` of docs/benchmarks.md is rewritten.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from report import markdown_table, pct, write_section

EVENT = "skinDeformedDetection"

SUBSCRIBER = r"""
import json, sys, threading, time
import paho.mqtt.client as mqtt
spec = json.loads(sys.argv[1])
got = []
now = time.perf_counter_ns
subscribed, flowing = threading.Event(), threading.Event()
seen = set()
def on_connect(c, u, flags, rc, props=None):
    c.subscribe(spec["filter"], qos=0)
def on_subscribe(c, u, mid, rcs, props=None):
    subscribed.set()
def on_message(c, u, m):
    t = now()
    p = m.payload
    thing = m.topic.split("/")[-3]
    # '{"timeStamp":123,...': the stamp without decoding the whole payload
    got.append((thing, int(p[13:p.index(b",", 13)]), t))
    if not flowing.is_set():
        seen.add(thing)
        if len(seen) >= spec["expect"]:
            flowing.set()
c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
c.on_connect, c.on_subscribe, c.on_message = on_connect, on_subscribe, on_message
c.connect(spec["host"], spec["port"])
c.loop_start()
subscribed.wait(30)
print("ready", flush=True)
if spec["expect"]:  # a message of every expected Thing: the whole path is up
    print("flowing" if flowing.wait(60) else f"only {sorted(seen)}", flush=True)
# the hub side says when it is done sending, and the stamp of each Thing's last message it sent
waiting = json.loads(sys.stdin.readline())
deadline, quiet, done = time.monotonic() + 60, time.monotonic() + 5.0, 0
while waiting and time.monotonic() < min(deadline, quiet):  # a busy machine lags: wait for them
    time.sleep(0.05)
    n = len(got)
    for thing, ts, _ in got[done:n]:  # in order per topic: a Thing's last one came after the others
        if ts >= waiting.get(thing, ts + 1):
            del waiting[thing]
    if n > done:
        done, quiet = n, time.monotonic() + 5.0  # silence for 5 s: the rest is lost
c.loop_stop()
print(json.dumps(got), flush=True)
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Mosquitto:
    def __init__(self) -> None:
        binary = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        if not Path(binary).exists():
            raise SystemExit("mosquitto not found: apt-get install mosquitto (.ci/run installs it)")
        self.port = free_port()
        self.dir = Path(tempfile.mkdtemp(prefix="bench-mqtt-"))
        conf = self.dir / "mosquitto.conf"
        conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
                        "set_tcp_nodelay true\n"  # docs/scale-out.md: the broker's own Nagle
                        "max_queued_messages 0\nmax_queued_bytes 0\n")  # a slow subscriber lags, not drops
        self.proc = subprocess.Popen([binary, "-c", str(conf)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        for _ in range(200):
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return
            time.sleep(0.05)
        raise SystemExit("mosquitto did not start")

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(10)
        shutil.rmtree(self.dir, ignore_errors=True)


class Subscriber:
    """The subscriber process: ``ready`` once subscribed, ``flowing`` once a message of each of
    ``expect`` Things came in; told to stop (with each Thing's last stamp sent), what it received."""

    def __init__(self, port: int, topic_filter: str, expect: int = 0) -> None:
        spec = {"host": "127.0.0.1", "port": port, "filter": topic_filter, "expect": expect}
        self.proc = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, json.dumps(spec)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)

    async def expect(self, word: str) -> None:
        line = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), 90)
        if line.strip() != word:
            raise RuntimeError(f"subscriber not {word}: {line}{self.proc.stderr.read()}")

    async def result(self, until: dict[str, int]) -> list[tuple[str, int, int]]:
        self.proc.stdin.write(json.dumps(until) + "\n")
        self.proc.stdin.flush()
        out = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), 120)
        self.proc.wait(30)
        if not out:
            raise RuntimeError(f"the subscriber ended ({self.proc.returncode}) with no result: "
                               f"{self.proc.stderr.read()[-2000:]}")
        return json.loads(out)


def hub_config(broker: Mosquitto, tmp: Path, *, history: bool, immediate: bool = True):
    from wott_hub.config import HubConfig
    from wott_hub.mqtt import MqttConfig

    return HubConfig(id="bench", http_port=0, ws_port=None, history=history, database=str(tmp / "bench.db"),
                     mqtt=MqttConfig(url=broker.url, queue_max=1_000_000, immediate=immediate))


async def _connected(hub) -> None:
    """The publisher's connection is up (its queue may be streaming: the subscriber says when the
    messages flow)."""
    for _ in range(400):
        if hub._mqtt.connected:
            return
        await asyncio.sleep(0.025)
    raise RuntimeError(f"the hub did not connect to the broker: {hub.health().get('mqtt')}")


async def _sent(hub, deadline_s: float = 60.0) -> None:
    """What the hub queued so far is on the socket: (the publisher counts a batch once it is)."""
    target = hub._mqtt.published + len(hub._mqtt.queue)
    end = time.monotonic() + deadline_s
    while hub._mqtt.published < target and hub._mqtt.connected and time.monotonic() < end:
        await asyncio.sleep(0.01)


# --- 1. throughput --------------------------------------------------------------------------------

SOURCE_TD = {"@context": ["https://www.w3.org/2022/wot/td/v1.1"], "title": "source",
             "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc",
             "events": {EVENT: {"data": {"type": "object"}}}}


async def throughput(broker: Mosquitto, tmp: Path, rates: list[int], seconds: float) -> list[list]:
    from bench_hub.common import payload_maker

    from wott_hub.events.record import KIND_EVENT
    from wott_hub.hub import Hub

    make = payload_maker()
    rows = []
    async with Hub(hub_config(broker, tmp, history=False)) as hub:
        await hub.expose_thing("source", SOURCE_TD)
        await _connected(hub)
        plane = hub._plane
        k = 0
        for rate in [*rates, 0]:  # 0: as fast as the plane takes them
            sub = Subscriber(broker.port, f"wott/{hub.hub_id}/source/events/{EVENT}")
            await sub.expect("ready")
            first = k
            t0 = time.perf_counter()
            end = t0 + seconds
            while (now := time.perf_counter()) < end:
                due = int((now - t0) * rate) + first if rate else k + 1000
                while k < due:
                    plane.publish("source", KIND_EVENT, EVENT, k, make(k))
                    k += 1
                await asyncio.sleep(0.001 if rate else 0)
            offered_s = time.perf_counter() - t0
            await _sent(hub)  # what the hub still holds goes out before the subscriber stops
            got = await sub.result({"source": k - 1})
            received = {ts for _, ts, _ in got if first <= ts < k}
            lost = (k - first) - len(received)
            span_s = (got[-1][2] - got[0][2]) / 1e9 if len(got) > 1 else float("nan")
            rows.append(["max" if not rate else f"{rate:,}", f"{(k - first) / offered_s:,.0f}",
                         f"{len(received) / span_s:,.0f}" if span_s == span_s else "-", k - first, lost,
                         hub._mqtt.dropped])
            print(f"throughput offered {rows[-1][0]}/s: sent {k - first}, received {len(received)}, "
                  f"lost {lost}, at the subscriber {rows[-1][2]}/s", flush=True)
    return rows


# --- 2. latency -----------------------------------------------------------------------------------

async def latency(broker: Mosquitto, tmp: Path, n_dev: int, seconds: float, immediate: bool) -> dict:
    from bench_hub.latency import make_driver_class, press_frames

    from wott_hub.examples import example_device
    from wott_hub.hub import Hub, tune_for_hub

    hub = Hub(hub_config(broker, tmp, history=True, immediate=immediate))
    hub._plane.trace = True
    await hub.start()
    tune_for_hub()  # what `wott-hub run` does after start-up
    try:
        base = example_device("flat")
        frames = press_frames(base, 240)
        Driver = make_driver_class()
        stamps: dict[tuple[str, int], int] = {}  # (thing, timeStamp) -> the frame's trace stamp "in"

        class Keep:
            active = True

            def __init__(self, thing: str) -> None:
                self.thing = thing

            def __call__(self, rec) -> None:
                if rec.trace is not None and rec.name == EVENT:
                    stamps[(self.thing, rec.t_ns)] = rec.trace["in"]

        ids = [f"pad-{i}" for i in range(n_dev)]
        for did in ids:
            await hub.add_driver(Driver(replace(base, id=did, title=did), frames, 120.0,
                                        phase_s=random.random() / 120))
            hub._plane.add_tap(did, Keep(did))
        await _connected(hub)
        sub = Subscriber(broker.port, f"wott/{hub.hub_id}/+/events/{EVENT}", expect=n_dev)
        await sub.expect("ready")
        await sub.expect("flowing")
        await asyncio.sleep(1.0)  # warm-up
        pub0, queued0, cpu0 = hub._mqtt.published, len(hub._mqtt.queue), time.process_time()
        t0 = time.perf_counter_ns()
        await asyncio.sleep(seconds)
        t1 = time.perf_counter_ns()
        pub1, queued1, cpu1 = hub._mqtt.published, len(hub._mqtt.queue), time.process_time()
        last: dict[str, int] = {}
        for (thing, ts), t_in in stamps.items():
            if t0 <= t_in < t1:
                last[thing] = max(ts, last.get(thing, ts))
        got = await sub.result(last)
        dropped = hub._mqtt.dropped
    finally:
        await hub.stop()
    window_s = (t1 - t0) / 1e9
    processed = sum(1 for t in stamps.values() if t0 <= t < t1)
    lat = [t_recv - stamps[(thing, ts)] for thing, ts, t_recv in got
           if (thing, ts) in stamps and t0 <= stamps[(thing, ts)] < t1]
    return {"devices": n_dev, "offered": round(n_dev * 120 * window_s), "processed": processed,
            "received": len(lat), "lost": processed - len(lat), "dropped": dropped,
            "published_per_s": (pub1 - pub0) / window_s, "queued": (queued0, queued1),
            "hub_cpu": 100 * (cpu1 - cpu0) / window_s,
            "p50_ms": pct(lat, 50) / 1e6, "p99_ms": pct(lat, 99) / 1e6, "max_ms": max(lat, default=0) / 1e6}


async def main(args: argparse.Namespace) -> None:
    groups = set(args.groups.split(","))
    broker = Mosquitto()
    tmp = Path(tempfile.mkdtemp(prefix="bench-mqtt-hub-"))
    body = []
    load = os.getloadavg()
    try:
        if "throughput" in groups:
            rates = [10_000] if args.quick else [5_000, 10_000, 20_000, 40_000]
            rows = await throughput(broker, tmp, rates, args.seconds)
            body.append("Events/s, one hub -> one MQTT subscriber (QoS 0, one Thing, plane.publish paced "
                        "every ms; `max`: unpaced). Zero loss is the target.\n\n" + markdown_table(
                            ["offered/s", "sent/s", "received/s at the subscriber", "sent", "lost",
                             "dropped by the hub"], rows))
        if "latency" in groups:
            rows = []
            for run in range(1, args.runs + 1):  # the two settings alternated: this machine drifts
                for immediate in (True, False):
                    res = await latency(broker, tmp, args.devices, args.seconds, immediate)
                    print(f"latency {res['devices']} devices x 120 Hz, immediate = {str(immediate).lower()}: "
                          f"frames offered {res['offered']}, processed {res['processed']}; MQTT messages "
                          f"received {res['received']}, lost {res['lost']} (dropped by the hub "
                          f"{res['dropped']}); p50 {res['p50_ms']:.2f} ms, p99 {res['p99_ms']:.2f} ms "
                          f"(target <= 10), max {res['max_ms']:.1f} ms; publisher "
                          f"{res['published_per_s']:,.0f} msg/s, queue {res['queued'][0]} -> "
                          f"{res['queued'][1]}; hub CPU {res['hub_cpu']:.0f} % of a core", flush=True)
                    rows.append([str(immediate).lower(), run, res["offered"], res["processed"],
                                 res["received"], res["lost"], f"{res['p50_ms']:.2f}", f"{res['p99_ms']:.2f}",
                                 f"{res['max_ms']:.1f}", f"{res['published_per_s']:,.0f}",
                                 f"{res['hub_cpu']:.0f}"])
            of = {setting: [r for r in rows if r[0] == setting] for setting in ("true", "false")}
            medians = "; ".join(f"immediate = {k}: p99 {statistics.median(float(r[7]) for r in v):.2f} ms, "
                                f"{statistics.median(r[3] for r in v):,.0f} frames processed"
                                for k, v in of.items())
            body.append(f"Latency frame in -> MQTT subscriber, {args.devices} devices x 120 Hz "
                        f"(history on, SQLite), {args.seconds:g} s a run, `[mqtt] immediate` on and off "
                        "alternated; target p99 ≤ 10 ms. Offered: frames the drivers were due to yield; "
                        "processed: their events on the plane; lost: processed and not at the subscriber "
                        "within 60 s.\n\n" + markdown_table(
                            ["immediate", "run", "frames offered", "processed", "received", "lost", "p50 ms",
                             "p99 ms", "max ms", "MQTT messages/s sent", "hub CPU %"], rows)
                        + f"\n\nMedians of {args.runs}: {medians}.")
    finally:
        broker.stop()
        shutil.rmtree(tmp, ignore_errors=True)
    text = "\n\n".join(body) + f"\n\nLoad average at the start: {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}."
    print(text)
    if not (args.quick or args.no_write):
        print(f"written to {write_section('mqtt', 'MQTT event path', text, 'uv run wott-hub bench mqtt')}")


def parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="wott-hub bench mqtt", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one rate, a short run; docs untouched")
    ap.add_argument("--no-write", action="store_true", help="print only; leave docs/benchmarks.md alone")
    ap.add_argument("--groups", default="throughput,latency", help="comma-separated: throughput,latency")
    ap.add_argument("--devices", type=int, default=32, help="devices at 120 Hz in the latency group")
    ap.add_argument("--seconds", type=float, default=5.0, help="seconds measured per rate, per latency run")
    ap.add_argument("--runs", type=int, default=3, help="latency runs of each `immediate` setting")
    args = ap.parse_args()
    unknown = set(args.groups.split(",")) - {"throughput", "latency"}
    if unknown:
        ap.error(f"unknown group {', '.join(sorted(unknown))} (throughput, latency)")
    if args.devices < 1:
        ap.error("--devices: at least 1")
    if args.runs < 1:
        ap.error("--runs: at least 1")
    if not args.seconds > 0:
        ap.error("--seconds: a positive number")
    return args


if __name__ == "__main__":
    asyncio.run(main(parse_args()))
