"""The barrel's raw signal, simulated: both camera images of a scripted scene.

Ground truth is ``Scene.displacement_at(t, mesh)`` (the indentation model
today; the scene's own ``model`` key selects the Kelvin-Voigt skin once it
exists), so whatever the scene's mechanics, the images and the truth agree.
Each marker is drawn where the camera model projects its displaced position,
with the apparent size its distance and slant give it (``BarrelLayout``); the
images then go through the same detector, tracker and model as a real
sensor's frames. Not simulated: self-occlusion of markers behind a deep bulge,
lighting changes, lens vignetting (docs/barrel-vision.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from wott_hub.sim.scene import Scene

from .geometry import BarrelLayout

__all__ = ["BarrelSimulator", "RenderSettings", "SimulatedCameras"]


@dataclass(frozen=True)
class RenderSettings:
    blur_sigma: float = 1.0  # lens blur, px
    noise_std: float = 2.0  # sensor noise, grey levels
    background: float = 22.0  # the dark skin, grey level (real TacLink frames: ~24)
    intensity: float = 235.0  # a white dot
    seed: int = 0

    def __post_init__(self) -> None:
        if self.blur_sigma < 0 or self.noise_std < 0:
            raise ValueError("blur_sigma and noise_std must not be negative")
        if not 0 <= self.background < self.intensity <= 255:
            raise ValueError("need 0 <= background < intensity <= 255")


class BarrelSimulator:
    """Renders what the cameras of ``layout`` see while ``scene`` plays."""

    def __init__(self, layout: BarrelLayout, scene: Scene, render: RenderSettings | None = None) -> None:
        self.layout = layout
        self.scene = scene
        self.settings = render or RenderSettings()
        self._rng = np.random.default_rng(self.settings.seed)
        self._rest = np.zeros_like(layout.mesh.nodes)

    def truth(self, t_s: float) -> np.ndarray:
        """Ground-truth node displacement (N, 3) mm at scene time ``t_s``."""
        mesh = self.layout.mesh
        if not self.scene.indenters_at(t_s, mesh):
            return self._rest
        return self.scene.displacement_at(t_s, mesh)

    def render_displacement(self, displacement: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """One uint8 (H, W) image per camera for a node displacement (None: at rest)."""
        from wott_vision.render import render_markers

        s = self.settings
        points = self.layout.image_points(displacement)
        radii = self.layout.marker_radii(displacement)
        return tuple(
            render_markers(p, r, size=(cam.height, cam.width), blur_sigma=s.blur_sigma,
                           noise_std=s.noise_std, rng=self._rng, intensity=s.intensity,
                           background=s.background)
            for cam, p, r in zip(self.layout.cameras, points, radii, strict=True)
        )

    def render(self, t_s: float) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
        """(images, truth) at scene time ``t_s``."""
        truth = self.truth(t_s)
        return self.render_displacement(truth), truth


class SimulatedCameras:
    """Both simulated cameras as one reader: ``read()`` -> (True, (bottom, top)) at ``fps``.

    ``realtime`` paces reads like cameras (frame k is due k / fps after the first
    read; a slow reader skips frames, as a camera would drop them); otherwise
    frames come as fast as read, still 1 / fps apart in scene time. A scene that
    does not loop ends: ``read()`` returns (False, None) and ``ended`` is true.
    ``t_s`` and ``truth`` describe the frame last read.
    """

    def __init__(self, simulator: BarrelSimulator, fps: float = 30.0, *, realtime: bool = True,
                 max_frames: int | None = None) -> None:
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.simulator = simulator
        self.fps = float(fps)
        self.realtime = realtime
        self.max_frames = max_frames
        self.frames_read = 0
        self.ended = False
        self.failure = ""
        self.t_s = 0.0
        self.truth: np.ndarray | None = None
        self._k = 0
        self._t0: float | None = None

    def isOpened(self) -> bool:  # noqa: N802 - VideoCapture's name
        return not self.ended

    def read(self) -> tuple[bool, tuple[np.ndarray, ...] | None]:
        scene = self.simulator.scene
        if self.realtime:
            now = time.monotonic()
            if self._t0 is None:
                self._t0 = now
            due = self._t0 + self._k / self.fps
            if now < due:
                time.sleep(due - now)
            else:
                self._k = max(self._k, int((now - self._t0) * self.fps))  # skip missed frames
        t_s = self._k / self.fps
        if (not scene.loop and t_s > scene.duration_s) or (
                self.max_frames is not None and self.frames_read >= self.max_frames):
            self.ended = True
            self.failure = f"scene {scene.name!r} ended after {self.frames_read} frames"
            return False, None
        images, truth = self.simulator.render(t_s)
        self.t_s, self.truth = t_s, truth
        self._k += 1
        self.frames_read += 1
        return True, images

    def release(self) -> None:
        return None
