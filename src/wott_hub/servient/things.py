"""The Things the hub serves: their TD and property values, encoded once.

A ``ServedThing`` is the hub-side truth about one Thing. Its TD and static
property values are JSON-encoded when it is exposed and served as bytes from
then on (a barrel's skinNodes is ~70 kB: encoding it per request would cost
more than the request). Dynamic properties (contactInformation, the hub's
counters) are read through a function returning the encoded value.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

from wott_hub.events.record import encode
from wott_hub.td.raw import RAW_PROPERTIES
from wott_hub.types import RawReads

__all__ = ["ServedThing", "ThingRegistry"]


@dataclass(eq=False)
class ServedThing:
    id: str
    td: dict[str, Any]
    static: dict[str, str] = field(default_factory=dict)  # name -> encoded JSON
    dynamic: dict[str, Callable[[], str]] = field(default_factory=dict)  # name -> encoded JSON
    record: bool = True
    exposed: Any = None  # the wotpy ExposedThing
    raw: RawReads | None = None  # a device's raw signals (rawImage, pressureGrid), read on demand
    _td_bytes: bytes | None = None
    _etag: str | None = None

    @classmethod
    def create(cls, thing: str, td: dict[str, Any], static_values: dict[str, Any] | None = None,
               dynamic: dict[str, Callable[[], str]] | None = None, record: bool = True) -> ServedThing:
        static = {k: encode(v) for k, v in (static_values or {}).items()}
        return cls(thing, td, static, dict(dynamic or {}), record)

    @property
    def title(self) -> str:
        title: str = self.td.get("title", self.id)
        return title

    @property
    def property_names(self) -> list[str]:
        return list(self.td.get("properties") or {})

    @property
    def event_names(self) -> list[str]:
        return list(self.td.get("events") or {})

    def is_observable(self, name: str) -> bool:
        return bool((self.td.get("properties") or {}).get(name, {}).get("observable"))

    def td_bytes(self) -> bytes:
        if self._td_bytes is None:
            self._td_bytes = json.dumps(self.td, ensure_ascii=False).encode()
            self._etag = '"' + hashlib.blake2b(self._td_bytes, digest_size=12).hexdigest() + '"'
        return self._td_bytes

    @property
    def etag(self) -> str:
        self.td_bytes()
        etag = self._etag
        assert etag is not None  # td_bytes() sets it
        return etag

    def read(self, name: str) -> str | None:
        """The encoded value of property ``name``; None if the Thing has no such property."""
        getter = self.dynamic.get(name)
        if getter is not None:
            return getter()
        value = self.static.get(name)
        if value is None and name in (self.td.get("properties") or {}):
            return "null"
        return value

    def is_raw(self, name: str) -> bool:
        """A raw signal's property (served by the raw routes, encoded only for its reader)."""
        return self.raw is not None and name in RAW_PROPERTIES

    def read_all(self) -> str:
        """Every property's value but the raw signals' (each has its own forms, read on demand)."""
        # read() is None only for a name the TD lacks, and these names come from the TD
        return _json_object((n, v) for n in self.property_names
                            if not self.is_raw(n) and (v := self.read(n)) is not None)

    def static_json(self) -> str:
        """The static values as one JSON object (what history records), spliced from the texts
        encoded for serving: a barrel's mesh is not decoded and encoded again."""
        return _json_object(self.static.items())


def _json_object(items: Iterable[tuple[str, str]]) -> str:
    """``{name: value}`` from already-encoded values."""
    return "{" + ",".join([f"{json.dumps(n)}:{v}" for n, v in items]) + "}"


class ThingRegistry:
    """Served Things by id and by the URL-safe name wotpy routes WebSockets with.

    One rule for ids (issue 48): they are compared regardless of case everywhere (``GET /wot/PAD``
    serves ``Pad``, ``addDevice`` of ``PAD`` is a 409 beside it, a config with ``X`` and ``x`` is
    refused), because the WebSocket name (``slugify``) and MQTT topics fold case anyway."""

    def __init__(self) -> None:
        self.by_id: dict[str, ServedThing] = {}
        self.by_ws_name: dict[str, ServedThing] = {}
        self._folded: dict[str, ServedThing] = {}  # id.casefold() -> Thing

    def add(self, thing: ServedThing, ws_name: str) -> None:
        same = self._folded.get(thing.id.casefold())
        if same is not None:
            raise ValueError(f"a Thing with id {same.id!r} is already served (ids are compared regardless "
                             "of case)")
        if ws_name in self.by_ws_name:
            raise ValueError(f"Thing id {thing.id!r} collides with {self.by_ws_name[ws_name].id!r} "
                             f"in WebSocket URLs ({ws_name!r}): choose ids that differ after slugify")
        self.by_id[thing.id] = thing
        self.by_ws_name[ws_name] = thing
        self._folded[thing.id.casefold()] = thing

    def remove(self, thing_id: str) -> ServedThing | None:
        thing = self.by_id.pop(thing_id, None)
        if thing is not None:
            for k in [k for k, v in self.by_ws_name.items() if v is thing]:
                del self.by_ws_name[k]
            self._folded.pop(thing.id.casefold(), None)
        return thing

    def get(self, thing_id: str) -> ServedThing | None:
        """The Thing served under ``thing_id``, whatever its case."""
        return self.by_id.get(thing_id) or self._folded.get(thing_id.casefold())

    def __iter__(self) -> Iterator[ServedThing]:
        return iter(self.by_id.values())

    def __len__(self) -> int:
        return len(self.by_id)
