"""A wott-hub's recorded history, through the actions its hub Thing declares.

``historyDevices`` lists what is recorded, ``historyRecords`` pages a device's range as
JSON Lines (the client asks again with ``after`` = the last seq until a page is short),
``historyExport`` returns an MCAP file (docs/history.md of wott-hub). Forms are found
by action name and ``invokeaction`` in the TD, never by a URL pattern, so the hub decides
where they live. Times are ns since the epoch (int), a ``datetime``, or the hub's text
forms (ISO 8601, ``-10m``, ``now``).
"""

from __future__ import annotations

import datetime as dt
import json
import os
from collections.abc import AsyncGenerator, Sequence
from typing import Any

import httpx

from ._errors import InvalidTD, NotFound, TransportError
from ._td import find_form

__all__ = ["AsyncHistory", "Time"]

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
