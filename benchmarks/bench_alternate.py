"""``wott-hub bench alternate DIR [DIR ...]``: the latency group's point in several checkouts, alternated.

For the issues' "no worse than commit X" (28, 29, 35): a single `bench hub` invocation measures one
checkout, and the machine drifts by more than the differences sought from one invocation to the
next. Here each run is a process of its own in its checkout (``DIR/.venv``, made by ``uv sync``),
running that checkout's own ``bench_hub.latency.latency_ours`` (the hub, the devices and the clients
as `bench hub` runs them, SSE and WebSocket phases, no wotpy client) after a 2 s warm-up run; the
checkouts take turns, ``--rounds`` times, and the medians are printed. The hub's CPU per frame is
printed as measured and less the simulated devices' own (``latency.devices_own``; measured by this
checkout for one that does not). Printed only: the numbers go
into docs/benchmarks.md by hand, with the checkouts' commits.

Latency is printed twice. ``bench hub``'s p99 is over the frames the SSE (WS) client received; a
hub that falls behind and whose devices skip frames (the benchmark's drivers, like a camera, drop a
frame that is more than a period late) leaves its latest frames out of that figure, so a checkout
that processes fewer frames can show a lower p99. The "of due" columns are SSE percentiles over
every frame the devices were due to send in the window (devices x 120 Hz x duration), a frame
never delivered counting as later than any: ``inf`` when more than 5 % (1 %) of them never
arrived. The run reads the SSE latencies by wrapping ``latency.pct`` (the one function every
checkout's ``latency_ours`` takes its percentiles with, the SSE list first). Only SSE: the
WebSocket client's frames are matched to their traces by frame time, which older checkouts do
differently, so its count is not comparable across them.

    uv run wott-hub bench alternate ../before . --devices 32 --rounds 4
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path

__all__ = ["main", "of_due"]

_RUN = """
import asyncio, json, math, sys, tempfile
from pathlib import Path
sys.path.insert(0, "benchmarks")
from bench_hub import latency as L
seen = []  # every list latency_ours takes a percentile of, in order: the SSE latencies first
_pct = L.pct
def pct(values, q):
    seen.append(values)
    return _pct(values, q)
L.pct = pct
OF_DUE
async def main(n, dur):
    await L.latency_ours(n, 2.0, Path(tempfile.mkdtemp()), with_wotpy=False)  # warm-up, not kept
    seen.clear()
    r = await L.latency_ours(n, dur, Path(tempfile.mkdtemp()), with_wotpy=False)
    sse = seen[0]
    assert len(sse) == r["sse"][1], "latency_ours changed: see bench_alternate's docstring"
    due = n * 120 * dur  # the benchmark's devices run at 120 Hz
    fps = r["sse"][0] / dur  # cpu_us: latency.cpu_per_frame, written out (older checkouts lack it)
    print(json.dumps({"fps": fps, "sse_p99": r["sse"][3] / 1e6, "ws_p99": r["ws"][3] / 1e6,
                      "delivered": 100 * len(sse) / due, "sse_due_p95": of_due(sse, due, 95) / 1e6,
                      "sse_due_p99": of_due(sse, due, 99) / 1e6,
                      "cpu_us": 1e4 * r["cpu"]["sse-lean"][0] / max(1.0, fps),
                      "stages_p99": {k: v[1] / 1e6 for k, v in r["stages"].items()},
                      "devices_us": r.get("devices_us", float("nan"))}))
asyncio.run(main(int(sys.argv[1]), float(sys.argv[2])))
"""


def of_due(latencies: list[float], due: float, q: float) -> float:
    """The ``q``-th percentile (nearest rank) of the latencies of ``due`` frames, of which only these
    were delivered: a frame never delivered is later than any (``inf`` if more than 100 - q % were)."""
    rank = math.ceil(q * due / 100)
    return sorted(latencies)[rank - 1] if 0 < rank <= len(latencies) else math.inf


_RUN = _RUN.replace("OF_DUE", inspect.getsource(of_due))  # the run's copy: older checkouts lack it

_COLUMNS = (("fps", "frames/s", "{:.0f}"), ("sse_p99", "SSE p99 ms", "{:.2f}"),
            ("ws_p99", "WS p99 ms", "{:.2f}"), ("delivered", "SSE delivered %", "{:.1f}"),
            ("sse_due_p95", "of due: SSE p95", "{:.2f}"), ("sse_due_p99", "SSE p99", "{:.2f}"),
            ("cpu_us", "hub CPU µs/frame", "{:.0f}"), ("own_us", "less the devices' own", "{:.0f}"))


def _checkout(text: str) -> Path:
    path = Path(text).resolve()
    if not (path / ".venv" / "bin" / "python").exists() or not (path / "benchmarks" / "bench_hub").is_dir():
        raise argparse.ArgumentTypeError(f"{text}: not a wott-hub checkout with its .venv (uv sync there)")
    return path


def _commit(path: Path) -> str:
    done = subprocess.run(["git", "-C", str(path), "log", "-1", "--format=%h"], capture_output=True,
                          text=True)
    return done.stdout.strip() or path.name


def _run(path: Path, devices: int, duration: float) -> dict:
    done = subprocess.run([str(path / ".venv" / "bin" / "python"), "-c", _RUN, str(devices), str(duration)],
                          cwd=path, capture_output=True, text=True, timeout=600)
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines:
        raise SystemExit(f"{path}: the run failed: {done.stderr.strip()[-2000:]}")
    result: dict = json.loads(lines[-1])
    return result


def _devices_own(devices: int) -> float:
    """``bench_hub.latency.devices_own`` of this checkout (the same simulated devices as older ones)."""
    code = ("import asyncio, sys; sys.path.insert(0, 'benchmarks'); from bench_hub import latency as L; "
            f"print(asyncio.run(L.devices_own({devices})))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        raise SystemExit(f"the devices' own cost could not be measured: {done.stderr.strip()[-2000:]}")
    return float(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="wott-hub bench alternate", description=__doc__.split("\n\n")[0])
    ap.add_argument("checkouts", nargs="+", type=_checkout, metavar="DIR")
    ap.add_argument("--devices", type=int, default=32, help="devices at 120 Hz (default 32)")
    ap.add_argument("--duration", type=float, default=6.0, help="seconds measured per run (default 6)")
    ap.add_argument("--rounds", type=int, default=3, help="runs per checkout, alternated (default 3)")
    args = ap.parse_args(argv)
    if args.devices < 1 or args.rounds < 1 or not args.duration > 0:
        ap.error("--devices and --rounds must be at least 1, --duration positive")
    names = [f"{_commit(p)} ({p.name})" for p in args.checkouts]
    runs: dict[str, list[dict]] = {name: [] for name in names}
    devices: float | None = None  # for checkouts whose benchmark does not measure it, when one runs
    for k in range(args.rounds):
        for name, path in zip(names, args.checkouts, strict=True):
            r = _run(path, args.devices, args.duration)
            if r.get("devices_us") is None or math.isnan(r["devices_us"]):  # a checkout older than it
                if devices is None:
                    devices = _devices_own(args.devices)
                r["devices_us"] = devices
            r["own_us"] = r["cpu_us"] - r["devices_us"]
            runs[name].append(r)
            cells = " · ".join(f"{label} {fmt.format(r[key])}" for key, label, fmt in _COLUMNS)
            stages = ", ".join(f"{stage} {p99:.2f}" for stage, p99 in r["stages_p99"].items())
            print(f"round {k + 1} {name}: {cells} · stage p99 ms: {stages}", flush=True)
    print(f"\nmedians of {args.rounds} runs, {args.devices} devices x 120 Hz, {args.duration:g} s each:")
    for name, rs in runs.items():
        print(f"{name}: " + " · ".join(f"{label} {fmt.format(statistics.median(r[key] for r in rs))}"
                                       for key, label, fmt in _COLUMNS))


if __name__ == "__main__":
    main(sys.argv[1:])
