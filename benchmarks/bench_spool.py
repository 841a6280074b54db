"""Store and forward (issue 33): what the history spool costs and how fast it empties, SQLite and PostgreSQL.

- spool: records/s moved onto the spool (``storage.encode`` of a batch, then ``Spool.append``: one frame,
  written and fsync-ed), the work the writer does for each batch while the database is unreachable;
- forward: records/s from a full spool into the database through the real ``HistoryWriter`` (rows the
  database has already are looked up and left out), as after an outage or at the next start;
- stop: how long ``HistoryWriter.stop()`` takes with the database gone (PostgreSQL stopped; SQLite's
  write lock held by another connection) and a queue of records, which go to the spool.

Records as the pipeline publishes them (a skin packet with its arrays and a contactInformation change per
frame of a 120 Hz device, ``bench_hub.history``). PostgreSQL is a throw-away cluster (``tests/postgres.py``).

    nice uv run wott-hub bench spool [--records N] [--queued N] [--no-write]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sqlite3
import tempfile
import time
from pathlib import Path

from bench_hub.history import _hour_records
from report import markdown_table, write_section

__all__ = ["main"]

ROOT = Path(__file__).resolve().parent.parent


def _pg_module():
    spec = importlib.util.spec_from_file_location("wott_tests_postgres_bench", ROOT / "tests" / "postgres.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _fill_spool(url: str, folder: Path, records: list) -> float:
    """Encode and append ``records`` to a fresh spool in batches of 20,000; returns records/s."""
    from wott_hub.history import create_engine, open_storage
    from wott_hub.history.spool import Spool

    engine = create_engine(url)
    storage = open_storage(engine)
    spool = Spool(folder, 1 << 34)
    spool.open()
    t0 = time.perf_counter()
    for i in range(0, len(records), 20_000):
        batch = records[i:i + 20_000]
        payloads = storage.encode(batch)
        spool.append([(r.thing, r.seq, r.kind, r.name, r.t_ns, d)
                      for r, d in zip(batch, payloads, strict=True)])
    rate = len(records) / (time.perf_counter() - t0)
    spool.close()
    engine.dispose()
    return rate


def _forward(url: str, folder: Path, n: int) -> float:
    """A writer forwards a full spool into the database; returns records/s."""
    from wott_hub.history import HistoryWriter, create_engine, upgrade
    from wott_hub.history.spool import Spool

    engine = create_engine(url)
    upgrade(engine)
    writer = HistoryWriter(engine, integrity_check=False, process=True, spool=Spool(folder, 1 << 34))
    writer.register_thing("dev", title="dev", family="bench")
    t0 = time.perf_counter()
    writer.start()
    while writer.spool is not None and writer.spool.records:
        time.sleep(0.01)
    rate = n / (time.perf_counter() - t0)
    writer.stop()
    assert writer.forwarded == n, (writer.forwarded, n)
    engine.dispose()
    return rate


def _stop_down(url: str, folder: Path, records: list, take_down, bring_back) -> tuple[float, int]:
    """Stop a writer holding ``records`` while the database is down; returns (seconds, spooled)."""
    from wott_hub.history import HistoryWriter, create_engine, upgrade
    from wott_hub.history.spool import Spool

    engine = create_engine(url)
    upgrade(engine)
    writer = HistoryWriter(engine, integrity_check=False, process=True, spool=Spool(folder, 1 << 34))
    writer.register_thing("dev", title="dev", family="bench")
    writer.start()
    take_down()
    try:
        for r in records:
            writer.submit(r)
        t0 = time.perf_counter()
        writer.stop()
        took = time.perf_counter() - t0
    finally:
        bring_back()
    spooled = writer.outcome()["spooled"]
    engine.dispose()
    return took, spooled


def _renumbered(records: list, start: int) -> list:
    from wott_hub.events.record import Record

    return [Record(r.thing, start + i + 1, r.kind, r.name, r.t_ns, r.data, skin=r.skin)
            for i, r in enumerate(records)]


def run(args: argparse.Namespace) -> str:
    pg = _pg_module()
    records = list(_hour_records("dev", args.records // 2))
    queued = list(_hour_records("dev", args.queued // 2))
    cluster = pg.PgCluster(durable=True).start()
    rows = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            tmp_path = Path(tmp)
            db_file = tmp_path / "history.db"
            engines = {"SQLite": f"sqlite:///{db_file}",
                       "PostgreSQL": cluster.url(cluster.create_database("h"))}
            for name, url in engines.items():
                print(f"{name}: spool and forward {len(records):,} records ...", flush=True)
                spool_rate = _fill_spool(url, tmp_path / f"{name}.fill", records)
                forward_rate = _forward(url, tmp_path / f"{name}.fill", len(records))
                print(f"{name}: stop with the database down, {len(queued):,} queued ...", flush=True)
                if name == "SQLite":
                    blocker = sqlite3.connect(db_file, isolation_level=None, timeout=60)

                    def down(b=blocker):
                        b.execute("BEGIN IMMEDIATE")

                    def back(b=blocker):
                        b.execute("ROLLBACK")
                        b.close()
                else:
                    def down():
                        cluster._run("pg_ctl", "-D", str(cluster.data), "-m", "fast", "-w", "stop")

                    def back():
                        opts = (f"-c listen_addresses=127.0.0.1 -c port={cluster.port} "
                                f"-c unix_socket_directories={cluster.root} -c max_connections=200 "
                                "-c synchronous_commit=off")
                        cluster._run("pg_ctl", "-D", str(cluster.data), "-l",
                                     str(cluster.root / "server.log"), "-w", "-t", "60", "-o", opts, "start")
                took, spooled = _stop_down(url, tmp_path / f"{name}.stop", _renumbered(queued, 10**9),
                                           down, back)
                rows.append([name, f"{spool_rate:,.0f}", f"{forward_rate:,.0f}", f"{took:.2f}",
                             f"{spooled:,}"])
    finally:
        cluster.stop()
    load = os.getloadavg()
    return "\n".join([
        f"Load average at the end of the run: {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1/5/15 min) on "
        f"{os.cpu_count()} cores; the machine is shared, times stretch with it.",
        "",
        f"{len(records):,} records to spool and forward; {len(queued):,} queued when the writer is stopped "
        "with its database down (SQLite: its write lock held by another connection, the writer waits out "
        "its 10 s busy timeout; PostgreSQL: the server stopped, connections refused). The spool is a "
        "folder of segment files on the same disk, each append one fsync-ed frame (docs/reliability.md).",
        "",
        markdown_table(["engine", "onto the spool, records/s", "forwarded, records/s",
                        "stop with the database down, s", "records spooled at stop"], rows),
    ])


def main() -> None:
    p = argparse.ArgumentParser(prog="wott-hub bench spool", description=__doc__.split("\n\n")[0])
    p.add_argument("--records", type=int, default=400_000, help="records spooled and forwarded per engine")
    p.add_argument("--queued", type=int, default=100_000,
                   help="records queued when stopping with the database down")
    p.add_argument("--no-write", action="store_true", help="print only; leave docs/benchmarks.md alone")
    args = p.parse_args()
    if args.records < 2 or args.queued < 2:
        p.error("--records and --queued: at least 2")
    body = run(args)
    print(body)
    if not args.no_write:
        extra = "".join(f" --{k} {v}" for k, v, d in (("records", args.records, 400_000),
                                                     ("queued", args.queued, 100_000)) if v != d)
        write_section("spool", "Store and forward: the history spool", body,
                      f"uv run wott-hub bench spool{extra}")


if __name__ == "__main__":
    main()
