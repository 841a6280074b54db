"""Pressure counts <-> normal displacement through the skin over the taxels.

Model: the skin is a thin elastic layer (Young's modulus E, thickness h) on the
rigid taxel board, each taxel under its own column of skin loaded in uniaxial
compression with no coupling to its neighbours (a Winkler foundation, the same
model as ``wott_hub.tactile.contacts.WinklerForceModel``): strain d/h, stress
p = E·d/h, so the normal (inward) displacement is

    d = p · h / E,    p = counts · kpa_per_count.

The simulator applies the exact inverse (counts = round(E·d / (h · kpa_per_count)),
clipped to 0..65535; a taxel cannot feel a pull), so recovered displacement
differs from the ground truth's normal component only by quantisation: at most
half a count, ``quantum_mm / 2``. Shear is invisible to a pressure taxel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Compliance"]

MAX_COUNT = 0xFFFF


@dataclass(frozen=True, slots=True)
class Compliance:
    modulus_kpa: float
    thickness_mm: float
    kpa_per_count: float

    def __post_init__(self) -> None:
        for name in ("modulus_kpa", "thickness_mm", "kpa_per_count"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")

    @property
    def mm_per_count(self) -> float:
        return self.kpa_per_count * self.thickness_mm / self.modulus_kpa

    @property
    def quantum_mm(self) -> float:
        """Displacement of one count: the resolution of the recovered field."""
        return self.mm_per_count

    @property
    def full_scale_mm(self) -> float:
        return MAX_COUNT * self.mm_per_count

    def normal_mm(self, counts: np.ndarray) -> np.ndarray:
        """Inward normal displacement (mm) of each taxel from its pressure counts."""
        return np.asarray(counts, dtype=np.float64) * self.mm_per_count

    def pressure_kpa(self, counts: np.ndarray) -> np.ndarray:
        """Pressure (kPa) on each taxel from its counts."""
        return np.asarray(counts, dtype=np.float64) * self.kpa_per_count

    def counts(self, normal_mm: np.ndarray) -> np.ndarray:
        """What the taxels read for an inward displacement (the simulator's side)."""
        c = np.rint(np.asarray(normal_mm, dtype=np.float64) / self.mm_per_count)
        return np.clip(c, 0, MAX_COUNT).astype(np.uint16)
