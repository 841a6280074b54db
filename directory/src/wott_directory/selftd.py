"""The directory's own TD, instantiated from the normative Thing Model (``directory.tm.json``).

What the TM leaves optional we declare only if we serve it: everything but the
XPath and SPARQL searches. Every form states its ``op`` and
``htv:methodName`` (clients pick forms by them), and the TD states the TD 1.1
defaults a client decides by (``readOnly``/``writeOnly``/``observable``,
``safe``/``idempotent``, each form's ``contentType``, ``success`` of error responses).

Its security says exactly what the server enforces, and defines no scheme no
form uses: standalone, reads are open (``nosec``) unless ``protect_reads``,
writes need the ``token`` (bearer) unless ``open_writes``; a directory with
neither a token nor open writes accepts no writes, and its TD declares no write
action. Embedded in a server that checks every request itself (the hub's gate,
``td_security``), that server's schemes replace the directory's own.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any
from urllib.parse import urljoin

from .registration import DISCOVERY_CONTEXT
from .settings import DirectorySettings
from .validation import load_data

__all__ = ["WRITE_ACTIONS", "directory_td"]

WRITE_ACTIONS = ("createThing", "createAnonymousThing", "updateThing", "partiallyUpdateThing",
                 "deleteThing")
_UNSERVED = ("searchXPath", "searchSPARQL")
_OPS = {"properties": "readproperty", "actions": "invokeaction", "events": "subscribeevent"}


def directory_td(settings: DirectorySettings, version: str = "0.1.0",
                 td_security: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The TD; ``td_security``: what a server in front of the directory enforces instead of its own
    token (``securityDefinitions``, ``security`` of every form, and optionally ``writes`` and
    ``streams``: the security of write forms and of event streams when they differ)."""
    tm = copy.deepcopy(load_data("directory.tm.json"))
    td: dict[str, Any] = {
        # the array form TD 1.1 allows: node-wot 0.9 rejects a TD whose context starts with the 1.1 URI
        "@context": ["https://www.w3.org/2019/wot/td/v1", "https://www.w3.org/2022/wot/td/v1.1",
                     DISCOVERY_CONTEXT],
        "@type": "ThingDirectory",
        "id": settings.own_id,
        "title": settings.title,
        "description": "W3C WoT Thing Description Directory (WoT Discovery HTTP API) of wott-hub.",
        "version": {"instance": version, "model": tm["version"]["model"]},
        "base": settings.base_url,
    }
    td_security = _standalone_security(settings) if td_security is None else td_security
    td["securityDefinitions"] = copy.deepcopy(dict(td_security["securityDefinitions"]))
    td["security"] = list(td_security["security"])
    writes = td_security.get("writes")
    streams = td_security.get("streams")

    td["properties"] = tm["properties"]
    td["properties"]["things"]["readOnly"] = True
    _type_things(td["properties"]["things"])
    td["actions"] = {k: v for k, v in tm["actions"].items()
                     if k not in _UNSERVED and (writes != [] or k not in WRITE_ACTIONS)}
    td["events"] = tm["events"]
    for kind, op in _OPS.items():
        for name, affordance in td[kind].items():
            for form in affordance["forms"]:
                form.setdefault("op", op)
                form.setdefault("htv:methodName", "GET")
                if kind == "actions" and name in WRITE_ACTIONS and writes is not None:
                    form["security"] = list(writes)
                if kind == "events" and streams is not None:
                    form["security"] = list(streams)
                form["href"] = form["href"].lstrip("/")  # relative to base, which may have a path
                response = form.get("response")
                if isinstance(response, dict) and "contentType" not in response:
                    # TD 1.1 requires it; these responses (201/204) have an empty body
                    response["contentType"] = "text/plain"
                _state_form_defaults(kind, form)
    _state_affordance_defaults(td)
    # wotpy fetches a form's href as it is (no base, no URI template): a plain absolute form first
    forms = td["properties"]["things"]["forms"]
    forms.insert(0, {**copy.deepcopy(forms[0]), "href": urljoin(settings.base_url, "things")})
    return td


# HTTP's idempotent methods (RFC 9110 9.2.2): repeating the request leaves the directory as once
_IDEMPOTENT = ("createThing", "updateThing", "deleteThing", "retrieveThing", "searchJSONPath")


def _state_form_defaults(kind: str, form: dict[str, Any]) -> None:
    """TD 1.1 defaults the W3C playground's full schema asks for, stated (the hub's TDs do the same,
    wott_hub.td.defaults): a form's ``contentType`` is what its request carries, or for a request
    without a body (GET, DELETE) what it answers; an event's is its data's (``application/json``;
    ``response`` says the stream is ``text/event-stream``); an error response is no success."""
    response = form.get("response")
    if kind == "events":
        form.setdefault("contentType", "application/json")
    elif isinstance(response, dict) and "contentType" in response:
        form.setdefault("contentType", response["contentType"])
    for extra in form.get("additionalResponses") or ():
        extra.setdefault("success", False)


def _state_affordance_defaults(td: dict[str, Any]) -> None:
    for prop in td["properties"].values():
        prop.setdefault("writeOnly", False)
        prop.setdefault("observable", False)
    for name, action in td["actions"].items():
        action.setdefault("safe", False)
        action.setdefault("idempotent", name in _IDEMPOTENT)


def _standalone_security(settings: DirectorySettings) -> dict[str, Any]:
    """What the directory's own handlers enforce (``handlers.authorize``), as ``td_security``; only the
    schemes some form uses are defined. ``writes`` ``[]``: nobody can write (no token, not open)."""
    reads = "bearer_sc" if settings.protect_reads else "nosec_sc"
    if settings.open_writes:
        writes = ["nosec_sc"]
    else:
        writes = ["bearer_sc"] if settings.token is not None else []
    schemes: dict[str, Any] = {}
    for name in (reads, *writes):
        if name == "nosec_sc":
            schemes[name] = {"scheme": "nosec"}
        else:
            schemes[name] = {
                "scheme": "bearer", "in": "header", "name": "Authorization", "format": "opaque",
                "description": "The token set in the directory's settings ('token'): "
                               "'Authorization: Bearer <token>'.",
            }
    return {"securityDefinitions": schemes, "security": [reads], "writes": writes}


def _type_things(things: dict[str, Any]) -> None:
    """The TM's ``things`` is a ``oneOf`` (array, or a collection object) with no ``type``, which
    wotpy cannot consume; declare what a read without ``format`` returns, the array."""
    plain = next(s for s in things.pop("oneOf") if s.get("type") == "array")
    things.update(type="array", items=plain["items"])
    things["description"] += (" (an array; with format=collection, an object whose members are"
                              " the TDs: see the Discovery spec)")
