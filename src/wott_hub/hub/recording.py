"""The hub's history: the database it opens, the writer every recorded Thing feeds, the reader.

Opened after the TDs are served (``Hub.start``, in a thread: migrating can
take a moment); the event plane then hands each recorded record to the writer
and reads backfills from the reader. Each recorded Thing's TD and static values
are registered first, and its sequence continues where history says, so
``Last-Event-ID`` keeps meaning the same record across restarts.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sqlalchemy import Engine

    from wott_hub.config import HubConfig
    from wott_hub.events.plane import EventPlane
    from wott_hub.history import HistoryReader, HistoryWriter
    from wott_hub.servient import ServedThing

__all__ = ["HubHistory"]


class HubHistory:
    def __init__(self, config: HubConfig, plane: EventPlane, hub_id: str | None = None) -> None:
        self.config = config
        self.plane = plane
        self.hub_id = hub_id  # the hub's identity: its writer lease on a database shared by hubs
        self.engine: Engine | None = None
        self.writer: HistoryWriter | None = None
        self.reader: HistoryReader | None = None
        self.loop: asyncio.AbstractEventLoop | None = None  # the hub's, set before ``open``

    def open(self) -> None:
        """Open and migrate the database and start the writer (blocking: run in a thread)."""
        from wott_hub.history import HistoryReader, HistoryWriter, create_engine, database_url, upgrade

        cfg, loop, plane = self.config, self.loop, self.plane
        assert loop is not None
        self.engine = create_engine(database_url(cfg.database))
        upgrade(self.engine)

        def committed(watermarks: dict[str, int]) -> None:
            with contextlib.suppress(RuntimeError):  # loop closed during shutdown
                loop.call_soon_threadsafe(plane.on_committed, watermarks)

        self.writer = HistoryWriter(self.engine, batch_max=cfg.history_batch_max,
                                    interval_s=cfg.history_batch_ms / 1000, retention=cfg.retention,
                                    on_commit=committed, process=cfg.history_process,
                                    **({"hub_id": self.hub_id} if self.hub_id else {}))
        if cfg.directory.enabled:  # its directory writes here too: own the database before serving it
            self.writer.acquire_lease()  # a second hub on this database refuses here (Conflict)
        self.reader = HistoryReader(self.engine)
        plane.history_sink = self.writer
        plane.history_source = self.reader
        self.writer.start()

    async def register(self, served: ServedThing, family: str) -> int:
        """Record the Thing's TD and static values (the texts already encoded for serving); returns
        the last seq it may have used."""
        assert self.writer is not None
        return await asyncio.to_thread(
            self.writer.register_thing, served.id, title=served.title, family=family,
            td=served.td_bytes().decode(), static_values=served.static_json())

    async def attach(self, served: ServedThing, family: str) -> bool:
        """Record the Thing's TD and continue its sequence where history says (before any record);
        False (and the Thing is not recorded) when history is off or it is not to be recorded."""
        if not served.record or self.writer is None:
            served.record = False
            self.plane.continue_after(served.id, None, record=False)
            return False
        self.plane.continue_after(served.id, await self.register(served, family), record=True)
        return True

    async def close(self) -> None:
        """Write what is queued and close the database."""
        if self.writer is not None:
            await asyncio.to_thread(self.writer.stop)
        if self.engine is not None:
            self.engine.dispose()

    # --- what the hub Thing reports ------------------------------------------------------------

    def health(self) -> dict[str, Any]:
        from wott_hub.history.db import describe

        w, engine = self.writer, self.engine
        out: dict[str, Any] = {"enabled": w is not None}
        if w is not None and engine is not None:  # both set by open()
            out.update(w.health(), database=describe(engine.url))
        return out

    def counters(self) -> dict[str, Any]:
        w = self.writer
        if w is None:
            return {}
        return {"written": w.written, "queued": w.queue_depth, "dropped": w.dropped,
                "batches": w.batches, "lastBatchMs": round(w.last_batch_s * 1000, 3)}
