"""The hub's history: the database it opens, the writer every recorded Thing feeds, the reader.

Opened after the TDs are served (``Hub.start``, in a thread: migrating can
take a moment); the event plane then hands each recorded record to the writer
and reads backfills from the reader. Each recorded Thing's TD and static values
are registered first, and its sequence continues where history says, so
``Last-Event-ID`` keeps meaning the same record across restarts.

The writer has a spool (``history/spool.py``, ``spool_folder``): what cannot reach the
database waits there and is written when it answers, or at the next start. ``close`` is
bounded whatever the database does (``HistoryWriter.stop``), and safe while ``open`` still
runs in its thread (a Ctrl-C during start-up): ``open`` then gives up what it made. ``hurry``
(a second Ctrl-C) stops waiting for the database. The hub Thing's history reads and exports
run in threads of their own (``exports``, ``exports.py``), cancelled by ``close``.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .exports import Exports

if TYPE_CHECKING:
    from sqlalchemy import Engine

    from wott_hub.config import HubConfig
    from wott_hub.events.plane import EventPlane
    from wott_hub.history import HistoryReader, HistoryWriter
    from wott_hub.servient import ServedThing

__all__ = ["HubHistory", "spool_folder"]


def spool_folder(config: HubConfig, hub_id: str | None = None) -> Path:
    """Where the writer's spool lives: ``[hub] history_spool``; else beside a SQLite database
    (``<file>.spool``), else beside the config file (``<stem>.spool``), else
    ``wott-hub.spool/<hub id>`` in the working folder (a PostgreSQL URL given on the command line:
    hubs started there each have their own). Made only when something must wait in it."""
    if config.history_spool:
        return Path(config.history_spool)
    db = config.database
    if db.startswith("sqlite:///") and db != "sqlite:///:memory:":
        db = db.removeprefix("sqlite:///")
    if "://" not in db and db != ":memory:":
        path = Path(db).expanduser().resolve()
        return path.with_name(path.name + ".spool")
    if not config.source.startswith("<"):
        conf = Path(config.source).resolve()
        return conf.with_name(conf.stem + ".spool")
    return Path("wott-hub.spool").resolve() / (hub_id or "wott-hub")


class HubHistory:
    def __init__(self, config: HubConfig, plane: EventPlane, hub_id: str | None = None) -> None:
        self.config = config
        self.plane = plane
        self.hub_id = hub_id  # the hub's identity: its writer lease on a database shared by hubs
        self.engine: Engine | None = None
        self.writer: HistoryWriter | None = None
        self.reader: HistoryReader | None = None
        self.loop: asyncio.AbstractEventLoop | None = None  # the hub's, set before ``open``
        self.exports = Exports()  # the hub Thing's history reads and exports (exports.py)
        self._lock = threading.Lock()  # ``open`` (a thread) against ``close`` (the loop)
        self._closing = False

    def open(self) -> None:
        """Open and migrate the database and start the writer (blocking: run in a thread). If
        ``close`` came meanwhile, what was made is given up and nothing starts."""
        from wott_hub.history import HistoryReader, HistoryWriter, create_engine, database_url, upgrade
        from wott_hub.history.spool import Spool

        cfg, loop, plane = self.config, self.loop, self.plane
        assert loop is not None
        engine = create_engine(database_url(cfg.database))
        writer: HistoryWriter | None = None
        try:
            upgrade(engine)

            def committed(watermarks: dict[str, int]) -> None:
                with contextlib.suppress(RuntimeError):  # loop closed during shutdown
                    loop.call_soon_threadsafe(plane.on_committed, watermarks)

            with self._lock:
                if self._closing:
                    raise _Closed
                writer = HistoryWriter(engine, batch_max=cfg.history_batch_max,
                                       queue_max_bytes=int(cfg.history_queue_mb * 1e6),
                                       interval_s=cfg.commit_interval_s, retention=cfg.retention,
                                       on_commit=committed, process=cfg.history_process,
                                       spool=Spool(spool_folder(cfg, self.hub_id),
                                                   int(cfg.history_spool_mb * 1e6)),
                                       **({"hub_id": self.hub_id} if self.hub_id else {}))
                if cfg.directory.enabled:  # its directory writes here too: own the database before serving it
                    writer.acquire_lease()  # a second hub on this database refuses here (Conflict)
                self.engine, self.writer = engine, writer
                self.reader = HistoryReader(engine)
                plane.history_sink = writer
                plane.history_source = self.reader
                writer.start()  # forwards first what a previous run left in the spool
        except BaseException as e:
            if self.writer is not writer and writer is not None and writer.spool is not None:
                writer.spool.close()
            if self.engine is not engine:
                engine.dispose()
            if not isinstance(e, _Closed):
                raise

    def hurry(self) -> None:
        """Stop waiting for the database (a second Ctrl-C): what it cannot take goes to the spool now."""
        self.exports.cancel_all()
        if self.writer is not None:
            self.writer.hurry()

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
        """Write what is queued (bounded: ``HistoryWriter.stop``) and close the database."""
        with self._lock:
            self._closing = True
            writer, engine = self.writer, self.engine
        self.exports.cancel_all()
        if writer is not None:
            await asyncio.to_thread(writer.stop)
        if engine is not None:
            engine.dispose()

    # --- what the hub Thing reports ------------------------------------------------------------

    def health(self) -> dict[str, Any]:
        from wott_hub.history.db import describe

        w, engine = self.writer, self.engine
        out: dict[str, Any] = {"enabled": w is not None}
        if w is not None and engine is not None:  # both set by open()
            out.update(w.health(), database=describe(engine.url))
            _spool_damage(out, w)
            if self.plane.hold:  # "committed": what waits for its commit, what was let go past the bound
                out["held"] = self.plane.held_health()
        out["exports"] = self.exports.health()
        return out

    def outcome(self) -> dict[str, int] | None:
        """What became of the records, for a stop report (None: history off or never opened)."""
        return self.writer.outcome() if self.writer is not None else None

    def counters(self) -> dict[str, Any]:
        w = self.writer
        if w is None:
            return {}
        return {"written": w.written, "queued": w.queue_depth, "dropped": w.dropped,
                "batches": w.batches, "lastBatchMs": round(w.last_batch_s * 1000, 3)}


def _spool_damage(out: dict[str, Any], writer: HistoryWriter) -> None:
    """What of the spool could not be read (``Spool.damage``), in ``spool.damaged``; history is
    "degraded" while a damaged segment or a file set aside is still there (deleting it says it has
    been seen to): records lost are never only in the log (issue 48)."""
    sp = writer.spool
    damage = sp.damage() if sp is not None else []
    if not damage or not isinstance(out.get("spool"), dict):
        return
    out["spool"]["damaged"] = damage
    if out.get("state") == "ok":
        lost = sum(d["records"] for d in damage)
        estimated = " (estimated)" if any(d["estimated"] for d in damage) else ""
        said = f"{lost} records lost" if lost else "no record lost"
        out["state"], out["reason"] = "degraded", (
            f"the history spool could not be read whole: {said}{estimated}; set aside: "
            + ", ".join(Path(d["keptAs"]).name for d in damage[:4]) + (" ..." if len(damage) > 4 else ""))


class _Closed(Exception):
    """``close`` came while ``open`` ran: ``open`` gives up quietly."""
