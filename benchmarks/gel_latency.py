"""Part of ``bench gel``: a GelSight Mini at 25 fps and a DIGIT at 60 fps through a real hub, from the
frame read to its SSE event, and what the whole hub process costs meanwhile.

The recordings (folders of PNGs: Taxim's real Mini presses shaped to 320 x 240, the real DIGIT rest
frame with modelled presses; every other frame a press, the worst case) are played at their rates by
``wott-hub run`` in a process of its own. A client subscribes to each device's ``contactInformation``
(``observeproperty``, SSE: one event per frame, as every frame changes the contacts) and stamps each
event as it arrives (``time.time_ns``). The hub stamps each frame with the time it was due on its wall
clock (a recording is read when its frame is due, a late read keeps the due time), stored with the
event's sequence number in history: latency = arrival - due, both on this machine's clock. Frames
read late count against the hub (the lateness is in the latency). The hub's CPU over the same window
(``/proc/PID/stat``, its history process included) covers everything it does for the two sensors:
decoding, processing, actions, history, SSE.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from bench_hub.common import cpu_s, descendants

__all__ = ["latency"]

RATES = {"mini": 25.0, "digit": 60.0}
WINDOW_S = 15.0


def _hub_cpu_s(pid: int) -> float:
    """The hub's CPU seconds, its history process included."""
    total = 0.0
    for p in (pid, *descendants(pid)):
        try:
            total += cpu_s(p)
        except FileNotFoundError:
            pass
    return total


def _listen(url: str, got: list[tuple[int, int]], stop: threading.Event) -> None:
    import httpx

    with httpx.Client(timeout=None) as c, c.stream("GET", url, headers={"Accept": "text/event-stream"}) as r:
        seq = None
        for line in r.iter_lines():
            if line.startswith("id: "):
                seq = int(line[4:])
            elif line.startswith("data: ") and seq is not None:
                got.append((seq, time.time_ns()))
            if stop.is_set():
                return


def latency(recordings: dict[str, Path]) -> list[list[str]]:
    """Rows (device, events, p50, p99, frame period) and the hub's CPU, from a hub playing ``recordings``
    (device id -> folder of PNGs, long enough to outlast the window plus start-up)."""
    with tempfile.TemporaryDirectory() as tmp:
        port = 18000 + os.getpid() % 2000
        cfg = Path(tmp) / "hub.toml"
        family = {"mini": "gelsight-mini", "digit": "digit"}
        devices = "".join(f'\n[[device]]\nid = "{d}"\nfamily = "{family[d]}"\nsource = "{folder}"\n'
                          f'fps = {RATES[d]:g}\n' for d, folder in recordings.items())
        cfg.write_text(f'[hub]\nhttp_port = {port}\nws_port = false\ndatabase = "{tmp}/hub.db"\n{devices}')
        hub = subprocess.Popen([str(Path(sys.executable).with_name("wott-hub")), "run", "-c", str(cfg)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            import httpx

            deadline = time.monotonic() + 60
            while True:
                try:
                    if httpx.get(f"http://127.0.0.1:{port}/wot/digit", timeout=1).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                if time.monotonic() > deadline or hub.poll() is not None:
                    raise SystemExit(f"the hub did not start: {hub.stderr.read().decode()[-2000:]}")
                time.sleep(0.1)
            stop = threading.Event()
            got: dict[str, list[tuple[int, int]]] = {d: [] for d in recordings}
            threads = [threading.Thread(target=_listen, daemon=True, args=(
                f"http://127.0.0.1:{port}/wot/{d}/properties/contactInformation/observe", got[d], stop))
                for d in recordings]
            for t in threads:
                t.start()
            time.sleep(2.0)  # both devices past their rest reference, the subscriptions open
            for d in got:
                got[d].clear()
            cpu0, t0 = _hub_cpu_s(hub.pid), time.monotonic()
            time.sleep(WINDOW_S)
            cpu = (_hub_cpu_s(hub.pid) - cpu0) / (time.monotonic() - t0)
            stop.set()
            taken = {d: list(v) for d, v in got.items()}
        finally:
            hub.send_signal(signal.SIGINT)
            try:
                hub.wait(30)
            except subprocess.TimeoutExpired:
                hub.kill()
                hub.wait()
        rows = []
        with sqlite3.connect(f"{tmp}/hub.db") as db:
            for d, events in taken.items():
                due = dict(db.execute(
                    "SELECT e.seq, e.t_ns FROM events e JOIN things t ON t.key = e.thing_key "
                    "WHERE t.id = ? AND e.name = 'contactInformation'", (d,)).fetchall())
                lat = np.array([(at - due[seq]) / 1e6 for seq, at in events if seq in due])
                period = 1e3 / RATES[d]
                rows.append([f"{d} at {RATES[d]:g} fps: frame due -> SSE event", f"{len(lat)}",
                             f"p50 {np.percentile(lat, 50):.1f} ms · p99 {np.percentile(lat, 99):.1f} ms",
                             f"{period:.1f} ms"])
        rows.append(["the whole hub process over the same window (decoding, processing, actions, "
                     "history, SSE)", "", f"{100 * cpu:.0f} % of one core", ""])
    return rows
