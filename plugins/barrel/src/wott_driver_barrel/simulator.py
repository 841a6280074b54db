"""The barrel's raw signal, simulated: both camera images of a scripted scene.

Ground truth is ``Scene.displacement_at(t, mesh)`` (the scene's own ``model``
key selects the indentation model or the Kelvin-Voigt skin the default model is
trained on), so whatever the scene's mechanics, the images and the truth agree.
Each marker is drawn where the camera model projects its displaced position,
with the apparent size its distance and slant give it (``BarrelLayout``); the
images then go through the same detector, tracker and model as a real
sensor's frames. Not simulated: self-occlusion of markers behind a deep bulge,
lighting changes, lens vignetting (docs/barrel-vision.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wott_hub.plugin_api import Scene

from .geometry import BarrelLayout

__all__ = ["BarrelSimulator", "RenderSettings"]


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
        self._rest: tuple[np.ndarray, ...] | None = None  # the pictures at rest, once drawn

    def truth(self, t_s: float) -> np.ndarray:
        """Ground-truth node displacement (N, 3) mm at scene time ``t_s``."""
        return self.scene.displacement_at(t_s, self.layout.mesh)

    def render_displacement(self, displacement: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """One uint8 (H, W) image per camera for a node displacement (None: at rest)."""
        return self._expose(self._pictures(displacement))

    def render(self, t_s: float) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
        """(images, truth) at scene time ``t_s``.

        The skin at rest looks the same until something touches it: its pictures are drawn
        once and only the sensor noise is new on each frame (the same bytes, a tenth of the cost).
        """
        truth = self.truth(t_s)
        if self.scene.touching(t_s):
            return self._expose(self._pictures(truth)), truth
        if self._rest is None:
            self._rest = self._pictures(truth)
        return self._expose(self._rest), truth

    def _pictures(self, displacement: np.ndarray | None) -> tuple[np.ndarray, ...]:
        from wott_vision.render import marker_picture

        s = self.settings
        points, radii = self.layout.points_and_radii(displacement)
        return tuple(
            marker_picture(p, r, size=(cam.height, cam.width), blur_sigma=s.blur_sigma,
                           intensity=s.intensity, background=s.background)
            for cam, p, r in zip(self.layout.cameras, points, radii, strict=True)
        )

    def _expose(self, pictures: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        from wott_vision.render import expose

        return tuple(expose(p, self.settings.noise_std, self._rng) for p in pictures)
