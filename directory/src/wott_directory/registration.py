"""Registration information (WoT Discovery 7.3.1): the ``registration`` block of an Enriched TD.

The directory owns ``created``, ``modified`` and ``expires``; a producer gives
``ttl`` (seconds, relative to this registration) or, without a ttl, an
absolute ``expires``. Client values for ``created``/``modified``/``retrieved``
are ignored, and with a ttl so is a client ``expires``. Every TD the directory
serves carries the Discovery context URI, as Enriched TDs must.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from .errors import ValidationFailed
from .mergepatch import merge_diff, same_json
from .validation import MAX_TTL_S, json_bytes, parse_rfc3339

__all__ = ["DISCOVERY_CONTEXT", "Enriched", "WritePlan", "enrich", "iso", "plan_write", "same_content",
           "with_context"]

DISCOVERY_CONTEXT = "https://www.w3.org/2022/wot/discovery"


def iso(moment: datetime) -> str:
    """RFC 3339 in UTC with milliseconds, e.g. ``2026-11-22T10:00:00.123Z``."""
    return moment.astimezone(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def with_context(td: dict[str, Any]) -> dict[str, Any]:
    """The TD with the Discovery context URI in its ``@context`` (appended, order kept)."""
    ctx = td.get("@context")
    if ctx == DISCOVERY_CONTEXT or (isinstance(ctx, list) and DISCOVERY_CONTEXT in ctx):
        return td
    out = dict(td)
    if isinstance(ctx, list):
        out["@context"] = [*ctx, DISCOVERY_CONTEXT]
    elif ctx is None:
        out["@context"] = [DISCOVERY_CONTEXT]
    else:
        out["@context"] = [ctx, DISCOVERY_CONTEXT]
    return out


class Enriched:
    """A TD as stored and served (without ``retrieved``), with its times parsed once."""

    __slots__ = ("created", "expires", "modified", "td")

    def __init__(self, td: dict[str, Any], created: datetime, modified: datetime,
                 expires: datetime | None) -> None:
        self.td = td
        self.created = created
        self.modified = modified
        self.expires = expires

    @classmethod
    def from_stored(cls, td: dict[str, Any]) -> Enriched:
        reg = td.get("registration") or {}
        now = datetime.now(UTC)
        created = parse_rfc3339(reg.get("created", "")) or now
        modified = parse_rfc3339(reg.get("modified", "")) or created
        return cls(td, created, modified, parse_rfc3339(reg.get("expires", "")))


def enrich(td: dict[str, Any], now: datetime, previous: Enriched | None) -> Enriched:
    """The Enriched TD for a create or update of ``td`` at ``now``."""
    given = td.get("registration")
    reg_in: dict[str, Any] = given if isinstance(given, dict) else {}
    ttl = reg_in.get("ttl")
    expires: datetime | None = None
    if isinstance(ttl, int | float) and not isinstance(ttl, bool):
        if not 0 < ttl <= MAX_TTL_S:  # check_td says so first; never an OverflowError here
            raise ValidationFailed([{"field": "$.registration.ttl",
                                     "description": f"ttl must be in (0, {MAX_TTL_S}] s"}])
        expires = now + timedelta(seconds=ttl)
    elif isinstance(reg_in.get("expires"), str):
        expires = parse_rfc3339(reg_in["expires"])
        if expires is not None and expires <= now:
            raise ValidationFailed([{"field": "$.registration.expires",
                                     "description": "expires is in the past"}])
    created = previous.created if previous is not None else now
    reg: dict[str, Any] = {"created": iso(created), "modified": iso(now)}
    if expires is not None:
        reg["expires"] = iso(expires)
    if ttl is not None:
        reg["ttl"] = ttl
    out = with_context({k: v for k, v in td.items() if k != "registration"})  # a new dict either way
    out["registration"] = reg
    return Enriched(out, created, now, expires)


def same_content(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Same TD apart from the directory's bookkeeping times (a refresh, not a change)."""
    if a.keys() != b.keys():
        return False
    for key, value in a.items():
        if key == "registration":
            if (value or {}).get("ttl") != (b.get(key) or {}).get("ttl"):
                return False
        elif not same_json(value, b[key]):
            return False
    return True


@dataclass(frozen=True)
class WritePlan:
    """What a write will store and publish, worked out on the write thread."""

    rec: Enriched
    size: int  # bytes of the stored TD's JSON
    event: str | None  # "thing_created" | "thing_updated" | None (a refresh)
    data: dict[str, Any] | None  # the event's data: the TD, or the diff with the id
    data_size: int


def plan_write(thing_id: str, td: dict[str, Any], prev: Enriched | None, now: datetime) -> WritePlan:
    """The enriched TD, its size and its event (on the write thread: all of it grows with the TD). A
    write that changes nothing but the registration times (a refresh) keeps ``modified``, no event."""
    rec = enrich(td, now, prev)
    if prev is not None and same_content(prev.td, rec.td):
        reg = {**rec.td["registration"], "modified": iso(prev.modified)}
        rec = Enriched({**rec.td, "registration": reg}, prev.created, prev.modified, rec.expires)
        return WritePlan(rec, json_bytes(rec.td), None, None, 0)
    size = json_bytes(rec.td)
    if prev is None:
        return WritePlan(rec, size, "thing_created", rec.td, size)
    diff = {"id": thing_id, **merge_diff(prev.td, rec.td)}
    return WritePlan(rec, size, "thing_updated", diff, json_bytes(diff))
