"""``serve``: run a hub until SIGINT/SIGTERM, for ``wott-hub run`` and embedding programs."""

from __future__ import annotations

import asyncio
import contextlib
import signal
from collections.abc import Callable, Sequence
from typing import Any

from wott_hub.config import HubConfig

from .lifecycle import Hub

__all__ = ["serve"]


async def serve(config: HubConfig, *, ready: Callable[[Hub], None] | None = None,
                stop: asyncio.Event | None = None, extra_handlers: Sequence[tuple[Any, ...]] = ()) -> Hub:
    """Run a hub until SIGINT/SIGTERM (or ``stop``), then shut it down cleanly.

    With ``demo`` and no devices configured, the demo fleet (``plugins.demo.demo_devices``).
    """
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    installed = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
            installed.append(sig)
    if config.demo and not config.devices:
        from dataclasses import replace

        from wott_hub.plugins.demo import demo_devices

        config = replace(config, devices=tuple(demo_devices()))
    hub = Hub(config, extra_handlers=extra_handlers)
    try:
        await hub.start()
        if ready is not None:
            ready(hub)
        await stop.wait()
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)
        await hub.stop()
    return hub
