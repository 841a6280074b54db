"""The directory itself: TDs in memory for reads and search, SQLAlchemy for durability.

All TDs live in a dict (id -> Enriched TD) loaded at start and changed only
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
import bisect
import gc
import heapq
import json
import logging
import secrets
import time
import uuid
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, TypeVar

from sqlalchemy.engine import Engine

from .errors import BadRequest, DirectoryError, Forbidden, NotFound, ValidationFailed
from .events import Event, EventHub
from .mergepatch import apply_merge_patch, merge_diff
from .registration import Enriched, enrich, iso, same_content
from .search import SearchEngine, SearchTimedOut
from .selftd import directory_td
from .settings import DirectorySettings
from .store import ThingStore
from .validation import MAX_TD_DEPTH, check_depth, check_td, json_depth, parse_json_body

__all__ = ["MAX_PENDING_WRITES", "PARSE_ON_LOOP_BYTES", "Directory"]

log = logging.getLogger("wott_directory")

_R = TypeVar("_R")

MAX_PENDING_SEARCHES = 16
"""Searches queued for the search thread; past that a search gets 503 at once."""
MAX_PENDING_WRITES = 16
"""Writes queued for the write thread; past that a write gets 503 at once."""
PARSE_ON_LOOP_BYTES = 64 * 1024
"""Bodies up to this are parsed on the IOLoop (sub-millisecond); larger ones on the write thread."""


def _json_bytes(doc: Any) -> int:
    return len(json.dumps(doc, ensure_ascii=False, separators=(",", ":")).encode("utf-8"))


class StoreFull(DirectoryError):
    """A write that would take the stored TDs past ``max_store_bytes`` (413, naming the budget)."""

    def __init__(self, detail: str) -> None:
        super().__init__(413, detail)


@dataclass(frozen=True)
class _Plan:
    """What a write will store and publish, worked out on the write thread."""

    rec: Enriched
    size: int  # bytes of the stored TD's JSON
    event: str | None  # "thing_created" | "thing_updated" | None (a refresh)
    data: dict[str, Any] | None  # the event's data: the TD, or the diff with the id
    data_size: int


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
        self.search_engine = SearchEngine(max_length=self.settings.max_query_length)
        self.events = EventHub(self.settings.event_retention, self.settings.sse_queue,
                               self.settings.max_event_bytes)
        self._things: dict[str, Enriched] = {}
        self._sizes: dict[str, int] = {}  # bytes of each stored TD's JSON
        self.stored_bytes = 0
        self._anonymous: set[str] = set()
        self._own: set[str] = set()
        self._held: set[str] = set()
        self._unsearchable: set[str] = set()
        self._pending_searches = 0
        self._ids: list[str] = []
        self._expiry: list[tuple[float, str]] = []
        self._array: list[dict[str, Any]] | None = None
        self._lock = asyncio.Lock()
        self._boot = secrets.token_hex(4)
        self._version = 0
        self._trimmed_to = 0
        self._writes_since_freeze = 0
        self._purge_task: asyncio.Task[None] | None = None
        self._search_executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wott-directory-search")
        self._write_executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wott-directory-write")
        self._pending_writes = 0
        self.started = False

    # -- life cycle ------------------------------------------------------------
    async def start(self) -> None:
        """Create the tables if needed, load TDs and recent events, publish our own TD, start purging."""
        things, events = await self.store.open(self.settings.event_retention)
        for t in things:
            rec = Enriched.from_stored(t.td)
            self._things[t.id] = rec
            self._sizes[t.id] = t.size
            self.stored_bytes += t.size
            if t.anonymous:
                self._anonymous.add(t.id)
            if t.own:
                self._own.add(t.id)
            if json_depth(t.td, MAX_TD_DEPTH) > MAX_TD_DEPTH:
                self._unsearchable.add(t.id)
            if rec.expires is not None:
                self._expiry.append((rec.expires.timestamp(), t.id))
        self._ids = sorted(self._things)
        heapq.heapify(self._expiry)
        if self._unsearchable:
            log.warning("%d stored TD(s) nest deeper than %d levels and are left out of searches until "
                        "replaced: %s", len(self._unsearchable), MAX_TD_DEPTH,
                        ", ".join(sorted(self._unsearchable)[:10]))
        self.events.restore(events)
        self._trimmed_to = max(0, self.events.last_id - self.settings.event_retention)
        await self._trim_events()  # a smaller max_event_bytes than the last run's
        self._writes_since_freeze = 0
        if self.settings.freeze_gc:
            gc.freeze()
        self.started = True
        await self._publish_self()
        await self.purge()
        self._purge_task = asyncio.create_task(self._purge_loop())

    async def stop(self) -> None:
        """End SSE streams, stop purging, release the database (the engine too if we made it)."""
        self.events.close_all()
        if self._purge_task is not None:
            self._purge_task.cancel()
            try:
                await self._purge_task
            except asyncio.CancelledError:
                pass
            self._purge_task = None
        self._search_executor.shutdown(wait=True)
        self._write_executor.shutdown(wait=True)
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
            for stale in sorted(self._own - {td["id"]}):
                if stale in self._things:
                    await self._delete_locked(stale)
            self._own = {td["id"]}
            await self._put_locked(td["id"], td, anonymous=False)

    # -- reads -----------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._ids)

    def __contains__(self, thing_id: object) -> bool:
        return thing_id in self._things

    @property
    def etag(self) -> str:
        """Changes whenever the collection does (any create, update, refresh, delete)."""
        return f"{self._boot}-{self._version}"

    def get(self, thing_id: str, retrieved: str | None = None) -> dict[str, Any]:
        rec = self._things.get(thing_id)
        if rec is None:
            raise NotFound(f"No TD with id {thing_id!r}")
        return _served(rec.td, retrieved or iso(datetime.now(UTC)))

    def page(self, offset: int, limit: int) -> tuple[list[dict[str, Any]], int]:
        """TDs ``offset``..``offset+limit`` in ascending id (code point) order, and the total."""
        retrieved = iso(datetime.now(UTC))
        ids = self._ids[offset:offset + limit]
        return [_served(self._things[i].td, retrieved) for i in ids], len(self._ids)

    def snapshot(self) -> list[dict[str, Any]]:
        """The array JSONPath queries run on (shared, never mutated: treat as read-only)."""
        if self._array is None:
            skip = self._unsearchable
            self._array = [self._things[i].td for i in self._ids if i not in skip]
        return self._array

    def held(self, thing_id: str) -> bool:
        """Whether ``thing_id`` was written in-process, so HTTP clients may not change it."""
        return thing_id in self._held

    async def search(self, query: str) -> list[Any]:
        """Values the RFC 9535 query selects from the array of all TDs (400 on a bad query,
        400/503 naming the budget when it costs too much)."""
        return await self._search(query, lambda results: results)

    async def search_json(self, query: str, dumps: Callable[[Any], bytes]) -> bytes:
        """``search`` serialised by ``dumps`` on the search thread (a large answer is not encoded
        on the IOLoop)."""
        return await self._search(query, dumps)

    async def _search(self, query: str, finish: Callable[[list[Any]], _R]) -> _R:
        engine = self.search_engine
        deadline = time.monotonic() + engine.time_budget_s
        data = self.snapshot()
        if self._pending_searches >= MAX_PENDING_SEARCHES:
            raise DirectoryError(503, f"{MAX_PENDING_SEARCHES} searches are already waiting "
                                      "(MAX_PENDING_SEARCHES); try again shortly", [], {"Retry-After": "1"})

        def run() -> _R:  # compiling a long query takes a while too: not on the IOLoop either
            compiled = engine.compile(query)
            return finish(compiled.run_within(data, deadline, engine.time_budget_s, engine.max_nodes))

        self._pending_searches += 1
        try:
            return await asyncio.wait_for(
                asyncio.get_running_loop().run_in_executor(self._search_executor, run),
                engine.time_budget_s + 1.0)
        except TimeoutError:  # the thread checks its deadline itself; this only bounds the answer
            raise SearchTimedOut(engine.time_budget_s) from None
        finally:
            self._pending_searches -= 1

    # -- writes ----------------------------------------------------------------
    async def _on_write_thread(self, fn: Callable[..., _R], *args: Any, remote: bool = True) -> _R:
        """``fn(*args)`` on the write thread; for a client (``remote``), 503 at once when
        ``MAX_PENDING_WRITES`` already wait (the embedder's own writes always wait their turn)."""
        if remote and self._pending_writes >= MAX_PENDING_WRITES:
            raise DirectoryError(503, f"{MAX_PENDING_WRITES} writes are already waiting "
                                      "(MAX_PENDING_WRITES); try again shortly", [], {"Retry-After": "1"})
        self._pending_writes += 1
        try:
            return await asyncio.get_running_loop().run_in_executor(self._write_executor, fn, *args)
        finally:
            self._pending_writes -= 1

    async def parse_body(self, body: bytes) -> Any:
        """A request body as JSON (400 naming where it broke); a large one parsed on the write thread."""
        if len(body) <= PARSE_ON_LOOP_BYTES:
            return parse_json_body(body)
        return await self._on_write_thread(parse_json_body, body)

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
        await self._on_write_thread(check_td, td, remote=remote)
        async with self._lock:
            self._check_not_held(thing_id, remote)  # the embedder may have put it meanwhile
            anonymous = thing_id in self._anonymous
            created = await self._put_locked(thing_id, td, anonymous=anonymous, remote=remote)
            if not remote:
                self._held.add(thing_id)
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
        await self._on_write_thread(check_td, with_id, remote=remote)
        async with self._lock:
            await self._put_locked(thing_id, with_id, anonymous=True, remote=remote)
            if not remote:
                self._held.add(thing_id)
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
            prev = self._things.get(thing_id)
            if prev is None:
                raise NotFound(f"No TD with id {thing_id!r}")
            self._check_not_held(thing_id, remote)
            candidate = await self._on_write_thread(self._patched, thing_id, prev.td, patch, remote=remote)
            await self._put_locked(thing_id, candidate, anonymous=thing_id in self._anonymous, remote=remote)

    def _patched(self, thing_id: str, td: dict[str, Any], patch: dict[str, Any]) -> dict[str, Any]:
        """The patched TD, checked (on the write thread)."""
        candidate = apply_merge_patch(td, patch)
        if candidate.get("id") != thing_id:
            raise ValidationFailed([{"field": "$.id",
                                     "description": "the id of a TD cannot be changed or removed"}])
        size = _json_bytes({k: v for k, v in candidate.items() if k != "registration"})
        limit = self.settings.max_body_bytes
        if size > limit:
            raise DirectoryError(413, f"The patched TD would be {size} bytes, more than the {limit} a TD may "
                                      "have (max_body_bytes)")
        return check_td(candidate)

    async def delete(self, thing_id: str, *, remote: bool = False) -> None:
        self._check_not_own(thing_id)
        async with self._lock:
            if thing_id not in self._things:
                raise NotFound(f"No TD with id {thing_id!r}")
            self._check_not_held(thing_id, remote)
            await self._delete_locked(thing_id)

    def _check_not_own(self, thing_id: str) -> None:
        if thing_id == self.own_id:
            raise Forbidden("The directory's own TD is managed by the directory")

    def _check_not_held(self, thing_id: str, remote: bool) -> None:
        if remote and thing_id in self._held:
            raise Forbidden(f"The TD {thing_id!r} is registered by the application serving this directory "
                            "(the hub) and only it can change or delete it")

    @staticmethod
    def _plan(thing_id: str, td: dict[str, Any], prev: Enriched | None, now: datetime) -> _Plan:
        """The enriched TD, its size and its event (on the write thread: all of it grows with the TD)."""
        rec = enrich(td, now, prev)
        if prev is not None and same_content(prev.td, rec.td):
            reg = {**rec.td["registration"], "modified": iso(prev.modified)}
            rec = Enriched({**rec.td, "registration": reg}, prev.created, prev.modified, rec.expires)
            return _Plan(rec, _json_bytes(rec.td), None, None, 0)
        size = _json_bytes(rec.td)
        if prev is None:
            return _Plan(rec, size, "thing_created", rec.td, size)
        diff = {"id": thing_id, **merge_diff(prev.td, rec.td)}
        return _Plan(rec, size, "thing_updated", diff, _json_bytes(diff))

    async def _put_locked(self, thing_id: str, td: dict[str, Any], anonymous: bool,
                          remote: bool = False) -> bool:
        prev = self._things.get(thing_id)
        plan = await self._on_write_thread(self._plan, thing_id, td, prev, datetime.now(UTC), remote=False)
        rec = plan.rec
        old_size = self._sizes.get(thing_id, 0)
        budget = self.settings.max_store_bytes
        if remote and plan.size > old_size and self.stored_bytes - old_size + plan.size > budget:
            raise StoreFull(f"The directory's storage budget is full: {self.stored_bytes} of {budget} bytes "
                            f"of TDs stored (max_store_bytes), this TD is {plan.size}; delete TDs first")
        event = (Event(self.events.next_id(), plan.event, thing_id, plan.data, plan.data_size)
                 if plan.event is not None else None)
        row = {"id": thing_id, "td": rec.td, "anonymous": anonymous, "own": thing_id in self._own,
               "created": rec.created,
               "modified": rec.modified, "expires": rec.expires}
        await self.store.write(upserts=[row], events=[event] if event else [],
                               new_ids=[] if prev else [thing_id])
        self._things[thing_id] = rec
        self._sizes[thing_id] = plan.size
        self.stored_bytes += plan.size - old_size
        self._unsearchable.discard(thing_id)  # a TD written now passed the depth check
        if prev is None:
            bisect.insort(self._ids, thing_id)
            if anonymous:
                self._anonymous.add(thing_id)
        if rec.expires is not None:
            heapq.heappush(self._expiry, (rec.expires.timestamp(), thing_id))
        self._changed()
        if event is not None:
            self.events.publish(event)
        return prev is None

    async def _delete_locked(self, thing_id: str, reason: str = "deleted") -> None:
        event = Event(self.events.next_id(), "thing_deleted", thing_id, None)
        await self.store.write(deletes=[thing_id], events=[event])
        del self._things[thing_id]
        self.stored_bytes -= self._sizes.pop(thing_id, 0)
        self._anonymous.discard(thing_id)
        self._held.discard(thing_id)
        self._unsearchable.discard(thing_id)
        i = bisect.bisect_left(self._ids, thing_id)
        del self._ids[i]
        self._changed()
        self.events.publish(event)
        log.debug("TD %s %s", thing_id, reason)

    def _changed(self) -> None:
        self._version += 1
        self._array = None
        if self.settings.freeze_gc:
            self._writes_since_freeze += 1
            if self._writes_since_freeze >= self.settings.freeze_every:
                gc.freeze()
                self._writes_since_freeze = 0

    # -- expiry ----------------------------------------------------------------
    async def purge(self) -> list[str]:
        """Delete the TDs past their ``expires`` now; returns their ids."""
        now = datetime.now(UTC).timestamp()
        if not self._expiry or self._expiry[0][0] > now:
            await self._trim_events()
            return []
        purged = []
        async with self._lock:
            while self._expiry and self._expiry[0][0] <= now:
                stamp, thing_id = heapq.heappop(self._expiry)
                rec = self._things.get(thing_id)
                if rec is None or rec.expires is None or rec.expires.timestamp() != stamp:
                    continue  # deleted or re-registered since: a stale heap entry
                await self._delete_locked(thing_id, "expired")
                purged.append(thing_id)
        await self._trim_events()
        return purged

    async def _trim_events(self) -> None:
        """The database keeps the events the replay log keeps (count and bytes), no older one."""
        keep_after = max(self.events.last_id - self.settings.event_retention, self.events.first_kept - 1)
        if keep_after > self._trimmed_to:
            await self.store.trim_events(keep_after)
            self._trimmed_to = keep_after

    async def _purge_loop(self) -> None:
        while True:
            await asyncio.sleep(self.settings.purge_interval)
            try:
                await self.purge()
            except Exception:  # a database hiccup must not end purging for good
                log.exception("purging expired TDs failed; retrying in %.1f s", self.settings.purge_interval)


def _served(td: dict[str, Any], retrieved: str) -> dict[str, Any]:
    out = dict(td)
    out["registration"] = {**td.get("registration", {}), "retrieved": retrieved}
    return out

