"""The pad's optics: a pinhole camera under the gel, looking up through acrylic.

The camera sits below a clear acrylic plate that carries the gel; markers are
printed on the gel's contact surface (the device's z = 0 plane, normal +z) and
the camera looks along +z. Refraction through the flat acrylic and gel layers
is taken paraxially: a marker behind a layer of thickness t and index n
appears at depth t / n, so the optics behave like a pinhole at the *effective*
distance ``Z_eff = air_gap + acrylic / n_acrylic + gel / n_gel``. A press moves a
marker by dz (< 0, towards the camera) *inside the gel*, so its effective
distance changes by dz / n_gel only (docs/flat-pad.md, "camera model").

Camera axes equal the device axes (x right in the image, y down in the image,
z along the optical axis): seen from below, the image is the mirror of a top
view, which is what a real under-gel camera records.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PadOptics"]


@dataclass(frozen=True, slots=True)
class PadOptics:
    """Pinhole intrinsics plus the layer stack between the lens and the markers (mm, px)."""

    width: int = 640
    height: int = 480
    focal_px: float = 480.0
    air_gap_mm: float = 20.0
    acrylic_mm: float = 3.0
    acrylic_n: float = 1.49
    gel_mm: float = 4.0
    gel_n: float = 1.41
    centre_mm: tuple[float, float] | None = None  # device (x, y) on the optical axis; None: pad centre
    principal_px: tuple[float, float] | None = None  # (cx, cy); None: image centre

    def __post_init__(self) -> None:
        for name in ("focal_px", "air_gap_mm", "gel_mm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"optics.{name} must be a positive number, got {v!r}")
        if not (np.isfinite(self.acrylic_mm) and self.acrylic_mm >= 0):
            raise ValueError(f"optics.acrylic_mm must be >= 0, got {self.acrylic_mm!r}")
        for name in ("acrylic_n", "gel_n"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 1.0):
                raise ValueError(f"optics.{name} is a refractive index (>= 1), got {v!r}")
        if self.width < 16 or self.height < 16:
            raise ValueError(f"image size {self.width}x{self.height} is too small")

    @property
    def z_eff_mm(self) -> float:
        """Effective pinhole distance to the markers at rest."""
        return self.air_gap_mm + self.acrylic_mm / self.acrylic_n + self.gel_mm / self.gel_n

    @property
    def px_per_mm(self) -> float:
        """Image scale at rest (≈ 20 px/mm with the defaults at 640x480)."""
        return self.focal_px / self.z_eff_mm

    @property
    def principal(self) -> np.ndarray:
        if self.principal_px is not None:
            return np.asarray(self.principal_px, dtype=float)
        return np.array([(self.width - 1) / 2.0, (self.height - 1) / 2.0])

    def axis_mm(self, pad_centre: np.ndarray) -> np.ndarray:
        return np.asarray(self.centre_mm if self.centre_mm is not None else pad_centre, dtype=float)

    def distance(self, dz: np.ndarray | float) -> np.ndarray:
        """Effective distance of a marker displaced by ``dz`` (mm, device z) inside the gel."""
        return self.z_eff_mm + np.asarray(dz, dtype=float) / self.gel_n

    def project(self, points: np.ndarray, axis_mm: np.ndarray) -> np.ndarray:
        """Image positions (M, 2) px of marker positions (M, 3) mm whose rest z is 0."""
        z = self.distance(points[:, 2])
        px: np.ndarray = self.principal + self.focal_px * (points[:, :2] - axis_mm) / z[:, None]
        return px

    def backproject(self, px: np.ndarray, dz: np.ndarray, axis_mm: np.ndarray) -> np.ndarray:
        """In-plane positions (M, 2) mm of markers seen at ``px`` with normal displacement ``dz``."""
        z = self.distance(dz)
        mm: np.ndarray = axis_mm + (px - self.principal) * (z / self.focal_px)[:, None]
        return mm

    def scale(self, dz: np.ndarray | float) -> np.ndarray:
        """Image magnification (px per mm) of a marker displaced by ``dz``."""
        return self.focal_px / self.distance(dz)
