"""A simulator read like a camera, so a driver runs a simulated skin exactly as a real one.

Both camera-based families (barrel, flat pad) have a simulator with a
``scene`` and ``render(t_s) -> (images, truth)``; this reader paces it.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import numpy as np

from wott_hub.plugin_api import Scene

__all__ = ["SimulatedSource", "Simulator"]


class Simulator(Protocol):
    scene: Scene

    def render(self, t_s: float) -> tuple[Any, np.ndarray]:
        """(the camera image(s), ground-truth displacement) at scene time ``t_s``."""


class SimulatedSource:
    """VideoCapture-like reader over a ``Simulator`` at ``fps``.

    ``realtime`` paces ``read()`` like a camera (frame k is due k / fps after
    the first read; a slow reader skips frames, as a camera drops them);
    otherwise frames come as fast as they are read, still 1 / fps apart in
    scene time. A scene that does not loop ends: ``read()`` then returns
    ``(False, None)``, ``ended`` is true and ``failure`` says so. ``t_s`` and
    ``truth`` describe the frame last read; in real time, ``captured_s`` is the
    monotonic instant it was due (its exposure, as a camera's buffer timestamp
    says), not when a busy reader got round to it: the driver stamps the frame
    with that, so a late read does not move the frame in time.
    """

    def __init__(self, simulator: Simulator, fps: float, *, realtime: bool = True) -> None:
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.simulator = simulator
        self.fps = float(fps)
        self.realtime = realtime
        self.frames_read = 0
        self.ended = False
        self.failure = ""
        self.t_s = 0.0
        self.captured_s: float | None = None  # monotonic s the frame last read was due (real time only)
        self.truth: np.ndarray | None = None
        self._k = 0  # index of the next frame (ahead of frames_read once frames were skipped)
        self._t0: float | None = None
        self._opened = True

    def isOpened(self) -> bool:  # noqa: N802 - the cv2.VideoCapture spelling
        return self._opened and not self.ended

    def read(self) -> tuple[bool, Any]:
        if not self.isOpened():
            return False, None
        if self.realtime:
            now = time.monotonic()
            if self._t0 is None:
                self._t0 = now
            due = self._t0 + self._k / self.fps
            if now < due:
                time.sleep(due - now)
            else:
                self._k = max(self._k, int((now - self._t0) * self.fps))  # skip missed frames
        scene = self.simulator.scene
        t_s = self._k / self.fps
        if not scene.loop and t_s > scene.duration_s:
            self.ended = True
            self.failure = f"scene {scene.name!r} ended after {self.frames_read} frames"
            return False, None
        images, truth = self.simulator.render(t_s)
        self.t_s, self.truth = t_s, truth
        if self._t0 is not None:
            self.captured_s = self._t0 + self._k / self.fps
        self._k += 1
        self.frames_read += 1
        return True, images

    def release(self) -> None:
        self._opened = False
