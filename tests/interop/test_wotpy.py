"""wotpy 0.18, the Python WoT client, against the demo hub: every TD it serves consumed, every
property read over HTTP, every event of every live Thing and ``contactInformation`` received over
wotpy's WebSocket binding, the hub Thing's actions invoked, a write refused.

Before this issue ``wot.consume`` raised ``ValueError: Unknown type: None`` on
the hub Thing (the replay action's ``from``/``to`` had no ``type``) and on the
directory's TD (its ``things`` property).
"""

from __future__ import annotations

import asyncio
import json

import httpx
import pytest


def _served(url: str) -> dict[str, dict]:
    """Every TD the hub serves: its catalogue, its directory's own TD, each TD the directory lists."""
    with httpx.Client(timeout=10) as c:
        tds = {f"wot:{i}": c.get(f"{url}{path}").json() for i, path in c.get(f"{url}/wot").json().items()}
        tds["directory"] = c.get(f"{url}/.well-known/wot").json()
        tds.update({f"things:{td['id']}": td for td in c.get(f"{url}/things").json()})
    return tds


@pytest.fixture(scope="module")
def session(fleet, scripted_press, tare_every_device) -> dict:
    """One wotpy client session against the hub; what it got, for the tests to look at. The replay's
    range ends with a tare, whatever ran before this module (its deviceAction comes 10 s in)."""
    from wotpy.wot.servient import Servient
    from wotpy.wot.wot import WoT

    async def main() -> dict:
        wot = WoT(servient=Servient(catalogue_port=None))
        hub = await wot.consume_from_url(f"{fleet.url}/wot/hub")
        device = next(d["id"] for d in await hub.read_property("devices") if d["recorded"])
        await asyncio.to_thread(tare_every_device)
        replay = await hub.invoke_action("replay", {"device": device, "from": "-20s", "speed": 2,
                                                    "loop": True})
        tds = await asyncio.to_thread(_served, fleet.url)  # the replay Thing among them
        out = {"device": device, "replay": replay, "tds": tds, "reads": {}, "protocols": {}, "got": {}}
        reads, protocols, got = out["reads"], out["protocols"], out["got"]

        async def read(thing, name: str, href: str) -> None:
            reads[href] = await asyncio.wait_for(thing.read_property(name), 20)

        subs = []
        for key, td in tds.items():
            thing = wot.consume(json.dumps(td))
            pending = []
            for name, prop in td.get("properties", {}).items():
                protocols[(key, name)] = wot.servient.select_client(thing.td, name).protocol
                href = prop["forms"][0]["href"]  # a Thing listed twice (catalogue, directory): read once
                if href not in reads:
                    reads[href] = None
                    pending.append(read(thing, name, href))
            await asyncio.gather(*pending)
            if not key.startswith("wot:"):
                continue  # the same Things again (events below), or the directory (SSE only)
            for name in td.get("events", {}):
                protocols[(key, name)] = wot.servient.select_client(thing.td, name).protocol
                got[(key, name)] = received = []
                subs.append(thing.events[name].subscribe(on_next=lambda ev, to=received: to.append(ev.data)))
            if "contactInformation" in td["properties"]:
                got[(key, "contactInformation")] = changes = []
                subs.append(thing.properties["contactInformation"].subscribe(
                    on_next=lambda ev, to=changes: to.append(ev.data.value)))
        await asyncio.sleep(0.5)  # the subscriptions are sent as the sockets open
        await asyncio.to_thread(scripted_press, "late-wotpy")  # the hub Thing's healthChange
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 20
        while any(not v for v in got.values()) and loop.time() < deadline:
            await asyncio.sleep(0.1)
        for s in subs:
            s.dispose()
        device_thing = wot.consume(json.dumps(tds[f"wot:{device}"]))
        try:
            await device_thing.write_property("skinShape", {"shapeType": "barrel"})
        except Exception as e:  # noqa: BLE001 -- whatever wotpy raises, the test looks at it
            out["write"] = str(e)
        out["stop"] = await hub.invoke_action("stopReplay", {"thing": replay["thing"]})
        return out

    return asyncio.run(main())


def test_wotpy_consumes_every_td_and_reads_every_property_over_http(session):
    from wotpy.protocols.enums import Protocols

    tds, reads, protocols = session["tds"], session["reads"], session["protocols"]

    def value(key: str, name: str):
        return reads[tds[key]["properties"][name]["forms"][0]["href"]]

    assert f"wot:{session['replay']['thing']}" in tds and "wot:hub" in tds and "directory" in tds
    for key, td in tds.items():
        for name in td.get("properties", {}):
            assert protocols[(key, name)] == Protocols.HTTP, (key, name)
            assert value(key, name) is not None, (key, name)
    listed = {td["id"] for td in value("directory", "things")}
    assert listed == {td["id"] for k, td in tds.items() if k.startswith("things:")}
    replay, device = session["replay"]["thing"], session["device"]
    assert value(f"wot:{replay}", "skinShape") == value(f"wot:{device}", "skinShape")
    assert "shapeType" in value(f"wot:{device}", "skinShape")


def test_wotpy_receives_every_event_over_websocket_and_observes_contacts(session):
    from wotpy.protocols.enums import Protocols

    got, protocols = session["got"], session["protocols"]
    live = {k for k in session["tds"] if k.startswith("wot:")}
    assert {k for k, _ in got} == live
    for (key, name), data in got.items():
        # wotpy's own choice: events over WebSocket; properties, observed too, over HTTP (it
        # long-polls the observe form, which answers one JSON value per request without SSE)
        expected = Protocols.HTTP if name == "contactInformation" else Protocols.WEBSOCKETS
        assert protocols[(key, name)] == expected, (key, name)
        assert data, f"no {name} of {key} through wotpy"
    assert all("numOfContacts" in v for (_, n), values in got.items() if n == "contactInformation"
               for v in values)


def test_wotpy_invokes_the_hub_things_actions_and_is_refused_a_write(session):
    replay = session["replay"]
    assert replay["thing"] == f"replay-{session['device']}" and replay["after"] > 0
    assert session["stop"]["stopped"] is True and session["stop"]["emitted"] > 0
    assert "405" in session["write"]
