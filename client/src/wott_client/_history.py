"""A wott-hub's recorded history, through the actions its hub Thing declares.

``historyDevices`` lists what is recorded, ``historyRecords`` pages a device's range as
JSON Lines (the client asks again with ``after`` = the last seq until a page is short),
``historyExport`` returns an MCAP file (docs/history.md of wott-hub); ``startEpisode`` and
``endEpisode`` mark the episodes a learning export cuts the recording into (docs/learning.md).
``async_range`` reads a range of one skin event as arrays (``FieldRange``: the packets' nodes one
after the other, cut by ``offsets``), resumable after any record it returned
(``after=range.last_seq``). Forms are found by action name and ``invokeaction`` in the TD, never
by a URL pattern, so the hub decides where they live. Times are ns since the epoch (int), a
``datetime``, or the hub's text forms (ISO 8601, ``-10m``, ``now``).
"""

from __future__ import annotations

import datetime as dt
import json
import os
from collections.abc import AsyncGenerator, Sequence
from dataclasses import dataclass, field
from typing import Any

import httpx
import numpy as np
import numpy.typing as npt

from ._errors import ClientError, InvalidTD, NotFound, TransportError
from ._td import find_form

__all__ = ["AsyncHistory", "FieldRange", "Time"]

DISPLACEMENT, DEFORMATION = "skinDisplacement", "skinDeformedDetection"


@dataclass(frozen=True, slots=True)
class FieldRange:
    """A device's recorded ``skinDisplacement`` (or ``skinDeformedDetection``) packets as arrays.

    Packet ``k`` has seq ``seq[k]``, timeStamp ``t_ns[k]`` and the nodes
    ``ids[offsets[k]:offsets[k + 1]]`` with their ``values`` there: (M, 3) float32 mm vectors for
    ``skinDisplacement``, (M,) float32 mm intensities for ``skinDeformedDetection``. ``last_seq``
    resumes a read after this range (``async_range(..., after=r.last_seq)``)."""

    device: str
    name: str
    seq: npt.NDArray[np.int64] = field(repr=False)
    t_ns: npt.NDArray[np.int64] = field(repr=False)
    offsets: npt.NDArray[np.int64] = field(repr=False)
    ids: npt.NDArray[np.int64] = field(repr=False)
    values: npt.NDArray[np.float32] = field(repr=False)

    def __len__(self) -> int:
        return len(self.seq)

    @property
    def last_seq(self) -> int | None:
        return int(self.seq[-1]) if len(self.seq) else None

    def packet(self, k: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32]]:
        """(node ids, values) of packet ``k``."""
        a, b = int(self.offsets[k]), int(self.offsets[k + 1])
        return self.ids[a:b], self.values[a:b]

    def dense(self, n_nodes: int, rows: npt.NDArray[np.intp] | None = None) -> npt.NDArray[np.float32]:
        """Every packet as the whole field: (K, n_nodes, 3) or (K, n_nodes), zero where a packet is
        silent. ``rows``: each of ``ids``' row in the mesh (``Mesh.index_of(r.ids)``), when node ids are
        not simply rows."""
        out = np.zeros((len(self), n_nodes, *self.values.shape[1:]), np.float32)
        packet = np.repeat(np.arange(len(self)), np.diff(self.offsets))
        out[packet, self.ids if rows is None else rows] = self.values
        return out


def _range_of(device: str, name: str, records: list[dict[str, Any]]) -> FieldRange:
    """The arrays of ``records`` (``historyRecords`` lines of one skin event)."""
    vectors = name == DISPLACEMENT
    key = "arrayOfDisplacedNodes" if vectors else "arrayOfDeformedNodes"
    node_id = "nodeID" if vectors else "deformedNodeID"
    seq, ts, counts, ids, values = [], [], [], [], []
    try:
        for rec in records:
            data = rec["data"]
            nodes = data[key]
            seq.append(rec["seq"])
            ts.append(data["timeStamp"])
            counts.append(len(nodes))
            ids += [d[node_id] for d in nodes]
            if vectors:
                values += [(v["x"], v["y"], v["z"]) for v in (d["displacement"] for d in nodes)]
            else:
                values += [d["deformedNodeIntensity"] for d in nodes]
    except (KeyError, TypeError) as e:
        raise ClientError(f"{device}: a recorded {name} record is not one ({e!r})") from None
    offsets = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    shape = (-1, 3) if vectors else (-1,)
    return FieldRange(device, name, np.array(seq, np.int64), np.array(ts, np.int64), offsets,
                      np.array(ids, np.int64), np.array(values, np.float32).reshape(shape))

Time = int | str | dt.datetime | None


def _time(value: Time) -> int | str | None:
    if isinstance(value, dt.datetime):
        if value.tzinfo is None:
            value = value.astimezone()
        return int(value.timestamp() * 1e9)
    return value


def _problem(resp: httpx.Response) -> str:
    try:
        body = resp.json()
        return str(body.get("detail") or body.get("title") or resp.text)
    except ValueError:
        return resp.text[:200]


class AsyncHistory:
    """The history actions of one hub Thing (``AsyncClient.async_history``)."""

    def __init__(self, td: dict[str, Any], http: httpx.AsyncClient, url: str | None = None) -> None:
        self.td = td
        self.url = url
        self._http = http
        self._forms: dict[str, str] = {}
        for name in ("historyDevices", "historyRecords", "historyExport"):
            form = find_form(td, "invokeaction", "actions", name, url)
            if form is None:
                raise InvalidTD(f"{url or 'TD'}: no {name!r} action with an HTTP form (not a wott-hub's hub "
                                "Thing, or history is off)")
            self._forms[name] = form.href

    def __repr__(self) -> str:
        return f"<AsyncHistory {self.url!r}>"

    def _check(self, resp: httpx.Response, action: str) -> None:
        if resp.status_code == 404:
            raise NotFound(f"{action}: {_problem(resp)}")
        if resp.status_code >= 400:
            raise TransportError(f"{action}: HTTP {resp.status_code}: {_problem(resp)}")

    async def _post(self, action: str, body: dict[str, Any]) -> httpx.Response:
        if action not in self._forms:  # an action a hub may not have (episodes: a hub without history)
            form = find_form(self.td, "invokeaction", "actions", action, self.url)
            if form is None:
                raise InvalidTD(f"{self.url or 'TD'}: no {action!r} action with an HTTP form")
            self._forms[action] = form.href
        try:
            resp = await self._http.post(self._forms[action], json=body)
        except httpx.HTTPError as e:
            raise TransportError(f"{action}: {e!r}") from None
        self._check(resp, action)
        return resp

    async def async_devices(self) -> list[dict[str, Any]]:
        """Every recorded device: ``id``, ``title``, ``family``, ``count``, ``from``/``to`` (ns)."""
        devices: list[dict[str, Any]] = (await self._post("historyDevices", {})).json()
        return devices

    @staticmethod
    def _range(t_from: Time, t_to: Time, names: Sequence[str] | None) -> dict[str, Any]:
        body: dict[str, Any] = {}
        for key, value in (("from", _time(t_from)), ("to", _time(t_to))):
            if value is not None:
                body[key] = value
        if names:
            body["names"] = list(names)
        return body

    async def async_records(self, device: str, *, t_from: Time = None, t_to: Time = None,
                            names: Sequence[str] | None = None, limit: int | None = None,
                            page: int = 10_000) -> AsyncGenerator[dict[str, Any], None]:
        """The device's records in order (``thing``, ``seq``, ``t_ns``, ``kind``, ``name``, ``data``
        decoded), all of the range or the first ``limit``, fetched ``page`` at a time."""
        body = {"device": device, **self._range(t_from, t_to, names)}
        after, left = 0, limit
        while left is None or left > 0:
            n = page if left is None else min(page, left)
            resp = await self._post("historyRecords", {**body, "after": after, "limit": n})
            lines = resp.text.splitlines()
            for line in lines:
                rec = json.loads(line)
                after = rec["seq"]
                yield rec
            if left is not None:
                left -= len(lines)
            if len(lines) < n:
                return

    async def async_range(self, device: str, name: str = DISPLACEMENT, *, t_from: Time = None,
                          t_to: Time = None, after: int = 0, limit: int | None = None,
                          page: int = 10_000) -> FieldRange:
        """The device's ``name`` packets (``skinDisplacement`` or ``skinDeformedDetection``) of the range
        as arrays, all of it or the first ``limit``, after seq ``after`` (0: from the start)."""
        if name not in (DISPLACEMENT, DEFORMATION):
            raise ClientError(f"async_range reads {DISPLACEMENT} or {DEFORMATION}, not {name!r}")
        body = {"device": device, **self._range(t_from, t_to, [name])}
        records: list[dict[str, Any]] = []
        left = limit
        while left is None or left > 0:
            n = page if left is None else min(page, left)
            resp = await self._post("historyRecords", {**body, "after": after, "limit": n})
            lines = resp.text.splitlines()
            got = [json.loads(line) for line in lines]
            records += got
            if got:
                after = got[-1]["seq"]
            if left is not None:
                left -= len(got)
            if len(got) < n:
                break
        return _range_of(device, name, records)

    async def async_start_episode(self, task: str) -> dict[str, Any]:
        """Start an episode of the recording (the hub's ``startEpisode``): ``{"task", "from"}`` (ns). One
        at a time: a second start is a ``TransportError`` (HTTP 409) naming the open one."""
        started: dict[str, Any] = (await self._post("startEpisode", {"task": task})).json()
        return started

    async def async_end_episode(self) -> dict[str, Any]:
        """End the open episode (``endEpisode``): ``{"task", "from", "to"}`` (ns)."""
        ended: dict[str, Any] = (await self._post("endEpisode", {})).json()
        return ended

    async def async_export_mcap(self, path: str | os.PathLike[str], devices: Sequence[str] | str, *,
                                t_from: Time = None, t_to: Time = None, names: Sequence[str] | None = None,
                                scene: bool = True, scene_hz: float = 30.0) -> int:
        """Write the devices' records as an MCAP file (the hub encodes it); returns its size in bytes."""
        devices = [devices] if isinstance(devices, str) else list(devices)
        body = {"devices": devices, **self._range(t_from, t_to, names), "scene": scene, "sceneHz": scene_hz}
        size = 0
        try:
            async with self._http.stream("POST", self._forms["historyExport"], json=body) as resp:
                if resp.status_code >= 400:
                    await resp.aread()
                    self._check(resp, "historyExport")
                with open(path, "wb") as f:
                    async for chunk in resp.aiter_bytes():
                        f.write(chunk)
                        size += len(chunk)
        except httpx.HTTPError as e:
            raise TransportError(f"historyExport: {e!r}") from None
        return size
