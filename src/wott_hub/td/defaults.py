"""TD 1.1 defaults, stated in the TDs the hub serves where a client decides by them.

TD 1.1 (section 5.4) gives many terms a default, and the W3C playground's full
schema warns about every one not written down. The hub writes those a client
acts on: whether a property can be read, written or observed
(``readOnly``/``writeOnly``/``observable``), whether an action changes anything
or may be repeated (``safe``/``idempotent``), the media type of every form
(``contentType``) and, on an additional response, that it is not a success.

Not written: ``readOnly``/``writeOnly`` inside the data schemas of values (the
members and items of a property's value, action input/output, event data):
in a read-only value they say nothing a client can use, and stating them on
every nested schema would grow a device TD by about a quarter
(docs/interop.md, "The W3C validators").
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

__all__ = ["state_defaults"]

JSON = "application/json"


def state_defaults(td: dict[str, Any]) -> dict[str, Any]:
    """Write the defaults above into ``td`` where it does not state them (in place); returns it."""
    for aff in _affordances(td, "properties"):
        aff.setdefault("readOnly", False)
        aff.setdefault("writeOnly", False)
        aff.setdefault("observable", False)
    for aff in _affordances(td, "actions"):
        aff.setdefault("safe", False)
        aff.setdefault("idempotent", False)
    for form in _forms(td):
        form.setdefault("contentType", JSON)
        for response in form.get("additionalResponses") or ():
            if isinstance(response, dict):
                response.setdefault("success", False)
    return td


def _affordances(td: dict[str, Any], kind: str) -> Iterator[dict[str, Any]]:
    affordances = td.get(kind)
    if isinstance(affordances, dict):
        yield from (aff for aff in affordances.values() if isinstance(aff, dict))


def _forms(td: dict[str, Any]) -> Iterator[dict[str, Any]]:
    holders = [td, *(aff for kind in ("properties", "actions", "events") for aff in _affordances(td, kind))]
    for holder in holders:
        forms = holder.get("forms")
        if isinstance(forms, list):
            yield from (f for f in forms if isinstance(f, dict))
