"""What the hub's request handlers share: the event plane, the served Things, the layout."""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field
from typing import Any

from tornado.ioloop import PeriodicCallback

from wott_hub.events.plane import EventPlane

from .forms import FormLayout
from .things import ThingRegistry

__all__ = ["ServingContext"]


@dataclass(eq=False)
class ServingContext:
    plane: EventPlane
    things: ThingRegistry
    layout: FormLayout
    heartbeat_s: float = 15.0
    sse: set[Any] = field(default_factory=set)  # open SSE/long-poll handlers
    ws: set[Any] = field(default_factory=set)  # open WebSocket handlers
    raw_streams: int = 0  # open raw-signal streams (servient/raw.py: at most MAX_RAW_STREAMS)
    # set once every stream continues its recorded sequence: resumes wait for it
    streams_ready: asyncio.Event = field(default_factory=asyncio.Event)
    _heartbeat: PeriodicCallback | None = None

    def start(self) -> None:
        """SSE comments keep idle streams alive through proxies and reveal dead clients."""
        if self._heartbeat is None and self.heartbeat_s > 0:
            self._heartbeat = PeriodicCallback(self._beat, self.heartbeat_s * 1000 / 2)
            self._heartbeat.start()

    def _beat(self) -> None:
        now = time.monotonic()
        for handler in list(self.sse):
            handler.heartbeat(now, self.heartbeat_s)

    def close_streams(self) -> None:
        """End every stream (shutdown): subscribers close, handlers finish their responses."""
        if self._heartbeat is not None:
            self._heartbeat.stop()
            self._heartbeat = None
        for handler in list(self.sse):
            handler.end_stream()
        for handler in list(self.ws):
            handler.close(1001, "hub shutting down")
