"""The plugin inside the core package: family ``scene``, the ground-truth driver, and
family ``wot-remote``, tactile devices that speak WoT themselves (``wot_remote.py``); and the USB
ids of the gel sensors' cameras (``usb_cameras.py``), whose families are another plugin's.

A ``scene`` device plays a scripted scene on one of the example skins and
yields its ground-truth displacement directly (no raw signal, no simulator of
a transport), for benchmarks, tests and trying the hub out. Device families
with real hardware live in their own distributions under ``plugins/``.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

from wott_hub.configspec import says
from wott_hub.drivers.base import Driver
from wott_hub.tactile.materials import MATERIALS

from . import wot_remote
from .hookspecs import hookimpl
from .model import DeviceConfig, FamilyInfo, UsbMatch
from .naming import naming_device
from .settings import Meta, SettingsModel, read_settings, settings_schema

FAMILY = "scene"


class SceneSettings(SettingsModel):
    """A ``scene`` device's settings, declared once (bounds, defaults, descriptions); ``SCHEMA``
    is derived for docs and the registry. Exactly one of ``scene`` and ``step`` is given."""

    json_schema_extra: ClassVar[dict[str, Any]] = {"oneOf": [{"required": ["scene"]}, {"required": ["step"]}]}

    title: Annotated[str, Meta(description="Human-readable name (default: the device id).")] | None = None
    shape: Annotated[Literal["barrel", "flat", "cylinder"], Meta(
        description="Example skin to play the scene on (wott-hub td show --shape).")] = "flat"
    scene: Annotated[str, Meta(
        description="Scene TOML file (docs/scenes.md), relative to the working folder.")] | None = None
    step: Annotated[list[dict[str, Any]], Meta(min_length=1, description=(
        "Inline scene steps, as [[device.step]] tables, instead of a scene file."))] | None = None
    loop: Annotated[bool, Meta(description="With inline steps: replay forever.")] = True
    rate_hz: Annotated[float, says("a finite number", gt=0, le=10_000,
                                   description="Frames per second.")] = 120.0
    realtime: Annotated[bool, Meta(
        description="Pace frames on the clock; false yields them as fast as they are read.")] = True
    material: Annotated[str, Meta(extra_json_schema={"enum": sorted(MATERIALS)},
                                  description="Skin material; default: the example skin's.")] | None = None
    epsilon_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Deformation threshold ε in mm; default: the example skin's."))] | None = None


SCHEMA: dict[str, Any] = settings_schema(SceneSettings)


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "Ground truth of a scripted scene on an example skin, no raw signal (benchmarks, tests).",
        SceneSettings,
    ), wot_remote.family()]


@hookimpl
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    # Called only for this plugin's two families: which of them is the only question.
    if config.family == wot_remote.FAMILY:
        return wot_remote.open_device(config)
    from dataclasses import replace

    from wott_hub.drivers.scene import SceneDriver
    from wott_hub.errors import SettingsError
    from wott_hub.examples import example_device
    from wott_hub.sim.scene import Scene, SceneError

    with naming_device(config):
        s = read_settings(SceneSettings, config.settings)
        if (s.scene is None) == (s.step is None):  # the registry's schema says so too; opened directly
            raise SettingsError("setting 'scene': needs one of 'scene' or 'step'" if s.scene is None
                                else "setting 'scene': give only one of 'scene' or 'step'")
        if s.material is not None and s.material not in MATERIALS:
            raise SettingsError(f"setting 'material': {s.material!r} is not one of {sorted(MATERIALS)}")
        scene: Scene | str
        try:
            if s.scene is not None:
                scene = s.scene  # read by the driver's prepare(), off the event loop and bounded
            else:
                scene = Scene.from_dict({"scene": {"name": config.id, "loop": s.loop}, "step": s.step},
                                        source=f"device {config.id!r} step")
        except SceneError as e:
            raise SettingsError(f"setting 'scene': {e}") from None
    desc = example_device(s.shape, device_id=config.id)
    changes: dict[str, Any] = {"family": FAMILY, "title": config.id if s.title is None else s.title}
    if s.material is not None:
        changes["material"] = MATERIALS[s.material]
    if s.epsilon_mm is not None:
        changes["epsilon_mm"] = s.epsilon_mm
    return SceneDriver(replace(desc, **changes), scene, s.rate_hz, realtime=s.realtime)


@hookimpl
def wott_hub_claim_td(td: dict[str, Any]) -> DeviceConfig | None:
    return wot_remote.claim_td(td)


@hookimpl
def wott_hub_usb_devices() -> list[UsbMatch]:
    from .usb_cameras import CAMERAS

    return list(CAMERAS)
