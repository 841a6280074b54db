"""The barrel vision skin driver: two camera frames in, ``TactileFrame``s out, kept alive.

The source is a pair reader: ``CameraPair`` (two ``wott_vision.camera``
sources: device indices, video files, stream URLs) or the simulator
(``SimulatedCameras``). The run loop (worker thread, health, reconnecting
with backoff, a finite simulated scene ending the device) is
``wott_vision.driver.CameraDriver``'s; this module only turns a pair of frames
into displacement: ``degraded`` while the first frames do not show the marker
grid at rest ("first-frame" reference), when more than a tenth of the marker
views are lost, or when the model returns NaN/Inf (that frame is dropped).

A model that does not fit the contract never gets here: it is refused when
the device opens (``settings.open_barrel``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from wott_vision.driver import CameraDriver

from wott_hub.plugin_api import Health

from .estimator import BarrelEstimate, BarrelEstimator, ReferenceNotFound

if TYPE_CHECKING:
    from wott_vision.camera import CameraReader

__all__ = ["BarrelDriver", "CameraPair"]


class CameraPair:
    """Two camera sources read together: ``read()`` -> (True, (bottom, top)) or (False, None)."""

    def __init__(self, specs: tuple[int | str, ...], names: tuple[str, ...] = ("bottom", "top"), *,
                 fps: float | None = None, realtime: bool = True) -> None:
        from wott_vision.camera import CameraError, open_source

        self.names = names
        self.failure = ""
        self._cams: list[CameraReader] = []
        try:
            for spec, name in zip(specs, names, strict=True):
                try:
                    self._cams.append(open_source(spec, fps=fps, realtime=realtime))
                except CameraError as e:
                    raise CameraError(f"{name} camera: {e}") from None
        except BaseException:
            self.release()
            raise

    def read(self) -> tuple[bool, tuple[np.ndarray, ...] | None]:
        frames = []
        for cam, name in zip(self._cams, self.names, strict=True):
            _, frame = cam.read()
            if frame is None:  # a camera that failed gives (False, None), one that read (True, frame)
                self.failure = f"{name} camera: {cam.failure}"
                return False, None
            frames.append(frame)
        return True, tuple(frames)

    @property
    def recorded(self) -> bool:
        """Both recorded (files): frames carry the bottom camera's recorded time ``t_s``."""
        return bool(self._cams) and all(c.recorded for c in self._cams)

    @property
    def t_s(self) -> float | None:
        return self._cams[0].t_s if self._cams else None

    def release(self) -> None:
        for cam in self._cams:
            cam.release()
        self._cams = []


class BarrelDriver(CameraDriver):
    """One barrel skin: ``open_source()`` makes a pair reader, the estimator turns frames into D.

    ``last_estimate`` is the ``BarrelEstimate`` of the frame last estimated.
    """

    reference_error = ReferenceNotFound
    source_name = "cameras"
    estimator: BarrelEstimator
    last_estimate: BarrelEstimate | None

    def _estimate(self, images: tuple[np.ndarray, ...]) -> np.ndarray | None:
        est = self.estimator
        result = self.last_estimate = est.estimate(images)
        if not np.isfinite(result.displacement).all():
            self.set_health(Health.degraded, "the model returned NaN/Inf: frame dropped")
            return None
        total = est.layout.markers.n_markers * len(est.layout.cameras)
        self._report_health(result.displacement, self._frame_t_ns,
                            lost=result.lost if est.uses_markers else 0, total=total, what="marker views",
                            unavailable=est.unavailable_nodes, n_markers=total, clamped=result.clamped,
                            unavailable_markers=est.unavailable_markers)
        return result.displacement
