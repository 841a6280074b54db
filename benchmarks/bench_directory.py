"""Thing Description Directory with 10,000 Tactile TDs: create rate, list page time, JSONPath
query times, SSE fan-out to 50 listeners.

The directory runs as the real ``wott-directory`` command in its own process
(SQLite file, loopback, bearer token); this process is the client, over HTTP.
JSONPath is also timed in-process on the same TDs to separate the engine from
HTTP. ``--quick`` does the same on 500 TDs and 10 listeners.

    uv run wott-hub bench directory [--quick] [--tds N] [--listeners N]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any
from urllib.parse import quote, urlencode

from report import markdown_table, pct, write_section
from tornado.httpclient import AsyncHTTPClient, HTTPRequest
from wott_directory import DirectoryClient
from wott_directory.registration import enrich
from wott_directory.search import SearchEngine

from wott_hub.examples import example_device
from wott_hub.td.builder import build_tactile_td

TOKEN = "bench-token"
SHAPES = ("barrel", "flat", "cylinder")
QUERIES = [
    ("by title (equality, pre-filtered)", '$[?@.title=="skin-{k}"]'),
    ("id by title", '$[?@.title=="skin-{k}"].id'),
    ("ids of a family (1/3 match)", '$[?@["tac:family"]=="barrel-vision"].id'),
    ("regex on title (full scan)", '$[?search(@.title, "skin-0{k3}")].id'),
    ("all ids", "$[*].id"),
    ("nested test (all match)", "$[?@.properties.skinNodes.observable==true].id"),
]


def ms(x: float) -> str:
    return f"{x * 1000:.2f}"


def make_tds(n: int) -> list[dict[str, Any]]:
    templates = {s: build_tactile_td(example_device(s), base="http://127.0.0.1:8080/") for s in SHAPES}
    out = []
    for i in range(n):
        td = dict(templates[SHAPES[i % 3]])
        td["id"] = f"urn:wott:bench:{i:05d}"
        td["title"] = f"skin-{i:05d}"
        out.append(td)
    return out


def start_directory(tmp: Path) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, "WOTT_DIRECTORY_TOKEN": TOKEN}
    cmd = [sys.executable, "-m", "wott_directory.cli", "--port", "0", "--db", f"sqlite:///{tmp / 'bench.db'}",
           "--page-size", "1000", "--log-level", "WARNING"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()
    m = re.search(r"at (http://\S+/) ", line)
    if not m:
        proc.kill()
        raise RuntimeError(f"wott-directory did not start: {line!r}")
    return proc, m.group(1)


async def create_all(url: str, tds: list[dict[str, Any]], concurrency: int) -> float:
    http = AsyncHTTPClient(force_instance=True, max_clients=concurrency)
    headers = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/td+json"}
    bodies = [(td["id"], json.dumps(td).encode()) for td in tds]
    queue: asyncio.Queue = asyncio.Queue()
    for b in bodies:
        queue.put_nowait(b)

    async def worker() -> None:
        while not queue.empty():
            thing_id, body = queue.get_nowait()
            resp = await http.fetch(HTTPRequest(f"{url}things/{quote(thing_id, safe=':')}", method="PUT",
                                                headers=headers, body=body))
            assert resp.code == 201, resp.code

    t0 = time.perf_counter()
    await asyncio.gather(*(worker() for _ in range(concurrency)))
    elapsed = time.perf_counter() - t0
    http.close()
    return elapsed


async def time_gets(url: str, paths: list[str]) -> list[float]:
    http = AsyncHTTPClient(force_instance=True)
    out = []
    for path in paths:
        t0 = time.perf_counter()
        resp = await http.fetch(url + path)
        out.append(time.perf_counter() - t0)
        assert resp.code == 200
    http.close()
    return out


async def fanout(url: str, listeners: int, updates: int, thing_id: str) -> dict[str, float]:
    """Latency from sending a PATCH to each listener reading its event (diff=true carries the
    update number, so no clock is shared with the server)."""
    client = DirectoryClient(url, token=TOKEN)
    streams = [client.events("thing_updated", diff=True) for _ in range(listeners)]
    for s in streams:
        await s.open()
    sent: dict[str, float] = {}
    latencies: list[float] = []

    async def drain(stream) -> None:
        for _ in range(updates):
            ev = await stream.next(60)
            latencies.append(time.perf_counter() - sent[ev.data["description"]])

    readers = [asyncio.ensure_future(drain(s)) for s in streams]
    http = AsyncHTTPClient(force_instance=True)
    headers = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/merge-patch+json"}
    t0 = time.perf_counter()
    for i in range(updates):
        key = f"update {i}"
        sent[key] = time.perf_counter()
        await http.fetch(HTTPRequest(f"{url}things/{quote(thing_id, safe=':')}", method="PATCH",
                                     headers=headers, body=json.dumps({"description": key})))
    await asyncio.gather(*readers)
    total = time.perf_counter() - t0
    for s in streams:
        await s.close()
    http.close()
    client.close()
    return {"p50": pct(latencies, 50), "p99": pct(latencies, 99), "max": max(latencies),
            "delivered": len(latencies), "rate": len(latencies) / total, "total": total}


async def bench(args: argparse.Namespace) -> str:
    n = args.tds
    tds = make_tds(n)
    size = len(json.dumps(tds[0]))
    with tempfile.TemporaryDirectory() as tmp:
        proc, url = start_directory(Path(tmp))
        try:
            create_s = await create_all(url, tds, args.concurrency)
            rng = [0, n // 2, max(0, n - 100)]
            page100 = await time_gets(url, [f"things?offset={o}&limit=100" for o in rng * args.repeat])
            page1000 = await time_gets(url, [f"things?offset={o}&limit=1000" for o in rng[:2] * 3])
            step = max(1, n // 50)
            one = await time_gets(url, [f"things/urn:wott:bench:{i:05d}" for i in range(0, n, step)])

            # JSONPath: over HTTP, and in-process on the same (enriched) TDs
            from datetime import UTC, datetime

            now = datetime.now(UTC)
            data = sorted((enrich(td, now, None).td for td in tds), key=lambda t: t["id"])
            engine = SearchEngine()
            rows = []
            for label, template in QUERIES:
                qs = [template.format(k=f"{(i * 7919) % n:05d}", k3=f"{(i * 31) % 100:02d}")
                      for i in range(args.repeat)]
                local = []
                for q in qs:
                    t0 = time.perf_counter()
                    res = engine.search(q, data)
                    local.append(time.perf_counter() - t0)
                over_http = await time_gets(url, [f"search/jsonpath?{urlencode({'query': q})}" for q in qs])
                rows.append([label, f"`{template.format(k='04242', k3='42')}`", len(res),
                             ms(statistics.median(local)), ms(pct(local, 95)),
                             ms(statistics.median(over_http)), ms(pct(over_http, 95))])
            plain = SearchEngine()
            q0 = QUERIES[0][1].format(k="04242", k3="")
            t0 = time.perf_counter()
            for _ in range(5):
                plain.compile(q0).path.findall(data)
            unfiltered = (time.perf_counter() - t0) / 5

            fan = await fanout(url, args.listeners, args.updates, tds[0]["id"])
        finally:
            proc.send_signal(signal.SIGTERM)
            proc.wait(30)
    load = os.getloadavg()[0]
    body = [
        f"Load average at the end of the run: {load:.1f} on {os.cpu_count()} cores (the machine is shared; "
        "times stretch with it).",
        "",
        f"{n} Tactile TDs of {size / 1024:.1f} KiB each; `wott-directory` in its own process (SQLite file, "
        f"WAL), client in this process over HTTP on loopback; {args.concurrency} concurrent writers.",
        "",
        markdown_table(["what", "result"], [
            ["create (PUT, validated, committed)", f"{n / create_s:.0f} TDs/s ({create_s:.1f} s for {n})"],
            ["GET one TD, p50", f"{ms(statistics.median(one))} ms"],
            ["list page of 100, p50 / p95", f"{ms(statistics.median(page100))} / {ms(pct(page100, 95))} ms"],
            ["list page of 1000, p50", f"{ms(statistics.median(page1000))} ms"],
            [f"SSE fan-out: {args.updates} updates to {args.listeners} listeners",
             f"p50 {ms(fan['p50'])} ms, p99 {ms(fan['p99'])} ms, max {ms(fan['max'])} ms (write sent -> "
             f"event read); {fan['delivered']} events, {fan['rate']:.0f} events/s delivered"],
        ]),
        "",
        f"JSONPath (RFC 9535, python-jsonpath strict), {args.repeat} runs each, times in ms. "
        "In-process: the directory's search engine alone; HTTP: the whole request.",
        "",
        markdown_table(["query", "example", "results", "in-process p50", "p95", "HTTP p50", "p95"], rows),
        "",
        f"Without the equality pre-filter, the title query costs {ms(unfiltered)} ms in-process "
        "(python-jsonpath evaluating the filter on every TD).",
    ]
    return "\n".join(body)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="500 TDs, 10 listeners: a smoke run in seconds")
    p.add_argument("--tds", type=int, default=10_000)
    p.add_argument("--listeners", type=int, default=50)
    p.add_argument("--updates", type=int, default=200)
    p.add_argument("--concurrency", type=int, default=8)
    p.add_argument("--repeat", type=int, default=30)
    args = p.parse_args()
    if args.quick:
        args.tds, args.listeners, args.updates, args.repeat = 500, 10, 30, 5
    body = asyncio.run(bench(args))
    print(body)
    if not args.quick:
        extra = [f" --{k} {v}" for k, v, d in (("tds", args.tds, 10_000), ("listeners", args.listeners, 50))
                 if v != d]
        cmd = "uv run wott-hub bench directory" + "".join(extra)
        write_section("directory", "Thing Description Directory (10,000 TDs)", body, cmd)


if __name__ == "__main__":
    main()
