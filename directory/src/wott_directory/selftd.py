"""The directory's own TD, instantiated from the normative Thing Model (``directory.tm.json``).

What the TM leaves optional we declare only if we serve it: everything but the
XPath and SPARQL searches. Every form states its ``op`` and
``htv:methodName`` (clients pick forms by them), and the security of each form
follows the settings: reads open unless ``protect_reads``, writes behind the
bearer token unless ``open_writes``.
"""

from __future__ import annotations

import copy
from typing import Any

from .registration import DISCOVERY_CONTEXT
from .settings import DirectorySettings
from .validation import load_data

__all__ = ["WRITE_ACTIONS", "directory_td"]

WRITE_ACTIONS = ("createThing", "createAnonymousThing", "updateThing", "partiallyUpdateThing",
                 "deleteThing")
_UNSERVED = ("searchXPath", "searchSPARQL")
_OPS = {"properties": "readproperty", "actions": "invokeaction", "events": "subscribeevent"}


def directory_td(settings: DirectorySettings, version: str = "0.1.0") -> dict[str, Any]:
    tm = copy.deepcopy(load_data("directory.tm.json"))
    td: dict[str, Any] = {
        "@context": ["https://www.w3.org/2022/wot/td/v1.1", DISCOVERY_CONTEXT],
        "@type": "ThingDirectory",
        "id": settings.own_id,
        "title": settings.title,
        "description": "W3C WoT Thing Description Directory (WoT Discovery HTTP API) of wott-hub.",
        "version": {"instance": version, "model": tm["version"]["model"]},
        "base": settings.base_url,
    }
    schemes: dict[str, Any] = {"nosec_sc": {"scheme": "nosec"}}
    if settings.token is not None or not settings.open_writes or settings.protect_reads:
        schemes["bearer_sc"] = {
            "scheme": "bearer", "in": "header", "name": "Authorization", "format": "opaque",
            "description": "The static token of the directory's configuration: "
                           "'Authorization: Bearer <token>'.",
        }
    read_security = "bearer_sc" if settings.protect_reads else "nosec_sc"
    write_security = "nosec_sc" if settings.open_writes else "bearer_sc"
    td["securityDefinitions"] = schemes
    td["security"] = [read_security]

    td["properties"] = tm["properties"]
    td["properties"]["things"]["readOnly"] = True
    td["actions"] = {k: v for k, v in tm["actions"].items() if k not in _UNSERVED}
    td["events"] = tm["events"]
    for kind, op in _OPS.items():
        for name, affordance in td[kind].items():
            for form in affordance["forms"]:
                form.setdefault("op", op)
                form.setdefault("htv:methodName", "GET")
                if kind == "actions" and name in WRITE_ACTIONS:
                    form["security"] = [write_security]
                form["href"] = form["href"].lstrip("/")  # relative to base, which may have a path
                response = form.get("response")
                if isinstance(response, dict) and "contentType" not in response:
                    # TD 1.1 requires it; these responses (201/204) have an empty body
                    response["contentType"] = "text/plain"
    return td
