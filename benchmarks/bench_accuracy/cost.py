"""What the processing costs per frame, against another checkout's (``--cost-before``).

The frames are those of ``bench processing`` (the TacLink barrel and a 100 x 100 pad with
0, 1, 3 and 10 presses, held and scaled by up to 0.6 % frame to frame) and the hub
benchmark's moving press on the 16 x 16 pad (what each of the 32 devices of its latency
point processes). Both processors run in this process, round after round in turn, and each
``process`` call is timed alone; the minimum over the rounds is the cost with the least
interference from whatever else the machine runs, the median what it costs here and now.
The other checkout's ``tactile`` package is loaded under another name (it has only
relative imports), so ``git worktree add /tmp/before <commit>`` and
``--cost-before /tmp/before/src/wott_hub/tactile`` compare with any commit.
"""

from __future__ import annotations

import importlib.util
import statistics
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from report import markdown_table

from wott_hub import tactile
from wott_hub.examples import example_device
from wott_hub.tactile.indentation import Indenter, indent

__all__ = ["cost_table", "load_tactile"]


def load_tactile(folder: Path) -> ModuleType:
    """The ``tactile`` package in ``folder`` (another checkout's), as the module ``tactile_before``."""
    spec = importlib.util.spec_from_file_location("tactile_before", folder / "__init__.py",
                                                  submodule_search_locations=[str(folder)])
    if spec is None or spec.loader is None:
        raise SystemExit(f"--cost-before: no tactile package in {folder}")
    module = importlib.util.module_from_spec(spec)
    sys.modules["tactile_before"] = module
    spec.loader.exec_module(module)
    return module


def _cases() -> list[tuple[str, Any, list[np.ndarray], float]]:
    from bench_hub.latency import press_frames

    rng = np.random.default_rng(0)
    pad = example_device("flat")
    out = [("hub latency's moving press, 16 x 16 pad", pad.mesh, press_frames(pad, 240), pad.epsilon_mm)]
    for name, mesh, radius, depth in (("TacLink barrel", tactile.taclink_barrel(), 10.0, 3.0),
                                      ("pad 100 x 100", tactile.flat_pad(100, 100, pitch_mm=1.0), 4.0, 1.0)):
        for n in (0, 1, 3, 10):
            centres = mesh.nodes[rng.choice(mesh.free_indices, size=n, replace=False)] if n else []
            d = indent(mesh, [Indenter(c, depth, radius) for c in centres])
            out.append((f"{name}, {n} presses", mesh, [d * (1.0 + 0.001 * (k % 7)) for k in range(240)], 0.1))
    return out


def _per_frame(module: Any, mesh: Any, frames: list[np.ndarray], eps: float) -> list[float]:
    proc = module.FrameProcessor(mesh, module.ProcessingParams(epsilon_mm=eps))
    built = [module.TactileFrame(10**9 + i * 8_333_333, f) for i, f in enumerate(frames)]
    times = []
    for frame in built:
        t0 = time.perf_counter()
        proc.process(frame)
        times.append(time.perf_counter() - t0)
    return times[5:]  # the first frames build the caches


def cost_table(before: ModuleType, rounds: int = 5) -> str:
    rows = []
    for name, mesh, frames, eps in _cases():
        old: list[float] = []
        new: list[float] = []
        for _ in range(rounds):
            old += _per_frame(before, mesh, frames, eps)
            new += _per_frame(tactile, mesh, frames, eps)
        rows.append([name, f"{min(old) * 1e6:.1f} / {statistics.median(old) * 1e6:.1f}",
                     f"{min(new) * 1e6:.1f} / {statistics.median(new) * 1e6:.1f}",
                     f"{min(new) / min(old):.2f}"])
        print(rows[-1], file=sys.stderr)
    return markdown_table(["frames", "before µs (min / median)", "now µs (min / median)",
                           "now / before (min)"], rows)
