"""Skin materials: names, Shore hardness and the elastic modulus derived from it.

Datasheets give silicone skins as a Shore hardness; mechanics needs a Young's
modulus. The conversion used here is Gent's relation for Shore A,
E[MPa] = 0.0981 (56 + 7.62336 S) / (0.137505 (254 - 2.54 S)), and for Shore 00
Shore 00 a straight line through Smooth-On's Ecoflex datasheet values (100 %
modulus of 00-10, 00-30, 00-50), extended to 00-100 where it meets Gent's A0.
Both are empirical; expect ±30 % on soft silicones (docs/mechanics.md).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["Material", "MaterialError", "shore_to_modulus_mpa", "MATERIALS"]


class MaterialError(ValueError):
    """Unknown hardness scale or a value outside it."""


_SHORE = re.compile(r"^\s*shore\s*(00|a)\s*-?\s*(\d+(?:\.\d+)?)\s*$", re.IGNORECASE)


def shore_to_modulus_mpa(shore: str) -> float:
    """Young's modulus (MPa) from a hardness string such as ``"Shore 00-30"`` or ``"Shore A20"``."""
    m = _SHORE.match(shore)
    if not m:
        raise MaterialError(f"cannot read hardness {shore!r}: expected 'Shore 00-NN' or 'Shore ANN'")
    scale, value = m.group(1).upper(), float(m.group(2))
    if not 0 <= value <= 100:
        raise MaterialError(f"hardness {shore!r} is outside 0..100")
    if scale == "00":
        return 0.048 + 0.0007 * value + 0.0002 * max(value - 50.0, 0.0) ** 1.5 / 10.0
    value = min(value, 95.0)  # Gent's relation diverges at 100
    return 0.0981 * (56 + 7.62336 * value) / (0.137505 * (254 - 2.54 * value))


@dataclass(frozen=True, slots=True)
class Material:
    """A skin material as the TD advertises it, with the numbers mechanics needs."""

    material_type: str
    shore_hardness: str
    density_kg_m3: float = 1070.0
    youngs_modulus_mpa: float | None = None  # overrides the Shore estimate when known

    @property
    def modulus_mpa(self) -> float:
        if self.youngs_modulus_mpa is not None:
            return self.youngs_modulus_mpa
        return shore_to_modulus_mpa(self.shore_hardness)


MATERIALS: dict[str, Material] = {
    "ecoflex-00-10": Material("ecoflex", "Shore 00-10", 1040.0),
    "ecoflex-00-30": Material("ecoflex", "Shore 00-30", 1070.0),
    "ecoflex-00-50": Material("ecoflex", "Shore 00-50", 1070.0),
    "dragonskin-10": Material("dragonskin", "Shore A10", 1070.0),
    "dragonskin-20": Material("dragonskin", "Shore A20", 1080.0),
    "dragonskin-30": Material("dragonskin", "Shore A30", 1080.0),
}
