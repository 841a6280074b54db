"""``wott-hub bench fields [--quick] [--no-write] [--rate R] [--seconds S]``: issue 29's client numbers.

- decoding alone: 20-node ``skinDisplacement`` packets from bytes in memory to NumPy arrays, the binary
  form against the same packets as JSON over SSE (target: >= 20,000 packets/s from the binary form);
- the binary stream end to end: a hub publishes ``--rate`` packets/s to one Thing for ``--seconds``,
  wott-client (another process) reads its binary HTTP form: packets/s decoded, in order, none lost;
- raw images on loopback: a camera device whose 640 x 480 image changes at 60 frames/s; wott-client
  fetches the latest image as fast as it can through the .npy form (an H x W x C array: the target,
  >= 200 images/s), then the JPEG and PNG bytes the same way for comparison. The hub encodes each
  frame once per format, whatever the number of reads.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
from pathlib import Path

from report import markdown_table, write_section

from .decode import decode_rates, packets
from .hubside import FieldsHub

_BENCHMARKS = Path(__file__).resolve().parent.parent


class Reader:
    """``reader.py`` in its own process."""

    def __init__(self, spec: dict) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_BENCHMARKS), env.get("PYTHONPATH")) if p)
        self.proc = subprocess.Popen([sys.executable, "-m", "bench_fields.reader", json.dumps(spec)],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

    async def ready(self) -> None:
        line = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), 120)
        if line.strip() != "ready":
            raise RuntimeError(f"reader failed: {line}{self.proc.stderr.read()}")

    async def result(self, timeout: float = 300) -> dict:
        out = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), timeout)
        self.proc.wait(30)
        if not out:
            raise RuntimeError(f"reader failed: {self.proc.stderr.read()}")
        return json.loads(out)


async def run_hub(rate: float, seconds: float) -> tuple[dict, dict, float]:
    hub = await FieldsHub().start()
    try:
        n = int(rate * seconds)
        recs = packets(n)
        reader = Reader({"kind": "stream", "url": hub.url("fields"), "expect": n, "seconds": seconds + 60})
        await reader.ready()
        await asyncio.sleep(0.5)  # its stream open
        took = await hub.publish(recs, rate)
        stream = await reader.result()
        stream["published"] = n
        reader = Reader({"kind": "images", "url": hub.url("camera"), "seconds": seconds})
        await reader.ready()
        images = await reader.result()
        return stream, images, n / took
    finally:
        await hub.stop()


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="wott-hub bench fields", description=__doc__)
    p.add_argument("--quick", action="store_true", help="short runs (a smoke test, not numbers to quote)")
    p.add_argument("--no-write", action="store_true", help="print the report; leave docs/benchmarks.md alone")
    p.add_argument("--rate", type=float, default=20_000.0, help="stream: packets/s published")
    p.add_argument("--seconds", type=float, default=None,
                   help="stream and images: seconds (default 5, quick 2)")
    args = p.parse_args(argv)
    if args.rate <= 0 or (args.seconds is not None and args.seconds <= 0):
        p.error("--rate and --seconds must be positive")
    seconds = args.seconds or (2.0 if args.quick else 5.0)
    load = os.getloadavg()[0]
    decode = decode_rates(20_000 if args.quick else 100_000)
    stream, images, offered = asyncio.run(run_hub(args.rate, seconds))
    shape = " x ".join(map(str, images["shape"]))
    lossless = stream["in_order"] and stream["received"] == stream["published"]
    rate = f"{(stream['received'] - 1) / stream['span_s']:.0f}" if stream["span_s"] > 0 else "-"
    body = (
        "### Decoding alone: 20-node skinDisplacement packets, bytes in memory to NumPy, one process\n\n"
        + markdown_table(["form", "packets", "packets/s", "µs per packet", "bytes per packet"],
                         [[k, n, f"{n / s:.0f}", f"{1e6 * s / n:.2f}", b] for k, (n, s, b) in decode.items()])
        + "\n\n### The binary stream end to end (hub publishes, wott-client reads its HTTP form)\n\n"
        + markdown_table(["offered/s", "published", "received", "in order, none lost",
                          "packets/s (first to last)"],
                         [[f"{offered:.0f}", stream["published"], stream["received"],
                           "yes" if lossless else "NO", rate]])
        + f"\n\n### Raw images on loopback: the latest {shape} camera image, fetched in a loop\n\n"
        + markdown_table(["form", "images", "images/s", "MB/s", "bytes per image"],
                         [[label, n, f"{n / s:.0f}", f"{n * b / s / 1e6:.1f}", f"{b:.0f}"]
                          for label, key in (("wott-client async_image (.npy)", "npy"),
                                             ("JPEG", "jpeg"), ("PNG", "png"))
                          for n, s, b in [images[key]]])
        + f"\n\nThe hub and the reader each in their own process on this machine. Load average at start: "
          f"{load:.2f}{' (quick run)' if args.quick else ''}.\n")
    command = "uv run wott-hub bench fields" + (" --quick" if args.quick else "")
    print(body)
    if not args.no_write:
        title = "Displacement fields and raw images (issue 29)"
        print(f"written to {write_section('fields', title, body, command)}")


if __name__ == "__main__":
    main()
