"""Start-up group: ``wott-hub run`` (the demo scene) launched as a process -> TDs served.

Two launchers, alternated trial by trial so that a change of load hits both alike:
``uv run wott-hub run`` as the README types it (uv's own per-run work included: the lock and
environment check, and a bytecode pass if ``compile-bytecode`` were set; docs/hub.md,
"Start-up"), and the venv's ``wott-hub`` script (the hub's own start-up alone). The issue's
target (TDs served <= 1.5 s) is on the first. Then the demo "at rest" (no client connected, its
simulated devices playing their looping scenes): resident memory and CPU over ``REST_S``.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .common import cpu_s, descendants

__all__ = ["LAUNCHERS", "REST_S", "TRIALS", "at_rest", "launch_command", "run", "startup_times", "summary"]

TRIALS = 3
REST_S = 20.0
ROOT = Path(__file__).resolve().parents[2]  # the workspace: what `uv run` finds from the checkout
LAUNCHERS = ("uv run", "venv script")


def launch_command(launcher: str) -> list[str]:
    """The argv that starts the demo hub through ``launcher``; ``--project`` stands for running from
    the checkout (the hub itself runs in a throw-away directory, for its ``./wott-hub.db``)."""
    if launcher == "uv run":
        uv = os.environ.get("UV") or shutil.which("uv")  # `uv run` exports UV, the running uv
        if not uv:
            raise RuntimeError("startup: uv not found (run the benchmark with `uv run`)")
        return [uv, "run", "--project", str(ROOT), "wott-hub"]
    if launcher == "venv script":
        return [str(Path(sys.executable).parent / "wott-hub")]
    raise ValueError(f"unknown launcher {launcher!r}")


def _ports() -> tuple[int, int]:
    import socket

    with socket.socket() as a, socket.socket() as b:
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        return a.getsockname()[1], b.getsockname()[1]


def _one(cmd: list[str]) -> tuple[float, float, int]:
    import httpx

    port, ws_port = _ports()
    with tempfile.TemporaryDirectory() as cwd:
        t0 = time.monotonic()
        proc = subprocess.Popen([*cmd, "run", "--port", str(port), "--ws-port", str(ws_port), "--json"],
                                cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        served = float("nan")
        while time.monotonic() - t0 < 60 and proc.poll() is None:
            try:
                r = httpx.get(f"http://127.0.0.1:{port}/wot", timeout=0.5)
                if r.status_code == 200 and len(r.json()) > 1:
                    served = time.monotonic() - t0
                    break
            except httpx.HTTPError:
                pass
            time.sleep(0.01)
        line = proc.stdout.readline() if proc.stdout else ""
        proc.terminate()
        proc.wait(30)
    info = json.loads(line) if line.strip() else {"ready_s": float("nan"), "devices": []}
    return served, info["ready_s"], len(info["devices"])


def startup_times(trials: int, launchers: tuple[str, ...] = LAUNCHERS) -> dict[str, list]:
    """``trials`` starts per launcher, alternated: launcher -> [(TDs served s, ready s, devices)]."""
    out: dict[str, list] = {name: [] for name in launchers}
    commands = {name: launch_command(name) for name in launchers}
    for _ in range(trials):
        for name in launchers:
            out[name].append(_one(commands[name]))
    return out


def summary(trials: dict[str, list]) -> dict[str, tuple[float, float]]:
    """launcher -> (median TDs served, median ready), seconds."""
    return {name: (statistics.median(t[0] for t in rows), statistics.median(t[1] for t in rows))
            for name, rows in trials.items()}


def at_rest(seconds: float = REST_S) -> dict[str, float]:
    """The demo (venv script, so the process measured is the hub) once ready and settled for 5 s:
    its CPU over ``seconds`` (% of one core) and its resident memory (MiB) at the end, its child
    processes (the history writer's) counted in, the peak as the sum of each one's."""
    port, ws_port = _ports()
    with tempfile.TemporaryDirectory() as cwd:
        proc = subprocess.Popen([*launch_command("venv script"), "run", "--port", str(port), "--ws-port",
                                 str(ws_port), "--json"], cwd=cwd, stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, text=True)
        try:
            assert proc.stdout is not None
            proc.stdout.readline()  # the --json line: ready
            time.sleep(5.0)
            pids = [proc.pid, *descendants(proc.pid)]
            cpu0, t0 = sum(map(cpu_s, pids)), time.monotonic()
            time.sleep(seconds)
            cpu1, t1 = sum(map(cpu_s, pids)), time.monotonic()
            kib = [_memory_kib(pid) for pid in pids]
        finally:
            proc.terminate()
            proc.wait(30)
    return {"cpu_pct": 100 * (cpu1 - cpu0) / (t1 - t0), "rss_mib": sum(k["VmRSS"] for k in kib) / 1024,
            "peak_mib": sum(k["VmHWM"] for k in kib) / 1024, "seconds": seconds, "processes": len(pids)}


def _memory_kib(pid: int) -> dict[str, int]:
    status = Path(f"/proc/{pid}/status").read_text()
    return {k: int(v.split()[0]) for k, v in (line.split(":", 1) for line in status.splitlines())
            if k in ("VmRSS", "VmHWM")}



async def run() -> dict:
    print("startup ...", flush=True)
    return {"trials": startup_times(TRIALS), "rest": at_rest(), "load": os.getloadavg()}
