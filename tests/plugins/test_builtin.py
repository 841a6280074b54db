"""The built-in ``scene`` family: a scene's ground truth through the registry."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from wott_hub.drivers.base import DriverError
from wott_hub.plugins import DeviceConfig, Registry
from wott_hub.sim.scene import Scene

STEPS = [{"kind": "press", "at": [10.0, 10.0, 0.0], "start_s": 0.02, "duration_s": 0.1, "depth_mm": 1.2},
         {"kind": "tap", "at": [4.0, 15.0, 0.0], "start_s": 0.1, "depth_mm": 0.8, "radius_mm": 3.0}]


@pytest.fixture
def registry() -> Registry:
    return Registry(only=[])  # the built-in plugin alone


def frames_of(driver, n):
    async def collect():
        out = []
        async for f in driver.frames():
            out.append(f)
            if len(out) == n:
                break
        await driver.close()
        return out

    return asyncio.run(collect())


def test_scene_device_yields_the_scene_ground_truth(registry, tmp_path):
    cfg = DeviceConfig("bench", "scene", {"step": STEPS, "rate_hz": 100, "realtime": False, "title": "Bench"})
    driver = registry.open_device(cfg)
    desc = driver.description
    assert (desc.family, desc.title, desc.mesh.n_nodes) == ("scene", "Bench", 256)
    frames = frames_of(driver, 30)
    scene = Scene.from_dict({"scene": {"loop": True}, "step": STEPS})
    for k, f in enumerate(frames):
        np.testing.assert_array_equal(f.displacement, scene.displacement_at(k / 100, desc.mesh))
    assert max(np.abs(f.displacement).max() for f in frames) > 1.0  # the press is in there


def test_scene_file_and_overrides(registry, tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[scene]\nname = "s"\n[[step]]\nkind = "press"\nat = [0.0, 53.0, 130.0]\n')
    cfg = DeviceConfig("b", "scene", {"scene": str(path), "shape": "barrel", "material": "dragonskin-20",
                                      "epsilon_mm": 0.2})
    desc = registry.open_device(cfg).description
    assert (desc.material.shore_hardness, desc.epsilon_mm, desc.mesh.n_nodes) == ("Shore A20", 0.2, 707)


@pytest.mark.parametrize(("settings", "message"), [
    ({}, "setting 'scene': needs one of 'scene' or 'step'"),
    ({"scene": "x.toml", "step": STEPS}, "setting 'scene': give only one of 'scene' or 'step'"),
    ({"step": [{"kind": "poke", "at": [0, 0, 0]}]}, "setting 'scene': device 'b' step: step[0].kind: 'poke'"),
    ({"step": STEPS, "material": "rubber"}, "setting 'material': 'rubber' is not one of"),
    ({"step": STEPS, "rate_hz": 0}, "setting 'rate_hz': 0 is less than or equal to the minimum of 0"),
])
def test_bad_scene_settings_name_the_field(registry, settings, message):
    with pytest.raises(DriverError) as e:
        registry.open_device(DeviceConfig("b", "scene", settings))
    assert str(e.value).startswith(f"device 'b' (family 'scene'): {message}")


def test_a_scene_file_is_read_when_the_device_opens_and_its_errors_name_the_setting(registry, tmp_path):
    from wott_hub.runtime.opening import open_driver

    missing = DeviceConfig("b", "scene", {"scene": "/no/such/scene.toml"})
    with pytest.raises(DriverError) as e:
        asyncio.run(open_driver(missing, registry))  # read by prepare(), off the event loop
    assert str(e.value) == ("device 'b' (family 'scene'): setting 'scene': /no/such/scene.toml: "
                            "No such file or directory")
    path = tmp_path / "s.toml"
    path.write_text('[scene]\nname = "s"\n[[step]]\nkind = "press"\nat = [0.0, 0.0, 0.0]\n')
    driver = asyncio.run(open_driver(DeviceConfig("b", "scene", {"scene": str(path)}), registry))
    assert driver.scene.name == "s"
