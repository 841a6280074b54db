"""What a device says about itself: the static half of a Tactile TD."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from .materials import Material
from .mesh import SkinMesh

__all__ = ["CoordinateFrame", "DeviceDescription", "SkinShape"]

ShapeType = Literal["rectangularPrism", "cylinder", "barrel"]


@dataclass(frozen=True, slots=True)
class SkinShape:
    """The skin's nominal shape and dimensions (mm); only the relevant ones are set."""

    shape_type: ShapeType
    length_mm: float | None = None
    width_mm: float | None = None
    height_mm: float | None = None
    base_radius_mm: float | None = None
    middle_radius_mm: float | None = None


@dataclass(frozen=True, slots=True)
class CoordinateFrame:
    """Right-handed frame of all vectors the device reports (x forward, y left, z up)."""

    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    x_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    y_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    z_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    origin_name: str = "centerOfBottomCircle"


@dataclass(frozen=True)
class DeviceDescription:
    """Everything needed to build a device's Tactile TD and to process its frames.

    ``side_lobe_ratio``: the largest spurious peak the device's estimate makes
    beside a press, as a fraction of the press's peak (a camera model's side
    lobes; 0 for a device that measures each node directly). Processing drops
    contacts weaker than that beside a stronger one (docs/processing.md).
    """

    id: str
    title: str
    family: str
    shape: SkinShape
    material: Material
    mesh: SkinMesh
    frame: CoordinateFrame = field(default_factory=CoordinateFrame)
    epsilon_mm: float = 0.1
    thickness_mm: float = 3.0
    description: str = ""
    side_lobe_ratio: float = 0.0
