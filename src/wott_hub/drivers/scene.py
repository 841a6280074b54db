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

A consumer slower than the rate makes the driver skip the missed ticks (a real
camera drops frames too) rather than burst to catch up; skipped ticks are
counted and reported as ``degraded`` health while it lasts. Frame timestamps
are wall-clock nanoseconds (history and replay need calendar time) derived
from the monotonic clock, so they never go backwards even if NTP steps the
wall clock.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import numpy as np

from wott_hub.sim.scene import Scene
from wott_hub.tactile import DeviceDescription, TactileFrame

from .base import Driver, DriverError, Health, Tareable

__all__ = ["LOOP_CACHE_MB", "SHORT_WAIT_S", "SceneDriver"]

SHORT_WAIT_S = 0.05
LOOP_CACHE_MB = 64.0


class SceneDriver(Driver, Tareable):
    """Yields ``TactileFrame``s of ``scene`` on ``description.mesh`` at ``rate_hz``.

    ``realtime=False`` yields frames as fast as the consumer takes them, with
    timestamps still spaced by ``1 / rate_hz`` (for tests and recording a
    known sequence quickly). A non-looping scene ends after its duration.
    """

    def __init__(
        self,
        description: DeviceDescription,
        scene: Scene,
        rate_hz: float = 120.0,
        *,
        realtime: bool = True,
        max_frames: int | None = None,
    ) -> None:
        super().__init__(description)
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise DriverError(f"rate_hz must be a positive number, got {rate_hz!r}")
        self.scene = scene
        self.rate_hz = float(rate_hz)
        self.realtime = realtime
        self.max_frames = max_frames
        self.frames_yielded = 0
        self.frames_skipped = 0
        self.tares = 0
        self._closed = asyncio.Event()
        self._loop_frames = self._repeating_frames()
        self._cache: list[np.ndarray | None] = [None] * self._loop_frames

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
