"""The wott-hub plugin of the gel sensors (entry point ``gel``): families ``gelsight-mini`` and ``digit``.

Importing this module imports neither cv2 nor pyudev: the hooks describe the families and wire a
driver together; a recording is probed (cv2) when a device opens, a sensor when it runs.
"""

from __future__ import annotations

from wott_hub.plugin_api import DeviceConfig, Driver, FamilyInfo, hookimpl, naming_device

from .settings import DIGIT, MINI, DigitSettings, MiniSettings, open_gel

__all__ = ["wott_hub_calibrate", "wott_hub_families", "wott_hub_open_device"]


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [
        FamilyInfo(MINI, "GelSight Mini: a USB camera under a lit gel; contacts (centre, radius) from colour "
                         "change against the rest frame (docs/gel.md).", MiniSettings),
        FamilyInfo(DIGIT, "DIGIT (Meta/GelSight): a USB camera under a lit gel, frames turned 90°; contacts "
                          "(centre, radius) from colour change against the rest frame (docs/gel.md).",
                   DigitSettings),
    ]


@hookimpl
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    with naming_device(config):  # the registry calls this only for MINI's and DIGIT's devices
        return open_gel(config.id, config.family, dict(config.settings))


@hookimpl
def wott_hub_calibrate(family: str, data: str, out: str, options: dict[str, str]) -> str:
    from .calibration import calibrate_file

    return calibrate_file(family, data, out, options)
