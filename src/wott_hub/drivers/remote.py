"""A tactile device that speaks WoT itself, consumed over HTTP and SSE (family ``wot-remote``).

The device's Tactile TD is the whole contract: the driver follows its forms,
nothing else. ``prepare`` reads ``skinNodes`` and ``skinCells`` (and, when
they are there, ``skinShape``, ``skinMaterial``, ``sensorCoordinateFrame``)
from their ``readproperty`` forms and builds the ``SkinMesh``; ``frames``
subscribes to ``skinDeformedDetection`` through its SSE form and turns each
packet into a ``TactileFrame``.

Precision: a packet carries one intensity per deformed node (the norm of its
displacement), no direction. The driver puts each node's intensity along the
inward normal of the rebuilt mesh, so the re-exposed device is as precise as
the packets: the same deformed nodes and intensities (to the packets' 1 µm
rounding), contacts where the source's are, forces along the normal (shear is
not in the packets and is lost). Its ε is the source's (``tac:epsilon``) less
one rounding step, so a node the source reports at exactly ε is kept.

Bounded, whatever the device sends (it may be anything on the network that announces
itself): the TD at most ``max_td_bytes`` (1 MiB by default), each of ``skinNodes`` and
``skinCells`` at most ``PROPERTY_BYTES_PER_NODE`` x ``max_nodes`` bytes, read as a stream
and refused as soon as it is longer; a mesh of more than ``max_nodes`` nodes (20,000 by
default) or more than ``CELLS_PER_NODE`` x that many cells is refused before it is built.
Parsing the answers and building the mesh run on a worker thread, never on the event
loop that carries the other devices' frames. A refusal is a ``DriverError`` naming the
bound: the device is not adopted, and says why (docs/reliability.md).

The stream is kept alive here: a refused or dropped connection is reported as
``disconnected`` with its reason and retried with ``Backoff``; the reconnect
sends ``Last-Event-ID``, so a source that keeps history (a wott-hub) resends
what was missed and nothing twice. ``retarget(td)`` moves to the device's new
address (discovery saw it come back elsewhere) keeping the resume point.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import re
import time
from collections.abc import AsyncIterator
from typing import Any
from urllib.parse import urljoin, urlsplit

import numpy as np

from wott_hub.tactile import (
    MATERIALS,
    CoordinateFrame,
    DeviceDescription,
    Material,
    MeshError,
    SkinMesh,
    SkinShape,
    TactileFrame,
)
from wott_hub.td.media import TD_ACCEPT

from .backoff import Backoff
from .base import Driver, DriverError, Health, Retargetable

__all__ = ["CELLS_PER_NODE", "EVENT", "FAMILY", "MAX_NODES", "MAX_TD_BYTES", "PROPERTY_BYTES_PER_NODE",
           "SKIN", "RemoteWoTDriver", "event_url", "property_url", "tactile_affordances"]

log = logging.getLogger("wott_hub.drivers.remote")

FAMILY = "wot-remote"
SKIN = ("skinNodes", "skinCells")
EVENT = "skinDeformedDetection"
_ROUNDING_MM = 0.0006  # a packet's intensities are rounded to 1 µm; one step and a margin
MAX_NODES = 20_000
"""Default cap on a remote device's mesh (the TacLink barrel has 707 nodes, a 64x64 mattress 4,096)."""
MAX_TD_BYTES = 1024 * 1024
"""Default cap on a remote device's TD, bytes."""
PROPERTY_BYTES_PER_NODE = 256
"""A skinNodes or skinCells answer may be this many bytes per allowed node (~110 are used)."""
CELLS_PER_NODE = 4
"""Cells per allowed node at most (a closed triangle mesh has about 2)."""


# --- reading a TD's forms ---------------------------------------------------------------

def _ops(form: dict[str, Any], default: str) -> list[str]:
    op = form.get("op", default)
    if isinstance(op, str):
        return [op]
    return [o for o in op if isinstance(o, str)] if isinstance(op, list) else []


def _absolute(td: dict[str, Any], href: Any, td_url: str | None = None) -> str | None:
    if not isinstance(href, str):
        return None
    base = td.get("base") if isinstance(td.get("base"), str) else td_url
    url = urljoin(base, href) if base else href
    return url if urlsplit(url).scheme in ("http", "https") and urlsplit(url).netloc else None


def property_url(td: dict[str, Any], name: str, td_url: str | None = None) -> str | None:
    """URL of the first HTTP ``readproperty`` form of property ``name`` answering JSON (GET)."""
    aff = (td.get("properties") or {}).get(name)
    if not isinstance(aff, dict):
        return None
    for form in aff.get("forms") or []:
        if not isinstance(form, dict) or "readproperty" not in _ops(form, "readproperty"):
            continue
        if form.get("htv:methodName", "GET") != "GET" or form.get("subprotocol"):
            continue
        if "json" not in form.get("contentType", "application/json"):
            continue
        url = _absolute(td, form.get("href"), td_url)
        if url is not None:
            return url
    return None


def event_url(td: dict[str, Any], name: str = EVENT, td_url: str | None = None) -> str | None:
    """URL of the first HTTP Server-Sent Events ``subscribeevent`` form of event ``name``."""
    aff = (td.get("events") or {}).get(name)
    if not isinstance(aff, dict):
        return None
    for form in aff.get("forms") or []:
        if not isinstance(form, dict) or "subscribeevent" not in _ops(form, "subscribeevent"):
            continue
        if form.get("subprotocol") != "sse" and form.get("contentType") != "text/event-stream":
            continue
        url = _absolute(td, form.get("href"), td_url)
        if url is not None:
            return url
    return None


def tactile_affordances(td: dict[str, Any], td_url: str | None = None) -> dict[str, str] | None:
    """The URLs the driver needs (skinNodes, skinCells, skinDeformedDetection), or None if the TD
    lacks one of them or offers no form this driver can use (HTTP GET, SSE)."""
    urls = {name: property_url(td, name, td_url) for name in SKIN}
    urls[EVENT] = event_url(td, EVENT, td_url)
    found = {name: url for name, url in urls.items() if url is not None}
    return found if len(found) == len(urls) else None


# --- from property values to a DeviceDescription ----------------------------------------------

def _shown(url: Any) -> str:
    """A URL as an error or a health reason shows it: without its query (it may carry a token)."""
    parts = urlsplit(str(url))
    return f"{parts.scheme}://{parts.netloc}{parts.path}" if parts.netloc else str(url).partition("?")[0]


def _unquoted(error: BaseException) -> str:
    """An HTTP client's message with every URL in it shown as ``_shown`` does."""
    return re.sub(r"https?://[^\s'\"]+", lambda m: _shown(m.group(0)), str(error))


def _parse(raw: bytes, name: str) -> Any:
    try:
        return json.loads(raw)
    except (ValueError, RecursionError) as e:
        raise DriverError(f"{name}: not JSON: {type(e).__name__}: {e}") from None


def _counted(value: Any, key: str, limit: int, what: str) -> None:
    items = value.get(key) if isinstance(value, dict) else None
    if isinstance(items, list) and len(items) > limit:
        raise DriverError(f"the device's mesh has {len(items)} {what}, more than the {limit} allowed "
                          f"(max_nodes); not adopted")


def _mesh(nodes_value: Any, cells_value: Any, name: str) -> tuple[SkinMesh, dict[int, int] | None]:
    """The mesh in node-ID order, and the ID -> row map when IDs are not 0..N-1."""
    try:
        nodes = sorted(nodes_value["arrayOfNodes"], key=lambda n: int(n["nodeID"]))
        ids = [int(n["nodeID"]) for n in nodes]
        xyz = np.array([[float(n["nodeLocation"][k]) for k in "xyz"] for n in nodes])
        index = None if ids == list(range(len(ids))) else {i: row for row, i in enumerate(ids)}
        cells = []
        for c in cells_value["arrayOfCells"]:
            ids_c = [int(v) for v in c["connectedNodes"]]
            cells.append(ids_c if index is None else [index[v] for v in ids_c])
        if len({len(c) for c in cells}) > 1:
            raise MeshError("cells mix triangles and quads")
        mesh = SkinMesh(xyz, np.array(cells, dtype=np.int64), np.ones(len(xyz), dtype=bool), name)
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise DriverError(f"skinNodes/skinCells do not describe a mesh: {type(e).__name__}: {e}") from None
    return mesh, index


def _shape(value: Any) -> SkinShape:
    if isinstance(value, dict) and value.get("shapeType") in ("rectangularPrism", "cylinder", "barrel"):
        def dim(key: str) -> float | None:
            v = value.get(key)
            return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None

        return SkinShape(value["shapeType"], length_mm=dim("lengthDimension"), width_mm=dim("widthDimension"),
                         height_mm=dim("heightDimension"), base_radius_mm=dim("baseRadiusDimension"),
                         middle_radius_mm=dim("middleRadiusDimension"))
    return SkinShape("rectangularPrism")


def _material(value: Any) -> Material:
    default = MATERIALS["ecoflex-00-30"]
    if not isinstance(value, dict):
        return default
    kind, shore = value.get("materialType"), value.get("materialShoreHardness")
    for known in MATERIALS.values():
        if known.material_type == kind and known.shore_hardness == shore:
            return known
    try:
        material = Material(str(kind), str(shore))
        material.modulus_mpa  # noqa: B018  # a hardness the skin model cannot read is no material
        return material
    except ValueError:
        return default


def _frame(value: Any) -> CoordinateFrame:
    try:
        o, a = value["originLocation"], value["axisOrientation"]

        def v(p: dict[str, Any]) -> tuple[float, float, float]:
            return (float(p["x"]), float(p["y"]), float(p["z"]))

        return CoordinateFrame(v(o), v(a["xAxis"]), v(a["yAxis"]), v(a["zAxis"]),
                               str(o.get("originName", "centerOfBottomCircle")))
    except (KeyError, TypeError, ValueError):
        return CoordinateFrame()


def re_exposed_epsilon(td: dict[str, Any], override: float | None = None) -> float:
    """ε of the re-exposed device: below every intensity the source can send (see module doc)."""
    if override is not None:
        return override
    eps = td.get("tac:epsilon")
    if isinstance(eps, bool) or not isinstance(eps, int | float) or not eps > 0:
        return 0.1
    return max(eps - _ROUNDING_MM, eps / 2)


# --- the driver ----------------------------------------------------------------------------

class RemoteWoTDriver(Driver, Retargetable):
    """``td`` (a Tactile TD) or ``url`` (where to fetch it) says where the device is."""

    def __init__(self, device_id: str, *, td: dict[str, Any] | None = None, url: str | None = None,
                 title: str | None = None, timeout_s: float = 5.0, idle_timeout_s: float = 60.0,
                 epsilon_mm: float | None = None, thickness_mm: float = 3.0,
                 backoff: Backoff | None = None, queue_size: int = 1024, token: str | None = None,
                 max_nodes: int = MAX_NODES, max_td_bytes: int = MAX_TD_BYTES) -> None:
        if td is None and url is None:
            raise DriverError("needs the device's TD or its URL")
        super().__init__(None)  # type: ignore[arg-type]  # described by prepare()
        self.device_id = device_id
        self.td = td
        self.td_url = url
        self._token = token  # sent as a bearer header on every request (TD, properties, SSE)
        self.title = title
        self.timeout_s = timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.epsilon_mm = epsilon_mm
        self.thickness_mm = thickness_mm
        self.backoff = backoff or Backoff(initial_s=0.2, cap_s=10.0)
        self.queue_size = queue_size
        self.max_nodes = max_nodes
        self.max_td_bytes = max_td_bytes
        self.last_event_id: str | None = None
        self.packets = 0
        self.bad_packets = 0
        self.connects = 0
        self._index: dict[int, int] | None = None
        self._inward: np.ndarray = np.zeros((0, 3))  # per node, set by prepare()
        self._last_t = 0
        self._queue: asyncio.Queue[TactileFrame | None] | None = None
        self._reader: asyncio.Task[None] | None = None
        self._closed = False

    # -- describing the device ---------------------------------------------------------------

    def _client(self) -> Any:
        import httpx

        auth = {"Authorization": f"Bearer {self._token}"} if self._token else {}
        return httpx.AsyncClient(timeout=httpx.Timeout(self.timeout_s, read=self.idle_timeout_s),
                                 follow_redirects=True, headers=auth)

    async def prepare(self) -> None:
        import httpx

        raw: dict[str, bytes] = {}
        try:
            async with self._client() as client:
                if self.td is None:
                    body = await self._get(client, self.td_url, TD_ACCEPT, self.max_td_bytes,
                                           "the TD (max_td_bytes)")
                    td = await asyncio.to_thread(_parse, body, "the TD")
                    if not isinstance(td, dict):
                        raise DriverError(f"{_shown(self.td_url)} did not answer a TD (a JSON object)")
                    self.td = td
                urls = tactile_affordances(self.td, self.td_url)
                if urls is None:
                    raise DriverError("the TD lacks skinNodes, skinCells or skinDeformedDetection with "
                                      "HTTP (GET) and SSE forms")
                limit = PROPERTY_BYTES_PER_NODE * self.max_nodes
                for name in SKIN:
                    why = f"{PROPERTY_BYTES_PER_NODE} per node, max_nodes {self.max_nodes}"
                    raw[name] = await self._read_raw(client, name, limit, why)
                for name in ("skinShape", "skinMaterial", "sensorCoordinateFrame"):
                    if property_url(self.td, name, self.td_url) is not None:
                        with contextlib.suppress(httpx.HTTPError, DriverError):
                            raw[name] = await self._read_raw(client, name, 64 * 1024)
        except httpx.HTTPError as e:  # unreachable, an HTTP error
            where = _shown(self.td_url or (self.td or {}).get("base"))
            raise DriverError(f"cannot read the device at {where}: {type(e).__name__}: "
                              f"{_unquoted(e)}") from None
        # parsing and building a mesh is milliseconds per thousand nodes: never on the event loop
        self.description = await asyncio.to_thread(self._describe, self.td, raw)
        self._inward = -self.description.mesh.normals

    def _describe(self, td: dict[str, Any], raw: dict[str, bytes]) -> DeviceDescription:
        """The device's description from the raw property answers (on a worker thread, bounded)."""
        values: dict[str, Any] = {}
        for name, body in raw.items():
            try:
                values[name] = _parse(body, name)
            except DriverError:
                if name in SKIN:
                    raise
        _counted(values["skinNodes"], "arrayOfNodes", self.max_nodes, "nodes")
        _counted(values["skinCells"], "arrayOfCells", CELLS_PER_NODE * self.max_nodes, "cells")
        mesh, self._index = _mesh(values["skinNodes"], values["skinCells"], self.device_id)
        source = self.td_url or td.get("base") or td.get("id", "")
        return DeviceDescription(
            id=self.device_id, title=self.title or str(td.get("title") or self.device_id), family=FAMILY,
            shape=_shape(values.get("skinShape")), material=_material(values.get("skinMaterial")),
            mesh=mesh, frame=_frame(values.get("sensorCoordinateFrame")),
            epsilon_mm=re_exposed_epsilon(td, self.epsilon_mm), thickness_mm=self.thickness_mm,
            description=f"WoT device {td.get('id', '')} ({source}), re-exposed: intensities along the "
                        "inward normal, as precise as its skinDeformedDetection packets",
        )

    def _known_td(self) -> dict[str, Any]:
        if self.td is None:
            raise DriverError(f"device {self.device_id!r}: its TD is not known (prepare() was not called)")
        return self.td

    @staticmethod
    async def _get(client: Any, url: Any, accept: str, limit: int, what: str) -> bytes:
        """The body at ``url``, read as a stream and refused once it is longer than ``limit`` bytes."""
        async with client.stream("GET", url, headers={"Accept": accept}) as resp:
            resp.raise_for_status()
            length = resp.headers.get("Content-Length")
            if length is not None and length.isdigit() and int(length) > limit:
                raise DriverError(f"{what} is {int(length)} bytes, more than the {limit} allowed; "
                                  "not adopted")
            chunks, size = [], 0
            async for chunk in resp.aiter_bytes():
                size += len(chunk)
                if size > limit:
                    raise DriverError(f"{what} is more than the {limit} bytes allowed; not adopted")
                chunks.append(chunk)
        return b"".join(chunks)

    async def _read_raw(self, client: Any, name: str, limit: int, why: str = "") -> bytes:
        url = property_url(self._known_td(), name, self.td_url)
        if url is None:
            raise DriverError(f"the TD has no HTTP readproperty form for {name}")
        return await self._get(client, url, "application/json", limit, f"{name} ({why})" if why else name)

    # -- frames ----------------------------------------------------------------------------------

    async def frames(self) -> AsyncIterator[TactileFrame]:
        if self.description is None:
            raise DriverError(f"device {self.device_id!r}: prepare() was not called")
        self._queue = asyncio.Queue(self.queue_size)
        self._start_reader()
        try:
            while (frame := await self._queue.get()) is not None:
                yield frame
        finally:
            await self._stop_reader()

    def _start_reader(self) -> None:
        if self._queue is not None and not self._closed:
            self._reader = asyncio.create_task(self._read_stream(), name=f"wot-remote:{self.device_id}")

    async def _stop_reader(self) -> None:
        task, self._reader = self._reader, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def _read_stream(self) -> None:
        import httpx
        from httpx_sse import SSEError, aconnect_sse

        queue = self._queue
        if queue is None:  # started by frames() only, which made the queue
            return
        async with self._client() as client:
            while not self._closed:
                url = event_url(self._known_td(), EVENT, self.td_url)
                if url is None:  # retargeted to a TD without the event's SSE form: nothing to follow
                    self.set_health(Health.disconnected, f"the TD has no SSE form for {EVENT}")
                    return
                headers = {"Last-Event-ID": self.last_event_id} if self.last_event_id else {}
                if self.health().state is not Health.ok or self.connects == 0:
                    self.set_health(Health.disconnected, f"connecting to {_shown(url)}")
                quiet = False
                try:
                    async with aconnect_sse(client, "GET", url, headers=headers) as source:
                        source.response.raise_for_status()
                        self.connects += 1
                        self.backoff.reset()
                        self.set_health(Health.ok)
                        async for sse in source.aiter_sse():
                            if sse.id:
                                self.last_event_id = sse.id
                            # no data: httpx-sse hands a keep-alive or retry: block on as an empty message
                            if sse.event not in (EVENT, "message", "") or not sse.data:
                                continue
                            frame = self._packet_frame(sse.data)
                            if frame is not None:
                                await queue.put(frame)
                    reason = "the device ended its event stream"
                except httpx.ReadTimeout:
                    quiet, reason = True, f"no data for {self.idle_timeout_s:g} s"
                except (httpx.HTTPError, SSEError, OSError) as e:
                    reason = f"{type(e).__name__}: {_unquoted(e)}".rstrip(": ")
                if quiet and self.health().state is Health.ok:
                    continue  # a silent stream, not a fault: reconnect at once, resuming
                self.set_health(Health.disconnected, reason)
                delay = self.backoff.next_delay()
                log.info("device %s: %s; reconnecting in %.2f s", self.device_id, reason, delay)
                await asyncio.sleep(delay)

    def _packet_frame(self, data: str) -> TactileFrame | None:
        """One packet -> the displacement it implies; None (and counted) if it is not one."""
        n = self.description.mesh.n_nodes
        try:
            packet = json.loads(data)
            nodes = packet["arrayOfDeformedNodes"]
            ids = np.fromiter((int(d["deformedNodeID"]) for d in nodes), dtype=np.int64, count=len(nodes))
            value = np.fromiter((float(d["deformedNodeIntensity"]) for d in nodes), dtype=np.float64,
                                count=len(nodes))
            t = packet.get("timeStamp")
            t_ns = int(t) if isinstance(t, int) and not isinstance(t, bool) and t >= 0 else time.time_ns()
        except (ValueError, KeyError, TypeError):
            self.bad_packets += 1
            self.set_health(Health.degraded, "a skinDeformedDetection packet is not one")
            return None
        if self._index is not None:
            ids = np.array([self._index.get(int(i), -1) for i in ids], dtype=np.int64)
        ok = (ids >= 0) & (ids < n) & np.isfinite(value) & (value >= 0)
        if not ok.all():
            self.bad_packets += 1
            self.set_health(Health.degraded, f"packet with {int((~ok).sum())} unknown node(s) or bad "
                                             "intensities (ignored)")
            ids, value = ids[ok], value[ok]
        self.packets += 1
        d = np.zeros((n, 3))
        d[ids] = value[:, None] * self._inward[ids]
        self._last_t = t_ns = max(t_ns, self._last_t)  # the processor refuses time going back
        return TactileFrame(t_ns, d)

    # -- discovery's hooks -----------------------------------------------------------------------

    def retarget(self, td: dict[str, Any]) -> None:
        """The device is now where ``td`` says (same device, new address): reconnect there,
        resuming from the last event received."""
        self.td = td
        self.td_url = None
        self.backoff.reset()
        if self._reader is not None:
            self._reader.cancel()
            self._start_reader()

    async def close(self) -> None:
        self._closed = True
        await self._stop_reader()
        if self._queue is not None:
            with contextlib.suppress(asyncio.QueueFull):
                self._queue.put_nowait(None)
