"""The wott-hub plugin of the barrel vision skin (entry point ``barrel``): family ``barrel-vision``.

Importing this module imports neither cv2 nor onnxruntime: the hooks describe
the family and wire a driver together. Opening a device loads its ONNX model
(onnxruntime), so a model that does not fit is refused right there; the
cameras (cv2) are opened by the driver's worker thread when the device starts.
"""

from __future__ import annotations

from wott_hub.plugin_api import DeviceConfig, Driver, FamilyInfo, hookimpl, naming_device

from .settings import FAMILY, BarrelSettings, open_barrel

__all__ = ["wott_hub_demo_devices", "wott_hub_families", "wott_hub_open_device"]


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "Barrel vision skin (TacLink-style): two fisheye cameras inside a barrel skin with 16 x 16 "
        "markers; marker tracking and an ONNX model give the 585 free nodes' displacement "
        "(docs/barrel-vision.md).",
        BarrelSettings,
    )]


@hookimpl
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    with naming_device(config):  # the registry calls this only for FAMILY's devices
        return open_barrel(config.id, dict(config.settings))


@hookimpl
def wott_hub_demo_devices() -> list[DeviceConfig]:
    return [DeviceConfig("barrel-1", FAMILY, {"title": "Barrel vision skin (simulated)", "source": "sim"})]
