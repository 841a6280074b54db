"""The demo fleet ``wott-hub run`` serves without a config: live devices whatever is installed."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from wott_hub.examples import example_device

from .model import DeviceConfig
from .registry import get_registry

if TYPE_CHECKING:
    from wott_hub.tactile import SkinMesh

__all__ = ["demo_devices"]


def demo_devices() -> list[DeviceConfig]:
    """The demo fleet: each installed plugin's simulated devices (``wott_hub_demo_devices``).

    With no plugin contributing any, the built-in ``scene`` family plays a
    looping scene (press, slide, tap, pinch) on each example skin, so
    ``wott-hub run`` always shows live devices.
    """
    found = get_registry().demo_devices()
    if found:
        return found
    out = []
    for shape in ("barrel", "flat", "cylinder"):
        mesh = example_device(shape).mesh
        out.append(DeviceConfig(f"scene-{shape}", "scene", {
            "title": f"{shape} skin (scene)", "shape": shape, "loop": True, "step": _demo_steps(mesh)}))
    return out


def _demo_steps(mesh: SkinMesh) -> list[dict[str, Any]]:
    """A looping scene on ``mesh``: press, slide, tap and pinch on free nodes around its middle.

    On a skin around an axis (barrel, cylinder) the middle is inside it, so the steps go around
    the middle of the half the device page's default camera looks at (from +x, -y; docs/twin.md):
    a new user sees them without turning the view.
    """
    free = mesh.free_indices
    pts = mesh.nodes[free]
    centre = pts.mean(axis=0)
    dist = np.sqrt(((pts - centre) ** 2).sum(axis=1))
    if dist.min() > 0.25 * dist.max():  # hollow: nothing near the middle
        towards = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)  # the camera's side, horizontally
        side = (pts - centre) @ towards
        centre = centre + towards * float(np.median(side[side > 0]))
        free, pts = free[side > 0], pts[side > 0]
    order = free[((pts - centre) ** 2).sum(axis=1).argsort()]
    scale = float(max(pts.max(axis=0) - pts.min(axis=0)))
    radius = max(scale / 12, 2.0)
    depth = min(2.0, radius / 2)

    def at(i: int) -> list[float]:
        return [round(float(v), 3) for v in mesh.nodes[order[min(i, len(order) - 1)]]]

    far = len(order) // 3
    return [
        {"kind": "press", "at": at(0), "start_s": 0.5, "duration_s": 1.0, "depth_mm": depth,
         "radius_mm": radius},
        {"kind": "slide", "at": at(far), "to": at(0), "start_s": 2.0, "duration_s": 1.5,
         "depth_mm": depth * 0.8, "radius_mm": radius, "shear_mm": depth / 4},
        {"kind": "tap", "at": at(far // 2), "start_s": 4.0, "depth_mm": depth, "radius_mm": radius},
        {"kind": "pinch", "at": at(far), "to": at(2 * far), "start_s": 4.8, "duration_s": 1.0,
         "depth_mm": depth, "radius_mm": radius, "approach_mm": radius},
    ]
