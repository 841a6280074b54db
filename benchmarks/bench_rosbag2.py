"""rosbag2 export of one hour of one 120 Hz device (issue 30; target ≤ 60 s), read back by rosbags.

The hour is ``bench storage``'s: per frame a skinDeformedDetection packet of 20 nodes and a
contactInformation change (864,000 records), written into a fresh SQLite history on the barrel
skin's TD. Then ``export_rosbag2`` (history/rosbag2.py) of the whole range, timed (wall and CPU),
and the bag opened by ``rosbags`` and every message deserialised (counted, not timed in the
target). The MCAP export (Foxglove profile) of the same range is timed beside it.

    uv run wott-hub bench rosbag2 [--minutes 60] [--no-doc]
"""

from __future__ import annotations

import argparse
import gc
import os
import tempfile
import time
from pathlib import Path

from bench_storage import _write, _writer, records
from report import markdown_table, write_section

__all__ = ["main"]


def _dir_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=60.0, help="Recorded time of the device (default 60).")
    ap.add_argument("--no-doc", action="store_true", help="Print only; leave docs/benchmarks.md alone.")
    args = ap.parse_args()
    if not args.minutes > 0:
        ap.error("--minutes: a positive number")
    from rosbags.highlevel import AnyReader

    from wott_hub.history import HistoryReader
    from wott_hub.history.mcap import export_mcap
    from wott_hub.history.rosbag2 import export_rosbag2

    frames = int(args.minutes * 60 * 120)
    scale = 60.0 / args.minutes
    recs = records("dev", frames)
    gc.freeze()
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="wott-bench-rosbag2-") as d:
        tmp = Path(d)
        engine, w = _writer(tmp / "hour.db", True)
        _write(engine, w, recs)
        w.stop()
        del recs
        gc.collect()
        reader = HistoryReader(engine)
        bag = tmp / "bag"
        t0, c0 = time.perf_counter(), time.process_time()
        summary = export_rosbag2(reader, bag, ["dev"])
        bag_s, bag_cpu = time.perf_counter() - t0, time.process_time() - c0
        bag_mb = _dir_mb(bag)
        t0 = time.perf_counter()
        n = 0
        with AnyReader([bag]) as r:
            for conn, _, raw in r.messages():
                r.deserialize(raw, conn.msgtype)
                n += 1
        read_s = time.perf_counter() - t0
        assert n == summary.messages, (n, summary.messages)
        path = tmp / "hour.mcap"
        t0, c0 = time.perf_counter(), time.process_time()
        with path.open("wb") as f:
            fox = export_mcap(reader, f, ["dev"])
        mcap_s, mcap_cpu = time.perf_counter() - t0, time.process_time() - c0
        mcap_mb = path.stat().st_size / 1e6
        engine.dispose()
    load_after = os.getloadavg()
    hour = "one hour" if scale == 1 else f"{args.minutes:g} min, scaled x{scale:g} to one hour"
    rows = [["rosbag2 (ROS 2, CDR; `--format rosbag2`)", f"{summary.records:,}", f"{summary.messages:,}",
             f"{bag_s * scale:.1f}", f"{bag_cpu * scale:.1f}", f"{bag_mb * scale:.0f}"],
            ["MCAP (Foxglove; `--format mcap`, scenes at 30 Hz)", f"{fox.records:,}",
             f"{fox.records + fox.scene_messages:,}", f"{mcap_s * scale:.1f}", f"{mcap_cpu * scale:.1f}",
             f"{mcap_mb * scale:.0f}"]]
    body = f"""
One 120 Hz device ({hour}): per frame a skinDeformedDetection packet of 20 nodes and a
contactInformation change, recorded in SQLite (the barrel skin's TD), exported whole. Target: the
rosbag2 export of one hour in ≤ 60 s. Read back: `rosbags` opened the bag and deserialised all
{n:,} messages in {read_s * scale:.1f} s{" (scaled)" if scale != 1 else ""}.

{markdown_table(["export", "records", "messages", "wall s / hour", "CPU s / hour", "MB / hour"], rows)}

Load average {load[0]:.2f} before, {load_after[0]:.2f} after (2 shared cores: wall times vary with it).
"""
    print(body)
    if not args.no_doc:
        cmd = "uv run wott-hub bench rosbag2" + ("" if scale == 1 else f" --minutes {args.minutes:g}")
        write_section("rosbag2", "rosbag2 and MCAP export of one hour (issue 30)", body, cmd)


if __name__ == "__main__":
    main()
