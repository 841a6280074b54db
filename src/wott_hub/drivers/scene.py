"""A driver that plays a scripted ``Scene`` on a device at a fixed frame rate.

It yields the scene's ground truth (no raw signal, no camera, no model), so the
whole hub path -- processing, event plane, history, SSE -- runs with no
hardware and with a known answer. The plugin registry exposes it as the
built-in family ``scene``; the hub's tests and benchmarks use it directly.

Timing: frame ``k`` is due at ``start + k / rate_hz`` on the monotonic clock.
Waits up to ``SHORT_WAIT_S`` are a plain sleep (``wait_for`` on the close event
costs a task per frame, ~30 us); longer ones end early when the driver closes.

A looping scene of the indentation model (a pure function of scene time) whose
loop is a whole number of frames repeats exactly: its frames are computed in
the first loop and replayed from then on (``LOOP_CACHE_MB`` at most), so a
simulated fleet costs the hub what real devices would, not the simulation again.

A scene file is read in ``prepare()``, never where the device is opened (the open
hook runs on the event loop that carries every other device's frames): on a daemon
thread of its own, at most ``SCENE_FILE_MAX_BYTES`` and ``SCENE_FILE_TIMEOUT_S``
(``read_scene_file``). A FIFO is read without blocking on its open (a FIFO nobody
writes to ends empty at once; one written to slowly ends at the time bound), a
device such as ``/dev/zero`` ends at the size bound: each is a ``SettingsError``
naming the file and the bound, the device is not opened, and nothing else waits.

A consumer slower than the rate makes the driver skip the missed ticks (a real
camera drops frames too) rather than burst to catch up; skipped ticks are
counted and reported as ``degraded`` health while it lasts. Frame timestamps
are wall-clock nanoseconds (history and replay need calendar time) derived
from the monotonic clock, so they never go backwards even if NTP steps the
wall clock.
"""

from __future__ import annotations

import asyncio
import os
import select
import threading
import time
import tomllib
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np

from wott_hub.errors import SettingsError
from wott_hub.sim.scene import Scene, SceneError
from wott_hub.tactile import DeviceDescription, TactileFrame

from .base import Driver, DriverError, Health, Tareable

__all__ = ["LOOP_CACHE_MB", "SCENE_FILE_MAX_BYTES", "SCENE_FILE_TIMEOUT_S", "SHORT_WAIT_S", "SceneDriver",
           "read_scene_file"]

SHORT_WAIT_S = 0.05
LOOP_CACHE_MB = 64.0
SCENE_FILE_MAX_BYTES = 1024 * 1024
"""A scene file is a few kB of TOML; a larger one (or an endless device) is refused."""
SCENE_FILE_TIMEOUT_S = 5.0
"""Reading and parsing a scene file may take this long at most (a FIFO written to slowly)."""


def _read_bounded(path: Path, max_bytes: int, deadline: float) -> bytes:
    """At most ``max_bytes + 1`` bytes of ``path`` by ``deadline`` (monotonic); opened non-blocking so
    a FIFO without a writer neither blocks the open nor the reads."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        chunks: list[bytes] = []
        size = 0
        while size <= max_bytes:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            try:
                chunk = os.read(fd, min(65536, max_bytes + 1 - size))
            except BlockingIOError:  # a FIFO whose writer has written nothing yet
                time.sleep(0.01)
                continue
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        return b"".join(chunks)
    finally:
        os.close(fd)


def _load(path: Path, max_bytes: int, deadline: float) -> Scene:
    try:
        raw = _read_bounded(path, max_bytes, deadline)
    except TimeoutError:
        raise
    except OSError as e:
        raise SceneError(f"{path}: {e.strerror or e}") from None
    if len(raw) > max_bytes:
        raise SceneError(f"{path}: larger than {max_bytes} bytes (SCENE_FILE_MAX_BYTES); not a scene file")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise SceneError(f"{path}: {e}") from None
    return Scene.from_dict(data, source=str(path))


async def read_scene_file(path: str | Path, *, max_bytes: int = SCENE_FILE_MAX_BYTES,
                          timeout_s: float = SCENE_FILE_TIMEOUT_S) -> Scene:
    """The ``Scene`` of a file, read and parsed on a daemon thread (module docstring); a
    ``SettingsError`` (setting ``scene``) for a file that cannot be read within the bounds or is no
    scene. A thread still blocked past the bound (a hung network file system) is left behind."""
    path = Path(path)
    loop = asyncio.get_running_loop()
    fut: asyncio.Future[Scene] = loop.create_future()
    deadline = time.monotonic() + timeout_s

    def run() -> None:
        try:
            value: Scene | None = _load(path, max_bytes, deadline)
            error: BaseException | None = None
        except TimeoutError:
            value, error = None, SceneError(f"{path}: not read within {timeout_s:g} s "
                                            "(SCENE_FILE_TIMEOUT_S); a FIFO or device that does not end?")
        except Exception as e:  # a scene the model refuses (SceneError), or a bug: the device's error
            value, error = None, e
        try:
            loop.call_soon_threadsafe(_settle, fut, value, error)
        except RuntimeError:  # the loop closed meanwhile
            pass

    threading.Thread(target=run, name="scene-file", daemon=True).start()
    try:
        return await asyncio.wait_for(asyncio.shield(fut), timeout_s + 1.0)
    except TimeoutError:
        raise SettingsError(f"setting 'scene': {path}: not read within {timeout_s:g} s") from None
    except SceneError as e:
        raise SettingsError(f"setting 'scene': {e}") from None


def _settle(fut: asyncio.Future[Scene], value: Scene | None, error: BaseException | None) -> None:
    if fut.done():
        return
    if error is not None:
        fut.set_exception(error)
    else:
        assert value is not None  # no error: a scene
        fut.set_result(value)


class SceneDriver(Driver, Tareable):
    """Yields ``TactileFrame``s of ``scene`` on ``description.mesh`` at ``rate_hz``.

    ``realtime=False`` yields frames as fast as the consumer takes them, with
    timestamps still spaced by ``1 / rate_hz`` (for tests and recording a
    known sequence quickly). A non-looping scene ends after its duration.
    """

    def __init__(
        self,
        description: DeviceDescription,
        scene: Scene | str | Path,
        rate_hz: float = 120.0,
        *,
        realtime: bool = True,
        max_frames: int | None = None,
    ) -> None:
        """``scene``: the ``Scene``, or the path of its file (read by ``prepare()``)."""
        super().__init__(description)
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise DriverError(f"rate_hz must be a positive number, got {rate_hz!r}")
        self.scene_file = None if isinstance(scene, Scene) else Path(scene)
        self._scene = scene if isinstance(scene, Scene) else None
        self.rate_hz = float(rate_hz)
        self.realtime = realtime
        self.max_frames = max_frames
        self.frames_yielded = 0
        self.frames_skipped = 0
        self.tares = 0
        self._closed = asyncio.Event()
        self._loop_frames = 0
        self._cache: list[np.ndarray | None] = []
        if self._scene is not None:
            self._plan_loop()

    @property
    def scene(self) -> Scene:
        if self._scene is None:
            raise DriverError(f"device {self.description.id!r}: its scene file is read by prepare(), "
                              "which was not called")
        return self._scene

    async def prepare(self) -> None:
        if self._scene is None and self.scene_file is not None:
            try:
                self._scene = await read_scene_file(self.scene_file)
            except SettingsError as e:
                d = self.description
                raise SettingsError(f"device {d.id!r} (family {d.family!r}): {e}") from None
            self._plan_loop()

    def _plan_loop(self) -> None:
        self._loop_frames = self._repeating_frames()
        self._cache = [None] * self._loop_frames

    def _repeating_frames(self) -> int:
        """Frames per loop if the scene repeats frame for frame and one loop fits the cache; else 0."""
        scene = self.scene
        if not scene.loop or scene.model == "kelvin-voigt" or scene.duration_s <= 0:
            return 0
        n = round(scene.duration_s * self.rate_hz)
        size_mb = n * self.description.mesh.n_nodes * 3 * 8 / 1e6
        if n < 1 or abs(n - scene.duration_s * self.rate_hz) > 1e-9 * n or size_mb > LOOP_CACHE_MB:
            return 0
        return n

    def _displacement(self, k: int, t_s: float) -> np.ndarray:
        n = self._loop_frames
        if not n:
            return self.scene.displacement_at(t_s, self.description.mesh)
        i = k % n
        d = self._cache[i]
        if d is None:  # (a frame skipped in the first loop is computed when it first comes)
            d = self._cache[i] = self.scene.displacement_at(i / self.rate_hz, self.description.mesh)
            d.setflags(write=False)  # shared by every loop from now on
        return d


    async def frames(self) -> AsyncIterator[TactileFrame]:
        period = 1.0 / self.rate_hz
        mono0 = time.monotonic()
        wall0_ns = time.time_ns()
        k = 0
        while not self._closed.is_set():
            if self.max_frames is not None and self.frames_yielded >= self.max_frames:
                return
            t_s = k * period
            if not self.scene.loop and t_s > self.scene.duration_s:
                return
            if self.realtime:
                delay = mono0 + t_s - time.monotonic()
                if delay > 0:
                    if delay <= SHORT_WAIT_S:
                        await asyncio.sleep(delay)
                        if self._closed.is_set():
                            return
                    else:
                        try:
                            await asyncio.wait_for(self._closed.wait(), delay)
                            return  # closed while waiting
                        except TimeoutError:
                            pass
                elif delay < -period:  # late by more than a frame: drop the missed ticks
                    missed = int(-delay / period)
                    k += missed
                    self.frames_skipped += missed
                    self.set_health(Health.degraded, "consumer slower than the frame rate: frames skipped")
                    await asyncio.sleep(0)  # late means the loop is busy: let the others run
                    continue
                else:
                    self.set_health(Health.ok)
                    await asyncio.sleep(0)
            else:
                await asyncio.sleep(0)  # let others run; never monopolise the loop
            frame = TactileFrame(wall0_ns + int(round(t_s * 1e9)), self._displacement(k, t_s))
            k += 1
            self.frames_yielded += 1
            yield frame

    def tare(self) -> str:
        """A scene is ground truth, at rest when no step touches it: nothing to zero; the tare is recorded."""
        self.tares += 1
        return "a scripted scene has no rest offset: nothing to zero"

    async def close(self) -> None:
        self._closed.set()
