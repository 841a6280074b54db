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
- ``ok`` otherwise; ``ok`` with the reason ``below threshold: ...`` while the
  skin has been displaced more than ``BELOW_THRESHOLD_FLOOR`` x ε but never
  above ε for ``below_threshold_s`` (a press too light to be reported: the
  silence is explained).

Markers unavailable at rest (``unavailable_nodes``: missing, merged or occluded
markers, their nodes read 0) and displacements clamped to the family's
physical bound are reported in the health reason too (``_report_health``); the hub
serves ``unavailable_nodes`` as the observable ``unavailableNodes`` property
(``ReportsUnavailableNodes``) and gives its processor
``below_threshold_floor``/``below_threshold_s`` (``NoisyAtRest``, docs/processing.md).

Time: a live camera's frames are stamped with the hub clock when read. A
recorded source (a reader with ``recorded`` true: video files, image
sequences) stamps each frame with its recorded time ``t_s`` from the start,
mapped onto the hub clock when the source was opened (a replayed loop continues
after the last frame, never backwards); it paces itself (``realtime``) or runs
as fast as read. A simulator with ``realtime = false`` uses its scene time; in real time, the
instant its frame was due (``captured_s``, monotonic: a late read does not move the frame in time).

The rest reference survives a reconnect (the camera did not move relative to
the skin); only the tracker restarts from it. Nothing here imports cv2: the
reader that ``open_source`` makes does, in the worker thread.

A source that never opens (a FIFO nobody writes, a stream URL that black-holes) must
not make the device impossible to remove or the hub impossible to stop. So the
worker thread is a daemon thread of the driver's own (``_Worker``), never the event
loop's default executor, whose threads the interpreter joins at exit; a source is
opened outside the lock that guards the reader, so ``close()`` never waits for an
open; and releasing a reader (``close()``, the end of ``frames()``) is done by the worker thread
that opened and read it (``_release_on_worker``: OpenCV's FFmpeg capture must not outlive, or be
released beside, its own threads) and waits at most ``RELEASE_TIMEOUT_S`` (a reader stuck in a
read keeps the lock). Whatever is still
stuck then is left to its daemon thread: an open that returns after ``close()``
releases what it opened.

Raw signals (``ServesRawSignals``): each camera's latest image, one ``RawSignal`` per name of
``raw_signals`` (set by the family when it opens the device: its cameras' names and sizes). The
worker thread keeps a reference to the last frame it read (one assignment per frame, no copy);
``raw_sample`` hands it out as H x W grey or H x W x 3 RGB (a camera's BGR, reversed as a view).
"""

from __future__ import annotations

import abc
import asyncio
import queue
import threading
import time
from collections.abc import AsyncIterator, Callable
from typing import Any, ClassVar, Protocol, TypeVar

import numpy as np

from wott_hub.plugin_api import (
    Backoff,
    DeviceDescription,
    Driver,
    DriverError,
    Health,
    NoisyAtRest,
    RawSample,
    RawSignal,
    Recalibratable,
    ReportsUnavailableNodes,
    ServesRawSignals,
    TactileFrame,
    Tareable,
)

__all__ = ["BELOW_THRESHOLD_FLOOR", "LOST_FRACTION_DEGRADED", "RELEASE_TIMEOUT_S", "CameraDriver",
           "FrameReader"]

LOST_FRACTION_DEGRADED = 0.1
BELOW_THRESHOLD_FLOOR = 0.75  # x epsilon: above the image-noise floor at rest of both families
RELEASE_TIMEOUT_S = 2.0
"""Longest wait for a reader's release (``close()``); a reader stuck in a read is left behind."""

T = TypeVar("T")


class _Worker:
    """A driver's blocking calls (open, read, estimate), in order, on one daemon thread of its own.

    A call that never returns (an open that hangs) holds only this thread, and a daemon
    thread does not keep the process alive at exit; an awaiting coroutine that is
    cancelled stops waiting at once (the call's result is then dropped)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._jobs: queue.SimpleQueue[tuple[Callable[[], Any], asyncio.Future[Any]] | None] | None = None

    def call(self, fn: Callable[[], T]) -> asyncio.Future[T]:
        fut: asyncio.Future[T] = asyncio.get_running_loop().create_future()
        if self._jobs is None:  # each thread its own queue: a stopped one still stuck takes no new call
            self._jobs = queue.SimpleQueue()
            threading.Thread(target=self._run, args=(self._jobs,), name=self.name, daemon=True).start()
        self._jobs.put((fn, fut))
        return fut

    def stop(self) -> None:
        """The thread ends after the call it is in, if any (a new ``call`` starts another)."""
        if self._jobs is not None:
            self._jobs.put(None)
            self._jobs = None

    @staticmethod
    def _run(jobs: queue.SimpleQueue[tuple[Callable[[], Any], asyncio.Future[Any]] | None]) -> None:
        while (job := jobs.get()) is not None:
            fn, fut = job
            try:
                value, error = fn(), None
            except BaseException as e:  # handed to the awaiting coroutine
                value, error = None, e
            try:
                fut.get_loop().call_soon_threadsafe(_settle, fut, value, error)
            except RuntimeError:  # the loop is closed: nobody waits any more
                pass


def _settle(fut: asyncio.Future[Any], value: Any, error: BaseException | None) -> None:
    if fut.cancelled():
        return
    if error is not None:
        fut.set_exception(error)
    else:
        fut.set_result(value)


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


class _SourceLost(RuntimeError):
    """The source gave no frame; the reason is the message (the health reason: it never leaves
    ``frames()``)."""


class _SourceEnded(Exception):
    """A finite simulated source played to its end: the device is done, not lost (``frames()`` ends)."""


def _recorded_base(read_ns: int, last_t_ns: int, reader: Any) -> int:
    """The hub time of a recording's t_s = 0: when its first read began (``read_ns``, hub time: the
    reader paces from there), after the last frame of a previous read (``last_t_ns``). Not when it was
    opened: the hub's loop may be busy between the two (the frames of the device opened first were
    stamped ~100 ms early)."""
    t_s_ns = int(round(float(getattr(reader, "t_s", 0.0) or 0.0) * 1e9))
    return max(read_ns, last_t_ns + 1_000_000) - t_s_ns


class CameraDriver(Driver, Tareable, Recalibratable, NoisyAtRest, ReportsUnavailableNodes, ServesRawSignals):
    """One camera-based skin: ``open_source()`` makes a reader, the estimator turns frames into D.

    A subclass names what its estimator raises while the frame shows no grid
    at rest (``reference_error``), what is at rest (``rest_subject``), and
    implements ``_estimate``. ``max_frames`` stops after that many frames
    (tests, recording a known sequence). ``prepare`` runs once in the worker
    thread before the source is first opened (start-up work too slow for
    ``open_device``). ``last_estimate``, ``last_truth`` and ``last_truth_t_s``
    (simulators only: the scene time of that truth) describe the frame last estimated.
    """

    reference_error: ClassVar[type[Exception]]
    rest_subject: ClassVar[str] = "skin"
    below_threshold_floor: float = BELOW_THRESHOLD_FLOOR  # the hub's processor uses it too (NoisyAtRest)
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
        self.last_truth_t_s: float | None = None
        self._reader: FrameReader | None = None
        self._lock = threading.Lock()  # a reader is never released while a thread reads it
        self._closed = asyncio.Event()
        self._worker = _Worker(f"camera:{description.id}")
        self._wall0_ns = time.time_ns()
        self._mono0_ns = time.monotonic_ns()
        self._base_ns: int | None = None  # hub time of a recorded source's t_s = 0
        self._last_t_ns = 0
        self.below_threshold_s = 1.0  # 0: never report a press below epsilon
        self._below_since_ns: int | None = None
        self.unavailable_nodes: list[int] = []
        self.clamped_frames = 0
        self._frame_t_ns = 0  # time of the frame being estimated (``_estimate`` reads it)
        self._rest_request: str | None = None  # "tare" | "recalibrate", done on the next frame read
        self.raw_signals: tuple[RawSignal, ...] = ()  # the cameras, in the order a frame holds them
        self._raw: tuple[int, Any] | None = None  # (t_ns, images) of the last frame read: a reference

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

    def _report_health(self, displacement: np.ndarray, t_ns: int, *, lost: int, total: int, what: str,
                       unavailable: list[int], n_markers: int, clamped: int,
                       unavailable_markers: int | None = None) -> None:
        """Health of an estimated frame: unavailable markers, tracking losses, clamps, a press below ε."""
        reasons = []
        self.unavailable_nodes = unavailable
        if unavailable:
            shown = ", ".join(map(str, unavailable[:32])) + (", ..." if len(unavailable) > 32 else "")
            k = len(unavailable) if unavailable_markers is None else unavailable_markers
            reasons.append(f"{k} of {n_markers} markers unavailable; unknown nodes, reported at rest: "
                           f"{shown}")
        if lost > LOST_FRACTION_DEGRADED * total:
            reasons.append(f"tracker lost {lost} of {total} {what}")
        if clamped:
            self.clamped_frames += 1
            reasons.append(f"{clamped} nodes beyond the physical bound, clamped")
        if reasons:
            self.set_health(Health.degraded, "; ".join(reasons))
            return
        eps = self.description.epsilon_mm
        peak = float(np.sqrt(np.einsum("ij,ij->i", displacement, displacement).max(initial=0.0)))
        if BELOW_THRESHOLD_FLOOR * eps < peak <= eps and self.below_threshold_s > 0:
            if self._below_since_ns is None:
                self._below_since_ns = t_ns
            if (t_ns - self._below_since_ns) / 1e9 >= self.below_threshold_s:  # a stable reason: one change
                floor = BELOW_THRESHOLD_FLOOR * eps
                self.set_health(Health.ok, f"below threshold: displaced {floor:g}-{eps:g} mm (epsilon "
                                           f"{eps:g} mm) for over {self.below_threshold_s:g} s: not reported")
                return
        else:
            self._below_since_ns = None
        self.set_health(Health.ok)

    # -- worker-thread side ----------------------------------------------------
    def _open(self) -> None:
        if self._prepare is not None:  # one-off start-up work (a depth calibration), off the event loop
            self._prepare()
            self._prepare = None
        reader = self.open_source()  # not under the lock: an open that hangs must not hold up close()
        opened = getattr(reader, "isOpened", None)
        if opened is not None and not opened():
            _release(reader)
            raise _SourceLost(f"cannot open {self.source_name}")
        with self._lock:
            if self._closed.is_set():  # closed while it opened: nobody will read it
                _release(reader)
                raise _SourceLost(f"{self.source_name} is closed")
            self._reader = reader
            self._base_ns = None  # a recording's: set at its first read (``_step``)
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
                raise _SourceLost(f"{self.source_name} is closed")
            read_ns, (ok, images) = self._wall0_ns - self._mono0_ns + time.monotonic_ns(), reader.read()
            if ok and self._base_ns is None and getattr(reader, "recorded", False):
                self._base_ns = _recorded_base(read_ns, self._last_t_ns, reader)
            t_ns = self._timestamp(reader)
            truth = getattr(reader, "truth", None)
            truth_t_s = getattr(reader, "t_s", None) if truth is not None else None
        if not ok or images is None:
            if getattr(reader, "ended", False):
                raise _SourceEnded
            raise _SourceLost(getattr(reader, "failure", "")
                             or f"{self.source_name} returned no frame (unplugged, or end of stream)")
        self._last_t_ns = max(self._last_t_ns, t_ns)
        self._raw = (t_ns, images)  # one assignment: raw_sample reads it on the loop
        request, self._rest_request = self._rest_request, None
        if request is not None and self.estimator.has_reference:
            self._take_rest(request, images)
        if self.estimator.has_reference:
            self._frame_t_ns = t_ns
            displacement = self._estimate(images)
        else:
            try:
                self.estimator.set_reference(images)
            except self.reference_error as e:
                self.set_health(Health.degraded, self._waiting_reason(e))
                return None
            self.set_health(Health.ok)
            displacement = np.zeros((self.description.mesh.n_nodes, 3))  # the rest frame itself
        self.last_truth, self.last_truth_t_s = truth, truth_t_s
        return None if displacement is None else self._frame(t_ns, displacement)

    def _frame(self, t_ns: int, displacement: np.ndarray) -> TactileFrame:
        """The frame handed to the hub (a subclass adds what it measures besides the node field)."""
        return TactileFrame(t_ns, displacement)

    def _waiting_reason(self, e: Exception) -> str:
        """The health reason while the first frames give no reference (``e``: why this one did not)."""
        return f"waiting for the {self.rest_subject} at rest: {e}"

    # -- raw signals (``ServesRawSignals``): the last frame read, as it is ---------------------------
    def raw_sample(self, name: str) -> RawSample | None:
        raw = self._raw
        if raw is None:
            return None
        t_ns, images = raw
        frames = images if isinstance(images, tuple | list) else (images,)
        for signal, image in zip(self.raw_signals, frames, strict=False):
            if signal.name == name:
                image = np.asarray(image)
                if image.ndim == 3 and image.shape[2] == 3:
                    image = image[..., ::-1]  # OpenCV's BGR as RGB, a view
                return RawSample(t_ns, image)
        return None

    # -- device actions (``Tareable``, ``Recalibratable``): requested on the loop, done in the thread --
    def _refuse_without_reference(self, action: str) -> None:
        """A tare or recalibration needs a reference to replace: without one the action fails with the
        reason the device has none (issue 44: it answered ``ok`` and did nothing)."""
        if not self.estimator.has_reference:
            why = self.health().reason or "no frame read yet"
            raise DriverError(f"cannot {action}: no rest reference yet ({why})")

    def tare(self) -> str:
        self._refuse_without_reference("tare")
        self._rest_request = "tare"
        return f"the next frame is the {self.rest_subject}'s new rest reference"

    def recalibrate(self) -> str:
        self._refuse_without_reference("recalibrate")
        self._rest_request = "recalibrate"
        return f"the marker grid is found again in the next frame (the {self.rest_subject} must be at rest)"

    def _recalibrate(self, images: Any) -> None:
        """Find the marker grid again in ``images``; a subclass widens its search first if it narrowed it."""
        self.estimator.set_reference(images)

    def _take_rest(self, request: str, images: Any) -> None:
        """A new reference from ``images``; one that cannot be taken keeps the previous one (health says)."""
        try:
            if request == "recalibrate":
                self._recalibrate(images)
            else:
                self.estimator.set_reference(images)
        except self.reference_error as e:
            self.set_health(Health.degraded, f"{request} failed, the previous reference is kept: {e}")
            return
        self.set_health(Health.ok)

    def _timestamp(self, reader: FrameReader) -> int:
        """Wall-clock ns from the monotonic clock (never backwards); the recorded time of a file;
        scene time for a fast simulator."""
        t_s = getattr(reader, "t_s", None)
        if t_s is not None and self._base_ns is not None and getattr(reader, "recorded", False):
            return self._base_ns + int(round(float(t_s) * 1e9))
        if t_s is not None and not getattr(reader, "realtime", True):
            return self._wall0_ns + int(round(float(t_s) * 1e9))
        captured_s = getattr(reader, "captured_s", None)
        if captured_s is not None:  # when the frame was taken, not when a busy thread read it
            t_ns = self._wall0_ns + int(round(float(captured_s) * 1e9)) - self._mono0_ns
            return max(t_ns, self._last_t_ns + 1)
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
                        await self._worker.call(self._open)
                    except Exception as e:  # any failure to open is a reason to retry, not to die
                        self.set_health(Health.disconnected, _reason(e, f"cannot open {self.source_name}"))
                        if await self._pause():
                            return
                        continue
                try:
                    frame = await self._worker.call(self._step)
                except _SourceEnded:
                    return
                except Exception as e:  # a driver never raises out of frames() for a transient fault
                    if self._closed.is_set():  # close() released the source under the read: not a fault
                        return
                    await self._worker.call(self._release)
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
            await self._release_on_worker()

    async def close(self) -> None:
        self._closed.set()
        await self._release_on_worker()

    async def _release_on_worker(self) -> None:
        """Release the source on the worker thread that opened and read it, waited for
        ``RELEASE_TIMEOUT_S`` at most, then stop that thread.

        OpenCV's FFmpeg capture owns decoder threads (FFV1 decodes on several); released from
        another thread while its own is still alive, or not released at all before the process
        exits, its C++ threads are destroyed joinable and the process aborts ("terminate called
        without an active exception", exit 134: issue 44, ``config check --open`` on an FFV1 AVI).
        Queued behind a read in progress, the release runs as soon as the read returns; a worker
        stuck longer (a source that never answers) is left to its daemon thread as before."""
        if self._reader is not None:
            try:
                await asyncio.wait_for(asyncio.shield(self._worker.call(self._release)), RELEASE_TIMEOUT_S)
            except TimeoutError:
                pass
        self._worker.stop()


def _release(reader: Any) -> None:
    release = getattr(reader, "release", None)
    if release is not None:
        try:
            release()
        except Exception:  # a reader that fails to release is gone anyway
            pass


def _reason(e: BaseException, context: str) -> str:
    """The health reason for a failure: the source's own words, or the failure in its context.

    ``_SourceLost`` and ``OSError`` (``CameraError``) messages are written to be read and name
    the source already; anything else (a bug, a model error) needs to say where it happened.
    """
    text = str(e).strip()
    if text and isinstance(e, _SourceLost | OSError):
        return text
    return f"{context}: {text or type(e).__name__}"
