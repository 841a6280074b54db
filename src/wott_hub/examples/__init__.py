"""Example devices, one per shape: used by ``td show``, the demo fleet (demo.py) and tests."""

from __future__ import annotations

from wott_hub.tactile import (
    MATERIALS,
    CoordinateFrame,
    DeviceDescription,
    SkinShape,
    cylinder,
    flat_pad,
    taclink_barrel,
)

__all__ = ["example_device"]


def example_device(shape: str, device_id: str | None = None) -> DeviceDescription:
    """A realistic device of the given shape: barrel (TacLink), flat (pad), cylinder."""
    if shape == "barrel":
        return DeviceDescription(
            id=device_id or "barrel-1", title=device_id or "barrel-1", family="barrel-vision",
            shape=SkinShape("barrel", height_mm=260.0, base_radius_mm=36.28, middle_radius_mm=53.36),
            material=MATERIALS["ecoflex-00-30"], mesh=taclink_barrel(), epsilon_mm=0.1,
            thickness_mm=3.0,
        )
    if shape == "flat":
        mesh = flat_pad(16, 16, pitch_mm=1.5, name="flat-pad")
        return DeviceDescription(
            id=device_id or "pad-1", title=device_id or "pad-1", family="flat-vision",
            shape=SkinShape("rectangularPrism", length_mm=22.5, width_mm=22.5, height_mm=4.0),
            material=MATERIALS["ecoflex-00-50"], mesh=mesh, epsilon_mm=0.02, thickness_mm=4.0,
            frame=CoordinateFrame(origin_name="cornerOfPad"),
        )
    if shape == "cylinder":
        mesh = cylinder(40.0, 120.0, rings=16, rays=24, clamp_margin_mm=10.0)
        return DeviceDescription(
            id=device_id or "cylinder-1", title=device_id or "cylinder-1", family="taxel-array",
            shape=SkinShape("cylinder", height_mm=120.0, base_radius_mm=40.0),
            material=MATERIALS["dragonskin-10"], mesh=mesh, epsilon_mm=0.05, thickness_mm=2.0,
        )
    raise ValueError(f"unknown shape {shape!r}: expected barrel, flat or cylinder")
