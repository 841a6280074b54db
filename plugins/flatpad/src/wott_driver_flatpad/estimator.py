"""From a camera image to the pad's displacement field (N x 3 mm).

Per frame: the shared marker detector and tracker (``wott_vision``) give each
marker's image position; the photometry gives its apparent area; the parallax
solver and the depth model turn areas into dz (depth.py); the optics turn image
positions at that depth back into millimetres, so the in-plane part is free of
the perspective magnification a press causes. Markers the tracker
loses take their neighbours' values; clamped (border) nodes are held at zero
as the mesh promises.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from wott_vision.markers import as_gray

from .depth import DepthModel, MarkerPhotometry, ParallaxSolver, fill_lost
from .geometry import PadLayout

__all__ = ["PadEstimate", "PadEstimator", "ReferenceNotFound", "order_grid"]


class ReferenceNotFound(ValueError):
    """The image does not show the configured marker grid at rest (yet)."""


@dataclass(frozen=True, slots=True, eq=False)
class PadEstimate:
    displacement: np.ndarray  # (N, 3) mm, device frame
    lost: int  # markers the tracker lost in this frame (filled from neighbours)
    area_ratio: np.ndarray  # (N,) A / A_rest as measured, NaN where lost
    cue: np.ndarray  # (N,) x = Z / Z0 - 1, what the depth model maps to dz


def order_grid(points: np.ndarray, layout: PadLayout) -> np.ndarray:
    """Detected rest markers in node order (r * cols + c), or ReferenceNotFound.

    Sorting by image row then column needs no camera calibration, only a grid
    roughly aligned with the image (a tilt under about half a pitch across the
    pad); the spacing check rejects a frame where a marker is missing or a
    speck was taken for one.
    """
    m = layout.n_markers
    if len(points) != m:
        raise ReferenceNotFound(
            f"found {len(points)} markers, expected {layout.rows}x{layout.cols} = {m} "
            "(is the pad touched, or are rows/cols/pitch wrong?)"
        )
    by_y = points[np.argsort(points[:, 1], kind="stable")]
    rows = by_y.reshape(layout.rows, layout.cols, 2)
    order = np.argsort(rows[:, :, 0], axis=1, kind="stable")
    g = np.take_along_axis(rows, order[..., None], axis=1)
    dx = np.linalg.norm(np.diff(g, axis=1), axis=2)
    dy = np.linalg.norm(np.diff(g, axis=0), axis=2)
    spacing = np.median(np.concatenate([dx.ravel(), dy.ravel()]))
    worst = max(np.abs(dx / spacing - 1).max(), np.abs(dy / spacing - 1).max())
    if worst > 0.35:
        raise ReferenceNotFound(
            f"the {m} detected markers do not form a regular {layout.rows}x{layout.cols} grid "
            f"(spacing off by {worst:.0%} somewhere): pad touched or grid tilted"
        )
    return g.reshape(m, 2)


class PadEstimator:
    """Holds the rest reference and turns each following image into displacements."""

    def __init__(self, layout: PadLayout, depth_model: DepthModel | None = None, *,
                 parallax: bool = True, nonlinear_passes: int = 1, depth: bool = True) -> None:
        self.layout = layout
        self.depth_model = depth_model or DepthModel.physical(layout.optics)
        self.depth = depth
        self.nonlinear_passes = int(nonlinear_passes)
        self.solver = ParallaxSolver(layout, parallax) if depth else None
        area = np.pi * layout.marker_radius_px**2
        self.detect_kwargs = {"min_area": max(2, int(0.15 * area)), "max_area": int(6 * area) + 16}
        self.reference_px: np.ndarray | None = None
        self._detector = None  # restricted to the pad once the reference is known
        self._photometry: MarkerPhotometry | None = None
        self._tracker = None
        self._rest_xy: np.ndarray | None = None
        self._free = layout.mesh.free

    @property
    def has_reference(self) -> bool:
        return self.reference_px is not None

    def detect(self, gray: np.ndarray) -> np.ndarray:
        if self._detector is not None:
            return self._detector(gray)
        from wott_vision.markers import detect_markers

        return detect_markers(gray, **self.detect_kwargs)

    def _pad_detector(self, shape: tuple[int, int], px: np.ndarray):
        """A detector that only searches the pad (plus a pitch of margin): less image, less time."""
        from wott_vision.markers import MarkerDetector

        m = int(np.ceil(self.layout.pitch_px))
        x0, y0 = np.maximum(np.floor(px.min(axis=0)).astype(int) - m, 0)
        x1, y1 = np.ceil(px.max(axis=0)).astype(int) + m + 1
        mask = np.zeros(shape, dtype=np.uint8)
        mask[y0:y1, x0:x1] = 255
        return MarkerDetector(mask=mask, **self.detect_kwargs)

    def set_reference(self, frame: np.ndarray) -> None:
        """Take this image (pad at rest) as the reference all displacements are measured from."""
        gray = as_gray(frame)
        px = order_grid(self.detect(gray), self.layout)
        self._photometry = MarkerPhotometry(gray, px, self.layout.window_half_px,
                                            2 * self.layout.marker_radius_px)
        self.reference_px = px
        self._detector = self._pad_detector(gray.shape, px)
        o = self.layout.optics
        self._rest_xy = o.backproject(px, np.zeros(len(px)), self.layout.axis_mm)
        self.reset_tracking()

    def reset_tracking(self) -> None:
        """Restart the tracker from the reference (after a reconnect the last positions are stale)."""
        from wott_vision.tracking import MarkerTracker

        if self.reference_px is None:
            raise ReferenceNotFound("no reference image yet")
        self._tracker = MarkerTracker(self.reference_px)

    def track(self, gray: np.ndarray) -> np.ndarray:
        if self._tracker is None:
            raise ReferenceNotFound("no reference image yet")
        return np.asarray(self._tracker.track(self.detect(gray)), dtype=float)

    def update(self, frame: np.ndarray) -> PadEstimate:
        gray = as_gray(frame)
        px = self.track(gray)
        return self.solve(gray, px)

    def solve(self, gray: np.ndarray, px: np.ndarray) -> PadEstimate:
        """Displacements from tracked positions ``px`` (NaN rows: lost) in image ``gray``."""
        lay, o, axis = self.layout, self.layout.optics, self.layout.axis_mm
        ref = self.reference_px
        seen = np.isfinite(px).all(axis=1)
        lost = int((~seen).sum())
        if lost:
            px = ref + fill_lost(lay, px - ref, seen)
        if self.depth:
            ratio = self._photometry.area_ratio(gray, px)
            ratio[~seen] = np.nan
            good = np.isfinite(ratio)
            log_ratio = np.log(np.where(good, ratio, 1.0))
            if not good.all():
                log_ratio = fill_lost(lay, log_ratio, good)
            cue = np.expm1(self.solver.solve(log_ratio, self.nonlinear_passes))
            dz = np.nan_to_num(self.depth_model.dz(cue), nan=0.0, posinf=0.0, neginf=0.0)
        else:
            ratio = np.ones(len(px))
            cue = np.zeros(len(px))
            dz = np.zeros(len(px))
        xy = o.backproject(px, dz, axis) - self._rest_xy
        d = np.column_stack([xy, dz])
        d[~self._free] = 0.0
        return PadEstimate(d, lost, ratio, cue)
