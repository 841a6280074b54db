"""LeRobot export of one hour of the demo's three devices at 30 fps plus a camera (issue 46; target ≤ 60 s,
memory bounded).

The hour: the built-in demo fleet's three skins (``scene-barrel``, ``scene-flat``, ``scene-cylinder``, the
example skins' TDs), each at 30 frames/s with a skinDeformedDetection packet of ~20 nodes, its
skinDisplacement sibling and a contactInformation change per frame and a touch action every 2 s; and a
640 x 480 camera on ``scene-flat`` recording a PNG at ``--camera-hz`` (1 image/s by default, what the
vision families' ``record_raw_hz`` documents: ~0.8 GB a camera-hour). Written straight through
``HistoryWriter`` into a fresh SQLite history, a minute at a time (60 distinct images, cycled).

Then the real command, in a process of its own (its peak RSS from ``wait4``, plus its video process's
peak, VmHWM read while it runs: the two counted as if at once)::

    wott-hub history export --format lerobot -o DIR --device scene-barrel --device scene-flat
        --device scene-cylinder --fps 30 --no-check --no-progress

108,000 rows at one hour, one episode (no marks); the dataset is read back (row count, video frames).

    uv run wott-hub bench lerobot [--minutes 60] [--camera-hz 1] [--codec h264] [--no-doc]
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from report import markdown_table, write_section

__all__ = ["main"]

DEVICES = {"scene-barrel": "barrel", "scene-flat": "flat", "scene-cylinder": "cylinder"}
CAMERA = "scene-flat"
FPS = 30
T0 = 1_763_000_000 * 10**9
ACTIONS = ["touch", "press", "slip", "release"]


def _images(n: int = 60, h: int = 480, w: int = 640) -> list[str]:
    """Base64 PNGs of a gel pad's view: a lit gradient, a pressed blob moving, sensor noise."""
    from PIL import Image

    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:h, 0:w]
    out = []
    for k in range(n):
        blob = 90 * np.exp(-((xx - 160 - 5 * k) ** 2 + (yy - 240) ** 2) / 3000.0)
        img = np.stack([60 + xx * 120 / w + blob, 80 + yy * 100 / h + blob, 140 - blob / 2], axis=-1)
        img = np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8)
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, format="PNG")
        out.append(base64.b64encode(buf.getvalue()).decode())
    return out


def _record(db: Path, minutes: float, camera_hz: float) -> int:
    """The recorded hour (or ``minutes``); the number of records."""
    from wott_hub.events.fields import FieldArrays, FieldRecord
    from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, SkinArrays, encode
    from wott_hub.examples import example_device
    from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
    from wott_hub.runtime.payloads import skin_deformed_json
    from wott_hub.tactile.processing import FrameResult
    from wott_hub.td.builder import build_tactile_td, static_property_values

    engine = create_engine(database_url(db))
    upgrade(engine)
    w = HistoryWriter(engine, integrity_check=False)
    seq, nodes = {}, {}
    for thing, shape in DEVICES.items():
        desc = example_device(shape, thing)
        td = build_tactile_td(desc)
        if thing == CAMERA:
            td["events"]["rawImageRecorded"] = {
                "title": "rawImageRecorded",
                "data": {"type": "object", "properties": {"camera": {"type": "string", "enum": ["camera"]}}},
            }
        seq[thing] = w.register_thing(
            thing,
            title=thing,
            family="scene",
            td=json.dumps(td),
            static_values=json.dumps(static_property_values(desc)),
        )
        nodes[thing] = desc.mesh.n_nodes
    w.start()
    images = _images()
    rng = np.random.default_rng(7)
    frames = int(minutes * 60 * FPS)
    image_every = max(1, round(FPS / camera_hz)) if camera_hz > 0 else 0
    total = 0
    for lo in range(0, frames, 60 * FPS):  # a minute at a time: bounded memory
        batch: list[Record] = []
        for k in range(lo, min(frames, lo + 60 * FPS)):
            t = T0 + k * 10**9 // FPS
            for thing, n in nodes.items():
                start = int(rng.integers(0, n - 40))
                ids = start + np.sort(rng.choice(40, 20, replace=False))
                inten = np.round(rng.uniform(0.005, 2.0, 20), 3)
                res = FrameResult(t, ids, inten, False, [], [], True)
                micro = np.round(rng.normal(0, 400, (20, 3))).astype(np.int64)
                force = round(float(-inten.sum()), 3)
                seq[thing] += 3
                batch += [
                    Record(
                        thing,
                        seq[thing] - 2,
                        KIND_EVENT,
                        "skinDeformedDetection",
                        t,
                        skin_deformed_json(res),
                        skin=SkinArrays(ids, inten),
                    ),
                    FieldRecord(thing, seq[thing] - 1, t, FieldArrays(ids.astype(np.int64), micro)),
                    Record(
                        thing,
                        seq[thing],
                        KIND_PROPERTY,
                        "contactInformation",
                        t,
                        encode(
                            {
                                "numOfContacts": 1,
                                "contactLocations": [{"x": 1.0 * start, "y": 2.0, "z": 0.0}],
                                "contactForces": [{"x": 0.0, "y": 0.0, "z": force}],
                            }
                        ),
                    ),
                ]
                if k % (2 * FPS) == 0:
                    seq[thing] += 1
                    batch.append(
                        Record(
                            thing,
                            seq[thing],
                            KIND_EVENT,
                            "actionDetection",
                            t,
                            encode(ACTIONS[(k // (2 * FPS)) % len(ACTIONS)]),
                        )
                    )
            if image_every and k % image_every == 0:
                seq[CAMERA] += 1
                batch.append(
                    Record(
                        CAMERA,
                        seq[CAMERA],
                        KIND_EVENT,
                        "rawImageRecorded",
                        t,
                        json.dumps(
                            {
                                "timeStamp": t,
                                "camera": "camera",
                                "width": 640,
                                "height": 480,
                                "channels": 3,
                                "image": images[(k // image_every) % len(images)],
                            },
                            separators=(",", ":"),
                        ),
                    )
                )
        for r in batch:
            w.submit(r)
        assert w.flush(3600)
        total += len(batch)
    w.stop()
    engine.dispose()
    return total


def _export(db: Path, out: Path, codec: str) -> tuple[float, float, float, str]:
    """(wall s, CPU s, peak RSS MB, stderr) of the command in a process of its own."""
    cmd = [
        str(Path(sys.executable).with_name("wott-hub")),
        "history",
        "export",
        "--format",
        "lerobot",
        "-o",
        str(out),
        *[a for d in DEVICES for a in ("--device", d)],
        "--fps",
        str(FPS),
        "--codec",
        codec,
        "--database",
        str(db),
        "--no-check",
        "--no-progress",
    ]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    children: dict[int, float] = {}  # the export's video processes: pid -> their peak RSS (VmHWM), MB
    done = threading.Event()
    watch = threading.Thread(target=_watch_children, args=(proc.pid, children, done), daemon=True)
    watch.start()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    done.set()
    watch.join()
    err = proc.stderr.read() if proc.stderr is not None else ""
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"the export failed ({proc.returncode}): {err}")
    # its own peak (wait4's ru_maxrss: the largest of it and its children) plus its children's: both
    # peaks counted as if at once (an upper bound of the pair's)
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024 + sum(children.values()), err


def _watch_children(pid: int, peaks: dict[int, float], done: threading.Event) -> None:
    """Each child of ``pid``'s peak RSS (VmHWM), read every 0.1 s while it runs."""
    while not done.wait(0.1):
        try:
            tasks = Path(f"/proc/{pid}/task").iterdir()
            kids = [int(c) for t in tasks for c in (t / "children").read_text().split()]
        except (FileNotFoundError, ProcessLookupError):
            continue
        for kid in kids:
            try:
                status = Path(f"/proc/{kid}/status").read_text()
            except FileNotFoundError:
                continue
            for line in status.splitlines():
                if line.startswith("VmHWM:"):
                    peaks[kid] = max(peaks.get(kid, 0.0), int(line.split()[1]) / 1024)


def _read_back(out: Path) -> tuple[int, int, float]:
    """(rows, video frames, MB) of the dataset."""
    import av
    import pyarrow.parquet as pq

    rows = sum(pq.ParquetFile(p).metadata.num_rows for p in out.glob("data/*/*.parquet"))
    frames = 0
    for p in out.glob("videos/*/*/*.mp4"):
        with av.open(str(p)) as c:
            frames += sum(1 for _ in c.demux(video=0) if _.size)
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) / 1e6
    return rows, frames, size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=60.0, help="Recorded time (default 60).")
    ap.add_argument(
        "--camera-hz", type=float, default=1.0, help="Camera images recorded per second (default 1)."
    )
    ap.add_argument("--codec", default="h264", help="Video codec: h264 (default) or av1.")
    ap.add_argument("--no-doc", action="store_true", help="Print only; leave docs/benchmarks.md alone.")
    args = ap.parse_args()
    if not args.minutes > 0 or args.camera_hz < 0:
        ap.error("--minutes > 0 and --camera-hz >= 0")
    scale = 60.0 / args.minutes
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="wott-bench-lerobot-") as d:
        tmp = Path(d)
        t0 = time.perf_counter()
        records = _record(tmp / "hour.db", args.minutes, args.camera_hz)
        build_s = time.perf_counter() - t0
        db_mb = (tmp / "hour.db").stat().st_size / 1e6
        out = tmp / "dataset"
        wall, cpu, rss, err = _export(tmp / "hour.db", out, args.codec)
        rows, frames, size = _read_back(out)
    load_after = os.getloadavg()
    expected = int(args.minutes * 60 * FPS)
    assert rows == expected and frames == expected, (rows, frames, expected)
    said = err.strip().rpartition(" in ")[0]  # "1 episode, N frames (M records)", without the temporary path
    hour = "one hour" if scale == 1 else f"{args.minutes:g} min, scaled x{scale:g} to one hour"
    table = markdown_table(
        [
            "recorded",
            "records",
            "rows",
            "video frames",
            "wall s / hour",
            "CPU s / hour",
            "peak RSS MB",
            "dataset MB",
        ],
        [
            [
                hour,
                f"{records:,}",
                f"{rows:,}",
                f"{frames:,}",
                f"{wall * scale:.1f}",
                f"{cpu * scale:.1f}",
                f"{rss:.0f}",
                f"{size * scale:.0f}",
            ]
        ],
    )
    body = f"""
The demo's three skins at {FPS} frames/s (skin packet, displacement packet and contacts per frame, an
action every 2 s) and a 640 x 480 camera recording {args.camera_hz:g} image/s, written through
`HistoryWriter` into SQLite ({db_mb * scale:.0f} MB an hour, built in {build_s:.0f} s), exported whole by
the command (one episode, {args.codec}, a process of its own; peak RSS from `wait4` plus its video
process's VmHWM, as if both at once).
Target: ≤ 60 s an hour, memory bounded. The command said: {said}

{table}

Load average {load[0]:.2f} before, {load_after[0]:.2f} after (2 shared cores: wall times vary with it).
"""
    print(body)
    if not args.no_doc:
        cmd = "uv run wott-hub bench lerobot" + ("" if scale == 1 else f" --minutes {args.minutes:g}")
        write_section("lerobot", "LeRobot export of one hour, three skins and a camera (issue 46)", body, cmd)


if __name__ == "__main__":
    main()
