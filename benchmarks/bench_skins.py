"""Skins that speak serial and WebSocket (issue 45): every sample read and processed at the target rates,
all at once with the demo fleet, the hub's CPU per sample, and what 1 KiB of garbage mid-stream costs.

    uv run wott-hub bench skins [--seconds 20] [--quick] [--no-write]

A writer process (this file, ``--writer``) plays the boards: an AnySkin at 500 samples/s, a FlexiTac
12 x 32 and a 3D-ViTac 16 x 16 at 100 frames/s, each on its own pty (the plugins' simulated lines:
paced, every frame different), and a simulated ``xela_server`` with 4 uSPa46 at 100 messages/s on
127.0.0.1. The hub runs in this process (``Hub``, SQLite history, recording everything) with the demo
fleet and those devices. The demo runs alone for ``--seconds`` first; then the writer starts sending
(every port open, every XELA position connected) for as long, and halfway through puts 1 KiB of random
bytes on each serial line, once.

Counted per device: sent (frames the line wrote; XELA: messages written to the hub's connection), read
(frames the hub's decoder took; XELA: messages it received), processed (the pipeline's frames: the first
readings make the baseline, 5 AnySkin samples, 30 matrix frames, 10 XELA readings, the last of which is
processed too), lost = sent - read (the frames the garbage hit among them), and duplicates (processed
beyond what was read). CPU: this process's CPU time (``time.process_time``, the hub and little else)
during the skins' phase less the demo's rate of the first, per skin sample processed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from report import markdown_table, write_section

RATES = {"anyskin": 500.0, "flexitac": 100.0, "3dvitac": 100.0}
XELA_RATE, XELA_POSITIONS = 100.0, 4
BASELINE = {"anyskin": 5, "flexitac": 30, "3dvitac": 30, "xela": 10}
GARBAGE = 1024


def writer(folder: Path, seconds: float) -> None:
    """The boards: report the ports and the URL, wait for "go", play, report what was sent."""
    from wott_driver_anyskin.boards import BOARDS
    from wott_driver_anyskin.simulator import AnySkinSimulator
    from wott_driver_taxel.line import SimulatedLine
    from wott_driver_taxel.matrix import MARKER, encode_3dvitac, encode_flexitac
    from wott_driver_taxel.pty_port import PtyPort
    from wott_driver_xela.simulator import ReplayServer, XelaSimulator

    rng = np.random.default_rng(45)

    def matrix(encode, shape):
        def make(k: int) -> bytes:
            v = rng.integers(15, 40, shape)
            if k % 100 < 30:  # a press, 0.3 s of every second
                v[3:6, 4:8] += 150
            return bytes(encode(v))

        return make

    board = AnySkinSimulator(BOARDS["anyskin"], rate_hz=RATES["anyskin"], link=folder / "anyskin")
    lines = {
        "anyskin": board.line,
        "flexitac": SimulatedLine(PtyPort(folder / "flexitac"), 100.0, matrix(encode_flexitac, (12, 32))),
        "3dvitac": SimulatedLine(PtyPort(folder / "3dvitac"), 100.0, matrix(encode_3dvitac, (16, 16))),
    }
    for line in lines.values():
        line.port.open()
    xela = XelaSimulator({p: "uSPa46" for p in range(1, XELA_POSITIONS + 1)})
    server = ReplayServer(xela.message, rate_hz=XELA_RATE, hold=True)
    server.start()
    print(json.dumps({"ports": {k: str(folder / k) for k in lines}, "url": server.url}), flush=True)
    sys.stdin.readline()  # go
    server.release()
    for line in lines.values():
        line.start()
    t0, garbage = time.monotonic(), False
    while (elapsed := time.monotonic() - t0) < seconds:
        board.press(0 if int(elapsed) % 2 else None, 500.0)
        xela.press(1, 8 if int(elapsed) % 2 else None)
        if not garbage and elapsed > seconds / 2:
            for line in lines.values():
                line.write_raw(rng.integers(0, 256, GARBAGE, dtype=np.uint8).tobytes())
            garbage = True
        time.sleep(0.05)
    for line in lines.values():
        line.halt()
    lines["flexitac"].write_raw(MARKER)  # a frame is confirmed by the next one's marker
    time.sleep(0.5)  # the messages in flight
    sent_xela = server.delivered
    server.stop()
    print(
        json.dumps(
            {
                "sent": {k: line.frames_sent for k, line in lines.items()},
                "overrun": {k: line.frames_dropped for k, line in lines.items()},
                "xela": sent_xela,
            }
        ),
        flush=True,
    )
    sys.stdin.readline()  # the hub has read it all
    for line in lines.values():
        line.stop()


def _say(proc: subprocess.Popen[str], word: str) -> None:
    assert proc.stdin is not None
    proc.stdin.write(word + "\n")
    proc.stdin.flush()


async def measure(seconds: float, tmp: Path, cameras: bool = True) -> dict:
    from wott_hub.config import HubConfig
    from wott_hub.hub import Hub
    from wott_hub.network import DiscoveryConfig
    from wott_hub.plugins import DeviceConfig
    from wott_hub.plugins.demo import demo_devices

    proc = subprocess.Popen(
        [sys.executable, __file__, "--writer", str(tmp), str(seconds)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    where = json.loads(proc.stdout.readline())
    ports = where["ports"]
    serial = {
        "anyskin": DeviceConfig("anyskin", "anyskin", {"port": ports["anyskin"], "backoff_cap_s": 0.2}),
        **{
            p: DeviceConfig(p, "taxel-array", {"port": ports[p], "protocol": p, "backoff_cap_s": 0.2})
            for p in ("flexitac", "3dvitac")
        },
    }
    xela = {
        f"xela-{p}": DeviceConfig(
            f"xela-{p}", "xela", {"url": where["url"], "position": p, "model": "uSPa46"}
        )
        for p in range(1, XELA_POSITIONS + 1)
    }
    # without the cameras, the hub is not saturated and the skins' CPU is the difference (--no-cameras)
    demo = [d for d in demo_devices() if cameras or d.family not in ("flat-vision", "barrel-vision")]
    hub = Hub(
        HubConfig(
            http_port=0,
            ws_port=0,
            database=str(tmp / "hub.db"),
            discovery=DiscoveryConfig.off(),
            devices=(*demo, *serial.values(), *xela.values()),
        )
    )
    await hub.start()
    try:
        deadline = time.monotonic() + 30
        while not all(
            s in ("ok", "degraded") for s in (hub.health()["devices"][n]["state"] for n in [*serial, *xela])
        ):
            if time.monotonic() > deadline:
                raise RuntimeError(f"the skins did not connect: {hub.health()['devices']}")
            await asyncio.sleep(0.05)
        cpu0, wall0 = time.process_time(), time.monotonic()
        await asyncio.sleep(seconds)  # the demo alone
        cpu1, wall1 = time.process_time(), time.monotonic()
        demo_frames = {d.id: hub.health()["devices"][d.id]["frames"] for d in demo}
        await asyncio.to_thread(_say, proc, "go")
        report = json.loads(await asyncio.to_thread(proc.stdout.readline))
        cpu2, wall2 = time.process_time(), time.monotonic()
        health, settled = hub.health()["devices"], 0  # the last frames in flight: until none for 0.5 s
        for _ in range(200):
            await asyncio.sleep(0.05)
            now = hub.health()["devices"]
            still = all(now[n]["frames"] == health[n]["frames"] for n in [*serial, *xela])
            settled = settled + 1 if still else 0
            health = now
            if settled == 10:
                break
        out = {
            "report": report,
            "processed": {n: health[n]["frames"] for n in [*serial, *xela]},
            "read": {n: hub.devices[n].pipeline.driver.counters.as_dict() for n in serial},
            "xela_read": hub.devices["xela-1"].pipeline.driver.connection.messages,
            "xela_dropped": [hub.devices[n].pipeline.driver.dropped for n in xela],
            "demo_cpu_s_per_s": (cpu1 - cpu0) / (wall1 - wall0),
            "skins_cpu_s": (cpu2 - cpu1) - (cpu1 - cpu0) / (wall1 - wall0) * (wall2 - wall1),
            "skins_wall_s": wall2 - wall1,
            "demo_frames": sum(health[d.id]["frames"] - demo_frames[d.id] for d in demo),
        }
        await asyncio.to_thread(_say, proc, "done")
    finally:
        await hub.stop()
        proc.wait(30)
    return out


def rows_of(m: dict) -> tuple[list[list[object]], int]:
    """One row per device: rate, sent, read, processed, lost, duplicated, overruns, resyncs, short frames,
    skipped at the start (bytes before the first whole frame)."""
    rows, total = [], 0
    rep = m["report"]
    for name in ("anyskin", "flexitac", "3dvitac"):
        c = m["read"][name]
        sent, read, processed = rep["sent"][name], c["frames"] + c.get("duplicates", 0), m["processed"][name]
        total += processed
        joined = 1 if c["skipped_bytes"] else 0  # the frame the port was opened in, read from its middle
        rows.append([name, f"{RATES[name]:g}/s", sent, read, processed, sent - read - joined, joined,
                     processed - (read - BASELINE[name] + 1), c["dropped"], rep["overrun"][name],
                     c["resyncs"], c.get("short_frames", c.get("truncated"))])
    sent, read = rep["xela"], m["xela_read"]
    for p in range(1, XELA_POSITIONS + 1):
        processed = m["processed"][f"xela-{p}"]
        total += processed
        rows.append([f"xela-{p} (uSPa46)", f"{XELA_RATE:g}/s", sent, read, processed, sent - read, "",
                     processed - (read - BASELINE["xela"] + 1), m["xela_dropped"][p - 1], "", "", ""])
    return rows, total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--quick", action="store_true", help="3 s phases; the page is not written")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--no-cameras", action="store_true",
                    help="the demo without its cameras: the CPU per skin sample (on 2 cores the cameras "
                         "saturate the hub and skip frames when the skins come, which hides their cost)")
    ap.add_argument("--writer", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.writer:
        writer(Path(args.writer[0]), float(args.writer[1]))
        return
    seconds = 3.0 if args.quick else args.seconds
    with tempfile.TemporaryDirectory() as tmp:
        m = asyncio.run(measure(seconds, Path(tmp), cameras=not args.no_cameras))
    rows, processed = rows_of(m)
    header = ["device", "rate", "sent", "read", "processed", "lost to the garbage", "joined mid-frame",
              "duplicated", "dropped (hub behind)", "line overruns", "resyncs", "short frames"]
    table = markdown_table(header, rows)
    per_sample_us = 1e6 * m["skins_cpu_s"] / processed if processed else float("nan")
    body = (
        f"{seconds:g} s of the demo fleet alone, then {seconds:g} s with the skins: {processed} skin samples "
        "processed. 1 KiB of garbage on each serial line halfway through: lost = sent - read - the frame the "
        "port was opened in (3D-ViTac drops the first line after opening: it may be a line's tail).\n\n"
        f"{table}\n\n"
        f"Hub CPU: the demo alone {100 * m['demo_cpu_s_per_s']:.0f} % of a core; the skins on top "
        f"{100 * m['skins_cpu_s'] / m['skins_wall_s']:.0f} % of a core, **{per_sample_us:.0f} µs of CPU per "
        "skin sample** (decoding, baseline, processing, records, SQLite history)."
    )
    print(body)
    if not (args.quick or args.no_write):
        print(
            write_section(
                "skins", "Skins over serial and WebSocket (issue 45)", body, "uv run wott-hub bench skins"
            )
        )


if __name__ == "__main__":
    main()
