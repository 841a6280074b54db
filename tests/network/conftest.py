from __future__ import annotations

import pytest


def scene_device(device_id: str, shape: str = "flat"):
    """A ``scene`` device pressing its skin now and then (cheap: flat and cylinder skins)."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device(shape).mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
    return DeviceConfig(device_id, "scene", {"shape": shape, "loop": True, "rate_hz": 60.0, "step": [
        {"kind": "press", "at": at, "start_s": 0.1, "duration_s": 0.3, "depth_mm": 1.0, "radius_mm": 4.0}]})


@pytest.fixture(scope="session")
def scene():
    """scene(device_id, shape="flat") -> DeviceConfig (test modules cannot import conftest)."""
    return scene_device
