"""The run loop of a camera-based skin: a frame source in, ``TactileFrame``s out, kept alive.

The barrel skin and the flat pad differ in what a frame is (two images or one)
and in how it becomes displacement; keeping the source alive is the same for
both, so it lives here once. Reading and estimation run in a worker thread (a
camera read blocks for a frame period, the estimate is milliseconds of NumPy
and OpenCV), so the event loop never stalls.

Health, as the driver contract asks:

- ``disconnected`` with the reason while the source is away (cannot open it, no
  frame: unplugged, a stream dropped, a video file at its end). The driver
  releases it and reopens it after an exponential backoff
  (``wott_hub.drivers.backoff``), reset by the first good frame; so a recording
  replays in a loop. A reader whose ``ended`` became true (a simulator playing
  a scene that does not loop) ends ``frames()`` instead: the device is done.
- ``degraded`` while the first frames do not show the marker grid at rest (no
  reference yet: nothing is yielded), or whatever the subclass's estimate says
  (``_report_lost``: more than a tenth of the markers lost).
- ``ok`` otherwise.

The rest reference survives a reconnect (the camera did not move relative to
the skin); only the tracker restarts from it. Nothing here imports cv2: the
reader that ``open_source`` makes does, in the worker thread.
"""

from __future__ import annotations

import abc
import asyncio
import threading
import time
from collections.abc import AsyncIterator, Callable
from typing import Any, ClassVar, Protocol

import numpy as np

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import Driver, Health
from wott_hub.tactile import DeviceDescription, TactileFrame

__all__ = ["LOST_FRACTION_DEGRADED", "CameraDriver", "FrameReader", "SourceEnded", "SourceLost"]

LOST_FRACTION_DEGRADED = 0.1


class FrameReader(Protocol):
    """The ``cv2.VideoCapture`` reading interface; optional ``isOpened``, ``failure``, ``ended``,
    ``t_s``/``realtime`` (scene time of a simulator) and ``truth`` (its ground truth)."""

    def read(self) -> tuple[bool, Any]: ...

    def release(self) -> None: ...


class Estimator(Protocol):
    @property
    def has_reference(self) -> bool: ...

    def set_reference(self, images: Any) -> None: ...

    def reset_tracking(self) -> None: ...


class SourceLost(RuntimeError):
    """The source gave no frame; the reason is the message."""


class SourceEnded(Exception):
    """A finite simulated source played to its end: the device is done, not lost."""


class CameraDriver(Driver):
    """One camera-based skin: ``open_source()`` makes a reader, the estimator turns frames into D.

    A subclass names what its estimator raises while the frame shows no grid
    at rest (``reference_error``), what is at rest (``rest_subject``), and
    implements ``_estimate``. ``max_frames`` stops after that many frames
    (tests, recording a known sequence). ``prepare`` runs once in the worker
    thread before the source is first opened (start-up work too slow for
    ``open_device``). ``last_estimate`` and ``last_truth`` (simulators only)
    describe the frame last estimated.
    """

    reference_error: ClassVar[type[Exception]]
    rest_subject: ClassVar[str] = "skin"
    source_name: str = "camera"

    def __init__(
        self,
        description: DeviceDescription,
        estimator: Estimator,
        open_source: Callable[[], FrameReader],
        *,
        source_name: str | None = None,
        backoff: Backoff | None = None,
        max_frames: int | None = None,
        prepare: Callable[[], None] | None = None,
    ) -> None:
        super().__init__(description)
        self.estimator = estimator
        self.open_source = open_source
        if source_name is not None:
            self.source_name = source_name
        self.backoff = backoff or Backoff()
        self.max_frames = max_frames
        self._prepare = prepare
        self.frames_yielded = 0
        self.reconnects = 0
        self.last_estimate: Any = None
        self.last_truth: np.ndarray | None = None
        self._reader: FrameReader | None = None
        self._lock = threading.Lock()  # a reader is never released while a thread reads it
        self._closed = asyncio.Event()
        self._wall0_ns = time.time_ns()
        self._mono0_ns = time.monotonic_ns()

    @abc.abstractmethod
    def _estimate(self, images: Any) -> np.ndarray | None:
        """(N, 3) displacement of a frame read once the reference is set; None drops the frame.

        Runs in the worker thread; sets ``last_estimate`` and the health the estimate implies.
        """

    def _report_lost(self, lost: int, total: int, what: str) -> None:
        if lost > LOST_FRACTION_DEGRADED * total:
            self.set_health(Health.degraded, f"tracker lost {lost} of {total} {what}")
        else:
            self.set_health(Health.ok)

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
        """Read one frame and estimate it; None while there is no reference yet, or for a dropped frame."""
        with self._lock:
            reader = self._reader
            if reader is None:
                raise SourceLost(f"{self.source_name} is closed")
            ok, images = reader.read()
            t_ns = self._timestamp(reader)
            truth = getattr(reader, "truth", None)
        if not ok or images is None:
            if getattr(reader, "ended", False):
                raise SourceEnded
            raise SourceLost(getattr(reader, "failure", "")
                             or f"{self.source_name} returned no frame (unplugged, or end of stream)")
        if self.estimator.has_reference:
            displacement = self._estimate(images)
        else:
            try:
                self.estimator.set_reference(images)
            except self.reference_error as e:
                self.set_health(Health.degraded, f"waiting for the {self.rest_subject} at rest: {e}")
                return None
            self.set_health(Health.ok)
            displacement = np.zeros((self.description.mesh.n_nodes, 3))  # the rest frame itself
        self.last_truth = truth
        return None if displacement is None else TactileFrame(t_ns, displacement)

    def _timestamp(self, reader: FrameReader) -> int:
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
                    if self._closed.is_set():  # close() released the source under the read: not a fault
                        return
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
        await asyncio.to_thread(self._release)


def _release(reader: Any) -> None:
    release = getattr(reader, "release", None)
    if release is not None:
        try:
            release()
        except Exception:  # a reader that fails to release is gone anyway
            pass


def _reason(e: BaseException, context: str) -> str:
    """The health reason for a failure: the source's own words, or the failure in its context.

    ``SourceLost`` and ``OSError`` (``CameraError``) messages are written to be read and name
    the source already; anything else (a bug, a model error) needs to say where it happened.
    """
    text = str(e).strip()
    if text and isinstance(e, SourceLost | OSError):
        return text
    return f"{context}: {text or type(e).__name__}"
