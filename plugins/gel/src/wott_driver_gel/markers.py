"""The marker path: printed dots on the gel tracked against the rest frame -> shear on the node grid.

A GelSight Mini marker gel carries black dots on its lit surface (a few bright-dot gels exist too).
The gel's light is uneven (a colour gradient across the view), so dots are found on the local
contrast, not on the raw grey: ``128 + grey - blur(grey)`` with a blur several dots wide, where a dark
dot is dark and a bright one bright whatever the light around it; ``wott_vision.markers``'
detector then finds them with the matching ``polarity``. ``find_markers`` looks for both polarities
in the rest frame and keeps the one that shows a regular pattern (at least ``MIN_MARKERS`` dots whose
nearest-neighbour spacings agree within ``MAX_SPACING_CV``): a marker-less gel shows none.

Per frame the dots are detected and tracked (``wott_vision.tracking.MarkerTracker``: nearest
detection within a gate of the spacing, lost ones following their neighbours); each node of the
view's grid takes the inverse-distance-weighted displacement of its 4 nearest markers, in mm (x, y;
z is the depth's, where calibrated).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from wott_vision.markers import MarkerDetector

__all__ = ["MAX_SPACING_CV", "MIN_MARKERS", "MarkerField", "contrast", "find_markers"]

MIN_MARKERS = 16
MAX_SPACING_CV = 0.25


def contrast(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """The local contrast of a frame's grey (uint8, 128 where flat; see the module doc)."""
    import cv2

    g = np.asarray(image)
    if g.ndim == 3:
        g = cv2.cvtColor(g, cv2.COLOR_BGR2GRAY)
    f = g.astype(np.float32)
    out: np.ndarray = np.clip(128.0 + f - cv2.GaussianBlur(f, (0, 0), sigma_px), 0, 255).astype(np.uint8)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class Markers:
    points: np.ndarray  # (M, 2) px, the rest positions
    polarity: str  # "dark" | "bright"
    spacing_px: float  # median nearest-neighbour distance


def _detector(polarity: str, mm_per_px: float) -> MarkerDetector:
    from wott_vision.markers import MarkerDetector

    r_min, r_max = 0.08 / mm_per_px, 0.6 / mm_per_px  # dot radii, px
    return MarkerDetector(min_area=max(4.0, np.pi * r_min**2), max_area=np.pi * r_max**2, threshold=None,
                          polarity=polarity, split=False)


def find_markers(rest: np.ndarray, mm_per_px: float) -> Markers | None:
    """The rest frame's marker pattern, or None if it shows none (see the module doc)."""
    from scipy.spatial import cKDTree

    sigma = 1.5 / mm_per_px  # several dots wide
    image = contrast(rest, sigma)
    best: Markers | None = None
    for polarity in ("dark", "bright"):
        pts = _detector(polarity, mm_per_px)(image)
        if len(pts) < MIN_MARKERS:
            continue
        d, _ = cKDTree(pts).query(pts, k=2)
        nn = d[:, 1]
        spacing = float(np.median(nn))
        if spacing <= 0 or float(np.std(nn) / spacing) > MAX_SPACING_CV:
            continue
        if best is None or len(pts) > len(best.points):
            best = Markers(pts, polarity, spacing)
    return best


class MarkerField:
    """Tracks ``markers`` frame by frame; ``displacement`` gives the nodes' (x, y) in mm."""

    def __init__(self, markers: Markers, nodes_mm: np.ndarray, mm_per_px: float) -> None:
        from scipy.spatial import cKDTree
        from wott_vision.tracking import MarkerTracker

        self.markers, self.mm_per_px = markers, mm_per_px
        self.sigma_px = 1.5 / mm_per_px
        self.detect = _detector(markers.polarity, mm_per_px)
        self.tracker = MarkerTracker(markers.points)
        k = min(4, len(markers.points))
        dist, idx = cKDTree(markers.points).query(nodes_mm[:, :2] / mm_per_px, k=k)
        w = 1.0 / np.maximum(dist, 1e-6) ** 2
        self.idx, self.w = idx, w / w.sum(axis=1, keepdims=True)
        self.lost = 0
        self.dot_px = max(2.0, 0.2 / mm_per_px)  # a dot's radius, px (measured at the first frame)
        self.last = markers.points

    def reset(self) -> None:
        self.tracker.reset()

    def displacement(self, image: np.ndarray) -> np.ndarray:
        """(N, 2) mm: each node's in-plane displacement in this frame."""
        pts = self.detect(contrast(image, self.sigma_px))
        if len(self.detect.areas):
            self.dot_px = float(np.sqrt(np.median(self.detect.areas) / np.pi))
        tracked = self.tracker.track(pts)
        self.lost = int(np.isnan(tracked[:, 0]).sum())
        where = np.where(np.isnan(tracked), self.tracker.estimate, tracked)
        self.last = np.nan_to_num(where, nan=-1e6)
        moved = (where - self.markers.points) * self.mm_per_px
        moved = np.nan_to_num(moved)
        out: np.ndarray = np.einsum("nk,nkd->nd", self.w, moved[self.idx])
        return out

    def dots(self, shape: tuple[int, ...], blur_px: float) -> np.ndarray:
        """(H, W) bool: where the dots are at rest and in the last frame, widened by ``blur_px``. A dot
        that moves changes the colour where it was and where it is: shear, not contact."""
        import cv2

        mask = np.zeros(shape[:2], np.uint8)
        r = int(np.ceil(self.dot_px + 1.5 * blur_px))
        for x, y in np.concatenate([self.markers.points, self.last]):
            if 0 <= x < shape[1] and 0 <= y < shape[0]:
                cv2.circle(mask, (int(round(x)), int(round(y))), r, 1, -1)
        out: np.ndarray = mask.astype(bool)
        return out
