"""The barrel vision skin driver: two camera frames in, ``TactileFrame``s out, kept alive.

The source is a pair reader: ``CameraPair`` (two ``wott_vision.camera``
sources: device indices, video files, stream URLs) or the simulator
(``SimulatedCameras``). Reading and estimation run in a worker thread (a
camera read blocks for a frame period, the estimate is a few milliseconds of
NumPy and OpenCV), so the event loop never stalls.

Health, as the driver contract asks:

- ``disconnected`` with the reason while a camera is away (cannot open it, no
  frame: unplugged, a stream dropped, a video file at its end). The driver
  releases both cameras and reopens them after an exponential backoff
  (``wott_hub.drivers.backoff``), reset by the first good frame; so a pair of
  recordings replays in a loop.
- ``degraded`` while the first frames do not show the marker grid at rest
  ("first-frame" reference), or when more than a tenth of the markers are lost.
- ``ok`` otherwise.

A model that does not fit the contract never gets here: it is refused when
the device opens (``settings.open_barrel``).
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import AsyncIterator, Callable
from typing import Any, Protocol

import numpy as np

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import Driver, Health
from wott_hub.tactile import DeviceDescription, TactileFrame

from .estimator import BarrelEstimate, BarrelEstimator, ReferenceNotFound

__all__ = ["BarrelDriver", "CameraPair", "PairReader", "SourceLost"]

LOST_FRACTION_DEGRADED = 0.1


class PairReader(Protocol):
    def read(self) -> tuple[bool, Any]: ...

    def release(self) -> None: ...


class SourceLost(RuntimeError):
    """A camera gave no frame; the reason is the message."""


class SourceEnded(Exception):
    """A finite simulated source played to its end: the device is done, not lost."""


class CameraPair:
    """Two camera sources read together: ``read()`` -> (True, (bottom, top)) or (False, None)."""

    def __init__(self, specs: tuple[int | str, ...], names: tuple[str, ...] = ("bottom", "top")) -> None:
        from wott_vision.camera import CameraError, open_source

        self.names = names
        self.failure = ""
        self._cams: list = []
        try:
            for spec, name in zip(specs, names, strict=True):
                try:
                    self._cams.append(open_source(spec))
                except CameraError as e:
                    raise CameraError(f"{name} camera: {e}") from None
        except BaseException:
            self.release()
            raise

    def read(self) -> tuple[bool, tuple[np.ndarray, ...] | None]:
        frames = []
        for cam, name in zip(self._cams, self.names, strict=True):
            ok, frame = cam.read()
            if not ok:
                self.failure = f"{name} camera: {cam.failure}"
                return False, None
            frames.append(frame)
        return True, tuple(frames)

    def release(self) -> None:
        for cam in self._cams:
            cam.release()
        self._cams = []


class BarrelDriver(Driver):
    """One barrel skin: ``open_source()`` makes a pair reader, the estimator turns frames into D.

    ``max_frames`` stops after that many frames (tests, recording a known
    sequence). A reader with an ``ended`` attribute that becomes true (the
    simulator playing a scene that does not loop) ends ``frames()`` instead of
    reconnecting. ``last_estimate`` and ``last_truth`` (simulator only) describe
    the frame last yielded.
    """

    def __init__(
        self,
        description: DeviceDescription,
        estimator: BarrelEstimator,
        open_source: Callable[[], PairReader],
        *,
        source_name: str = "cameras",
        backoff: Backoff | None = None,
        max_frames: int | None = None,
    ) -> None:
        super().__init__(description)
        self.estimator = estimator
        self.open_source = open_source
        self.source_name = source_name
        self.backoff = backoff or Backoff()
        self.max_frames = max_frames
        self.frames_yielded = 0
        self.reconnects = 0
        self.last_estimate: BarrelEstimate | None = None
        self.last_truth: np.ndarray | None = None
        self._reader: PairReader | None = None
        self._lock = threading.Lock()  # a reader is never released while a thread reads it
        self._closed = asyncio.Event()
        self._wall0_ns = time.time_ns()
        self._mono0_ns = time.monotonic_ns()

    # -- worker-thread side ----------------------------------------------------
    def _open(self) -> None:
        with self._lock:
            self._reader = self.open_source()
        self.estimator.reset_tracking()

    def _release(self) -> None:
        with self._lock:
            reader, self._reader = self._reader, None
            if reader is not None:
                reader.release()

    def _step(self) -> TactileFrame | None:
        """Read both frames and estimate; None while there is no reference yet."""
        with self._lock:
            reader = self._reader
            if reader is None:
                raise SourceLost(f"{self.source_name} closed")
            ok, images = reader.read()
            t_ns = self._timestamp(reader)
            truth = getattr(reader, "truth", None)
        if not ok or images is None:
            if getattr(reader, "ended", False):
                raise SourceEnded
            raise SourceLost(getattr(reader, "failure", "") or f"{self.source_name}: no frame")
        est = self.estimator
        if not est.has_reference:
            try:
                est.set_reference(images)
            except ReferenceNotFound as e:
                self.set_health(Health.degraded, f"waiting for the skin at rest: {e}")
                return None
            self.set_health(Health.ok)
            self.last_truth = truth
            return TactileFrame(t_ns, np.zeros((self.description.mesh.n_nodes, 3)))
        result = est.estimate(images)
        self.last_estimate, self.last_truth = result, truth
        total = est.layout.markers.n_markers * len(est.layout.cameras)
        if est.uses_markers and result.lost > LOST_FRACTION_DEGRADED * total:
            self.set_health(Health.degraded, f"tracker lost {result.lost} of {total} marker views")
        else:
            self.set_health(Health.ok)
        return TactileFrame(t_ns, result.displacement)

    def _timestamp(self, reader: PairReader) -> int:
        """Wall-clock ns from the monotonic clock (never backwards); scene time for a fast simulator."""
        t_s = getattr(reader, "t_s", None)
        if t_s is not None and not getattr(reader, "realtime", True):
            return self._wall0_ns + int(round(float(t_s) * 1e9))
        return self._wall0_ns + time.monotonic_ns() - self._mono0_ns

    # -- event-loop side ---------------------------------------------------------
    async def _pause(self) -> bool:
        """Wait out the next backoff delay; True if closed meanwhile."""
        try:
            await asyncio.wait_for(self._closed.wait(), self.backoff.next_delay())
            return True
        except TimeoutError:
            return False

    async def frames(self) -> AsyncIterator[TactileFrame]:
        try:
            while not self._closed.is_set():
                if self.max_frames is not None and self.frames_yielded >= self.max_frames:
                    return
                if self._reader is None:
                    try:
                        await asyncio.to_thread(self._open)
                    except Exception as e:  # any failure to open is a reason to retry, not to die
                        self.set_health(Health.disconnected, _reason(e, f"cannot open {self.source_name}"))
                        if await self._pause():
                            return
                        continue
                try:
                    frame = await asyncio.to_thread(self._step)
                except SourceEnded:
                    return
                except Exception as e:  # a driver never raises out of frames() for a transient fault
                    await asyncio.to_thread(self._release)
                    self.set_health(Health.disconnected, _reason(e, f"{self.source_name} failed"))
                    self.reconnects += 1
                    if await self._pause():
                        return
                    continue
                if frame is None:
                    await asyncio.sleep(0)
                    continue
                self.backoff.reset()
                self.frames_yielded += 1
                yield frame
        finally:
            await asyncio.to_thread(self._release)

    async def close(self) -> None:
        self._closed.set()


def _reason(e: BaseException, fallback: str) -> str:
    text = str(e).strip()
    return text if text else f"{fallback} ({type(e).__name__})"
