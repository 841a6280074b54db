"""The marker grid and where it lands in the image.

Markers are the nodes of the pad's quad mesh: marker (r, c) is node
``r * cols + c`` of ``flat_pad(rows, cols, pitch_mm=...)`` at x = c * pitch,
y = r * pitch. The layout joins that grid to the optics and derives the pixel
sizes every image step uses, and refuses a grid that does not fit the image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from wott_hub.plugin_api import SkinMesh, flat_pad

from .camera import PadOptics

__all__ = ["GRID_MAX", "GRID_MIN", "PadLayout"]

GRID_MIN = 7
GRID_MAX = 16


@dataclass(frozen=True)
class PadLayout:
    rows: int = 16
    cols: int = 16
    pitch_mm: float = 1.5
    marker_radius_mm: float = 0.35
    optics: PadOptics = field(default_factory=PadOptics)

    def __post_init__(self) -> None:
        for name in ("rows", "cols"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or not GRID_MIN <= v <= GRID_MAX:
                raise ValueError(f"grid {name} must be an integer in {GRID_MIN}..{GRID_MAX}, got {v!r}")
        if not (np.isfinite(self.pitch_mm) and self.pitch_mm > 0):
            raise ValueError(f"pitch_mm must be positive, got {self.pitch_mm!r}")
        if not (np.isfinite(self.marker_radius_mm) and 0 < self.marker_radius_mm < 0.3 * self.pitch_mm):
            raise ValueError(
                f"marker_radius_mm must be in (0, 0.3 * pitch = {0.3 * self.pitch_mm:.3g}) so that "
                f"markers stay apart under a press, got {self.marker_radius_mm!r}"
            )
        if self.pitch_px < 12:
            raise ValueError(
                f"the pitch is {self.pitch_px:.1f} px in the image; at least 12 px are needed "
                "(raise pitch_mm or optics.focal_px)"
            )
        px = self.rest_px
        margin = self.window_half_px + 1
        o = self.optics
        if (px.min(axis=0) < margin).any() or px[:, 0].max() > o.width - 1 - margin or (
            px[:, 1].max() > o.height - 1 - margin
        ):
            # the grid may fit the view and still not the tracker's margin: say which (issue 44)
            k = o.px_per_mm
            span = ((self.cols - 1) * self.pitch_mm, (self.rows - 1) * self.pitch_mm)
            view = (o.width / k, o.height / k)
            usable = ((o.width - 1 - 2 * margin) / k, (o.height - 1 - 2 * margin) / k)
            fits = span[0] <= usable[0] and span[1] <= usable[1]
            where = ("but it is off-centre: a marker falls within the margin (check optics.centre_mm and "
                     "principal_px)" if fits else "too large for it")
            raise ValueError(
                f"a {self.rows}x{self.cols} grid at {self.pitch_mm} mm spans {span[0]:.1f} x "
                f"{span[1]:.1f} mm; "
                f"the camera sees {view[0]:.1f} x {view[1]:.1f} mm ({k:.1f} px/mm), of which the markers "
                f"may use {usable[0]:.1f} x {usable[1]:.1f} mm (the tracker needs {margin:.0f} px, "
                f"{margin / k:.2f} mm, between a marker and the image's edge): the grid is {where}; "
                "lower pitch_mm, or see more of the pad: raise mm_per_px (lower focal_px)"
            )

    @property
    def n_markers(self) -> int:
        return self.rows * self.cols

    @cached_property
    def mesh(self) -> SkinMesh:
        return flat_pad(self.rows, self.cols, pitch_mm=self.pitch_mm, name="flat-pad")

    @property
    def centre_mm(self) -> np.ndarray:
        return np.array([(self.cols - 1) * self.pitch_mm / 2.0, (self.rows - 1) * self.pitch_mm / 2.0])

    @property
    def axis_mm(self) -> np.ndarray:
        """Device (x, y) on the optical axis."""
        return self.optics.axis_mm(self.centre_mm)

    @cached_property
    def rest_px(self) -> np.ndarray:
        return self.optics.project(self.mesh.nodes, self.axis_mm)

    @property
    def pitch_px(self) -> float:
        return self.pitch_mm * self.optics.px_per_mm

    @property
    def marker_radius_px(self) -> float:
        return self.marker_radius_mm * self.optics.px_per_mm

    @property
    def window_half_px(self) -> int:
        """Half-size of the square window a marker's brightness is summed over.

        Just under half the pitch: wide enough for a marker magnified by a deep
        press plus its blur, narrow enough to exclude the neighbours.
        """
        return max(3, int(np.floor(0.45 * self.pitch_px)))

    def grid(self, values: np.ndarray) -> np.ndarray:
        """Per-marker values (M, ...) as a (rows, cols, ...) array."""
        return values.reshape(self.rows, self.cols, *values.shape[1:])
