"""``naming_device``: a family builder's DriverError gains the device and family, nothing else does."""

import pytest

from wott_hub.drivers.base import DriverError
from wott_hub.plugins import DeviceConfig, Registry, naming_device


def test_driver_errors_name_the_device_and_family_other_errors_pass_unchanged():
    cfg = DeviceConfig("left", "barrel-vision", {})
    with pytest.raises(DriverError) as e, naming_device(cfg):
        raise DriverError("fps: must be positive, got 0.0")
    assert str(e.value) == "device 'left' (family 'barrel-vision'): fps: must be positive, got 0.0"
    with pytest.raises(KeyError), naming_device(cfg):  # a bug stays a bug: the registry records it
        raise KeyError("camera")


def test_camera_families_word_their_errors_like_the_registry():
    registry = Registry(only=["barrel", "flatpad"])
    for family in ("barrel-vision", "flat-vision"):
        with pytest.raises(DriverError) as e:
            registry.open_device(DeviceConfig("d", family, {"scene": "/no/such/scene.toml"}))
        assert str(e.value).startswith(f"device 'd' (family '{family}'): scene: /no/such/scene.toml")
