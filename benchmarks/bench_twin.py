"""``wott-hub bench twin``: the digital twin's delays as its device page measures them.

The WoTT paper measured its client from a touch on the hub to the mesh drawn (230 ms end to
end on its PC). This starts the demo hub as a user types it (``wott-hub run``, its own
process, history on), opens each device page in headless Chromium (Debian's chromium driven
by Playwright, the tests' set-up: software WebGL, no GPU), lets it run, and reads the page's
own measurements (``window.__twinStats``, the numbers behind its delay panel):

- hub -> page: SSE message received minus the packet's ``timeStamp`` (hub clock);
- page -> screen: received to the animation frame after the draw that shows it;
- end to end: ``timeStamp`` to that frame;

and the draws/packets ratio (packets are coalesced into the next draw, never lost: the page
accounts for every one). Hub and browser share a clock here, so the numbers are exact.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import quote, urljoin

import httpx
from report import markdown_table, pct, write_section

CHROMIUM = os.environ.get("WOTT_CHROMIUM", "/usr/bin/chromium")
# the browser tests' arguments (tests/web/conftest.py): headless, software WebGL
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--enable-unsafe-swiftshader",
]
TARGETS = "barrel end to end p50 ≤ 46 ms, p95 ≤ 100 ms; hub → page p50 ≤ 10 ms (issue 18)"


def start_hub(folder: Path, timeout_s: float) -> tuple[subprocess.Popen, dict]:
    """The demo hub (``wott-hub run``, free ports, history in ``folder``) and its --json line."""
    cmd = [sys.executable, "-c", "from wott_hub.cli import main; main()", "run", "--port", "0",
           "--ws-port", "0", "--json", "--database", str(folder / "hub.db")]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=open(folder / "hub.log", "w"), text=True)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                raise SystemExit(f"the hub exited ({proc.returncode}); see {folder / 'hub.log'}")
            continue
        if line.startswith("{"):
            return proc, json.loads(line)
    proc.terminate()
    raise SystemExit(f"the hub did not start within {timeout_s:.0f} s")


def stop_hub(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(20)
    except subprocess.TimeoutExpired:
        proc.kill()


class SseProbe(threading.Thread):
    """A plain SSE client on the device's events beside the page: hub -> client without a browser,
    so the page's own share of hub -> page shows (run in this process, off the page's cores' budget
    only as far as the OS allows)."""

    def __init__(self, td_url: str) -> None:
        super().__init__(daemon=True)
        td = httpx.get(td_url, timeout=30).json()
        form = next(f for f in td.get("forms", []) if "subscribeallevents" in (
            f["op"] if isinstance(f["op"], list) else [f["op"]]) and f.get("subprotocol") == "sse")
        self.url = urljoin(td_url, form["href"])
        self.delays: list[float] = []
        self.stop = threading.Event()

    def run(self) -> None:
        from httpx_sse import connect_sse

        with httpx.Client(timeout=30) as c, connect_sse(c, "GET", self.url) as es:
            for ev in es.iter_sse():
                t_ns = time.time_ns()
                if self.stop.is_set():
                    return
                if '"arrayOfDeformedNodes"' in ev.data:
                    self.delays.append((t_ns - json.loads(ev.data)["timeStamp"]) / 1e6)


def measure(ctx, url: str, td_url: str, seconds: float, warmup: float) -> dict:
    """One device page for ``seconds`` after ``warmup``: the page's stats snapshot."""
    page = ctx.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(f"{url}/twin/device.html?td={quote(td_url, safe='')}")
        page.wait_for_function("window.twin && window.twin.ready && window.twin.streamState === 'open'",
                               timeout=60_000)
        time.sleep(warmup)
        probe = SseProbe(td_url)
        probe.start()
        page.evaluate("window.__twinStats.reset()")
        time.sleep(seconds)
        snap = page.evaluate("window.__twinStats.snapshot()")
        probe.stop.set()
        probe.join(10)
        snap["probe"] = probe.delays
    finally:
        page.close()
    snap["errors"] = errors
    return snap


def row(device: str, s: dict) -> list[object]:
    def p(key: str, q: float) -> str:
        v = pct(s[key], q)
        return "–" if v != v else f"{v:.1f}"

    accounted = s["coalesced"] + s["waiting"] + s["dropped"] == s["packets"]

    def both(key: str) -> str:
        return f"{p(key, 50)} / {p(key, 95)}"

    return [device, both("hubToPage"), both("pageToScreen"), both("endToEnd"),
            f"{s['draws']} / {s['packets']}", "yes" if accounted else "NO", p("drawMs", 50), both("probe")]


def main() -> None:
    ap = argparse.ArgumentParser(prog="wott-hub bench twin", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=25.0, help="Measured time per device (default 25).")
    ap.add_argument("--warmup", type=float, default=3.0, help="Seconds before measuring (default 3).")
    ap.add_argument("--devices", default="", help="Comma-separated device keys (default: every demo device).")
    ap.add_argument("--no-write", action="store_true", help="Print only; leave docs/benchmarks.md alone.")
    args = ap.parse_args()
    if not args.seconds > 0 or not args.warmup >= 0:
        ap.error("--seconds must be positive and --warmup not negative")
    if not Path(CHROMIUM).exists():
        raise SystemExit(f"{CHROMIUM} not found: apt-get install chromium (or set WOTT_CHROMIUM)")
    from playwright.sync_api import sync_playwright

    folder = Path(tempfile.mkdtemp(prefix="wott-bench-twin-"))
    load_before = os.getloadavg()
    proc, where = start_hub(folder, 180)
    results: dict[str, dict] = {}
    try:
        devices = where["devices"]
        wanted = [d for d in args.devices.split(",") if d] or list(devices)
        unknown = [d for d in wanted if d not in devices]
        if unknown:
            raise SystemExit(f"--devices: {', '.join(unknown)} not served; "
                             f"the demo hub has {', '.join(devices)}")
        with sync_playwright() as pw:
            ctx = pw.chromium.launch_persistent_context(
                str(folder / "profile"), executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True,
                viewport={"width": 1280, "height": 760})
            try:
                for key in wanted:
                    print(f"{key}: {args.seconds:.0f} s ...", flush=True)
                    results[key] = measure(ctx, where["http"], devices[key], args.seconds, args.warmup)
            finally:
                ctx.close()
    finally:
        stop_hub(proc)
        shutil.rmtree(folder, ignore_errors=True)
    load_after = os.getloadavg()

    header = ["device", "hub → page p50 / p95 ms", "page → screen p50 / p95 ms", "end to end p50 / p95 ms",
              "draws / packets", "every packet drawn or coalesced", "draw call p50 ms",
              "hub → SSE client p50 / p95 ms"]
    table = markdown_table(header, [row(k, s) for k, s in results.items()])
    load = (f"load average {load_before[0]:.2f} before, {load_after[0]:.2f} after "
            f"({os.cpu_count()} cores; the hub, Chromium and this script share them)")
    print(table)
    print(load)
    for k, s in results.items():
        if s["errors"]:
            print(f"{k}: page errors: {s['errors']}")
    if args.no_write:
        return
    body = (f"The device page's own delay panel (`window.__twinStats`), demo hub (`wott-hub run`, "
            f"history on) and headless Chromium (software WebGL) on the same machine, "
            f"{args.seconds:.0f} s per device after {args.warmup:.0f} s. Targets: {TARGETS}; "
            f"the paper's PC: 230 ms end to end.\n\n"
            f"{table}\n\n{load}. \"draw call\": the page's own CPU time to update and render one frame; "
            "\"hub → SSE client\": a plain Python SSE client on the same stream at the same time, no browser "
            "(the timeStamp is the frame's, so the device's own processing is in both).")
    cmd = "wott-hub bench twin" + (f" --seconds {args.seconds:g}" if args.seconds != 25 else "")
    print(f"written to {write_section('twin', 'Digital twin (device page in headless Chromium)', body, cmd)}")


if __name__ == "__main__":
    main()
