"""From a camera image to the pad's displacement field (N x 3 mm).

Per frame: the shared marker detector and tracker (``wott_vision``) give each
marker's image position; the photometry gives its apparent area; the parallax
solver and the depth model turn areas into dz (depth.py); the optics turn image
positions at that depth back into millimetres, so the in-plane part is free of
the perspective magnification a press causes. Markers the tracker
loses take their neighbours' values; clamped (border) nodes are held at zero
as the mesh promises.

A rest image with markers missing, merged or occluded still gives a reference
(``wott_vision.reference``: detections matched to the optics' expected
positions) as long as at least ``MIN_AVAILABLE`` of them are seen; the others
are *unavailable*: their nodes read 0 (never reported as deformed) and are
listed in ``unavailable_nodes`` for the device's health. Displacements are
clamped to the pad's physical bound (``PadEstimate.clamped`` counts the nodes):
in-plane to ``max_shear_mm``, depth to the gel's thickness.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, TypedDict

import numpy as np
from wott_vision.markers import as_gray

from wott_hub.plugin_api import InvalidInput

from .depth import DepthModel, MarkerPhotometry, ParallaxSolver, fill_lost
from .geometry import PadLayout

if TYPE_CHECKING:
    from wott_vision.markers import MarkerDetector
    from wott_vision.tracking import MarkerTracker

__all__ = ["MIN_AVAILABLE", "PadEstimate", "PadEstimator", "ReferenceNotFound", "order_grid"]

MIN_AVAILABLE = 0.5  # fewer markers matched at rest: the pad is touched or the grid is wrong


class ReferenceNotFound(InvalidInput):
    """The image does not show the configured marker grid at rest (yet): it cannot be the rest reference."""


@dataclass(frozen=True, slots=True, eq=False)
class PadEstimate:
    displacement: np.ndarray  # (N, 3) mm, device frame
    lost: int  # markers the tracker lost in this frame (filled from neighbours)
    area_ratio: np.ndarray  # (N,) A / A_rest as measured, NaN where lost
    cue: np.ndarray  # (N,) x = Z / Z0 - 1, what the depth model maps to dz
    unavailable: int = 0  # markers not seen at rest (their nodes read 0)
    clamped: int = 0  # nodes whose displacement was beyond the pad's physical bound


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


class _DetectArgs(TypedDict):
    min_area: int
    max_area: int


class PadEstimator:
    """Holds the rest reference and turns each following image into displacements."""

    def __init__(self, layout: PadLayout, depth_model: DepthModel | None = None, *,
                 parallax: bool = True, nonlinear_passes: int = 1, depth: bool = True) -> None:
        self.layout = layout
        self.depth_model = depth_model or DepthModel.physical(layout.optics)
        self.depth = depth
        self.nonlinear_passes = int(nonlinear_passes)
        self._parallax = parallax
        area = np.pi * layout.marker_radius_px**2
        self.detect_kwargs: _DetectArgs = {"min_area": max(2, int(0.15 * area)),
                                           "max_area": int(6 * area) + 16}
        self.reference_px: np.ndarray | None = None
        self._detector: MarkerDetector | None = None  # restricted to the pad once the reference is known
        self._photometry: MarkerPhotometry | None = None
        self._tracker: MarkerTracker | None = None
        self._rest_xy: np.ndarray | None = None
        self._free = layout.mesh.free
        self.available: np.ndarray | None = None  # (M,) bool; None: every marker seen at rest
        self.max_depth_mm = float(layout.optics.gel_mm)
        self.max_shear_mm = float(layout.optics.gel_mm)  # a gel sheared further than it is thick tears

    @cached_property
    def solver(self) -> ParallaxSolver | None:
        """The depth solver (None without ``depth``), factorised on first use: in the driver's worker
        thread when frames start, not when the device is opened (SciPy's import and the
        factorisation, ~0.2 s, would delay the hub serving the TD; docs/hub.md, "Start-up and
        bytecode")."""
        return ParallaxSolver(self.layout, self._parallax) if self.depth else None

    @property
    def has_reference(self) -> bool:
        return self.reference_px is not None

    def detect(self, gray: np.ndarray) -> np.ndarray:
        if self._detector is not None:
            return self._detector(gray)
        from wott_vision.markers import detect_markers

        return detect_markers(gray, **self.detect_kwargs)

    def _pad_detector(self, shape: tuple[int, ...], px: np.ndarray) -> MarkerDetector:
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
        points = self.detect(gray)
        available: np.ndarray | None = None
        try:
            px = order_grid(points, self.layout)
        except ReferenceNotFound as e:
            from wott_vision.reference import match_expected

            match = match_expected(points, self.layout.rest_px)
            if match.available.mean() < MIN_AVAILABLE:
                raise e from None
            px, available = match.px, match.available
        self.available = None if available is None or available.all() else available
        self._photometry = MarkerPhotometry(gray, px, self.layout.window_half_px,
                                            2 * self.layout.marker_radius_px)
        self.reference_px = px
        self._detector = self._pad_detector(gray.shape, px)
        o = self.layout.optics
        self._rest_xy = o.backproject(px, np.zeros(len(px)), self.layout.axis_mm)
        self.reset_tracking()

    def recalibrate(self, frame: np.ndarray) -> None:
        """``set_reference`` searching the whole image again (the pad may have moved in it); if no grid
        is found, the previous reference and search area are kept."""
        narrowed, self._detector = self._detector, None
        try:
            self.set_reference(frame)
        except ReferenceNotFound:
            self._detector = narrowed
            raise

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
        ref, photometry, rest_xy = self.reference_px, self._photometry, self._rest_xy
        if ref is None or photometry is None or rest_xy is None:  # set together by set_reference
            raise ReferenceNotFound("no reference image yet")
        seen = np.isfinite(px).all(axis=1)
        available = self.available
        if available is not None:
            seen &= available
        lost = int((~seen).sum()) - (0 if available is None else int((~available).sum()))
        if lost:
            px = ref + fill_lost(lay, px - ref, seen)
        solver = self.solver  # there is one exactly when ``depth`` is set
        if solver is not None:
            ratio = photometry.area_ratio(gray, px)
            ratio[~seen] = np.nan
            good = np.isfinite(ratio)
            log_ratio = np.log(np.where(good, ratio, 1.0))
            if not good.all():
                log_ratio = fill_lost(lay, log_ratio, good)
            cue = np.expm1(solver.solve(log_ratio, self.nonlinear_passes))
            dz = np.nan_to_num(self.depth_model.dz(cue), nan=0.0, posinf=0.0, neginf=0.0)
        else:
            ratio = np.ones(len(px))
            cue = np.zeros(len(px))
            dz = np.zeros(len(px))
        xy = o.backproject(px, dz, axis) - rest_xy
        d = np.column_stack([xy, dz])
        d[~self._free] = 0.0
        if available is not None:
            d[~available] = 0.0  # unknown, not deformed: the health lists these nodes
        clamped = _clamp(d, self.max_shear_mm, self.max_depth_mm)
        return PadEstimate(d, lost, ratio, cue, 0 if available is None else int((~available).sum()), clamped)

    @property
    def unavailable_nodes(self) -> list[int]:
        """Nodes whose marker was not seen at rest (marker m is node m on the pad)."""
        return [] if self.available is None else np.flatnonzero(~self.available).tolist()


def _clamp(d: np.ndarray, max_shear_mm: float, max_depth_mm: float) -> int:
    """Clamp ``d`` in place to the physical bound: |dz| <= depth, |(dx, dy)| <= shear; nodes clamped."""
    dz = d[:, 2]
    over_z = np.abs(dz) > max_depth_mm
    shear2 = d[:, 0] ** 2 + d[:, 1] ** 2
    over_xy = shear2 > max_shear_mm**2
    if not (over_z.any() or over_xy.any()):
        return 0
    np.clip(dz, -max_depth_mm, max_depth_mm, out=dz)
    if over_xy.any():
        d[over_xy, :2] *= (max_shear_mm / np.sqrt(shear2[over_xy]))[:, None]
    return int((over_z | over_xy).sum())
