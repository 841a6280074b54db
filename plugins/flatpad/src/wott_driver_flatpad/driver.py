"""The flat vision pad driver: a frame source in, ``TactileFrame``s out, kept alive.

The source is anything with the ``cv2.VideoCapture`` reading interface: a
USB camera, a video file or image sequence (through ``wott_vision.camera``) or
the simulator. The run loop (worker thread, health, reconnecting with backoff,
a file replaying as a camera that unplugs at its end, a finite simulated scene
ending the device) is ``wott_vision.driver.CameraDriver``'s; this module only
turns an image into displacement: ``degraded`` while the first frames do not
show the configured marker grid at rest, when markers are unavailable at rest,
when the tracker loses more than a tenth of the markers (they are filled from
their neighbours) or a displacement was clamped to the gel's thickness.
"""

from __future__ import annotations

import numpy as np
from wott_vision.driver import CameraDriver, FrameReader

from .estimator import PadEstimate, PadEstimator, ReferenceNotFound

__all__ = ["FlatPadDriver", "FrameReader"]


class FlatPadDriver(CameraDriver):
    """One pad: ``open_source()`` makes a reader, the estimator turns images into frames.

    ``prepare`` (a depth calibration) runs in the worker thread before the
    source is first opened.
    """

    reference_error = ReferenceNotFound
    rest_subject = "pad"
    estimator: PadEstimator
    last_estimate: PadEstimate | None

    def _recalibrate(self, image: np.ndarray) -> None:
        self.estimator.recalibrate(image)

    def _estimate(self, image: np.ndarray) -> np.ndarray:
        est = self.estimator
        result = self.last_estimate = est.update(image)
        n = self.description.mesh.n_nodes
        self._report_health(result.displacement, self._frame_t_ns, lost=result.lost, total=n, what="markers",
                            unavailable=est.unavailable_nodes, n_markers=n, clamped=result.clamped)
        return result.displacement
