"""From introductions to consumed TDs: the hub's WoT Discoverer (WoT Discovery section 5).

Introductions are mDNS records (``Browser``) and directory URLs. For each one
the explorer fetches the TD; a ``ThingDirectory`` TD is explored in turn (all
its TDs, then its ``/events`` for changes), a ``ThingLink`` is followed to its
target, anything else is a Thing. Results are merged by TD id, whichever
introduction found them, so a device seen by mDNS and in a directory, or one
that leaves and comes back on another address, stays one Thing: ``on_found``
once, then ``on_updated`` (new TD or address) and ``on_lost`` (gone from every
introduction that announced it).

Bounded: a TD is read up to ``max_td_bytes`` (1 MiB by default; a longer one is not
read to its end) and parsed off the event loop when it is large.

Quiet about what it cannot read: the Things other hubs announce are usually
protected (401 without their token), and one remote hub serves dozens of them. So
a failed fetch is a warning once per origin (``scheme://host:port``, one line per
remote hub, naming how many of its Things were refused so far when it is read again),
and each further failure from there is logged at debug.

Each new Thing goes through the ``claim(td)`` it is given (the hub gives the plugin
registry's ``claim``, the hook that adapts foreign TDs; none: nothing is adopted): its
``DeviceConfig``, or None if no plugin adopts it, travels with the ``FoundThing``. The
hub exposes claimed Things; the explorer itself opens nothing and knows no plugin.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urljoin, urlsplit

from tornado.httpclient import AsyncHTTPClient, HTTPClientError, HTTPRequest
from tornado.httputil import HTTPInputError
from tornado.simple_httpclient import HTTPStreamClosedError
from wott_directory.client import DirectoryClient, ProblemError

from wott_hub.td.media import TD_ACCEPT

from .browser import _call
from .records import ServiceRecord

__all__ = ["MAX_TD_BYTES", "Claim", "Explorer", "FoundThing", "td_kind"]

log = logging.getLogger("wott_hub.discovery")

MAX_TD_BYTES = 1024 * 1024
"""Default cap on a TD fetched from an introduction, bytes."""
_PARSE_ON_LOOP_BYTES = 64 * 1024  # larger bodies are parsed on a worker thread


def td_kind(td: dict[str, Any]) -> str:
    """``Directory``, ``Link`` or ``Thing`` from the TD's ``@type`` (WoT Discovery 7.1/7.2)."""
    types = td.get("@type", [])
    types = types if isinstance(types, list) else [types]
    names = {str(t).rsplit("#", 1)[-1].rsplit(":", 1)[-1] for t in types}
    if "ThingDirectory" in names:
        return "Directory"
    if "ThingLink" in names:
        return "Link"
    return "Thing"


@dataclass
class FoundThing:
    id: str
    td: dict[str, Any]
    """The consumed TD: as fetched, with ``base`` set to where it came from when it had none, and
    without the directory's ``registration`` block."""
    url: str
    sources: set[str] = field(default_factory=set)
    """Introductions that currently vouch for it: ``mdns:<instance name>``, ``tdd:<directory URL>``."""
    config: Any = None
    """What ``claim`` returned (a ``DeviceConfig``), or None."""

    @property
    def present(self) -> bool:
        return bool(self.sources)


Callback = Callable[[FoundThing], Any | Awaitable[Any]]
Claim = Callable[[dict[str, Any]], Any]
"""A foreign TD -> the ``DeviceConfig`` that adopts it, or None (the plugin registry's ``claim``)."""


class Explorer:
    def __init__(self, on_found: Callback, on_updated: Callback | None = None,
                 on_lost: Callback | None = None,
                 claim: Claim | None = None, timeout: float = 5.0,
                 own_ids: set[str] | None = None, follow_directories: bool = True,
                 directory_token: str | None = None, max_td_bytes: int = MAX_TD_BYTES) -> None:
        self.on_found = on_found
        self.on_updated = on_updated
        self.on_lost = on_lost
        self.claim = claim
        self.timeout = timeout
        self.own_ids = own_ids if own_ids is not None else set()
        self.follow_directories = follow_directories
        self.directory_token = directory_token
        self.max_td_bytes = max_td_bytes
        self.things: dict[str, FoundThing] = {}
        self.directories: dict[str, asyncio.Task[None]] = {}
        self.unreadable: dict[str, int] = {}  # origin (scheme://host:port) -> TDs it refused us, in a row
        self._http = AsyncHTTPClient(force_instance=True, max_body_size=max_td_bytes)
        self._service_things: dict[str, str] = {}  # mDNS name -> TD id
        self._service_dirs: dict[str, str] = {}  # mDNS name -> directory URL
        self._lock = asyncio.Lock()

    # -- fetching ----------------------------------------------------------------
    async def fetch_td(self, url: str) -> dict[str, Any]:
        req = HTTPRequest(url, headers={"Accept": TD_ACCEPT}, request_timeout=self.timeout,
                          follow_redirects=True)
        try:
            resp = await self._http.fetch(req)
        except (HTTPInputError, HTTPStreamClosedError) as e:  # past max_td_bytes tornado stops reading
            raise ValueError(f"{url}: not read to its end ({e}): a TD longer than {self.max_td_bytes} bytes "
                             "(max_td_bytes) is refused") from None
        body = resp.body
        big = len(body) > _PARSE_ON_LOOP_BYTES
        td = await asyncio.to_thread(json.loads, body) if big else json.loads(body)
        if not isinstance(td, dict):
            raise ValueError(f"{url} did not return a TD (a JSON object)")
        return td

    async def fetch_record(self, rec: ServiceRecord) -> tuple[dict[str, Any], str]:
        """The TD of a service, trying each of its addresses (a stale one may linger in caches)."""
        errors = []
        for host in rec.hosts:
            url = f"{rec.scheme}://{host}:{rec.port}{rec.td_path}"
            try:
                return await self.fetch_td(url), url
            except (OSError, HTTPClientError, ValueError) as e:
                errors.append(f"{url}: {e}")
        raise OSError("; ".join(errors))

    # -- mDNS introductions ------------------------------------------------------
    async def service_added(self, rec: ServiceRecord) -> None:
        """Browser ``on_add``/``on_update``: fetch the TD the service points to and merge it."""
        try:
            td, url = await self.fetch_record(rec)
        except OSError as e:
            self._unreadable(rec, e)
            return
        self._readable(rec)
        source = f"mdns:{rec.name}"
        kind = td_kind(td)
        if kind == "Directory" or rec.kind == "Directory":
            base = b if isinstance(b := td.get("base"), str) else rec.base_url
            self._service_dirs[rec.name] = base
            if self.follow_directories and td.get("id") not in self.own_ids:
                self.add_directory(base)
            return
        if kind == "Link":
            linked, url = await self._follow_link(td, url)
            if linked is None:
                return
            td = linked
        old_id = self._service_things.get(rec.name)
        thing_id = await self._merge(td, url, source)
        if thing_id is None:
            return
        self._service_things[rec.name] = thing_id
        if old_id is not None and old_id != thing_id:
            await self._drop_source(old_id, source)

    service_updated = service_added

    def _unreadable(self, rec: ServiceRecord, error: OSError) -> None:
        """One warning per origin that refuses us (a remote hub), the rest at debug."""
        origin = _origin(rec)
        refused = self.unreadable.get(origin, 0)
        self.unreadable[origin] = refused + 1
        if refused == 0:
            log.warning("cannot read the TDs announced by %s (%s: %s); its further failures are logged at "
                        "debug", origin, rec.name, error)
        else:
            log.debug("could not fetch the TD of %s: %s", rec.name, error)

    def _readable(self, rec: ServiceRecord) -> None:
        refused = self.unreadable.pop(_origin(rec), 0)
        if refused > 1:
            log.info("%s answers again (%d of its TDs could not be read before)", _origin(rec), refused)

    async def service_removed(self, rec: ServiceRecord) -> None:
        """Browser ``on_remove``: the Thing loses this introduction (lost when it has no other)."""
        thing_id = self._service_things.pop(rec.name, None)
        if thing_id is not None:
            await self._drop_source(thing_id, f"mdns:{rec.name}")
        url = self._service_dirs.pop(rec.name, None)
        if url is not None and url not in self._service_dirs.values():
            await self.remove_directory(url)

    async def _follow_link(self, td: dict[str, Any], url: str) -> tuple[dict[str, Any] | None, str]:
        for link in td.get("links", []):
            if link.get("rel") == "describedby" and isinstance(link.get("href"), str):
                target = urljoin(url, link["href"])
                try:
                    return await self.fetch_td(target), target
                except (OSError, HTTPClientError, ValueError) as e:
                    log.warning("ThingLink %s -> %s failed: %s", url, target, e)
        return None, url

    # -- directories ---------------------------------------------------------------
    def add_directory(self, url: str) -> None:
        """Explore a directory (once): its TDs now, and its changes as they happen."""
        url = url if url.endswith("/") else url + "/"
        if url not in self.directories:
            self.directories[url] = asyncio.ensure_future(self._follow(url))

    async def remove_directory(self, url: str) -> None:
        task = self.directories.pop(url, None)
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        for thing_id in [i for i, t in self.things.items() if f"tdd:{url}" in t.sources]:
            await self._drop_source(thing_id, f"tdd:{url}")

    async def _follow(self, url: str) -> None:
        client = DirectoryClient(url, token=self.directory_token, timeout=self.timeout)
        source = f"tdd:{url}"
        last_event: str | None = None
        delay = 0.5
        try:
            while True:
                try:
                    async with client.events(last_event_id=last_event) as stream:
                        if last_event is None:  # first contact: what is there already
                            for td in await client.list():
                                await self._merge_from_directory(td, url, source)
                        delay = 0.5
                        async for ev in stream:
                            last_event = stream.last_event_id
                            await self._directory_event(client, ev.type, ev.data, url, source)
                except (OSError, ProblemError) as e:
                    log.info("directory %s: %s; retrying in %.1f s", url, e, delay)
                await asyncio.sleep(delay)
                delay = min(delay * 2, 30.0)
        finally:
            client.close()

    async def _directory_event(self, client: DirectoryClient, kind: str, data: Any, url: str,
                               source: str) -> None:
        thing_id = data.get("id") if isinstance(data, dict) else None
        if not isinstance(thing_id, str) or thing_id in self.own_ids:
            return
        if kind == "thing_deleted":
            await self._drop_source(thing_id, source)
            return
        try:
            td = await client.get(thing_id)
        except (OSError, ProblemError) as e:
            log.info("directory %s: cannot fetch %s: %s", url, thing_id, e)
            return
        await self._merge_from_directory(td, url, source)

    async def _merge_from_directory(self, td: dict[str, Any], url: str, source: str) -> None:
        if td_kind(td) == "Directory":
            if self.follow_directories and td.get("id") not in self.own_ids and td.get("base"):
                base = td["base"] if td["base"].endswith("/") else td["base"] + "/"
                if base != url:
                    self.add_directory(base)
            return
        await self._merge(td, urljoin(url, f"things/{td.get('id', '')}"), source)

    # -- merging -------------------------------------------------------------------
    async def _merge(self, td: dict[str, Any], url: str, source: str) -> str | None:
        td = _consumed(td, url)
        thing_id = i if isinstance(i := td.get("id"), str) else url
        if thing_id in self.own_ids:
            return None
        async with self._lock:
            found = self.things.get(thing_id)
            if found is None:
                config = None
                if self.claim is not None:
                    try:
                        config = self.claim(td)
                    except Exception:
                        log.exception("claiming %s failed", thing_id)
                found = FoundThing(thing_id, td, url, {source}, config)
                self.things[thing_id] = found
                await _call(self.on_found, found)
                return thing_id
            changed = not found.present or found.td != td or found.url != url
            found.sources.add(source)
            if changed:
                found.td, found.url = td, url
                await _call(self.on_updated, found)
        return thing_id

    async def _drop_source(self, thing_id: str, source: str) -> None:
        async with self._lock:
            found = self.things.get(thing_id)
            if found is None or source not in found.sources:
                return
            found.sources.discard(source)
            if not found.present:
                await _call(self.on_lost, found)

    async def close(self) -> None:
        for url in list(self.directories):
            task = self.directories.pop(url)
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._http.close()


def _origin(rec: ServiceRecord) -> str:
    return f"{rec.scheme}://{min(rec.hosts)}:{rec.port}"


def _consumed(td: dict[str, Any], url: str) -> dict[str, Any]:
    out = {k: v for k, v in td.items() if k != "registration"}
    if not isinstance(out.get("base"), str) and urlsplit(url).scheme in ("http", "https"):
        parts = urlsplit(url)
        out["base"] = f"{parts.scheme}://{parts.netloc}/"
    return out
