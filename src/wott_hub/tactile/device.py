"""What a device says about itself: the static half of a Tactile TD."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from .materials import Material
from .mesh import SkinMesh

__all__ = ["DISPLACEMENT", "NODE_UNITS", "CoordinateFrame", "DeviceDescription", "NodeSignal", "SkinShape"]

ShapeType = Literal["rectangularPrism", "cylinder", "barrel"]

NODE_UNITS = {"displacement": "mm", "magneticField": "uT", "taxelSignal": "count", "force": "N"}
"""What a node's vector may measure (its vocabulary term) and the unit it is always given in."""


@dataclass(frozen=True, slots=True)
class NodeSignal:
    """What the 3-vector each frame gives a node measures (``TactileFrame.displacement`` carries it,
    whatever it is): a skin's displacement in mm (the default), a magnetometer's field change in µT, a
    taxel's signal change in counts (x, y shear, z normal), or a force in N. ε is in its unit; the TD
    states that unit and declares ``skinDisplacement`` only for a displacement (docs/skins.md,
    "Honest units"). A displacement becomes force through the skin's material, a force is summed, and
    any other signal gives no force at all (``contactForces`` is then empty)."""

    quantity: str = "displacement"

    def __post_init__(self) -> None:
        if self.quantity not in NODE_UNITS:
            raise ValueError(f"node signal must be one of {', '.join(NODE_UNITS)}, got {self.quantity!r}")

    @property
    def unit(self) -> str:
        return NODE_UNITS[self.quantity]

    @property
    def is_displacement(self) -> bool:
        return self.quantity == "displacement"

    @property
    def gives_force(self) -> bool:
        return self.quantity in ("displacement", "force")


DISPLACEMENT = NodeSignal()


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
    contacts weaker than that beside a stronger one (docs/processing.md). ``node_signal``: what the
    frames' node vectors measure; ``epsilon_mm`` is in its unit (mm for the default displacement).
    ``measures_contacts``: the driver measures its contacts itself, with their radii
    (``TactileFrame.contacts``, ``tactile.measured``): the TD declares ``contactRadii`` and
    ``contactInformation`` is unknown (null) until the driver's first frame with a reference;
    ``force_estimate`` says how such a device estimates its contacts' forces (the TD says it, an
    estimate); empty, it gives none and ``contactForces`` is empty. ``shear``: the device measures
    its nodes' in-plane motion (false: a gel without markers sees none, so its TD declares no
    ``skinDisplacement``).
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
    node_signal: NodeSignal = DISPLACEMENT
    measures_contacts: bool = False
    force_estimate: str = ""
    shear: bool = True
