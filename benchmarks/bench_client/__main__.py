"""``wott-hub bench client [--quick] [--no-write] [--rate R] [--seconds S] [--devices N] [--hz F]``."""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from report import markdown_table, pct, write_section

from .decode import decode_rates
from .hubside import BenchHub

CLIENTS = ("wott-client", "wotpy ConsumedThing")
_KIND = {"wott-client": "ours", "wotpy ConsumedThing": "wotpy"}
_BENCHMARKS = Path(__file__).resolve().parent.parent


class ClientProcess:
    """One client in its own process (``clients.py`` states the protocol)."""

    def __init__(self, kind: str, urls: list[str], idle_s: float, drain_s: float) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_BENCHMARKS), env.get("PYTHONPATH")) if p)
        spec = json.dumps({"kind": kind, "urls": urls, "idle_s": idle_s, "drain_s": drain_s})
        self.proc = subprocess.Popen([sys.executable, "-m", "bench_client.clients", spec],
                                     stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

    async def ready(self, timeout: float = 120) -> None:
        line = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), timeout)
        if line.strip() != "ready":
            raise RuntimeError(f"client failed: {line}{self.proc.stderr.read()}")

    async def result(self, published: int, timeout: float = 300) -> dict:
        self.proc.stdin.write(f"{published}\n")
        self.proc.stdin.flush()
        out = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), timeout)
        self.proc.wait(30)
        if not out:
            raise RuntimeError(f"client failed: {self.proc.stderr.read()}")
        return json.loads(out)


async def _wait(predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        await asyncio.sleep(0.05)
    return True


async def measure(bench: BenchHub, client: str, rate: float, seconds: float, idle_s: float) -> dict:
    proc = ClientProcess(_KIND[client], bench.td_urls, idle_s, drain_s=max(10.0, seconds))
    await proc.ready()
    subscribed = await _wait(bench.subscribed, 10)
    t0 = time.perf_counter()
    seqs = await bench.publish_at(rate, seconds)
    offered = sum(map(len, seqs.values())) / (time.perf_counter() - t0)
    res = await proc.result(sum(map(len, seqs.values())))
    events = res["events"]
    published = sum(map(len, seqs.values()))
    if client == "wott-client":  # every Thing's ids, in order, exactly the ones published
        by_thing: dict[int, list[int]] = {}
        for i, eid, _, _ in events:
            by_thing.setdefault(i, []).append(eid)
        lossless = all(by_thing.get(i, []) == seqs[t] for i, t in enumerate(bench.ids))
    else:  # wotpy hands on no event id: count only
        lossless = len(events) == published
    lat = [e[2] - e[3] for e in events]
    span_s = (events[-1][2] - events[0][2]) / 1e9 if len(events) > 1 else float("nan")
    print(f"  {client}: {len(events)}/{published} records", file=sys.stderr)
    return {"client": client, "offered": offered, "published": published, "received": len(events),
            "lossless": lossless, "subscribed": subscribed,
            "decoded_per_s": (len(events) - 1) / span_s if span_s > 0 else float("nan"),
            "cpu_ms_per_1k": 1e6 * res["cpu_s"] / max(1, len(events)),
            "p50_ms": pct(lat, 50) / 1e6, "p99_ms": pct(lat, 99) / 1e6, "max_ms": pct(lat, 100) / 1e6}


async def run_group(n_things: int, rate: float, seconds: float, idle_s: float) -> list[dict]:
    bench = await BenchHub(n_things).start()
    try:
        return [await measure(bench, client, rate, seconds, idle_s) for client in CLIENTS]
    finally:
        await bench.stop()


def table(rows: list[dict]) -> str:
    return markdown_table(
        ["client", "offered/s", "published", "received", "in order, none lost",
         "NumPy fields/s (first to last)",
         "CPU ms per 1k", "p50 ms", "p99 ms", "max ms"],
        [[r["client"], f"{r['offered']:.0f}", r["published"], r["received"], "yes" if r["lossless"] else "NO",
          f"{r['decoded_per_s']:.0f}", f"{r['cpu_ms_per_1k']:.0f}", f"{r['p50_ms']:.1f}",
          f"{r['p99_ms']:.1f}",
          f"{r['max_ms']:.1f}"] for r in rows])


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="wott-hub bench client", description=__doc__)
    p.add_argument("--quick", action="store_true", help="short runs (a smoke test, not numbers to quote)")
    p.add_argument("--no-write", action="store_true", help="print the report; leave docs/benchmarks.md alone")
    p.add_argument("--rate", type=float, default=25_000.0, help="throughput group: records/s offered")
    p.add_argument("--seconds", type=float, default=None,
                   help="publishing time per client (default 10, quick 3)")
    p.add_argument("--devices", type=int, default=32, help="latency group: Things")
    p.add_argument("--hz", type=float, default=120.0, help="latency group: records/s per Thing")
    args = p.parse_args(argv)
    if args.rate <= 0 or args.devices < 1 or args.hz <= 0 or (args.seconds is not None and args.seconds <= 0):
        p.error("--rate, --devices, --hz and --seconds must be positive")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    seconds = args.seconds or (3.0 if args.quick else 10.0)
    load = os.getloadavg()[0]
    throughput = asyncio.run(run_group(1, args.rate, seconds, idle_s=5.0))
    latency = asyncio.run(run_group(args.devices, args.devices * args.hz, seconds, idle_s=5.0))
    decode = decode_rates(20_000 if args.quick else 100_000)
    body = ("### Decoding alone: SSE bytes in memory to NumPy fields, one process\n\n"
            + markdown_table(["client", "records", "records/s", "µs per record"],
                             [[k, n, f"{n / s:.0f}", f"{1e6 * s / n:.1f}"] for k, (n, s) in decode.items()])
            + "\n\n"
            f"### Throughput: one Thing, {args.rate:.0f} skinDeformedDetection records/s offered "
            f"for {seconds:.0f} s\n\n"
            f"{table(throughput)}\n\n"
            f"### Latency: {args.devices} Things x {args.hz:.0f} Hz for {seconds:.0f} s\n\n"
            f"{table(latency)}\n\n"
            "Each client in its own process, one after the other against the same hub; a record counts once "
            "its dense NumPy field exists. Latency: publication to field, wall clock. "
            f"Load average at start: {load:.2f}{' (quick run)' if args.quick else ''}.\n")
    command = "uv run wott-hub bench client" + (" --quick" if args.quick else "")
    if args.no_write:
        print(body)
    else:
        print(f"written to {write_section('client', 'Python client (wott-client vs wotpy)', body, command)}")
        print(body)


if __name__ == "__main__":
    main()
