"""The directory itself: TDs in memory for reads and search, SQLAlchemy for durability.

A short class composing pieces of one job each: storage (``store.py``: ``ThingStore`` for the
database, ``Catalogue`` for the TDs in memory), search (``search.py``: ``SearchThread``),
validation (``validation.py``; the registration block and each write's plan: ``registration.py``),
lifecycle events (``events.py``: ``EventHub``), expiry (``expiry.py``) and the threads that keep
work growing with a TD off the IOLoop (``threads.py``). What stays here is the order of a write.

All TDs live in memory (``Catalogue``), loaded at start and changed only
after the database committed the change, so reads never touch the database
and a failed write leaves both unchanged. Writes are serialised by one lock;
each produces at most one lifecycle event, published after the commit.

A write that changes nothing but the registration times (a producer
refreshing its ttl) only moves ``expires``: it keeps ``modified`` and emits no
event, so fleets of hubs refreshing their Things do not flood subscribers.

Held TDs (issue 16): a TD written through this in-process API (``remote=False``,
the default; the embedding hub registers its devices and its hub Thing so) is
*held* by the embedder, and writes from HTTP clients (``remote=True``, what the
handlers pass) to its id are refused with 403, token or not. The mark lives in
memory: an embedder that re-registers its Things before it lets HTTP requests
through (the hub does: its router holds requests until then) needs no more.

Budgets in bytes, not only counts (docs/reliability.md): the stored TDs together at
most ``max_store_bytes`` of JSON (a client's write that would pass it is refused with
413, the embedder's own TDs always pass); one TD, a merge patch's result included, at
most ``max_body_bytes`` (413); the replay log at most ``max_event_bytes`` of event data
(``events.EventHub``), the database trimmed to what it keeps.

Every write's work that grows with the TD (validation, the merge patch, the
registration, the diff for ``thing_updated``, measuring it) runs on a thread of its
own, so a 2 MiB TD or one with 40,000 properties holds up no read; at most
``MAX_PENDING_WRITES`` wait for that thread, more get 503 at once. Bodies over
``PARSE_ON_LOOP_BYTES`` are parsed there too (``parse_body``).

Search runs on one thread of its own with a time budget counted from the
request (see ``search.py``); at most ``MAX_PENDING_SEARCHES`` wait for it, more
get 503 at once. TDs stored before the depth limit existed and deeper than it
stay readable by id but are left out of searches (logged at start), so nothing
stored can make a search fail for everyone.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import uuid
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from typing import Any, TypeVar

from sqlalchemy.engine import Engine

from .errors import BadRequest, DirectoryError, Forbidden, NotFound, ValidationFailed
from .events import Event, EventHub
from .expiry import Expiry
from .registration import iso, plan_write
from .search import MAX_PENDING_SEARCHES, SearchEngine, SearchThread
from .selftd import directory_td
from .settings import DirectorySettings
from .store import Catalogue, ThingStore
from .threads import WorkThread
from .validation import MAX_TD_DEPTH, check_depth, check_td, parse_json_body, patched

__all__ = ["MAX_PENDING_SEARCHES", "MAX_PENDING_WRITES", "PARSE_ON_LOOP_BYTES", "Directory", "StoreFull"]

log = logging.getLogger("wott_directory")

_R = TypeVar("_R")

MAX_PENDING_WRITES = 16
"""Writes queued for the write thread; past that a write gets 503 at once."""
PARSE_ON_LOOP_BYTES = 64 * 1024
"""Bodies up to this are parsed on the IOLoop (sub-millisecond); larger ones on the write thread."""


class StoreFull(DirectoryError):
    """A write that would take the stored TDs past ``max_store_bytes`` (413, naming the budget)."""

    def __init__(self, detail: str) -> None:
        super().__init__(413, detail)


class Directory:
    """A Thing Description Directory; serve it with ``make_app`` or ``directory_handlers``."""

    def __init__(self, settings: DirectorySettings | None = None, engine: Engine | str = "sqlite://", *,
                 create_tables: bool = True, td_security: Mapping[str, Any] | None = None) -> None:
        """``create_tables=False`` when the owner of ``engine`` migrates the schema itself (the hub's
        Alembic revisions create ``tdd_things`` and ``tdd_events``): the directory then only checks
        they exist, so ``create_all`` never races or contradicts the migrations. ``td_security``:
        the schemes a server in front of it enforces, declared in its own TD (``selftd.directory_td``)."""
        self.settings = settings or DirectorySettings()
        self.td_security = td_security
        self.store = ThingStore(engine, create_tables=create_tables)
        self.catalogue = Catalogue()
        self.search_engine = SearchEngine(max_length=self.settings.max_query_length)
        self.searches = SearchThread(self.search_engine)
        self.events = EventHub(self.settings.event_retention, self.settings.sse_queue,
                               self.settings.max_event_bytes)
        self.expiry = Expiry()
        self.writes = WorkThread("wott-directory-write", MAX_PENDING_WRITES, "writes", "MAX_PENDING_WRITES")
        self._lock = asyncio.Lock()
        self._writes_since_freeze = 0
        self.started = False

    # -- life cycle ------------------------------------------------------------
    async def start(self) -> None:
        """Create the tables if needed, load TDs and recent events, publish our own TD, start purging."""
        things, events = await self.store.open(self.settings.event_retention)
        cat = self.catalogue
        cat.load(things)
        for thing_id, rec in cat.things.items():
            self.expiry.add(thing_id, rec)
        if cat.unsearchable:
            log.warning("%d stored TD(s) nest deeper than %d levels and are left out of searches until "
                        "replaced: %s", len(cat.unsearchable), MAX_TD_DEPTH,
                        ", ".join(sorted(cat.unsearchable)[:10]))
        self.events.restore(events)
        await self._trim_events()  # a smaller max_event_bytes than the last run's
        self._writes_since_freeze = 0
        if self.settings.freeze_gc:
            gc.freeze()
        self.started = True
        await self._publish_self()
        await self.purge()
        self.expiry.start(self.purge, self.settings.purge_interval)

    async def stop(self) -> None:
        """End SSE streams, stop purging, release the database (the engine too if we made it)."""
        self.events.close_all()
        await self.expiry.stop()
        self.searches.shutdown()
        self.writes.shutdown()
        await self.store.close()
        self.started = False

    async def set_base_url(self, base_url: str) -> None:
        """Where the directory is reachable, once the server knows its port; re-publishes our TD."""
        self.settings = self.settings.with_base_url(base_url)
        if self.started:
            await self._publish_self()

    @property
    def own_id(self) -> str:
        return self.settings.own_id

    def own_td(self) -> dict[str, Any]:
        return self.get(self.own_id)

    async def _publish_self(self) -> None:
        td = directory_td(self.settings, td_security=self.td_security)
        async with self._lock:
            for stale in sorted(self.catalogue.own - {td["id"]}):
                if stale in self.catalogue.things:
                    await self._delete_locked(stale)
            self.catalogue.own = {td["id"]}
            await self._put_locked(td["id"], td, anonymous=False)

    # -- reads -----------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.catalogue.ids)

    def __contains__(self, thing_id: object) -> bool:
        return thing_id in self.catalogue.things

    @property
    def etag(self) -> str:
        """Changes whenever the collection does (any create, update, refresh, delete)."""
        return self.catalogue.etag

    @property
    def stored_bytes(self) -> int:
        """Bytes of JSON of the stored TDs together (the budget is ``max_store_bytes``)."""
        return self.catalogue.stored_bytes

    def get(self, thing_id: str, retrieved: str | None = None) -> dict[str, Any]:
        rec = self.catalogue.things.get(thing_id)
        if rec is None:
            raise NotFound(f"No TD with id {thing_id!r}")
        return _served(rec.td, retrieved or iso(datetime.now(UTC)))

    def page(self, offset: int, limit: int) -> tuple[list[dict[str, Any]], int]:
        """TDs ``offset``..``offset+limit`` in ascending id (code point) order, and the total."""
        retrieved = iso(datetime.now(UTC))
        return [_served(td, retrieved) for td in self.catalogue.page(offset, limit)], len(self)

    def snapshot(self) -> list[dict[str, Any]]:
        """The array JSONPath queries run on (shared, never mutated: treat as read-only)."""
        return self.catalogue.snapshot()

    def held(self, thing_id: str) -> bool:
        """Whether ``thing_id`` was written in-process, so HTTP clients may not change it."""
        return thing_id in self.catalogue.held

    async def search(self, query: str) -> list[Any]:
        """Values the RFC 9535 query selects from the array of all TDs (400 on a bad query,
        400/503 naming the budget when it costs too much)."""
        return await self.searches.run(query, self.snapshot, lambda results: results)

    async def search_json(self, query: str, dumps: Callable[[Any], bytes]) -> bytes:
        """``search`` serialised by ``dumps`` on the search thread (a large answer is not encoded
        on the IOLoop)."""
        return await self.searches.run(query, self.snapshot, dumps)

    # -- writes ----------------------------------------------------------------
    async def parse_body(self, body: bytes) -> Any:
        """A request body as JSON (400 naming where it broke); a large one parsed on the write thread."""
        if len(body) <= PARSE_ON_LOOP_BYTES:
            return parse_json_body(body)
        return await self.writes.run(parse_json_body, body)

    async def put(self, thing_id: str, td: Any, *, remote: bool = False) -> bool:
        """Create or replace the TD ``thing_id`` (PUT); True if it was created. ``remote``: an HTTP
        client's write, refused on held ids; otherwise the embedder's, and the id becomes held."""
        if not isinstance(td, dict):
            check_td(td)
        if "id" not in td:
            raise ValidationFailed([{"field": "$.id", "description": "a TD sent with PUT must have an id; "
                                                                     "POST /things creates anonymous TDs"}])
        if td["id"] != thing_id:
            raise ValidationFailed([{"field": "$.id", "description":
                                     f"{td['id']!r} does not match the id in the URL ({thing_id!r})"}])
        self._check_not_own(thing_id)
        self._check_not_held(thing_id, remote)
        await self.writes.run(check_td, td, bounded=remote)
        async with self._lock:
            self._check_not_held(thing_id, remote)  # the embedder may have put it meanwhile
            anonymous = thing_id in self.catalogue.anonymous
            created = await self._put_locked(thing_id, td, anonymous=anonymous, remote=remote)
            if not remote:
                self.catalogue.held.add(thing_id)
            return created

    async def create_anonymous(self, td: Any, *, remote: bool = False) -> str:
        """Register a TD without id (POST); returns the ``urn:uuid`` id it was given (held unless
        ``remote``, as with ``put``)."""
        if isinstance(td, dict) and "id" in td:
            raise ValidationFailed([{"field": "$.id", "description":
                                     "a TD with an id must be created with PUT /things/{id}"}])
        if not isinstance(td, dict):
            check_td(td)
        thing_id = f"urn:uuid:{uuid.uuid4()}"
        with_id: dict[str, Any] = {}
        for key, value in td.items():
            with_id[key] = value
            if key == "@context":
                with_id["id"] = thing_id
        if "id" not in with_id:
            with_id = {"id": thing_id, **with_id}
        await self.writes.run(check_td, with_id, bounded=remote)
        async with self._lock:
            await self._put_locked(thing_id, with_id, anonymous=True, remote=remote)
            if not remote:
                self.catalogue.held.add(thing_id)
        return thing_id

    async def patch(self, thing_id: str, patch: Any, *, remote: bool = False) -> None:
        """Apply a JSON merge patch, then validate the result as a whole TD (``remote`` as for ``put``);
        a result larger than ``max_body_bytes`` is refused (413): patches cannot grow a TD past what
        a PUT may send."""
        if not isinstance(patch, dict):
            raise BadRequest("A merge patch of a TD must be a JSON object (a Partial TD)")
        check_depth(patch, "The merge patch")  # applying it recurses as deep as it nests
        self._check_not_own(thing_id)
        async with self._lock:
            prev = self.catalogue.things.get(thing_id)
            if prev is None:
                raise NotFound(f"No TD with id {thing_id!r}")
            self._check_not_held(thing_id, remote)
            candidate = await self.writes.run(patched, thing_id, prev.td, patch, self.settings.max_body_bytes,
                                              bounded=remote)
            await self._put_locked(thing_id, candidate, anonymous=thing_id in self.catalogue.anonymous,
                                   remote=remote)

    async def delete(self, thing_id: str, *, remote: bool = False) -> None:
        self._check_not_own(thing_id)
        async with self._lock:
            if thing_id not in self.catalogue.things:
                raise NotFound(f"No TD with id {thing_id!r}")
            self._check_not_held(thing_id, remote)
            await self._delete_locked(thing_id)

    def _check_not_own(self, thing_id: str) -> None:
        if thing_id == self.own_id:
            raise Forbidden("The directory's own TD is managed by the directory")

    def _check_not_held(self, thing_id: str, remote: bool) -> None:
        if remote and thing_id in self.catalogue.held:
            raise Forbidden(f"The TD {thing_id!r} is registered by the application serving this directory "
                            "(the hub) and only it can change or delete it")

    async def _put_locked(self, thing_id: str, td: dict[str, Any], anonymous: bool,
                          remote: bool = False) -> bool:
        cat = self.catalogue
        prev = cat.things.get(thing_id)
        plan = await self.writes.run(plan_write, thing_id, td, prev, datetime.now(UTC), bounded=False)
        old_size = cat.sizes.get(thing_id, 0)
        budget = self.settings.max_store_bytes
        if remote and plan.size > old_size and cat.stored_bytes - old_size + plan.size > budget:
            raise StoreFull(f"The directory's storage budget is full: {cat.stored_bytes} of {budget} bytes "
                            f"of TDs stored (max_store_bytes), this TD is {plan.size}; delete TDs first")
        event = (Event(self.events.next_id(), plan.event, thing_id, plan.data, plan.data_size)
                 if plan.event is not None else None)
        await self.store.write(upserts=[cat.row(thing_id, plan.rec, anonymous)],
                               events=[event] if event else [], new_ids=[] if prev else [thing_id])
        cat.stored(thing_id, plan.rec, plan.size, anonymous)
        self.expiry.add(thing_id, plan.rec)
        self._changed()
        if event is not None:
            self.events.publish(event)
        return prev is None

    async def _delete_locked(self, thing_id: str, reason: str = "deleted") -> None:
        event = Event(self.events.next_id(), "thing_deleted", thing_id, None)
        await self.store.write(deletes=[thing_id], events=[event])
        self.catalogue.removed(thing_id)
        self._changed()
        self.events.publish(event)
        log.debug("TD %s %s", thing_id, reason)

    def _changed(self) -> None:
        if self.settings.freeze_gc:  # the TDs are long-lived: out of the collector's way
            self._writes_since_freeze += 1
            if self._writes_since_freeze >= self.settings.freeze_every:
                gc.freeze()
                self._writes_since_freeze = 0

    # -- expiry ----------------------------------------------------------------
    async def purge(self) -> list[str]:
        """Delete the TDs past their ``expires`` now; returns their ids."""
        now = datetime.now(UTC).timestamp()
        purged = []
        if self.expiry.due(now):
            async with self._lock:
                for thing_id in self.expiry.pop_due(now, self.catalogue.things.get):
                    await self._delete_locked(thing_id, "expired")
                    purged.append(thing_id)
        await self._trim_events()
        return purged

    async def _trim_events(self) -> None:
        """The database keeps the events the replay log keeps (count and bytes), no older one."""
        keep_after = self.events.to_trim()
        if keep_after is not None:
            await self.store.trim_events(keep_after)
            self.events.trimmed_to = keep_after


def _served(td: dict[str, Any], retrieved: str) -> dict[str, Any]:
    out = dict(td)
    out["registration"] = {**td.get("registration", {}), "retrieved": retrieved}
    return out
