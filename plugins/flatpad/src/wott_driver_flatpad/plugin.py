"""The wott-hub plugin of the flat vision pad (entry point ``flatpad``): family ``flat-vision``.

Importing this module imports neither cv2 nor onnxruntime: the hooks only
describe the family and wire a driver together; cv2 is loaded by the driver's
worker thread when the device starts.
"""

from __future__ import annotations

from wott_hub.plugin_api import DeviceConfig, Driver, FamilyInfo, hookimpl, naming_device

from .settings import FAMILY, PadSettings, open_pad

__all__ = ["wott_hub_demo_devices", "wott_hub_families", "wott_hub_open_device"]


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "Flat vision pad (GelSight/DIGIT-style): one camera under a gel with a rows x cols marker "
        "grid; shear from marker motion, depth from apparent marker area (docs/flat-pad.md).",
        PadSettings,
    )]


@hookimpl
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    with naming_device(config):  # the registry calls this only for FAMILY's devices
        return open_pad(config.id, dict(config.settings))


@hookimpl
def wott_hub_demo_devices() -> list[DeviceConfig]:
    # 30 frames/s: rendering and estimating a 640x480 frame cost ~10 ms of CPU, and the demo
    # shares 2 cores with every other family's simulator
    return [DeviceConfig("flatpad-1", FAMILY, {"title": "Flat vision pad (simulated)", "source": "sim",
                                               "fps": 30.0})]
