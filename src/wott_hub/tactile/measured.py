"""Contacts a driver measures itself, beside the node field (issue 44).

A gel sensor (GelSight Mini, DIGIT) sees each contact directly: the patch of the
gel whose colour changed, its centre and its radius. Deriving contacts again from
a coarse node field would lose both (a contact's radius is finer than a node's
spacing). Such a driver hands its contacts with the frame (``TactileFrame.contacts``)
and declares it (``DeviceDescription.measures_contacts``); the processor then reports
them as measured (tracked across frames like any contact) and ``contactInformation``
carries ``contactRadii`` beside ``contactLocations``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wott_hub.errors import InvalidInput

__all__ = ["MeasuredContact"]


@dataclass(frozen=True, slots=True)
class MeasuredContact:
    """One measured contact: centre (mm, device frame), radius (mm), the depth at its centre (mm, 0:
    not measured) and the force on the skin (N, into it; zeros: not estimated)."""

    location: tuple[float, float, float]
    radius_mm: float
    depth_mm: float = 0.0
    force_n: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        values = (*self.location, self.radius_mm, self.depth_mm, *self.force_n)
        if len(self.location) != 3 or len(self.force_n) != 3:
            raise InvalidInput("a measured contact's location and force are 3-vectors")
        if not all(math.isfinite(v) for v in values):
            raise InvalidInput(f"a measured contact has a NaN/Inf value: {values}")
        if self.radius_mm < 0:
            raise InvalidInput(f"a measured contact's radius must be >= 0, got {self.radius_mm}")
