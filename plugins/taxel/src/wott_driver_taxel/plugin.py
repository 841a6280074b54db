"""The ``taxel-array`` family for wott-hub (entry point ``taxel`` in group ``wott_hub.drivers``).

Imports stay light here (no pyserial until a device is opened) so that listing
plugins or loading the registry costs nothing for hubs without taxel arrays.
"""

from __future__ import annotations

from importlib import resources
from typing import Any

from wott_hub.plugins import DeviceConfig, FamilyInfo, hookimpl, naming_device
from wott_hub.plugins.settings import BACKOFF_PROPERTIES
from wott_hub.tactile.materials import MATERIALS

FAMILY = "taxel-array"
DEMO_SCENE = "demo.toml"

SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "properties": {
        "title": {"type": "string", "description": "Human-readable name; default the device id."},
        "port": {"type": "string", "minLength": 1,
                 "description": "Serial device (/dev/ttyUSB0, COM3) or pyserial URL (socket://host:port)."},
        "baudrate": {"type": "integer", "minimum": 1, "default": 921600, "description": "Bits per second."},
        "protocol": {"enum": ["binary", "ascii"], "default": "binary",
                     "description": "Framed binary or ASCII lines (docs/taxel-protocol.md)."},
        "rows": {"type": "integer", "minimum": 2, "maximum": 255, "default": 16,
                 "description": "Taxel rows (along device y)."},
        "cols": {"type": "integer", "minimum": 2, "maximum": 255, "default": 16,
                 "description": "Taxel columns (along device x)."},
        "pitch_mm": {"type": "number", "exclusiveMinimum": 0, "default": 4.0,
                     "description": "Taxel spacing, mm."},
        "material": {"enum": sorted(MATERIALS), "default": "ecoflex-00-30",
                     "description": "Skin over the taxels (its modulus sets the compliance)."},
        "thickness_mm": {"type": "number", "exclusiveMinimum": 0, "default": 3.0,
                         "description": "Skin thickness over the taxels, mm."},
        "kpa_per_count": {"type": "number", "exclusiveMinimum": 0, "default": 0.01,
                          "description": "Pressure of one count of a 16-bit taxel value, kPa."},
        "epsilon_mm": {"type": "number", "exclusiveMinimum": 0, "default": 0.05,
                       "description": "Displacement above which a taxel counts as deformed, mm."},
        "simulate": {"type": "boolean", "default": False,
                     "description": "Play a scene on a simulated board over a pty instead of opening port."},
        "scene": {"type": "string",
                  "description": "Scene TOML the simulator plays; default the bundled demo scene."},
        "rate_hz": {"type": "number", "exclusiveMinimum": 0, "maximum": 2000, "default": 100.0,
                    "description": "Simulator frame rate, frames/s."},
        **BACKOFF_PROPERTIES,
    },
    "additionalProperties": False,
    # A real board needs its port; a simulated one makes its own.
    "if": {"not": {"required": ["simulate"], "properties": {"simulate": {"const": True}}}},
    "then": {"required": ["port"]},
}


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "Serial taxel array: rows x cols pressure cells over pyserial (framed binary or ASCII lines); "
        "pressure -> normal displacement through the skin's compliance.",
        SCHEMA,
    )]


@hookimpl
def wott_hub_open_device(config: DeviceConfig):
    if config.family != FAMILY:
        return None
    return open_taxel_device(config)


@hookimpl
def wott_hub_demo_devices() -> list[DeviceConfig]:
    return [DeviceConfig("taxel-1", FAMILY, {"title": "Taxel array (simulated)", "simulate": True})]


def demo_scene_text() -> str:
    return resources.files("wott_driver_taxel").joinpath("scenes", DEMO_SCENE).read_text()


def open_taxel_device(config: DeviceConfig):
    """Build the driver from validated settings (defaults filled in by the registry)."""
    import tomllib
    from dataclasses import replace

    from wott_hub.drivers.base import DriverError
    from wott_hub.plugins.settings import backoff, with_defaults
    from wott_hub.sim.scene import Scene, SceneError
    from wott_hub.tactile import CoordinateFrame, DeviceDescription, SkinShape, flat_pad

    from .compliance import Compliance
    from .driver import TaxelDriver
    from .protocol import MAX_VALUES
    from .simulator import TaxelSimulator

    s = with_defaults(SCHEMA, config.settings)
    rows, cols = int(s["rows"]), int(s["cols"])
    with naming_device(config):
        if rows * cols > MAX_VALUES:
            raise DriverError(f"setting 'rows': {rows} x {cols} taxels do not fit a frame "
                              f"(max {MAX_VALUES} values)")
        if s["backoff_cap_s"] < s["backoff_initial_s"]:
            raise DriverError("setting 'backoff_cap_s': must not be below backoff_initial_s")
        reconnect = backoff(s)
    pitch, thickness = float(s["pitch_mm"]), float(s["thickness_mm"])
    material = MATERIALS[s["material"]]
    mesh = flat_pad(rows, cols, pitch_mm=pitch, clamp_border=False, name=f"taxel-{rows}x{cols}")
    desc = DeviceDescription(
        id=config.id, title=s.get("title", config.id), family=FAMILY,
        shape=SkinShape("rectangularPrism", length_mm=cols * pitch, width_mm=rows * pitch,
                        height_mm=thickness),
        material=material, mesh=mesh, frame=CoordinateFrame(origin_name="cornerOfPad"),
        epsilon_mm=float(s["epsilon_mm"]), thickness_mm=thickness,
        description=f"{rows} x {cols} taxel array, {pitch:g} mm pitch, {s['protocol']} protocol",
    )
    compliance = Compliance(material.modulus_mpa * 1000.0, thickness, float(s["kpa_per_count"]))
    simulator = None
    if s["simulate"]:
        with naming_device(config):
            try:
                if "scene" in s:
                    scene = Scene.load(s["scene"])
                else:
                    scene = Scene.from_dict(tomllib.loads(demo_scene_text()),
                                            source=f"wott_driver_taxel/scenes/{DEMO_SCENE}")
            except SceneError as e:
                raise DriverError(f"setting 'scene': {e}") from None
        simulator = TaxelSimulator(scene, mesh, (rows, cols), compliance, rate_hz=float(s["rate_hz"]),
                                   protocol=s["protocol"])
        desc = replace(desc, description=desc.description + " (simulated)")
    return TaxelDriver(
        desc, shape=(rows, cols), compliance=compliance, port=s.get("port"), baudrate=int(s["baudrate"]),
        protocol=s["protocol"], simulator=simulator, backoff=reconnect,
    )
