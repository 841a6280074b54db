"""Play a scene through a FrameProcessor, the way a driver and the hub would:
for tests and benchmarks of processing without any transport."""

from __future__ import annotations

from typing import Any

from wott_hub.sim.scene import Scene
from wott_hub.tactile import FrameProcessor, FrameResult, ProcessingParams, SkinMesh, TactileFrame


def play(mesh: SkinMesh, steps: list[dict[str, Any]], seconds: float | None = None, rate_hz: float = 120.0,
         params: ProcessingParams | None = None) -> list[FrameResult]:
    scene = Scene.from_dict({"step": steps})
    proc = FrameProcessor(mesh, params)
    n = int(round((seconds or scene.duration_s) * rate_hz))
    out = []
    for k in range(n):
        t = k / rate_hz
        out.append(proc.process(TactileFrame(int(round(t * 1e9)), scene.displacement_at(t, mesh))))
    return out


def actions(results: list[FrameResult]) -> list[str]:
    return [a for r in results for a in r.actions]
