"""The history commands a person types (issue 32): ``history list`` on 1 hour of one 120 Hz
device and on 24 hours of three, ``replay``'s first record, ``history export`` of the hour.

The databases are real history databases (the schema of ``migrations/``, SQLite, WAL):
ten seconds of one 120 Hz device touched all the time (per frame a skinDeformedDetection
packet and a contactInformation change, ``bench_storage.records``) written through
``HistoryWriter``, then copied in SQL, each copy ten seconds and its seqs later, until the
hour (864,000 records) or the day (20.7 million a device, 62 million for three, ~8 GB) is
there. What the commands read is what a hub recording that long leaves: the same rows, the
same indexes.

Measured, the median of ``--runs``, the database in the page cache (the first run warms it;
nothing here drops the machine's caches):

- ``history list``: the whole command as a person runs it (a process: Python, its imports,
  the query, the table), and the listing query alone in this process
  (``HistoryReader.things``); ``--count`` (exact record counts, a scan) for comparison;
- ``replay``: from starting the command to the first record at an SSE client that asked for
  it from the start (``Last-Event-ID: 0``), and to the command's ``replaying`` line;
- ``history export`` of the hour as JSON Lines into a file: records/s of the whole command.

    uv run wott-hub bench history_list [--keep DIR] [--runs 5] [--no-day]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from report import markdown_table, write_section

__all__ = ["build", "main"]

TEMPLATE_S = 10
"""Seconds of real records copied to fill a database."""

HZ = 120


def _wott_hub() -> str:
    return str(Path(sys.executable).parent / "wott-hub")


def build(path: Path, devices: int, hours: float) -> int:
    """A history database at ``path`` with ``devices`` devices of ``hours`` each; the records a device
    has. Kept when it is there already (``--keep``)."""
    import sqlite3

    from bench_storage import records

    from wott_hub.examples import example_device
    from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
    from wott_hub.td.builder import build_tactile_td, static_property_values

    frames = TEMPLATE_S * HZ
    copies = int(hours * 3600 / TEMPLATE_S)
    per_device = 2 * frames * copies
    if path.exists():
        return per_device
    tmp = path.with_name(path.name + ".part")
    for p in (tmp, Path(f"{tmp}-wal"), Path(f"{tmp}-shm")):
        p.unlink(missing_ok=True)
    engine = create_engine(database_url(tmp))
    upgrade(engine)
    w = HistoryWriter(engine, integrity_check=False, process=False)
    ids = [f"dev-{k}" for k in range(devices)]
    for did in ids:
        desc = example_device("flat", did)
        w.register_thing(did, title=did, family="bench", td=json.dumps(build_tactile_td(desc)),
                         static_values=json.dumps(static_property_values(desc)))
    w.start()
    for did in ids:
        for r in records(did, frames):
            w.submit(r)
    assert w.flush(600)
    w.stop()
    engine.dispose()
    span_ns = TEMPLATE_S * 10**9
    conn = sqlite3.connect(tmp)
    try:
        conn.execute("PRAGMA journal_mode=WAL")
        conn.execute("PRAGMA synchronous=OFF")
        conn.execute("PRAGMA cache_size=-200000")
        for did in ids:
            key = conn.execute("SELECT key FROM things WHERE id = ?", (did,)).fetchone()[0]
            for k in range(1, copies):
                conn.execute("INSERT INTO events (thing_key, seq, t_ns, kind, name, data) "
                             "SELECT thing_key, seq + ?, t_ns + ?, kind, name, data FROM events "
                             "WHERE thing_key = ? AND seq <= ? ORDER BY seq",
                             (k * 2 * frames, k * span_ns, key, 2 * frames))
                if k % 360 == 0:
                    conn.commit()
            conn.execute("UPDATE things SET seq_reserved = ? WHERE key = ?", (per_device, key))
            conn.commit()
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    finally:
        conn.close()  # the last connection: the WAL goes into the file, -wal and -shm are removed
    tmp.rename(path)
    return per_device


def _median_s(fn, runs: int) -> float:
    fn()  # warm: the page cache, the imports
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _child_cpu_s(fn, runs: int) -> float:
    """The median CPU time (user + system) of the process ``fn`` runs: on a loaded machine the wall
    time of a short command is mostly waiting for a core; its CPU time is what it costs."""
    import resource

    fn()
    times = []
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        fn()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return statistics.median(times)


def list_times(db: Path, runs: int) -> dict[str, float]:
    from wott_hub.history.db import open_existing
    from wott_hub.history.reader import HistoryReader

    def command(*extra: str) -> None:
        subprocess.run([_wott_hub(), "history", "list", "--database", str(db), *extra], check=True,
                       capture_output=True, env={**os.environ, "COLUMNS": "80"})

    reader = HistoryReader(open_existing(str(db), integrity=False))
    out = {"command_s": _median_s(command, runs), "command_cpu_s": _child_cpu_s(command, runs),
           "query_s": _median_s(lambda: reader.things(count=False), runs),
           "count_query_s": _median_s(lambda: reader.things(count=True), max(1, runs // 2))}
    reader.engine.dispose()
    return out


def baseline_times(runs: int) -> dict[str, float]:
    """What any command costs before it reads a database: Python itself, and ``wott-hub`` parsing a
    command line (typer, click, pydantic) with ``history list --help``."""
    def python() -> None:
        subprocess.run([sys.executable, "-c", "pass"], check=True)

    def helptext() -> None:
        subprocess.run([_wott_hub(), "history", "list", "--help"], check=True, capture_output=True)

    return {"python_s": _median_s(python, runs), "help_s": _median_s(helptext, runs),
            "help_cpu_s": _child_cpu_s(helptext, runs)}


def replay_times(db: Path, runs: int) -> dict[str, float]:
    import httpx

    def once() -> tuple[float, float]:
        t0 = time.perf_counter()
        cmd = ["replay", "--device", "dev-0", "--database", str(db), "--port", "0", "--ws-port", "0",
               "--json"]
        proc = subprocess.Popen([_wott_hub(), *cmd], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                text=True)
        try:
            assert proc.stdout is not None
            info = json.loads(proc.stdout.readline())
            t_line = time.perf_counter() - t0
            headers = {"Accept": "text/event-stream", "Last-Event-ID": "0"}
            with httpx.stream("GET", info["events"], headers=headers, timeout=60) as r:
                for line in r.iter_lines():
                    if line.startswith("data:"):
                        return t_line, time.perf_counter() - t0
            raise AssertionError("the replay's stream ended without a record")
        finally:
            proc.send_signal(2)
            proc.wait(60)

    once()
    pairs = [once() for _ in range(runs)]
    return {"line_s": statistics.median(p[0] for p in pairs),
            "first_record_s": statistics.median(p[1] for p in pairs)}


def export_rate(db: Path, records: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([_wott_hub(), "history", "export", "--device", "dev-0", "--database", str(db),
                        "--no-check", "-o", str(Path(tmp) / "out.jsonl")], check=True, capture_output=True)
        return records / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(prog="wott-hub bench history_list", description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep", type=Path, help="Folder for the databases (built once, reused).")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--no-day", action="store_true", help="Skip the 24 h x 3 devices database (~8 GB).")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        rows = []
        t0 = time.perf_counter()
        hour = folder / "hour-1x120hz.db"
        n = build(hour, 1, 1.0)
        took = time.perf_counter() - t0
        print(f"1 h database: {n:,} records ({hour.stat().st_size / 1e6:.0f} MB, built in {took:.0f} s)",
              flush=True)
        lt = list_times(hour, args.runs)
        rows.append(["1 h, 1 device x 120 Hz", f"{n:,}", f"{hour.stat().st_size / 1e6:.0f} MB",
                     f"{lt['command_s']:.2f} ({lt['command_cpu_s']:.2f})", f"{lt['query_s'] * 1000:.1f}",
                     f"{lt['count_query_s']:.2f}", "0.5"])
        if not args.no_day:
            t0 = time.perf_counter()
            day = folder / "day-3x120hz.db"
            m = build(day, 3, 24.0)
            print(f"24 h database: {3 * m:,} records ({day.stat().st_size / 1e9:.1f} GB, "
                  f"{time.perf_counter() - t0:.0f} s)", flush=True)
            dt = list_times(day, args.runs)
            rows.append(["24 h, 3 devices x 120 Hz", f"{3 * m:,}", f"{day.stat().st_size / 1e9:.1f} GB",
                         f"{dt['command_s']:.2f} ({dt['command_cpu_s']:.2f})", f"{dt['query_s'] * 1000:.1f}",
                         f"{dt['count_query_s']:.2f}", "2"])
        base = baseline_times(args.runs)
        rt = replay_times(hour, args.runs)
        rate = export_rate(hour, n)
    body = markdown_table(["database", "records", "size", "`history list` (command), s wall (CPU)",
                           "listing query, ms", "`--count` query, s", "target, s"], rows)
    body += ("\n\nFor comparison, the same machine at the same time: "
             f"`python -c pass` {base['python_s']:.2f} s, "
             f"`wott-hub history list --help` (Python, typer and its pydantic, no database) "
             f"{base['help_s']:.2f} s ({base['help_cpu_s']:.2f} s CPU): the command's time beyond these is "
             "SQLAlchemy's import (its ORM too: the history models) and the query.")
    body += (f"\n\n`replay --device dev-0` of the hour: its `--json` line {rt['line_s']:.2f} s and the first "
             "record "
             f"at an SSE client (`Last-Event-ID: 0`) {rt['first_record_s']:.2f} s after the command started "
             f"(target: the first record within 1 s). `history export` of the hour (JSON Lines into a file, "
             f"`--no-check`): {rate:,.0f} records/s for the whole command.\n")
    print(body)
    cmd = "uv run wott-hub bench history_list" + (" --no-day" if args.no_day else "")
    title = "History commands: list, replay start, export"
    print(f"written to {write_section('history_list', title, body, cmd)}")


if __name__ == "__main__":
    main()
