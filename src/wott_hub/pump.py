"""The device loop shared by the hub and its worker processes: frames in, results out.

Both run the same loop and differ only in where a result goes (the event plane
in the hub, a pipe to the hub in a worker), so the sink is a callback.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any

from wott_hub.tactile import FrameError, FrameResult

log = logging.getLogger(__name__)

Sink = Callable[[FrameResult, int], None]
"""Called with each frame's result and its entry time (perf_counter ns, 0 when not tracing)."""


async def pump(dev: Any, name: str, sink: Sink, *, trace: bool = False) -> None:
    """Run ``dev.driver`` through ``dev.processor`` into ``sink`` until the stream ends.

    ``dev`` carries the counters the hub reports (``state``, ``reason``, ``frames``,
    ``frame_errors``, ``restarts``). A frame the processor refuses is counted and
    skipped; a driver that raises is restarted with backoff (0.5 s doubling to 30 s).
    """
    backoff = 0.5
    clock = time.monotonic
    while True:
        try:
            dev.state = "running"
            last_yield = clock()
            async for frame in dev.driver.frames():
                # A driver that is behind may yield frames without ever awaiting; then this
                # loop would hold the event loop. Give the others a turn every 5 ms at most.
                if clock() - last_yield > 0.005:
                    await asyncio.sleep(0)
                    last_yield = clock()
                t_in = time.perf_counter_ns() if trace else 0
                try:
                    res = dev.processor.process(frame)
                except FrameError as e:
                    dev.frame_errors += 1
                    dev.reason = str(e)
                    continue
                dev.frames += 1
                sink(res, t_in)
                backoff = 0.5
            dev.state = "ended"
            dev.reason = "the device's frame stream ended"
            return
        except asyncio.CancelledError:
            raise
        except Exception as e:  # a driver bug: report, back off, try again
            dev.restarts += 1
            dev.state = "failed"
            dev.reason = f"{type(e).__name__}: {e}"
            log.exception("device %s failed; restarting in %.1f s", name, backoff)
            await asyncio.sleep(backoff)
            backoff = min(backoff * 2, 30.0)
