"""History and directory on PostgreSQL next to SQLite (issue 13): the same code on both engines.

- History: events/s through the real ``HistoryWriter`` (its batches, one transaction each),
  one 120 Hz device's records (skinDeformedDetection + contactInformation per frame), into
  an SQLite file (WAL, ``synchronous=NORMAL``) and into PostgreSQL (``synchronous_commit=off``,
  ``fsync`` on: the same guarantee, a crash of the hub loses nothing committed, a power
  loss may take back the last commits).
- Directory: ``wott-directory`` in its own process on each engine with N TDs (10,000):
  create rate, restart (loading every TD from the database), GET one TD, JSONPath by title
  over HTTP (p50/p95).

PostgreSQL is a throw-away cluster (``tests/postgres.py``: ``initdb``/``pg_ctl`` of Debian's
``postgresql`` package, a unix socket in a temporary folder), removed at the end.

    nice uv run wott-hub bench engines [--quick] [--no-write] [--events N] [--tds N] [--repeat N]

``--quick`` (a smoke run) and ``--no-write`` print only; otherwise the section ``engines`` of
docs/benchmarks.md is rewritten.
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import urlencode

from bench_directory import TOKEN, create_all, make_tds, time_gets
from bench_hub.history import _hour_records
from report import markdown_table, pct, write_section

__all__ = ["main"]

ROOT = Path(__file__).resolve().parent.parent


def _pg_module():
    spec = importlib.util.spec_from_file_location("wott_tests_postgres_bench", ROOT / "tests" / "postgres.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def history_rate(url: str, records: list) -> dict:
    """Events/s through HistoryWriter: a producer faster than the database, within the queue."""
    from wott_hub.history import HistoryWriter, create_engine, upgrade

    engine = create_engine(url)
    upgrade(engine)
    writer = HistoryWriter(engine, integrity_check=False, process=True)  # as the hub runs it
    writer.register_thing("dev", title="dev", family="bench")
    writer.start()
    t0 = time.perf_counter()
    for i in range(0, len(records), 10_000):
        while writer.queue_depth > 200_000:
            time.sleep(0.001)
        for r in records[i:i + 10_000]:
            writer.submit(r)
    assert writer.flush(900)
    elapsed = time.perf_counter() - t0
    batches = writer.batches
    writer.stop()
    assert writer.dropped == 0 and writer.failed_records == 0 and writer.written == len(records)
    engine.dispose()
    return {"rate": len(records) / elapsed, "seconds": elapsed, "batches": batches}


def _start_directory(db: str, log: Path) -> tuple[subprocess.Popen, str, float]:
    env = {**os.environ, "WOTT_DIRECTORY_TOKEN": TOKEN}
    cmd = [sys.executable, "-m", "wott_directory.cli", "--port", "0", "--db", db, "--page-size", "1000",
           "--log-level", "WARNING"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log.open("a"), text=True, env=env)
    line = proc.stdout.readline()
    m = re.search(r"at (http://\S+/) ", line)
    if not m:
        proc.kill()
        raise RuntimeError(f"wott-directory did not start on {db}: {line!r} (see {log})")
    return proc, m.group(1), time.perf_counter() - t0


def _stop(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    proc.wait(60)


async def directory_times(db: str, tds: list[dict], repeat: int, log: Path) -> dict:
    n = len(tds)
    proc, url, _ = _start_directory(db, log)
    try:
        create_s = await create_all(url, tds, 8)
    finally:
        _stop(proc)
    proc, url, restart_s = _start_directory(db, log)  # loads every TD from the database
    try:
        step = max(1, n // 50)
        one = await time_gets(url, [f"things/urn:wott:bench:{i:05d}" for i in range(0, n, step)])
        queries = [f'$[?@.title=="skin-{(i * 7919) % n:05d}"].id' for i in range(repeat)]
        by_title = await time_gets(url, [f"search/jsonpath?{urlencode({'query': q})}" for q in queries])
        page100 = await time_gets(url, [f"things?offset={o}&limit=100" for o in (0, n // 2) * 5])
    finally:
        _stop(proc)
    return {"create": n / create_s, "restart": restart_s, "one": statistics.median(one),
            "title_p50": statistics.median(by_title), "title_p95": pct(by_title, 95),
            "page100": statistics.median(page100)}


def _ms(x: float) -> str:
    return f"{x * 1000:.2f}"


def run(args: argparse.Namespace) -> str:
    pg = _pg_module()
    records = list(_hour_records("dev", args.events // 2))
    size = sum(len(r.data) for r in records[:1000]) / 1000
    tds = make_tds(args.tds)
    cluster = pg.PgCluster(durable=True).start()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            tmp_path = Path(tmp)
            engines = {"SQLite": f"sqlite:///{tmp_path / 'history.db'}",
                       "PostgreSQL": cluster.url(cluster.create_database("history"))}
            hist = {}
            for name, url in engines.items():
                print(f"history on {name}: {len(records)} records ...", flush=True)
                hist[name] = history_rate(url, records)
            dirs = {}
            dbs = {"SQLite": f"sqlite:///{tmp_path / 'tdd.db'}",
                   "PostgreSQL": cluster.url(cluster.create_database("tdd"))}
            for name, db in dbs.items():
                print(f"directory on {name}: {len(tds)} TDs ...", flush=True)
                dirs[name] = asyncio.run(directory_times(db, tds, args.repeat, tmp_path / "directory.log"))
    finally:
        cluster.stop()
    load = os.getloadavg()
    niced = " run under `nice`:" if os.nice(0) > 0 else ""
    target_h, target_q = 50_000, 0.020
    hist_rows = [[name, f"{r['rate']:,.0f}", f"{r['seconds']:.1f}", r["batches"],
                  "yes" if r["rate"] >= target_h else "**no**"] for name, r in hist.items()]
    dir_rows = [[name, f"{r['create']:.0f}", f"{r['restart']:.1f}", _ms(r["one"]), _ms(r["page100"]),
                 _ms(r["title_p50"]), _ms(r["title_p95"]), "yes" if r["title_p50"] <= target_q else "**no**"]
                for name, r in dirs.items()]
    return "\n".join([
        f"Load average at the end of the run: {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1/5/15 min) on "
        f"{os.cpu_count()} cores,{niced} the machine is shared, times stretch with it.",
        "",
        f"PostgreSQL {cluster.bindir.parent.name} (Debian's server, a throw-away cluster on a unix socket, "
        "`fsync` on, `synchronous_commit=off`); SQLite in WAL mode, `synchronous=NORMAL`: on both, a "
        "crash of the hub loses nothing committed, a power loss may take back the last commits.",
        "",
        f"History: {len(records):,} records ({size:.0f} bytes of JSON on average; skin packets carry "
        "their arrays, as the pipeline publishes them, and are stored packed) through the hub's "
        "`HistoryWriter` (batches of up to 20,000 rows, SQLite: multi-row INSERTs of 1,000; "
        "PostgreSQL: one binary COPY; one transaction per batch), as the hub runs it (`history_process`: "
        "a backlog this deep is written by the writer's thread, docs/history.md); target ≥ 50,000 "
        "events/s on both.",
        "",
        markdown_table(["engine", "events/s", "seconds", "batches", "≥ 50,000/s"], hist_rows),
        "",
        f"Directory: {len(tds):,} Tactile TDs, `wott-directory` in its own process, client over HTTP "
        f"on loopback; JSONPath `$[?@.title==\"skin-NNNNN\"].id`, {args.repeat} queries; target p50 ≤ 20 ms. "
        "Restart: process start to listening with every TD loaded from the database. Times in ms.",
        "",
        markdown_table(["engine", "create TDs/s", "restart s", "GET one p50", "page of 100 p50",
                        "by title p50", "p95", "p50 ≤ 20 ms"], dir_rows),
        "",
        "The directory answers JSONPath from its in-memory index of the TDs (the database is its "
        "store, read at start and written through): the query time hardly depends on the engine; "
        "create and restart do.",
    ])


def main() -> None:
    p = argparse.ArgumentParser(prog="wott-hub bench engines", description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="100,000 events, 500 TDs: a smoke run; no docs")
    p.add_argument("--no-write", action="store_true", help="print only; leave docs/benchmarks.md alone")
    p.add_argument("--events", type=int, default=1_000_000, help="history records per engine")
    p.add_argument("--tds", type=int, default=10_000, help="TDs in the directory")
    p.add_argument("--repeat", type=int, default=50, help="JSONPath queries by title")
    args = p.parse_args()
    for name in ("events", "tds", "repeat"):
        if getattr(args, name) < 2:
            p.error(f"--{name}: at least 2")
    if args.quick:
        args.events, args.tds, args.repeat = 100_000, 500, 10
    body = run(args)
    print(body)
    if not (args.quick or args.no_write):
        extra = "".join(f" --{k} {v}" for k, v, d in (("events", args.events, 1_000_000),
                                                     ("tds", args.tds, 10_000)) if v != d)
        doc = write_section("engines", "History and directory on PostgreSQL next to SQLite", body,
                            f"nice uv run wott-hub bench engines{extra}")
        print(f"written to {doc}")


if __name__ == "__main__":
    main()
