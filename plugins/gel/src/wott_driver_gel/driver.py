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
  columns, y along its rows, from the view's corner (``cornerOfView``), with their radii.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from wott_vision.driver import CameraDriver, FrameReader

from wott_hub.plugin_api import DriverError, Health, MeasuredContact, TactileFrame

from .contacts import ContactParams, PixelContact, find_contacts
from .rest import NoRestFrame, RestCollector, RestReference

if TYPE_CHECKING:
    from .settings import GelSettings

__all__ = ["FrameReader", "GelDriver", "GelEstimate", "GelEstimator"]


@dataclass(frozen=True, slots=True, eq=False)
class GelEstimate:
    contacts: list[PixelContact]
    change: np.ndarray  # (H, W) colour change from the reference, grey levels


class GelEstimator:
    """The rest reference and the contact finder of one gel (pixels in, mm out)."""

    def __init__(self, mm_per_px: float, params: ContactParams, collector: RestCollector) -> None:
        self.mm_per_px = mm_per_px
        self.params = params
        self.collector = collector
        self.reference: RestReference | None = None
        self.retaking = False

    @classmethod
    def of_settings(cls, s: GelSettings, mm_per_px: float) -> GelEstimator:
        area_px = s.min_area_mm2 / mm_per_px**2
        sigma = 2.0
        params = ContactParams(min_change=s.min_change, min_area_px=area_px,
                               radius_fraction=s.radius_fraction, sigma_px=sigma,
                               open_px=max(3, int(round(0.15 / mm_per_px)) | 1))  # ~0.15 mm, odd
        return cls(mm_per_px, params, RestCollector(s.rest_frames, s.rest_max_change, sigma))

    @property
    def has_reference(self) -> bool:
        return self.reference is not None

    def set_reference(self, image: np.ndarray) -> None:
        self.reference = self.collector.add(image)

    def reset_tracking(self) -> None:
        """Nothing tracked between frames (the reference survives a reconnect)."""

    def estimate(self, image: np.ndarray) -> GelEstimate:
        assert self.reference is not None
        contacts, change = find_contacts(image, self.reference, self.params)
        return GelEstimate(contacts, change)

    def measured(self, contacts: list[PixelContact]) -> tuple[MeasuredContact, ...]:
        k = self.mm_per_px
        return tuple(MeasuredContact((c.x * k, c.y * k, 0.0), c.radius * k) for c in contacts)


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
                est.reference = est.collector.add(image)
                est.retaking = False
                self.set_health(Health.ok)
            except NoRestFrame as e:
                if "changed" in str(e):
                    self.set_health(Health.degraded, f"tare: {e}; the previous reference is kept meanwhile")
        self.last_estimate = est.estimate(np.asarray(image))
        if not est.retaking:
            self.set_health(Health.ok)
        return np.zeros((self.description.mesh.n_nodes, 3))

    def _frame(self, t_ns: int, displacement: np.ndarray) -> TactileFrame:
        last = self.last_estimate
        contacts = self.estimator.measured(last.contacts) if last is not None else ()
        return TactileFrame(t_ns, displacement, contacts=contacts)
