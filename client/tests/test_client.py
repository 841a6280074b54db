"""The client against a live hub and a foreign WoT device: mesh arrays, frames equal to the packets
on the wire, resume with no gap and no duplicate, a directory's devices followed at once, the
blocking API, mDNS names."""

from __future__ import annotations

import asyncio
import json
import time
import uuid
from contextlib import aclosing

import httpx
import numpy as np
from httpx_sse import aconnect_sse
from wott_client import Action, ActionDetails, AsyncClient, Client, Contacts, Frame, InvalidTD, NotFound

DEFORMED = "skinDeformedDetection"


def _td_url(hub, device: str) -> str:
    return hub.url + httpx.get(hub.url + "/wot").json()[device]


def _thing_id(hub, device: str) -> str:
    return httpx.get(_td_url(hub, device)).json()["id"]


def _form(holder: dict, op: str) -> str:
    return next(f["href"] for f in holder["forms"] if op in f["op"] and f["href"].startswith("http"))


def test_mesh_arrays_match_the_hubs_td(hub, run):
    url = _td_url(hub, "cyl")
    td = httpx.get(url).json()
    nodes = httpx.get(_form(td["properties"]["skinNodes"], "readproperty")).json()
    cells = httpx.get(_form(td["properties"]["skinCells"], "readproperty")).json()

    async def scenario():
        async with AsyncClient() as c:
            return await (await c.async_thing(url)).async_mesh()

    mesh = run(scenario())
    assert mesh.nodes.shape == (nodes["numOfNodes"], 3) and mesh.nodes.dtype == np.float64
    for row, n in enumerate(nodes["arrayOfNodes"]):
        assert mesh.node_ids[row] == n["nodeID"]
        assert mesh.nodes[row].tolist() == [n["nodeLocation"][a] for a in "xyz"]
    assert mesh.cells.shape == (cells["numOfCells"], len(cells["arrayOfCells"][0]["connectedNodes"]))
    row_of = {int(i): r for r, i in enumerate(mesh.node_ids)}
    for row, cell in enumerate(cells["arrayOfCells"]):
        assert mesh.cells[row].tolist() == [row_of[i] for i in cell["connectedNodes"]]


def test_frames_are_dense_fields_equal_to_the_packets(hub, run, wait_for):
    """The client takes the multiplexed stream; a raw SSE reader of the one-event stream is the truth."""
    url = _td_url(hub, "pad")
    td = httpx.get(url).json()
    single = _form(td["events"][DEFORMED], "subscribeevent")
    assert any("subscribeallevents" in f["op"] for f in td["forms"])  # so the client multiplexes
    raw: dict[str, dict] = {}

    async def reference():
        async with httpx.AsyncClient(timeout=None) as h, aconnect_sse(h, "GET", single) as es:
            async for ev in es.aiter_sse():
                raw[ev.id] = json.loads(ev.data)

    async def scenario():
        ref = asyncio.ensure_future(reference())
        await asyncio.sleep(0.3)
        frames, others = [], []
        async with AsyncClient() as c:
            thing = await c.async_thing(url)
            mesh = await thing.async_mesh()
            async with aclosing(thing.async_frames()) as items:
                async for item in items:
                    (frames if isinstance(item, Frame) else others).append(item)
                    released = [f for f in frames if f.indices.size and not f.intensity.any()]
                    if len(frames) >= 40 and released:
                        break
        await wait_for(lambda: frames[-1].event_id in raw, what="reference stream caught up")
        ref.cancel()
        return mesh, frames, others

    mesh, frames, others = run(scenario())
    assert {type(o) for o in others} <= {Contacts, Action, ActionDetails}
    assert any(isinstance(o, Contacts) for o in others)
    compared = 0
    for f in frames:
        assert f.thing == td["id"] and f.intensity.shape == (len(mesh),)
        packet = raw.get(f.event_id)
        if packet is None:  # before the reference connected
            continue
        compared += 1
        sent = {d["deformedNodeID"]: d["deformedNodeIntensity"] for d in packet["arrayOfDeformedNodes"]}
        got = {int(mesh.node_ids[r]): float(f.intensity[r]) for r in np.flatnonzero(f.intensity)}
        assert got == {k: v for k, v in sent.items() if v != 0}
        assert sorted(int(mesh.node_ids[r]) for r in f.indices) == sorted(sent)
        assert f.timestamp_ns == packet["timeStamp"]
    assert compared >= 20


def test_resume_after_a_dropped_connection_has_no_gap_and_no_duplicate(hub, run, wait_for, proxy):
    """The client reaches the hub through a relay the test cuts twice; a direct reader is the truth."""
    url = _td_url(hub, "pad")
    td = httpx.get(url).json()
    events_url = _form(td, "subscribeallevents")
    truth: list[int] = []

    async def reference():
        async with httpx.AsyncClient(timeout=None) as h, aconnect_sse(h, "GET", events_url) as es:
            async for ev in es.aiter_sse():
                if ev.event in (DEFORMED, "actionDetection", "actionDetails"):  # what the client maps
                    truth.append(int(ev.id))

    async def scenario():
        ref = asyncio.ensure_future(reference())
        host, port = hub.url.removeprefix("http://").split(":")
        relay = await proxy(host, int(port)).start()
        relayed = json.loads(json.dumps(td).replace(hub.url, f"http://127.0.0.1:{relay.port}"))
        seen: list[int] = []
        async with AsyncClient() as c:
            thing = c.thing_from_td(relayed)
            async with aclosing(thing.async_frames(contacts=False)) as items:
                async for item in items:
                    assert isinstance(item, Frame | Action | ActionDetails)
                    seen.append(int(item.event_id))
                    if len(seen) in (15, 45):
                        relay.drop(pause_s=0.4)  # events keep coming meanwhile: the resume replays them
                    if len(seen) >= 90:
                        break
            reconnects, drops = thing.streams[0].reconnects, relay.drops
        await relay.stop()
        await wait_for(lambda: truth and truth[-1] >= seen[-1], what="reference stream caught up")
        ref.cancel()
        return seen, reconnects, drops

    seen, reconnects, drops = run(scenario())
    assert drops == 2 and reconnects >= 2
    assert seen == sorted(set(seen))  # no duplicate
    assert seen == [i for i in truth if seen[0] <= i <= seen[-1]]  # no gap


def test_a_foreign_device_by_mdns_name_and_its_outage(device_sim, run, wait_for):
    """Another server's TD (one SSE stream per event, named messages), found by its mDNS name; it
    closes its streams and refuses new ones for a while: every packet still arrives once, in order."""
    name = f"client-test-{uuid.uuid4().hex[:8]}"

    async def scenario():
        sim = await device_sim(name).start()
        try:
            async with AsyncClient(mdns_interfaces=["127.0.0.1"]) as c, httpx.AsyncClient(timeout=30) as h:
                thing = await c.async_thing(name)
                assert thing.url == sim.url and thing.id == f"urn:example:{name}"
                mesh = await thing.async_mesh()
                got: list[Frame] = []

                async def consume():  # from the start of the device's memory: nothing to race
                    async for f in thing.async_frames(contacts=False, actions=False, last_event_id="0"):
                        got.append(f)

                task = asyncio.ensure_future(consume())
                sent = (await h.post(sim.base + "press")).json()
                await wait_for(lambda: len(got) >= len(sent), what="first press received")
                await h.post(sim.base + "outage?seconds=1")
                sent += (await h.post(sim.base + "press")).json()  # during the outage
                await wait_for(lambda: len(got) >= len(sent), what="second press received after the outage")
                await asyncio.sleep(0.2)
                task.cancel()
                return mesh, sent, got, thing.streams[0].reconnects
        finally:
            await sim.stop()

    mesh, sent, got, reconnects = run(scenario())
    assert reconnects >= 1
    assert [f.event_id for f in got] == [str(s["id"]) for s in sent]
    for f, s in zip(got, sent, strict=True):
        expected = np.zeros(len(mesh))
        for d in s["packet"]["arrayOfDeformedNodes"]:
            expected[mesh.index_of([d["deformedNodeID"]])] = d["deformedNodeIntensity"]
        assert np.array_equal(f.intensity, expected)


def test_an_unknown_mdns_name_is_not_found(run):
    async def scenario():
        async with AsyncClient(mdns_interfaces=["127.0.0.1"]) as c:
            try:
                await c.async_thing(f"nobody-{uuid.uuid4().hex[:8]}")
            except NotFound as e:
                return str(e)
        return None

    assert "nobody answers" in (run(scenario()) or "")


def test_following_a_directorys_devices(hub, run):
    async def scenario():
        async with AsyncClient() as c:
            directory = await c.async_directory(hub.url, page_size=1)  # paged: Link rel="next" followed
            tds = await directory.async_tds()
            things = await directory.async_things()
            found = await directory.async_search("$[?@.title=='cyl'].id")
            frames: dict[str, int] = {}
            async with aclosing(directory.async_follow(contacts=False)) as items:
                async for thing, item in items:
                    if isinstance(item, Frame):
                        frames[thing.id] = frames.get(thing.id, 0) + 1
                    if len(frames) == 2 and min(frames.values()) >= 10:
                        break
            return tds, things, found, frames

    tds, things, found, frames = run(scenario())
    listed = {td["id"] for td in httpx.get(hub.url + "/things").json()}
    assert {td["id"] for td in tds} == listed and len(tds) == len(listed) >= 3
    assert {t.id for t in things} == {_thing_id(hub, "pad"), _thing_id(hub, "cyl")}
    assert found == [_thing_id(hub, "cyl")]
    assert set(frames) == {t.id for t in things}


def test_the_blocking_api(hub):
    url = _td_url(hub, "cyl")
    with Client() as c:
        thing = c.thing(url)
        mesh = thing.mesh()
        assert thing.read_property("skinShape")["shapeType"] == "cylinder"
        t0 = time.monotonic()
        frames = []
        for item in thing.frames(contacts=False, actions=False):
            frames.append(item)
            if len(frames) == 20:
                break
        assert time.monotonic() - t0 < 30
        assert all(isinstance(f, Frame) and f.intensity.shape == (len(mesh),) for f in frames)
        ids = [int(f.event_id) for f in frames]
        assert ids == sorted(set(ids))
        followed = []
        for thing_, _item in c.directory(hub.url).follow(contacts=False, actions=False):
            followed.append(thing_.id)
            if len(set(followed)) == 2:
                break
        assert set(followed) == {_thing_id(hub, "pad"), _thing_id(hub, "cyl")}


def test_a_td_that_is_not_tactile_is_refused(hub, run):
    async def scenario():
        async with AsyncClient() as c:
            try:
                await c.async_thing(_td_url(hub, "hub"))
            except InvalidTD as e:
                return str(e)
        return None

    assert "not a Tactile Thing" in (run(scenario()) or "")


def test_the_hubs_own_mdns_names_resolve(run, wait_for):
    """A hub announcing on 127.0.0.1: the client finds a Thing by the instance name a browser sees
    (``pad on <hub name> ...``)."""
    from zeroconf.asyncio import AsyncServiceBrowser, AsyncZeroconf

    from wott_hub.config import HubConfig
    from wott_hub.network import DiscoveryConfig

    from .conftest import HELPERS

    name = f"client-test-{uuid.uuid4().hex[:8]}"
    cfg = HubConfig(name=name, http_port=0, ws_port=0, history=False, devices=(HELPERS._press_scene("pad"),),
                    discovery=DiscoveryConfig(mdns=True, browse=False, interfaces=("127.0.0.1",)))
    h = HELPERS.HubThread(cfg).start()

    async def scenario():
        names: set[str] = set()
        aiozc = AsyncZeroconf(interfaces=["127.0.0.1"])
        browser = AsyncServiceBrowser(aiozc.zeroconf, "_wot._tcp.local.",
                                      handlers=[lambda name, **_: names.add(name)])

        def announced() -> str | None:
            return next((n for n in names if n.startswith(f"pad on {name}")), None)

        try:
            await wait_for(announced, timeout=30,
                           what=lambda: f"the hub's announcement (seen: {sorted(names)})")
        finally:
            await browser.async_cancel()
            await aiozc.async_close()
        async with AsyncClient(mdns_interfaces=["127.0.0.1"]) as c:
            return await c.async_thing(announced())

    try:
        thing = run(scenario())
        pad = _thing_id(h, "pad")
    finally:
        h.stop()
    assert thing.id == pad and thing.url == h.url + "/wot/pad"


def test_a_directory_by_its_mdns_name(hub, run):
    """A Directory service (``_directory._sub._wot._tcp``, TXT type=Directory) announced by the test
    for the session hub's directory: the client reaches the directory's API by that name."""
    from zeroconf.asyncio import AsyncZeroconf

    from wott_hub.discovery import Announcer

    name = f"client-test-dir-{uuid.uuid4().hex[:8]}"
    port = int(hub.url.rsplit(":", 1)[1])

    async def scenario():
        aiozc = AsyncZeroconf(interfaces=["127.0.0.1"])
        announcer = Announcer(aiozc, addresses=["127.0.0.1"])
        try:
            await announcer.announce_directory(name, port)
            async with AsyncClient(mdns_interfaces=["127.0.0.1"]) as c:
                directory = await c.async_directory(name)
                try:
                    await c.async_thing(name)
                except NotFound as e:
                    refused = str(e)
                return directory.url, await directory.async_things(), refused
        finally:
            await announcer.close()
            await aiozc.async_close()

    url, things, refused = run(scenario())
    assert url == f"http://127.0.0.1:{port}/"
    assert {t.id for t in things} == {_thing_id(hub, "pad"), _thing_id(hub, "cyl")}
    assert "is a Directory, not a Thing" in refused
