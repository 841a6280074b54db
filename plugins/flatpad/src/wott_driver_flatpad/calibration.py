"""Calibrate the depth model on simulated presses of known depth.

Each sample is one press held still (no sideways drag): the simulator renders
the rest image and the pressed image, the estimator measures every free
marker's cue x = Z / Z0 - 1 (area ratios through the parallax solve), and the
scene's ground truth gives its dz. ``fit_depth_model`` then fits
dz = Σ a_k x^k by least squares. For a real pad, collect (x, dz) the same way
with a stage of known depth (``PadEstimate.cue``) and
call ``fit_depth_model`` directly.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from wott_hub.plugin_api import Scene

from .depth import DepthModel, fit_depth_model
from .estimator import PadEstimator
from .geometry import PadLayout
from .simulator import PadSimulator, RenderSettings

__all__ = ["calibrate", "calibration_samples"]


def _press_scene(layout: PadLayout, depths: Sequence[float],
                 radii: Sequence[float]) -> tuple[Scene, list[float]]:
    """One press per (depth, radius, place), each held for 1 s; returns the scene and the hold times."""
    span = np.array([(layout.cols - 1) * layout.pitch_mm, (layout.rows - 1) * layout.pitch_mm])
    places = [np.array(f) * span for f in ((0.5, 0.5), (0.33, 0.4), (0.62, 0.66))]
    steps: list[dict[str, Any]] = []
    holds: list[float] = []
    t = 0.5
    for i, depth in enumerate(depths):
        for j, radius in enumerate(radii):
            at = places[(i + j) % len(places)]
            steps.append({"kind": "press", "at": [float(at[0]), float(at[1]), 0.0], "start_s": t,
                          "duration_s": 1.0, "depth_mm": float(depth), "radius_mm": float(radius)})
            holds.append(t + 0.5)
            t += 1.5
    return Scene.from_dict({"scene": {"name": "flatpad-calibration"}, "step": steps}), holds


def calibration_samples(
    layout: PadLayout,
    render: RenderSettings | None = None,
    depths: Sequence[float] = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0),
    radii: Sequence[float] = (4.0, 6.0),
    parallax: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """(x, dz_true) over the free markers of every simulated press."""
    scene, holds = _press_scene(layout, depths, radii)
    sim = PadSimulator(layout, scene, render)
    est = PadEstimator(layout, parallax=parallax)
    rest, _ = sim.render(0.0)
    est.set_reference(rest)
    free = layout.mesh.free
    xs, dzs = [], []
    for t in holds:
        img, truth = sim.render(t)
        est.reset_tracking()
        e = est.update(img)
        xs.append(e.cue[free])
        dzs.append(truth[free, 2])
    return np.concatenate(xs), np.concatenate(dzs)


def calibrate(layout: PadLayout, render: RenderSettings | None = None, degree: int = 1,
              **kwargs: Any) -> DepthModel:
    """A depth model fitted on simulated presses of this layout and image chain.

    Degree 1 (a gain) by default: with the parallax solve the physical model
    has no visible curvature left over 0-3 mm (docs/flat-pad.md), and higher
    degrees only fit the noise of the many near-zero samples.
    """
    x, dz = calibration_samples(layout, render, **kwargs)
    return fit_depth_model(x, dz, degree, source=f"simulated presses, {layout.rows}x{layout.cols}")
