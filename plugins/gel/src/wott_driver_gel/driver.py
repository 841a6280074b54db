"""The gel driver: frames in, measured contacts out (``TactileFrame.contacts``), kept alive.

The run loop (worker thread, reconnects, a recording replayed as a camera that unplugs at its
end, the raw image) is ``wott_vision.driver.CameraDriver``'s. What is the gel's:

- the rest reference is the median of several frames at rest (``rest.RestCollector``); until it
  is taken the device yields nothing, ``contactInformation`` stays unknown (null) and the health
  says why ("no rest frame yet: the image changed by X grey levels between frames");
- ``tare`` takes it again over the next frames at rest and answers failure, with the reason, when
  it cannot: no reference yet, or the gel touched now; frames that keep changing while it collects
  keep the previous reference (the health says so);
- each frame's contacts (``contacts.find_contacts``) are handed over in mm: x along the image's
  columns, y along its rows, from the view's corner (``cornerOfView``), with their radii;
- with markers (``markers.MarkerField``), the nodes' in-plane displacement (skinDisplacement);
- with a depth calibration (``depth.DepthCalibration``), a touched frame's depth map is integrated:
  each contact gets the indentation at its centre and a normal-force estimate (``depth.normal_force``
  over the disc twice its radius, along -z: into the gel), the nodes its depth (-z), and ``depthMap``
  serves the last map (zeros at rest: a frame without contact is flat, no integration is run).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from wott_vision.driver import LOST_FRACTION_DEGRADED, CameraDriver, FrameReader

from wott_hub.plugin_api import DriverError, Health, MeasuredContact, RawSample, TactileFrame

from .contacts import ContactParams, PixelContact, find_contacts, threshold
from .depth import DepthCalibration, normal_force
from .markers import MarkerField, find_markers
from .rest import NoRestFrame, RestCollector, RestReference, smooth

if TYPE_CHECKING:
    from .settings import GelSettings

__all__ = ["FrameReader", "GelDriver", "GelEstimate", "GelEstimator"]


@dataclass(frozen=True, slots=True, eq=False)
class GelEstimate:
    contacts: list[PixelContact]
    change: np.ndarray  # (H, W) change from the reference, grey levels (drift-free where contact can be)
    depth: np.ndarray | None = None  # (H/scale, W/scale) mm, calibrated devices, touched frames
    shear: np.ndarray | None = None  # (N, 2) mm, the nodes' in-plane displacement (a marker gel)


# The scale of the illumination drift taken out of the colour change (``contacts.drift_free``): 1.2 mm
# (40 px on Taxim's Mini frames), the smallest of 0.6 / 1.2 / 2.4 mm that leaves the Mini presses'
# radii as they were (0.6 mm cuts into a 1-2 mm contact: 54 % within 15 % instead of 71 %).
DRIFT_SIGMA_MM = 1.2


class GelEstimator:
    """The rest reference and the contact finder of one gel (pixels in, mm out)."""

    def __init__(self, mm_per_px: float, params: ContactParams, collector: RestCollector,
                 calibration: DepthCalibration | None = None, *, modulus_mpa: float = 0.0,
                 thickness_mm: float = 4.0) -> None:
        self.mm_per_px = mm_per_px
        self.params = params
        self.collector = collector
        self.calibration = calibration
        self.modulus_mpa, self.thickness_mm = modulus_mpa, thickness_mm
        self.reference: RestReference | None = None
        self.retaking = False
        self.markers = False  # the gel has markers: shear from them (``markers.MarkerField``)
        self.nodes_mm = np.zeros((0, 3))
        self.field: MarkerField | None = None

    @classmethod
    def of_settings(cls, s: GelSettings, mm_per_px: float, calibration: DepthCalibration | None = None
                    ) -> GelEstimator:
        area_px = s.min_area_mm2 / mm_per_px**2
        sigma = 2.0
        params = ContactParams(min_change=s.min_change, min_area_px=area_px,
                               radius_fraction=s.radius_fraction, sigma_px=sigma,
                               open_px=max(3, int(round(0.15 / mm_per_px)) | 1),  # ~0.15 mm, odd
                               drift_sigma_px=DRIFT_SIGMA_MM / mm_per_px)
        from wott_hub.plugin_api import MATERIALS

        return cls(mm_per_px, params, RestCollector(s.rest_frames, s.rest_max_change, sigma), calibration,
                   modulus_mpa=MATERIALS[s.material].modulus_mpa, thickness_mm=s.thickness_mm)

    @property
    def has_reference(self) -> bool:
        return self.reference is not None

    def set_reference(self, image: np.ndarray) -> None:
        self.take(self.collector.add(image))

    def take(self, ref: RestReference) -> None:
        """``ref`` as the rest reference; with markers, their pattern in it (``NoRestFrame`` if none)."""
        field = None
        if self.markers:
            found = find_markers(ref.raw, self.mm_per_px)
            if found is None:
                raise NoRestFrame("no rest frame yet: the rest frame shows no marker pattern (markers = "
                                  "grid, or found in the recording's first frame)")
            field = MarkerField(found, self.nodes_mm, self.mm_per_px)
        self.reference, self.field = ref, field

    def reset_tracking(self) -> None:
        """The markers tracked from their rest positions again (the reference survives a reconnect)."""
        if self.field is not None:
            self.field.reset()

    def estimate(self, image: np.ndarray) -> GelEstimate:
        ref = self.reference
        assert ref is not None
        frame = smooth(image, self.params.sigma_px)
        shear = None
        ignore = None
        if self.field is not None:  # the dots first: where they are is not contact
            shear = self.field.displacement(image)
            ignore = self.field.dots(image.shape, self.params.sigma_px)
        contacts, change = find_contacts(frame, ref, self.params, smoothed=True, ignore=ignore)
        depth = None
        if self.calibration is not None and contacts:
            if ignore is not None:  # the dots' colour is no slope
                frame = np.where(ignore[..., None], ref.image, frame)
            depth = self.calibration.depth(frame, ref.image, threshold(ref, self.params))
        return GelEstimate(contacts, change, depth, shear)

    def measured(self, est: GelEstimate) -> tuple[MeasuredContact, ...]:
        k = self.mm_per_px
        cal, depth = self.calibration, est.depth
        if cal is None or depth is None:
            return tuple(MeasuredContact((c.x * k, c.y * k, 0.0), c.radius * k) for c in est.contacts)
        s = cal.scale
        h, w = depth.shape
        yy, xx = np.mgrid[0:h, 0:w]
        out = []
        for c in est.contacts:
            cx, cy = c.x / s, c.y / s
            i, j = min(max(int(round(cy)), 0), h - 1), min(max(int(round(cx)), 0), w - 1)
            centre = float(depth[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2].max())
            near = (xx - cx) ** 2 + (yy - cy) ** 2 <= (2.0 * c.radius / s) ** 2
            force = normal_force(depth[near], s * k, self.modulus_mpa, self.thickness_mm)
            out.append(MeasuredContact((c.x * k, c.y * k, 0.0), c.radius * k, centre, (0.0, 0.0, -force)))
        return tuple(out)

    def node_depth(self, depth: np.ndarray, nodes_mm: np.ndarray) -> np.ndarray:
        """The depth map (mm) at each node (N, 3 rest positions, mm), nearest sample."""
        assert self.calibration is not None
        s = self.calibration.scale * self.mm_per_px
        h, w = depth.shape
        j = np.clip(np.rint(nodes_mm[:, 0] / s).astype(int), 0, w - 1)
        i = np.clip(np.rint(nodes_mm[:, 1] / s).astype(int), 0, h - 1)
        out: np.ndarray = depth[i, j]
        return out


class GelDriver(CameraDriver):
    """A GelSight Mini or a DIGIT, from a recording or the sensor (see the module doc)."""

    reference_error = NoRestFrame
    rest_subject = "gel"
    estimator: GelEstimator
    last_estimate: GelEstimate | None

    def _waiting_reason(self, e: Exception) -> str:
        return str(e)  # "no rest frame yet: ..." says it all

    def tare(self) -> str:
        """Take the rest reference again over the next ``rest_frames`` frames at rest."""
        est = self.estimator
        if est.reference is None:
            why = self.health().reason or "no frame yet"
            raise DriverError(f"cannot tare: no rest reference yet ({why})")
        last = self.last_estimate
        if last is not None and last.contacts:
            raise DriverError(f"cannot tare: the gel is touched ({len(last.contacts)} contact(s) in the last "
                              "frame); tare at rest")
        est.collector.reset()
        est.retaking = True
        return f"the next {est.collector.frames} frames at rest are the gel's new rest reference"

    def recalibrate(self) -> str:
        return self.tare()

    def _estimate(self, image: Any) -> np.ndarray:
        est = self.estimator
        if est.retaking:
            try:
                est.take(est.collector.add(image))
                est.retaking = False
                self.set_health(Health.ok)
            except NoRestFrame as e:
                if "changed" in str(e):
                    self.set_health(Health.degraded, f"tare: {e}; the previous reference is kept meanwhile")
        result = self.last_estimate = est.estimate(np.asarray(image))
        if not est.retaking:
            self.set_health(Health.ok)
        displacement = np.zeros((self.description.mesh.n_nodes, 3))
        if result.depth is not None:
            displacement[:, 2] = -est.node_depth(result.depth, self.description.mesh.nodes)
        if est.field is not None and result.shear is not None:
            displacement[:, :2] = result.shear
            total = len(est.field.markers.points)
            if not est.retaking and est.field.lost > LOST_FRACTION_DEGRADED * total:
                self.set_health(Health.degraded, f"tracker lost {est.field.lost} of {total} markers")
        return displacement

    def _frame(self, t_ns: int, displacement: np.ndarray) -> TactileFrame:
        last = self.last_estimate
        contacts = self.estimator.measured(last) if last is not None else ()
        if self.depth_shape:
            depth = last.depth if last is not None and last.depth is not None else None
            self._depth = (t_ns, depth if depth is not None else np.zeros(self.depth_shape))
        return TactileFrame(t_ns, displacement, contacts=contacts)

    depth_shape: tuple[int, ...] = ()  # (rows, cols) of depthMap; () without a calibration
    _depth: tuple[int, np.ndarray] | None = None

    def raw_sample(self, name: str) -> RawSample | None:
        """The camera's image (``CameraDriver``), or ``depth``: the last frame's depth map (mm)."""
        if name == "depth":
            last = self._depth
            return None if last is None else RawSample(last[0], last[1])
        return super().raw_sample(name)
