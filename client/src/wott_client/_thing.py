"""A consumed Tactile Thing: its mesh as arrays, its frames as a resumable stream.

Streams are chosen from the TD by ``op``: the Thing-level ``subscribeallevents``
SSE form when there is one (one connection carries every event, each message
named by ``event:``), else one ``subscribeevent`` stream per event (unnamed
messages: the stream says which event); likewise ``observeallproperties`` or
``observeproperty`` for ``contactInformation``. Each stream resumes on its own
with ``Last-Event-ID`` (``_stream.py``).
"""

from __future__ import annotations

from collections.abc import AsyncGenerator
from contextlib import aclosing
from typing import Any

import httpx

from ._errors import InvalidTD, NotFound, TransportError
from ._frames import Decoder, Item
from ._merge import merge
from ._stream import ResumableStream
from ._td import Mesh, find_form, is_tactile, parse_mesh

__all__ = ["AsyncThing"]

DEFORMATION, CONTACTS, ACTIONS = "skinDeformedDetection", "contactInformation", "actionDetection"
DETAILS = "actionDetails"  # declared by newer TDs only


async def get_json(http: httpx.AsyncClient, url: str) -> tuple[Any, httpx.Response]:
    """GET a JSON document, translating httpx's errors into the client's."""
    try:
        resp = await http.get(url, headers={"Accept": "application/json, application/td+json"})
    except httpx.HTTPError as e:
        raise TransportError(f"{url}: {e!r}") from None
    if resp.status_code == 404:
        raise NotFound(f"{url}: 404")
    if resp.status_code >= 400:
        raise TransportError(f"{url}: HTTP {resp.status_code}")
    try:
        return resp.json(), resp
    except ValueError:
        raise TransportError(f"{url}: the answer is not JSON") from None


class AsyncThing:
    """One Tactile Thing, from its TD (``AsyncClient.async_thing`` fetches one by URL or mDNS name)."""

    def __init__(self, td: dict[str, Any], http: httpx.AsyncClient, url: str | None = None) -> None:
        if not isinstance(td, dict) or not is_tactile(td):
            raise InvalidTD(f"{url or 'TD'}: not a Tactile Thing (needs skinNodes and skinDeformedDetection)")
        self.td = td
        self.url = url
        self.id: str = str(td.get("id") or td.get("title") or url)
        self.title: str = str(td.get("title", self.id))
        self._http = http
        self._mesh: Mesh | None = None
        self.streams: list[ResumableStream] = []  # of the last async_frames(), for inspection

    def __repr__(self) -> str:
        return f"<AsyncThing {self.id!r}>"

    async def async_read_property(self, name: str) -> Any:
        form = find_form(self.td, "readproperty", "properties", name, self.url)
        if form is None:
            raise InvalidTD(f"{self.id}: property {name!r} has no HTTP readproperty form")
        return (await get_json(self._http, form.href))[0]

    async def async_mesh(self) -> Mesh:
        """The rest mesh (read once, then cached)."""
        if self._mesh is None:
            nodes = await self.async_read_property("skinNodes")
            cells = None
            if "skinCells" in (self.td.get("properties") or {}):
                cells = await self.async_read_property("skinCells")
            self._mesh = parse_mesh(nodes, cells)
        return self._mesh

    def _plan(self, contacts: bool, actions: bool) -> list[tuple[str, str | None, frozenset[str]]]:
        """(href, the affordance of an unnamed message, affordances wanted) per stream to open."""
        declared = self.td.get("events") or {}
        events = {DEFORMATION} | ({ACTIONS, DETAILS} & set(declared) if actions else set())
        plan: list[tuple[str, str | None, frozenset[str]]] = []
        all_events = find_form(self.td, "subscribeallevents", url=self.url, stream=True)
        if all_events is not None:
            plan.append((all_events.href, None, frozenset(events)))
        else:
            for name in sorted(events):
                form = find_form(self.td, "subscribeevent", "events", name, self.url, stream=True)
                if form is None:
                    raise InvalidTD(f"{self.id}: event {name!r} has no SSE subscribeevent form")
                plan.append((form.href, name, frozenset({name})))
        if contacts and CONTACTS in (self.td.get("properties") or {}):
            form = find_form(self.td, "observeallproperties", url=self.url, stream=True)
            single = find_form(self.td, "observeproperty", "properties", CONTACTS, self.url, stream=True)
            if form is not None:
                plan.append((form.href, None, frozenset({CONTACTS})))
            elif single is not None:
                plan.append((single.href, CONTACTS, frozenset({CONTACTS})))
        return plan

    async def async_frames(self, *, contacts: bool = True, actions: bool = True,
                           last_event_id: str | None = None) -> AsyncGenerator[Item, None]:
        """Frames (and Contacts, Actions) as they come, forever; ``last_event_id``: resume the events."""
        batches = self.async_batches(contacts=contacts, actions=actions, last_event_id=last_event_id)
        async with aclosing(batches):
            async for batch in batches:
                for item in batch:
                    yield item

    async def async_batches(self, *, contacts: bool = True, actions: bool = True,
                            last_event_id: str | None = None) -> AsyncGenerator[list[Item], None]:
        """As ``async_frames``, a list per chunk read from the network (fewer hand-offs at high rates)."""
        decoder = Decoder(self.id, await self.async_mesh())
        plan = self._plan(contacts, actions)
        self.streams = [ResumableStream(self._http, href, last_event_id if i == 0 else None)
                        for i, (href, _, _) in enumerate(plan)]
        sources = [self._decoded(s, default, wanted, decoder)
                   for s, (_, default, wanted) in zip(self.streams, plan, strict=True)]
        async with aclosing(merge(sources)) as merged:
            async for batch in merged:
                yield batch

    async def _decoded(self, stream: ResumableStream, default: str | None, wanted: frozenset[str],
                       decoder: Decoder) -> AsyncGenerator[list[Item], None]:
        decode = decoder.decode
        async with aclosing(stream.batches()) as msgs_in:
            async for msgs in msgs_in:
                out = []
                for m in msgs:
                    name = m.event if m.event is not None and m.event != "message" else default
                    if name in wanted:
                        item = decode(name, m.id, m.data)
                        if item is not None:
                            out.append(item)
                if out:
                    yield out
