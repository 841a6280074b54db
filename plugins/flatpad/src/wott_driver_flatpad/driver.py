"""The flat vision pad driver: a frame source in, ``TactileFrame``s out, kept alive.

The source is anything with the ``cv2.VideoCapture`` reading interface: a
USB camera, a video file or image sequence (through ``wott_vision.camera``) or
the simulator. Reading and estimation run in a worker thread (a camera read
blocks for a frame period; the estimate is a few milliseconds of NumPy), so
the event loop never stalls.

Health, as the driver contract asks:

- ``disconnected`` with the reason (cannot open, no frame: unplugged or end
  of a file) while the source is away; the driver releases it and reopens it
  after an exponential backoff (``wott_hub.drivers.backoff``), reset by the
  first good frame. A file is a camera that unplugs at its end, so a recording
  replays in a loop.
- ``degraded`` while the first frames do not show the configured marker grid
  at rest (no reference yet: nothing is yielded), or when the tracker loses
  more than a tenth of the markers (they are filled from their neighbours).
- ``ok`` otherwise.

The rest reference survives a reconnect (the camera did not move relative to
the gel); only the tracker restarts from it.
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

from .estimator import PadEstimator, ReferenceNotFound

__all__ = ["FlatPadDriver", "FrameReader", "SourceLost"]

LOST_FRACTION_DEGRADED = 0.1


class FrameReader(Protocol):
    def read(self) -> tuple[bool, Any]: ...

    def release(self) -> None: ...


class SourceLost(RuntimeError):
    """The source gave no frame; the reason is the message."""


class SourceEnded(Exception):
    """A finite simulated source played to its end: the device is done, not lost."""


class FlatPadDriver(Driver):
    """One pad: ``open_source()`` makes a reader, the estimator turns images into frames.

    ``max_frames`` stops after that many frames (tests, recording a known
    sequence). ``prepare`` runs once in the worker thread before the source is
    first opened (start-up work too slow for ``open_device``). A reader with an
    ``ended`` attribute that becomes true (the simulator playing a scene that
    does not loop) ends ``frames()`` instead of reconnecting.
    """

    def __init__(
        self,
        description: DeviceDescription,
        estimator: PadEstimator,
        open_source: Callable[[], FrameReader],
        *,
        source_name: str = "camera",
        backoff: Backoff | None = None,
        max_frames: int | None = None,
        prepare: Callable[[], None] | None = None,
    ) -> None:
        super().__init__(description)
        self.estimator = estimator
        self.open_source = open_source
        self.source_name = source_name
        self.backoff = backoff or Backoff()
        self.max_frames = max_frames
        self._prepare = prepare
        self.frames_yielded = 0
        self.reconnects = 0
        self.last_estimate = None
        self.last_truth: np.ndarray | None = None
        self._reader: FrameReader | None = None
        self._lock = threading.Lock()  # a reader is never released while a thread reads it
        self._closed = asyncio.Event()
        self._wall0_ns = time.time_ns()
        self._mono0_ns = time.monotonic_ns()

    # -- worker-thread side ----------------------------------------------------
    def _open(self) -> None:
        if self._prepare is not None:  # one-off start-up work (a depth calibration), off the event loop
            self._prepare()
            self._prepare = None
        with self._lock:
            reader = self.open_source()
            opened = getattr(reader, "isOpened", None)
            if opened is not None and not opened():
                _release(reader)
                raise SourceLost(f"cannot open {self.source_name}")
            self._reader = reader
        if self.estimator.has_reference:
            self.estimator.reset_tracking()

    def _release(self) -> None:
        with self._lock:
            reader, self._reader = self._reader, None
            if reader is not None:
                _release(reader)

    def _step(self) -> TactileFrame | None:
        """Read one frame and estimate it; None while there is no reference yet."""
        with self._lock:
            reader = self._reader
            if reader is None:
                raise SourceLost(f"{self.source_name} is closed")
            ok, image = reader.read()
            t_ns = self._timestamp(reader)
            truth = getattr(reader, "truth", None)
        if not ok or image is None:
            if getattr(reader, "ended", False):
                raise SourceEnded
            raise SourceLost(getattr(reader, "failure", "")
                             or f"{self.source_name} returned no frame (unplugged, or end of stream)")
        est = self.estimator
        if not est.has_reference:
            try:
                est.set_reference(image)
            except ReferenceNotFound as e:
                self.set_health(Health.degraded, f"waiting for the pad at rest: {e}")
                return None
            self.set_health(Health.ok)
            self.last_truth = truth
            return TactileFrame(t_ns, np.zeros((self.description.mesh.n_nodes, 3)))
        result = est.update(image)
        self.last_estimate, self.last_truth = result, truth
        m = self.description.mesh.n_nodes
        if result.lost > LOST_FRACTION_DEGRADED * m:
            self.set_health(Health.degraded, f"tracker lost {result.lost} of {m} markers")
        else:
            self.set_health(Health.ok)
        return TactileFrame(t_ns, result.displacement)

    def _timestamp(self, reader: FrameReader) -> int:
        """Wall-clock ns from the monotonic clock (never backwards); scene time for a simulator."""
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
                except SourceLost as e:
                    self._lost(str(e))
                    if await self._pause():
                        return
                    continue
                except Exception as e:  # a driver never raises out of frames() for a transient fault
                    self._lost(_reason(e, f"{self.source_name} failed"))
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

    def _lost(self, reason: str) -> None:
        self.set_health(Health.disconnected, reason)
        self.reconnects += 1
        self._release()

    async def close(self) -> None:
        self._closed.set()
        await asyncio.to_thread(self._release)


def _release(reader: Any) -> None:
    release = getattr(reader, "release", None)
    if release is not None:
        try:
            release()
        except Exception:  # a reader that fails to release is gone anyway
            pass


def _reason(exc: BaseException, prefix: str) -> str:
    text = str(exc).strip()
    if not text:
        return f"{prefix}: {type(exc).__name__}"
    return text if text.startswith(prefix) else f"{prefix}: {text}"
