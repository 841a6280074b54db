"""wotpy adapters: same answers as wotpy, without the per-Thing and per-lookup costs."""

from __future__ import annotations

import asyncio

import httpx
import pytest
from wotpy.wot.dictionaries.thing import ThingFragment
from wotpy.wot.exposed.thing import ExposedThing
from wotpy.wot.servient import Servient
from wotpy.wot.thing import Thing
from wotpy.wot.wot import WoT

from wott_hub.events.plane import EventPlane
from wott_hub.examples import example_device
from wott_hub.servient import FastThing, HubServer, IndexedExposedThingSet, ServedThing
from wott_hub.td.builder import build_tactile_td, static_property_values
from wott_hub.td.validate import validate_td


def _fragment(title: str) -> ThingFragment:
    return ThingFragment({
        "@context": "https://www.w3.org/2019/wot/td/v1", "id": f"urn:test:{title}", "title": title,
        "security": "nosec_sc", "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}},
        "properties": {"level": {"type": "number", "observable": True}},
        "events": {"bump": {"data": {"type": "string"}}},
    })


def test_fast_thing_answers_like_wotpy_thing():
    for title in ("Pad 1", "barrel-1", "Ünïcode Thing"):
        slow, fast = Thing(thing_fragment=_fragment(title)), FastThing(_fragment(title))
        assert (fast.title, fast.id, fast.url_name) == (slow.title, slow.id, slow.url_name)
        assert list(fast.properties) == list(slow.properties) == ["level"]
        assert fast.thing_fragment.to_dict() == slow.thing_fragment.to_dict()


def test_indexed_set_finds_by_title_url_name_and_interaction():
    servient = Servient(catalogue_port=None)
    things = IndexedExposedThingSet()
    exposed = [ExposedThing(servient, FastThing(_fragment(f"Thing {i}"))) for i in range(50)]
    for e in exposed:
        things.add(e)
    e7 = exposed[7]
    assert things.find_by_thing_title("Thing 7") is e7
    assert things.find_by_thing_title("thing-7") is e7  # the URL-safe name, as wotpy allows
    assert things.find_by_interaction(e7.thing.properties["level"]) is e7
    assert things.contains(e7) and len(list(things.exposed_things)) == 50
    with pytest.raises(ValueError):
        things.add(ExposedThing(servient, FastThing(_fragment("thing 7"))))  # same URL name
    things.remove("thing-7")
    assert things.find_by_thing_title("Thing 7") is None and not things.contains(e7)
    with pytest.raises(ValueError):
        things.remove("Thing 7")


def _serve(n: int):
    plane = EventPlane()
    server = HubServer(plane, http_port=0, ws_port=0)
    layout = server.bind()
    desc = example_device("flat")
    values = static_property_values(desc)
    for i in range(n):
        tid = f"pad-{i}"
        td = build_tactile_td(desc, base=f"{layout.http_base}/", forms=layout.factory(tid),
                              context_url=layout.context_url)
        td["id"], td["title"], td["forms"] = f"urn:test:{tid}", f"Pad {i}", layout.thing_forms(tid)
        plane.add_stream(tid, record=False)
        server.expose(ServedThing.create(tid, td, values))
    return server


def test_many_things_on_one_servient_each_served_with_its_own_td():
    async def main():
        server = _serve(200)
        await server.start()
        try:
            async with httpx.AsyncClient() as c:
                catalogue = (await c.get(f"{server.layout.http_base}/wot")).json()
                assert len(catalogue) == 200
                for i in (0, 57, 199):
                    td = (await c.get(server.td_url(f"pad-{i}"))).json()
                    assert td["title"] == f"Pad {i}" and validate_td(td) == []
                    assert td["events"]["skinDeformedDetection"]["forms"][0]["href"].startswith(
                        f"{server.layout.http_base}/wot/pad-{i}/")
            assert len(server.servient._enabled_exposed_thing_titles) == 200
        finally:
            await server.stop()

    asyncio.run(main())


def test_wotpy_catalogue_port_serves_the_cached_tds():
    async def main():
        plane = EventPlane()
        server = HubServer(plane, http_port=0, ws_port=0)
        import socket

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        server.servient._catalogue_port = port
        layout = server.bind()
        td = build_tactile_td(example_device("flat"), base=f"{layout.http_base}/", forms=layout.factory("p"))
        plane.add_stream("p", record=False)
        server.expose(ServedThing.create("p", td))
        await server.start()
        try:
            async with httpx.AsyncClient() as c:
                assert (await c.get(f"http://127.0.0.1:{port}/")).json() == {"p": "/wot/p"}
                assert (await c.get(f"http://127.0.0.1:{port}/p")).json() == td
        finally:
            await server.stop()

    asyncio.run(main())


def test_a_thing_produced_directly_with_wotpy_still_works_over_websocket():
    """Things not served by the hub fall back to wotpy's own WebSocket handlers."""

    async def main():
        server = HubServer(EventPlane(), http_port=0, ws_port=0)
        server.bind()
        await server.start()
        try:
            wot = WoT(servient=server.servient)
            exposed = wot.produce(_fragment("plain"))
            await exposed.properties["level"].write(4.5)
            exposed.expose()
            td = {
                "@context": "https://www.w3.org/2019/wot/td/v1", "title": "plain", "id": "urn:test:plain",
                "security": "nosec_sc", "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}},
                "properties": {"level": {"type": "number", "forms": [
                    {"href": f"{server.layout.ws_base}/plain", "op": ["readproperty"]}]}},
            }
            import json

            client = WoT(servient=Servient(catalogue_port=None)).consume(json.dumps(td))
            return await client.read_property("level")
        finally:
            await server.stop()

    assert asyncio.run(main()) == 4.5
