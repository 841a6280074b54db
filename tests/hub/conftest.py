from __future__ import annotations

import pytest


def scene_device(device_id: str, shape: str, rate_hz: float = 120.0):
    """A ``scene``-family DeviceConfig touching its skin almost all the time (a busy stream)."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device(shape).mesh
    free = mesh.free_indices
    a = [float(v) for v in mesh.nodes[free[len(free) // 2]]]
    b = [float(v) for v in mesh.nodes[free[len(free) // 3]]]
    radius = 12.0 if shape == "barrel" else 4.0
    return DeviceConfig(device_id, "scene", {
        "shape": shape, "loop": True, "rate_hz": rate_hz, "step": [
            {"kind": "press", "at": a, "start_s": 0.0, "duration_s": 0.6, "depth_mm": 2.0,
             "radius_mm": radius},
            {"kind": "slide", "at": b, "to": a, "start_s": 0.7, "duration_s": 0.6, "depth_mm": 1.5,
             "radius_mm": radius},
        ]})


@pytest.fixture(scope="session")
def scene():
    return scene_device
