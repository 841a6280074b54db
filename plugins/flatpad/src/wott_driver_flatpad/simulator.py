"""A simulated flat vision pad: a scripted scene in, camera images out.

The scene's ground truth displacement (``Scene.displacement_at``) moves each
marker; the optics project it into the image. A marker is a small patch of
the gel surface, so its image area is R² π times the local area scale of the
mapping from the rest surface to the image, det(∂p/∂X0): that one number holds
the magnification of a closer marker, the in-plane stretch of the gel and the
foreshortening of a sloped surface seen off-axis (depth.py). It is computed on
the same scene evaluated on a grid ``refine`` times finer than the markers
(central differences over pitch / refine), so it is the local value, not the
marker-grid average the estimator's finite differences see; markers are drawn
as discs of that area (the ellipse a stretched marker really makes has the
same area, which is all the depth cue uses). The shared renderer (``wott_vision.render``) draws the
markers with blur and sensor noise, so the real detector and tracker run on
the result.

``wott_vision.simulated.SimulatedSource`` reads it like a camera, so the
driver drives a simulated pad exactly as it drives a USB camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wott_hub.plugin_api import Scene, flat_pad

from .geometry import PadLayout

__all__ = ["PadSimulator", "RenderSettings"]


@dataclass(frozen=True, slots=True)
class RenderSettings:
    blur_sigma: float = 1.0  # px: lens blur
    noise_std: float = 2.0  # grey levels: sensor noise
    seed: int = 0
    refine: int = 2  # ground-truth marker-area grid: pitch / refine


class PadSimulator:
    """Renders the marker image of ``scene`` at any scene time."""

    def __init__(self, layout: PadLayout, scene: Scene, render: RenderSettings | None = None) -> None:
        self.layout = layout
        self.scene = scene
        self.render_settings = render or RenderSettings()
        k = max(1, int(self.render_settings.refine))
        self._k = k
        self._fine = flat_pad((layout.rows - 1) * k + 1, (layout.cols - 1) * k + 1,
                              pitch_mm=layout.pitch_mm / k, name="flat-pad-fine")
        self._rng = np.random.default_rng(self.render_settings.seed)
        self._rest_radius = np.full(layout.n_markers, layout.marker_radius_mm)
        self._rest: np.ndarray | None = None  # the picture at rest, once drawn

    def truth(self, t_s: float) -> np.ndarray:
        """Ground-truth displacement (N x 3 mm) of the markers at scene time ``t_s``."""
        return self.scene.displacement_at(t_s, self.layout.mesh)

    def area_scale(self, t_s: float) -> np.ndarray:
        """det(∂p/∂X0) (px² per mm²) of the rest-surface-to-image mapping at each marker."""
        lay, k, o = self.layout, self._k, self.layout.optics
        d = self.scene.displacement_at(t_s, self._fine)
        fr, fc = (lay.rows - 1) * k + 1, (lay.cols - 1) * k + 1
        px = o.project(self._fine.nodes + d, lay.axis_mm).reshape(fr, fc, 2)
        h = lay.pitch_mm / k
        d_c = np.gradient(px, h, axis=1)[::k, ::k]
        d_r = np.gradient(px, h, axis=0)[::k, ::k]
        det: np.ndarray = (d_c[..., 0] * d_r[..., 1] - d_r[..., 0] * d_c[..., 1]).ravel()
        return det

    def markers(self, t_s: float, truth: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Image positions (M, 2) px and radii (M,) px of the markers at ``t_s``."""
        lay, o = self.layout, self.layout.optics
        d = self.truth(t_s) if truth is None else truth
        px = o.project(lay.mesh.nodes + d, lay.axis_mm)
        radius = self._rest_radius * np.sqrt(np.clip(self.area_scale(t_s), 1e-6, None))
        return px, radius

    def render(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(image (H, W) uint8, ground truth (N, 3) mm) at scene time ``t_s``.

        The pad at rest looks the same until something touches it: its picture is drawn once
        and only the sensor noise is new on each frame (the same bytes, a fraction of the cost).
        """
        from wott_vision.render import expose

        truth = self.truth(t_s)
        if self.scene.touching(t_s):
            picture = self._picture(t_s, truth)
        else:
            if self._rest is None:
                self._rest = self._picture(t_s, truth)
            picture = self._rest
        return expose(picture, self.render_settings.noise_std, self._rng), truth

    def _picture(self, t_s: float, truth: np.ndarray) -> np.ndarray:
        from wott_vision.render import marker_picture

        px, radius = self.markers(t_s, truth)
        o = self.layout.optics
        return marker_picture(px, radius, size=(o.height, o.width),
                              blur_sigma=self.render_settings.blur_sigma)
