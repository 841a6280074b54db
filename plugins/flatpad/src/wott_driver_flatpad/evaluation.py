"""Play a scene through the simulator and the estimator and score the result.

Shared by the end-to-end tests and ``benchmarks/bench_flatpad.py`` so both
measure the same thing: RMSE over the free markers of every frame, the
in-plane ("shear") and normal ("depth") parts reported apart, and frames
grouped by what touches the pad (a slide's in-plane stretch breaks the depth
prior, docs/flat-pad.md, so it is scored on its own).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from wott_hub.plugin_api import Scene

from .estimator import PadEstimator
from .geometry import PadLayout
from .simulator import PadSimulator, RenderSettings

__all__ = ["SceneScore", "frame_kind", "play_scene"]


def frame_kind(scene: Scene, t_s: float) -> str:
    """rest | slide | press (press, tap or pinch: no in-plane drag) for the frame at ``t_s``."""
    kinds = {s.kind for s in scene.steps if s.depth_at(t_s) > 0}
    if not kinds:
        return "rest"
    return "slide" if "slide" in kinds else "press"


@dataclass
class SceneScore:
    frames: int = 0
    lost: int = 0
    sq_shear: dict[str, float] = field(default_factory=dict)  # sum of squared in-plane errors, mm²
    sq_depth: dict[str, float] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)  # marker-frames per kind
    max_depth_err: dict[str, float] = field(default_factory=dict)
    estimate_s: list[float] = field(default_factory=list)  # per frame, grey image to displacement (wall)
    estimate_cpu_s: list[float] = field(default_factory=list)  # the same in process CPU time
    render_s: list[float] = field(default_factory=list)

    def add(self, kind: str, err: np.ndarray) -> None:
        for k in (kind, "all"):
            self.sq_shear[k] = self.sq_shear.get(k, 0.0) + float(np.sum(err[:, :2] ** 2))
            self.sq_depth[k] = self.sq_depth.get(k, 0.0) + float(np.sum(err[:, 2] ** 2))
            self.counts[k] = self.counts.get(k, 0) + len(err)
            self.max_depth_err[k] = max(self.max_depth_err.get(k, 0.0), float(np.abs(err[:, 2]).max()))

    def shear_rmse(self, kind: str = "all") -> float:
        """RMS of the in-plane error vector's length, mm."""
        return float(np.sqrt(self.sq_shear[kind] / self.counts[kind])) if self.counts.get(kind) else np.nan

    def depth_rmse(self, kind: str = "all") -> float:
        return float(np.sqrt(self.sq_depth[kind] / self.counts[kind])) if self.counts.get(kind) else np.nan

    @property
    def estimate_ms(self) -> float:
        return float(np.median(self.estimate_s) * 1e3) if self.estimate_s else np.nan

    @property
    def estimate_cpu_ms(self) -> float:
        """CPU time per frame: what the estimate costs on a machine shared with other work."""
        return float(np.median(self.estimate_cpu_s) * 1e3) if self.estimate_cpu_s else np.nan


def play_scene(layout: PadLayout, scene: Scene, fps: float = 60.0, *, render: RenderSettings | None = None,
               estimator: PadEstimator | None = None, seconds: float | None = None) -> SceneScore:
    """Render every frame of ``scene`` at ``fps``, estimate it, compare with the ground truth."""
    sim = PadSimulator(layout, scene, render)
    est = estimator or PadEstimator(layout)
    rest, _ = PadSimulator(layout, Scene("rest", ()), render).render(0.0)  # the pad untouched
    est.set_reference(rest)
    free = layout.mesh.free
    score = SceneScore()
    n = int(np.floor((seconds if seconds is not None else scene.duration_s) * fps)) + 1
    for i in range(n):
        t = i / fps
        t0 = time.perf_counter()
        img, truth = sim.render(t)
        t1, c1 = time.perf_counter(), time.process_time()
        e = est.update(img)
        t2, c2 = time.perf_counter(), time.process_time()
        score.render_s.append(t1 - t0)
        score.estimate_s.append(t2 - t1)
        score.estimate_cpu_s.append(c2 - c1)
        score.frames += 1
        score.lost += e.lost
        score.add(frame_kind(scene, t), (e.displacement - truth)[free])
    return score
