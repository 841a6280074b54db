"""A consumed Tactile Thing: its mesh as arrays, its frames as a resumable stream, its raw signals,
actions and properties.

Streams are chosen from the TD by ``op``: the Thing-level ``subscribeallevents``
SSE form when there is one (one connection carries every event, each message
named by ``event:``), else one ``subscribeevent`` stream per event (unnamed
messages: the stream says which event); likewise ``observeallproperties`` or
``observeproperty`` for ``contactInformation``. Each stream resumes on its own
with ``Last-Event-ID`` (``_stream.py``).

``skinDisplacement`` comes from its binary form when the TD offers one (an HTTP form with
``contentType`` ``application/vnd.wott.skin-displacement`` and ``subprotocol: "stream"``:
decoded without JSON, ``_fields.py``), else from its SSE form. Raw signals are read through
their ``application/x-npy`` forms (an image H x W x C uint8, a grid rows x cols float32: no
image decoder needed); actions through their ``invokeaction`` forms.
"""

from __future__ import annotations

import io
import json
from collections.abc import AsyncGenerator
from contextlib import aclosing
from typing import Any

import httpx
import numpy as np

from ._binary import BinaryStream
from ._bulk import BulkReader
from ._errors import ClientError, InvalidTD, NotFound, TransportError
from ._fields import CONTENT_TYPE, Displacement, displacement_of_text
from ._frames import Decoder, Item
from ._merge import merge
from ._stream import ResumableStream
from ._td import Form, Mesh, find_form, is_tactile, parse_mesh

__all__ = ["AsyncThing"]

DEFORMATION, CONTACTS, ACTIONS = "skinDeformedDetection", "contactInformation", "actionDetection"
DETAILS = "actionDetails"  # declared by newer TDs only
DISPLACEMENT = "skinDisplacement"  # newer TDs only
RAW_IMAGE, PRESSURE_GRID = "rawImage", "pressureGrid"  # devices with raw signals only
NPY = "application/x-npy"


def _problem(resp: httpx.Response) -> str:
    try:
        body = resp.json()
        return str(body.get("detail") or body.get("title") or resp.text[:200])
    except ValueError:
        return resp.text[:200]


def _detail(body: bytes, content_type: str) -> str:
    """A problem+json answer's detail, else the start of the body."""
    if "json" in content_type:
        try:
            problem = json.loads(body)
            return str(problem.get("detail") or problem.get("title") or body[:200])
        except (ValueError, AttributeError):
            pass
    return body[:200].decode("utf-8", "replace")


def _checked(resp: httpx.Response, what: str) -> httpx.Response:
    if resp.status_code == 404:
        raise NotFound(f"{what}: 404: {_problem(resp)}")
    if resp.status_code >= 400:
        raise TransportError(f"{what}: HTTP {resp.status_code}: {_problem(resp)}")
    return resp


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

    def __init__(self, td: dict[str, Any], http: httpx.AsyncClient, url: str | None = None,
                 bulk: BulkReader | None = None) -> None:
        if not isinstance(td, dict) or not is_tactile(td):
            raise InvalidTD(f"{url or 'TD'}: not a Tactile Thing (needs skinNodes and skinDeformedDetection)")
        self.td = td
        self.url = url
        self.id: str = str(td.get("id") or td.get("title") or url)
        self.title: str = str(td.get("title", self.id))
        self._http = http
        self._bulk = bulk  # large binary reads (raw images); made from the client's token if not given
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

    # --- displacement fields -----------------------------------------------------------------

    def _displacement_form(self) -> tuple[Form, bool]:
        """(form, binary) of ``skinDisplacement``: its binary stream if offered, else its SSE form."""
        if DISPLACEMENT not in (self.td.get("events") or {}):
            raise InvalidTD(f"{self.id}: no skinDisplacement event (an older hub, or another server)")
        form = find_form(self.td, "subscribeevent", "events", DISPLACEMENT, self.url,
                         content_type=CONTENT_TYPE, subprotocol="stream")
        if form is not None:
            return form, True
        form = find_form(self.td, "subscribeevent", "events", DISPLACEMENT, self.url, stream=True)
        if form is None:
            raise InvalidTD(f"{self.id}: skinDisplacement has neither a binary nor an SSE form")
        return form, False

    async def async_displacement_batches(self, *, last_event_id: str | None = None
                                         ) -> AsyncGenerator[list[Displacement], None]:
        """``skinDisplacement`` packets as they come, a list per network read, forever; each resumes
        after a drop (``last_event_id``: start after that packet's seq)."""
        form, binary = self._displacement_form()
        if binary:
            stream = BinaryStream(self._http, form.href, self.id, last_event_id)
            async with aclosing(stream.batches()) as batches:
                async for batch in batches:
                    yield batch
            return
        sse = ResumableStream(self._http, form.href, last_event_id)
        async with aclosing(sse.batches()) as msgs_in:
            async for msgs in msgs_in:
                out = [displacement_of_text(self.id, m.id, m.data) for m in msgs
                       if m.event in (None, "message", DISPLACEMENT) and m.data]
                if out:
                    yield out

    async def async_displacements(self, *, last_event_id: str | None = None
                                  ) -> AsyncGenerator[Displacement, None]:
        """As ``async_displacement_batches``, one packet at a time."""
        async with aclosing(self.async_displacement_batches(last_event_id=last_event_id)) as batches:
            async for batch in batches:
                for packet in batch:
                    yield packet

    # --- raw signals: the latest image or grid, as arrays -----------------------------------------

    @property
    def cameras(self) -> list[str]:
        """The cameras whose images ``async_image`` reads (empty: the Thing serves no images)."""
        image = (self.td.get("properties") or {}).get(RAW_IMAGE) or {}
        return list((image.get("uriVariables") or {}).get("camera", {}).get("enum") or [])

    async def _npy(self, name: str, **variables: Any) -> np.ndarray:
        form = find_form(self.td, "readproperty", "properties", name, self.url, content_type=NPY)
        if form is None:
            raise InvalidTD(f"{self.id}: property {name!r} has no {NPY} form")
        url = form.expand(**variables)
        if self._bulk is None:
            token = {k: v for k, v in self._http.headers.items() if k.lower() == "authorization"}
            self._bulk = BulkReader(token)
        status, ctype, body = await self._bulk.get(url, {"Accept": NPY})
        if status >= 400:
            detail = _detail(body, ctype)
            if status == 404:
                raise NotFound(f"{self.id} {name}: 404: {detail}")
            raise TransportError(f"{self.id} {name}: HTTP {status}: {detail}")
        try:
            array: np.ndarray = np.load(io.BytesIO(body), allow_pickle=False)
        except ValueError as e:
            raise TransportError(f"{url}: not a .npy array: {e}") from None
        return array

    async def async_image(self, camera: str | None = None) -> np.ndarray:
        """The camera's latest image, H x W x C uint8 (C 1 grey, 3 RGB); ``camera`` one of ``cameras``
        (default the first). The hub answers 400 naming ``camera`` for one it lacks."""
        return await self._npy(RAW_IMAGE, camera=camera)

    async def async_pressure(self) -> np.ndarray:
        """The latest pressure grid, rows x cols float32 kPa (a taxel array's)."""
        return await self._npy(PRESSURE_GRID)

    async def async_frame(self, camera: str | None = None) -> np.ndarray:
        """The device's latest raw frame, in digit-interface's spirit (``get_frame()``): a camera's image,
        else a taxel array's pressure grid; ``ClientError`` for a Thing that serves neither."""
        props = self.td.get("properties") or {}
        if RAW_IMAGE in props:
            return await self.async_image(camera)
        if PRESSURE_GRID in props:
            return await self._npy(PRESSURE_GRID)
        raise ClientError(f"{self.id}: serves no raw frame (no rawImage or pressureGrid property)")

    # --- actions and properties ---------------------------------------------------------------

    async def async_invoke(self, name: str, value: Any = None) -> Any:
        """Invoke action ``name`` through its ``invokeaction`` form; its output (None if it has none)."""
        form = find_form(self.td, "invokeaction", "actions", name, self.url)
        if form is None:
            raise InvalidTD(f"{self.id}: no action {name!r} with an HTTP form")
        try:
            resp = await self._http.post(form.href, json={} if value is None else value)
        except httpx.HTTPError as e:
            raise TransportError(f"{form.href}: {e!r}") from None
        _checked(resp, f"{self.id} {name}")
        return resp.json() if resp.content else None

    async def async_tare(self) -> Any:
        """The ``tare`` action: the skin as it is now becomes its rest reference."""
        return await self.async_invoke("tare")

    async def async_restart(self) -> Any:
        """The ``restart`` action: the hub closes the device's driver and opens it again."""
        return await self.async_invoke("restart")

    async def async_recalibrate(self) -> Any:
        """The ``recalibrate`` action (vision skins): the marker grid found again."""
        return await self.async_invoke("recalibrate")

    async def async_observe(self, name: str, *, last_event_id: str | None = None
                            ) -> AsyncGenerator[Any, None]:
        """The values of observable property ``name`` as they change (its SSE ``observeproperty`` form,
        resumed after a drop), forever."""
        form = find_form(self.td, "observeproperty", "properties", name, self.url, stream=True)
        if form is None:
            raise InvalidTD(f"{self.id}: property {name!r} has no SSE observeproperty form")
        stream = ResumableStream(self._http, form.expand(), last_event_id)
        async with aclosing(stream.batches()) as msgs_in:
            async for msgs in msgs_in:
                for m in msgs:
                    if m.data:
                        try:
                            yield json.loads(m.data)
                        except ValueError:
                            raise TransportError(f"{self.id} {name}: a message is not JSON") from None

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
