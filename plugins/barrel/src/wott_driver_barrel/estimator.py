"""Two camera frames in, node displacement out: detect, track, model.

Per camera, the shared detector (``wott_vision.markers``) finds the dots
inside the annulus where markers can appear (the mask also crops the search:
fewer pixels, no stray light from the rims) and the shared tracker
(``wott_vision.tracking``) keeps each dot's identity from frame to frame. A
marker the tracker lost this frame (two dots pressed into one blob, a glare)
enters the model at the tracker's best guess, where its neighbours carried
it, rather than at rest: a lost marker is usually lost *because* it moved.
A model that takes images skips detection and tracking altogether.

A marker lost in one camera but seen in the other (the usual case: two dots
merge in one view, not in both) is filled from the other view through the
camera model (``BarrelLayout.stereo_maps``): 0.17 px RMS on the demo scene
against 1.2 px for the neighbours' guess alone.

The reference is where each marker sits at rest, in the model's marker order:
``"model"`` takes it from the camera model (the simulator, or a sensor built
and calibrated to it); ``"first-frame"`` detects it in the first frame (skin
at rest) and orders the dots by ray and radius to match the model's order,
for a real sensor whose cameras sit slightly differently.

Either way the first frame read (skin at rest) says which markers are there:
with ``"model"`` its detections are matched to the model's rest positions
(``wott_vision.reference.match_expected``) before the first estimate, so a
marker painted out, merged with a neighbour or hidden is *unavailable* from
the start (its nodes read 0, listed in ``unavailable_nodes``), not a marker
the tracker loses on every frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from wott_hub.plugin_api import InvalidInput

from .geometry import BarrelLayout, FisheyeCamera
from .model import DisplacementModel

if TYPE_CHECKING:  # imported where used: the tracker loads SciPy
    from wott_vision.markers import MarkerDetector
    from wott_vision.tracking import MarkerTracker

__all__ = ["MAX_DISPLACEMENT_MM", "BarrelEstimate", "BarrelEstimator", "ReferenceNotFound", "annulus_mask",
           "clamp_norm", "order_like"]

REFERENCES = ("model", "first-frame")
MIN_AVAILABLE = 0.5  # of a camera's markers matched at rest, below which the frame is not a rest frame
MAX_DISPLACEMENT_MM = 25.0  # physical bound: half the rim's radius (36 mm); beyond, the model extrapolates


class ReferenceNotFound(InvalidInput):
    """The frame does not show the marker grid at rest (yet): it cannot be the rest reference."""


@dataclass
class BarrelEstimate:
    displacement: np.ndarray  # (N, 3) mm
    lost: int  # markers not detected this frame, both cameras together
    tracked_px: tuple[np.ndarray, ...] = ()  # per camera (M, 2), NaN where lost
    clamped: int = 0  # nodes displaced beyond MAX_DISPLACEMENT_MM, clamped to it


@dataclass
class BarrelEstimator:
    layout: BarrelLayout
    model: DisplacementModel
    reference: str = "model"
    detector: dict[str, Any] = field(default_factory=dict)
    tracker: dict[str, Any] = field(default_factory=dict)
    mask_margin_px: float = 18.0

    def __post_init__(self) -> None:
        from wott_vision.markers import MarkerDetector  # NumPy only: OpenCV comes with the first image

        if self.reference not in REFERENCES:
            raise ValueError(f"reference must be one of {REFERENCES}, got {self.reference!r}")
        # the detectors are built at the first frame (prepare); their options are checked now, so
        # that a bad combination (min_area > max_area) is refused when the device is opened
        try:
            MarkerDetector(**{k: v for k, v in self.detector.items() if k != "mask"})
        except ValueError as e:
            raise ValueError(f"detector: {e}") from None
        self.reference_px: tuple[np.ndarray, ...] | None = None
        self._detectors: list[MarkerDetector] = []
        self._trackers: list[MarkerTracker] = []
        self._stereo: np.ndarray | None = None
        self._prepared = False
        self.available: tuple[np.ndarray, ...] | None = None  # per camera (M,) bool; None: all seen
        self._unknown = np.zeros(self.layout.mesh.n_nodes, dtype=bool)
        self._checked = self.reference != "model"  # "model": the first frame says which markers are there

    def prepare(self) -> None:
        """Build the stereo maps, detectors and trackers (once; OpenCV and SciPy imported here).

        Called by the first ``set_reference``/``features``, i.e. in the driver's worker thread
        when frames start, not when the device is opened: the hub serves the device's TD without
        waiting ~0.4 s for them (docs/hub.md, "Start-up and bytecode")."""
        if self._prepared:
            return
        self._prepared = True
        self._stereo = self.layout.stereo_maps() if len(self.layout.cameras) == 2 else None
        if self.reference == "model" and self.uses_markers:
            self._set_reference(self.layout.reference_px)

    @property
    def uses_markers(self) -> bool:
        return self.model.contract.kind == "markers"

    @property
    def has_reference(self) -> bool:
        return (self.reference_px is not None and self._checked) or not self.uses_markers

    def _set_reference(self, ref: tuple[np.ndarray, ...]) -> None:
        from wott_vision.markers import MarkerDetector

        self.reference_px = tuple(np.asarray(r, dtype=np.float64) for r in ref)
        opts = dict(self.detector)
        use_mask = opts.pop("mask", True)
        self._detectors = [
            MarkerDetector(mask=annulus_mask(r, cam, self.mask_margin_px,
                                             r.mean(axis=0) if self.reference == "first-frame" else None)
                           if use_mask else None, **opts)
            for r, cam in zip(self.reference_px, self.layout.cameras, strict=True)
        ]
        self.reset_tracking()

    def reset_tracking(self) -> None:
        """Restart tracking from the reference (after a reconnect the last positions are stale)."""
        from wott_vision.tracking import MarkerTracker

        if self.reference_px is None:
            return
        self._trackers = [MarkerTracker(r, **self.tracker) for r in self.reference_px]

    def set_reference(self, images: tuple[np.ndarray, ...]) -> None:
        """Take these frames (skin at rest) as the reference ("first-frame" mode, or a tare).

        With ``"model"``, the first call only checks the frames against the
        model's rest markers: the reference stays the model's, less the markers
        not there.
        """
        from wott_vision.markers import MarkerDetector
        from wott_vision.reference import match_expected

        self.prepare()
        opts = {k: v for k, v in self.detector.items() if k != "mask"}
        if not self._checked:
            self._check_model_reference(images, MarkerDetector(**opts))
            return
        ordered, available = [], []
        for c, (img, model_ref) in enumerate(zip(images, self.layout.reference_px, strict=True)):
            pts = MarkerDetector(**opts)(img)
            try:
                ordered.append(order_like(pts, model_ref, self.layout.markers.rays))
                available.append(np.ones(len(model_ref), dtype=bool))
            except ReferenceNotFound as e:
                match = match_expected(pts, model_ref)  # markers missing, merged or occluded
                if match.available.mean() < MIN_AVAILABLE:
                    raise ReferenceNotFound(f"camera {self.layout.cameras[c].name}: {e}") from None
                ordered.append(match.px)
                available.append(match.available)
        self._set_available(None if all(a.all() for a in available) else tuple(available))
        self._set_reference(tuple(ordered))

    def _check_model_reference(self, images: tuple[np.ndarray, ...], detect: MarkerDetector) -> None:
        """Which of the model's rest markers the frames show (see module doc)."""
        from wott_vision.reference import match_expected

        available = []
        for c, (img, model_ref) in enumerate(zip(images, self.layout.reference_px, strict=True)):
            match = match_expected(detect(img), model_ref)
            if match.available.mean() < MIN_AVAILABLE:
                raise ReferenceNotFound(f"camera {self.layout.cameras[c].name}: {int(match.available.sum())} "
                                        f"of {len(model_ref)} markers where the camera model puts them")
            available.append(match.available)
        self._set_available(None if all(a.all() for a in available) else tuple(available))
        self._checked = True
        self.reset_tracking()

    def _set_available(self, available: tuple[np.ndarray, ...] | None) -> None:
        """Markers seen at rest per camera; a node is unknown when its nearest marker is seen by none."""
        self.available = available
        self._unknown = np.zeros(self.layout.mesh.n_nodes, dtype=bool)
        if available is None:
            return
        nowhere = ~np.logical_or.reduce(available)
        mesh = self.layout.mesh
        d = np.linalg.norm(mesh.nodes[:, None, :] - self.layout.markers.rest[None, :, :], axis=2)
        self._unknown = nowhere[d.argmin(axis=1)] & mesh.free

    @property
    def unavailable_markers(self) -> int:
        """Marker views (both cameras) not seen at rest."""
        return 0 if self.available is None else int(sum((~a).sum() for a in self.available))

    @property
    def unavailable_nodes(self) -> list[int]:
        """Nodes whose value is unknown (read 0): their nearest marker unavailable in every camera."""
        return np.flatnonzero(self._unknown).tolist()

    def features(self, images: tuple[np.ndarray, ...]) -> tuple[np.ndarray, int, tuple[np.ndarray, ...]]:
        """(model input (F,), markers lost, tracked positions per camera)."""
        self.prepare()
        if self.reference_px is None:
            raise ReferenceNotFound("no reference yet")
        motion, seen, lost, tracked = [], [], 0, []
        cams = zip(images, self._detectors, self._trackers, self.reference_px, strict=True)
        for c, (img, det, trk, ref) in enumerate(cams):
            px = trk.track(det(img), det.areas)
            ok = np.isfinite(px[:, 0])
            if self.available is not None:  # never seen at rest: no motion known, not lost either
                gone = ~self.available[c]
                px[gone] = np.nan
                lost += int((~ok & ~gone).sum())
                ok &= ~gone
                motion.append(np.where(ok[:, None], px, ref) - ref)
                seen.append(ok)
                tracked.append(px)
                continue
            lost += int((~ok).sum())
            motion.append(np.where(ok[:, None], px, trk.estimate) - ref)
            seen.append(ok)
            tracked.append(px)
        if self._stereo is not None:
            filled = [m.copy() for m in motion]
            for a in (0, 1):
                fill = ~seen[a] & seen[1 - a]
                if fill.any():
                    filled[a][fill] = np.einsum("mij,mj->mi", self._stereo[a][fill], motion[1 - a][fill])
            motion = filled
        return np.concatenate([m.ravel() for m in motion]), lost, tuple(tracked)

    def estimate(self, images: tuple[np.ndarray, ...]) -> BarrelEstimate:
        if len(images) != len(self.layout.cameras):
            raise ValueError(f"expected {len(self.layout.cameras)} images, got {len(images)}")
        for img, cam in zip(images, self.layout.cameras, strict=True):
            if img.shape[:2] != (cam.height, cam.width):
                raise ValueError(f"{cam.name} camera delivers {img.shape[1]}x{img.shape[0]} frames; the "
                                 f"camera model is {cam.width}x{cam.height} (setting cameras.width/height)")
        if not self.uses_markers:
            return BarrelEstimate(self.model.predict_images(images), 0)
        feats, lost, tracked = self.features(images)
        d = self.model.predict_markers(feats)
        if self.available is not None:
            d[self._unknown] = 0.0  # unknown, not deformed: the health lists these nodes
        return BarrelEstimate(d, lost, tracked, clamp_norm(d, MAX_DISPLACEMENT_MM))


def clamp_norm(d: np.ndarray, bound_mm: float) -> int:
    """Scale the rows of ``d`` (N, 3) longer than ``bound_mm`` back to it, in place; how many were."""
    n2 = np.einsum("ij,ij->i", d, d)
    over = n2 > bound_mm**2
    if not over.any():
        return 0
    d[over] *= (bound_mm / np.sqrt(n2[over]))[:, None]
    return int(over.sum())


def annulus_mask(ref: np.ndarray, cam: FisheyeCamera, margin_px: float = 18.0,
                 centre: np.ndarray | None = None) -> np.ndarray:
    """(H, W) mask of the ring of the image where the markers ``ref`` (M, 2) can appear."""
    c = np.array([cam.cx, cam.cy]) if centre is None else np.asarray(centre, dtype=np.float64)
    r = np.linalg.norm(ref - c, axis=1)
    yy, xx = np.mgrid[: cam.height, : cam.width]
    r2 = (xx - c[0]) ** 2 + (yy - c[1]) ** 2
    lo = max(r.min() - margin_px, 0.0)
    mask: np.ndarray = (r2 <= (r.max() + margin_px) ** 2) & (r2 >= lo**2)
    return mask


def _polar_keys(points: np.ndarray, rays: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ray bin, rank by radius within the ray, mean angle of each bin) around the points' centroid."""
    d = points - points.mean(axis=0)
    ang = np.arctan2(d[:, 1], d[:, 0])
    rad = np.hypot(d[:, 0], d[:, 1])
    phase = np.angle(np.mean(np.exp(1j * rays * ang))) / rays  # the rays' common angular offset
    step = 2 * np.pi / rays
    bins = np.round((ang - phase) / step).astype(int) % rays
    rank = np.zeros(len(points), dtype=int)
    for b in range(rays):
        idx = np.flatnonzero(bins == b)
        rank[idx[np.argsort(rad[idx])]] = np.arange(len(idx))
    centres = phase + np.arange(rays) * step
    return bins, rank, centres


def order_like(points: np.ndarray, model_ref: np.ndarray, rays: int) -> np.ndarray:
    """Reorder detected rest markers to the model's order: same ray by angle, same ring by radius."""
    points = np.asarray(points, dtype=np.float64)
    m = len(model_ref)
    rings = m // rays
    if len(points) != m:
        raise ReferenceNotFound(f"{len(points)} markers detected, expected {m}")
    pb, pr, pc = _polar_keys(points, rays)
    counts = np.bincount(pb, minlength=rays)
    if (counts != rings).any():
        bad = int(np.argmax(counts != rings))
        raise ReferenceNotFound(f"ray {bad} holds {counts[bad]} markers, expected {rings}")
    mb, mr, mc = _polar_keys(model_ref, rays)
    # each detected ray takes the model ray whose direction is closest (rotation within half a ray)
    diff = np.angle(np.exp(1j * (pc[:, None] - mc[None, :])))
    match = np.argmin(np.abs(diff), axis=1)
    if len(set(match.tolist())) != rays:
        raise ReferenceNotFound("the detected rays do not line up with the model's")
    slot = {(int(b), int(r)): i for i, (b, r) in enumerate(zip(mb, mr, strict=True))}
    out = np.empty_like(points)
    for p, (b, r) in enumerate(zip(pb, pr, strict=True)):
        out[slot[(int(match[b]), int(r))]] = points[p]
    return out
