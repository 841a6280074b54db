"""Served Things: encoded values spliced into objects, and the server telling who comes and goes."""

from __future__ import annotations

import json

import pytest

from wott_hub.events.plane import EventPlane
from wott_hub.examples import example_device
from wott_hub.servient import HubServer, ServedThing
from wott_hub.td.builder import build_tactile_td, static_property_values


def test_static_json_and_read_all_splice_the_encoded_values():
    td = {"title": "t", "properties": {"mesh": {}, "note": {}, "live": {}, "unset": {}}}
    values = {"mesh": [[0.1, 2.5e-7], [3, -1]], "note": {"text": "déjà \"vu\"\n", "none": None}}
    served = ServedThing.create("x", td, values, {"live": lambda: "[1,2]"})
    assert json.loads(served.static_json()) == values
    assert json.loads(served.read_all()) == {**values, "live": [1, 2], "unset": None}
    assert ServedThing.create("y", td).static_json() == "{}"


def test_the_server_tells_its_listeners_what_it_serves_and_removes():
    plane = EventPlane()
    server = HubServer(plane, http_port=0, ws_port=0)
    layout = server.bind()
    exposed, removed = [], []
    server.on_expose.append(exposed.append)
    server.on_remove.append(removed.append)
    desc = example_device("flat")
    td = build_tactile_td(desc, base=f"{layout.http_base}/", forms=layout.factory("p"))
    plane.add_stream("p", record=False)
    served = ServedThing.create("p", td, static_property_values(desc))
    server.expose(served)
    assert exposed == [served] and removed == []
    with pytest.raises(ValueError):  # refused: nobody is told
        server.expose(ServedThing.create("p", td))
    assert exposed == [served]
    server.remove("nothing-of-that-id")
    assert removed == []
    server.remove("p")
    assert removed == [served] and "p" not in server.things.by_id
