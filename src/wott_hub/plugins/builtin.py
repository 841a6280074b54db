"""The plugin inside the core package: family ``scene``, the ground-truth driver, and
family ``wot-remote``, tactile devices that speak WoT themselves (``wot_remote.py``).

A ``scene`` device plays a scripted scene on one of the example skins and
yields its ground-truth displacement directly (no raw signal, no simulator of
a transport), for benchmarks, tests and trying the hub out. Device families
with real hardware live in their own distributions under ``plugins/``.
"""

from __future__ import annotations

from typing import Any

from wott_hub.tactile.materials import MATERIALS

from . import wot_remote
from .hookspecs import hookimpl
from .model import DeviceConfig, FamilyInfo
from .naming import naming_device

FAMILY = "scene"

SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "properties": {
        "title": {"type": "string", "description": "Human-readable name (default: the device id)."},
        "shape": {"enum": ["barrel", "flat", "cylinder"], "default": "flat",
                  "description": "Example skin to play the scene on (wott-hub td show --shape)."},
        "scene": {"type": "string",
                  "description": "Scene TOML file (docs/scenes.md), relative to the working folder."},
        "step": {"type": "array", "items": {"type": "object"}, "minItems": 1,
                 "description": "Inline scene steps, as [[device.step]] tables, instead of a scene file."},
        "loop": {"type": "boolean", "description": "With inline steps: replay forever.", "default": True},
        "rate_hz": {"type": "number", "exclusiveMinimum": 0, "default": 120.0,
                    "description": "Frames per second."},
        "realtime": {"type": "boolean", "default": True,
                     "description": "Pace frames on the clock; false yields them as fast as they are read."},
        "material": {"enum": sorted(MATERIALS), "description": "Skin material; default: the example skin's."},
        "epsilon_mm": {"type": "number", "exclusiveMinimum": 0,
                       "description": "Deformation threshold ε in mm; default: the example skin's."},
    },
    "additionalProperties": False,
    "oneOf": [{"required": ["scene"]}, {"required": ["step"]}],
}


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "Ground truth of a scripted scene on an example skin, no raw signal (benchmarks, tests).",
        SCHEMA,
    ), wot_remote.family()]


@hookimpl
def wott_hub_open_device(config: DeviceConfig):
    if config.family == wot_remote.FAMILY:
        return wot_remote.open_device(config)
    if config.family != FAMILY:
        return None
    from dataclasses import replace

    from wott_hub.drivers.base import DriverError
    from wott_hub.drivers.scene import SceneDriver
    from wott_hub.examples import example_device
    from wott_hub.sim.scene import Scene, SceneError

    s = config.settings
    with naming_device(config):
        try:
            if "scene" in s:
                scene = Scene.load(s["scene"])
            else:
                scene = Scene.from_dict({"scene": {"name": config.id, "loop": s["loop"]}, "step": s["step"]},
                                        source=f"device {config.id!r} step")
        except SceneError as e:
            raise DriverError(f"setting 'scene': {e}") from None
    desc = example_device(s["shape"], device_id=config.id)
    changes: dict[str, Any] = {"family": FAMILY, "title": s.get("title", config.id)}
    if "material" in s:
        changes["material"] = MATERIALS[s["material"]]
    if "epsilon_mm" in s:
        changes["epsilon_mm"] = float(s["epsilon_mm"])
    return SceneDriver(replace(desc, **changes), scene, float(s["rate_hz"]), realtime=bool(s["realtime"]))


@hookimpl
def wott_hub_claim_td(td: dict[str, Any]) -> DeviceConfig | None:
    return wot_remote.claim_td(td)
