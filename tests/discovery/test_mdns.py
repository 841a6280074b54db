"""mDNS between processes on loopback: the hub's announcements are found and resolved with their TXT
records, and a WoT device in another process is picked up, claimed through the plugin registry,
lost when it leaves and updated (not duplicated) when it comes back on another address.

Zeroconf runs on 127.0.0.1 only (``interfaces=["127.0.0.1"]``): nothing leaves the machine.
"""

from __future__ import annotations

from typing import Any

import pytest
from wott_directory import Directory, DirectoryClient, DirectoryServer, DirectorySettings
from zeroconf import ServiceStateChange
from zeroconf.asyncio import AsyncServiceBrowser, AsyncZeroconf

from wott_hub.discovery import DIRECTORY_SUBTYPE, WOT_TCP, Announcer, Browser, Explorer, FoundThing
from wott_hub.examples import example_device
from wott_hub.plugins import hookimpl
from wott_hub.plugins.model import DeviceConfig, FamilyInfo
from wott_hub.plugins.registry import Registry
from wott_hub.td.builder import build_tactile_td
from wott_hub.td.validate import validate_td

TOKEN = "t0ken"


class ForeignTactilePlugin:
    """A driver plugin that adopts network devices whose TD carries the Tactile vocabulary."""

    @hookimpl
    def wott_hub_families(self) -> list[FamilyInfo]:
        return [FamilyInfo("wot-tactile", "A tactile device that speaks WoT itself",
                           {"type": "object", "properties": {"td_url": {"type": "string"}}})]

    @hookimpl
    def wott_hub_claim_td(self, td: dict[str, Any]) -> DeviceConfig | None:
        if [p for p in validate_td(td, interop=False) if p.rule == "tactile"]:
            return None
        return DeviceConfig(id=td["id"], family="wot-tactile", settings={"td_url": td["base"]})


@pytest.fixture
def registry() -> Registry:
    reg = Registry(entry_points=False)
    reg.register(ForeignTactilePlugin(), "wot-tactile-test")
    return reg


def test_hub_announcements_are_found_by_another_process(wait_for, run, discover):
    # introduction-dns-sd, -service-name, -service-name-directory, -txt-record
    async def scenario():
        directory = Directory(DirectorySettings(token=TOKEN))
        server = await DirectoryServer(directory).start()
        barrel = build_tactile_td(example_device("barrel"), base=server.url)
        client = DirectoryClient(server.url, token=TOKEN)
        await client.put(barrel)
        aiozc = AsyncZeroconf(interfaces=["127.0.0.1"])
        announcer = Announcer(aiozc, addresses=["127.0.0.1"])
        try:
            await announcer.announce_directory("wott-hub-test", server.port)
            await announcer.announce_thing("barrel-1", server.port, f"/things/{barrel['id']}")

            # another process browses (the real `wott-hub discover` command), again if a busy machine
            # made it miss one of ours in its window
            names = {"wott-hub-test", "barrel-1"}
            rows = await discover(names, 3)
            assert names <= rows.keys(), "discover never listed both announced services"
            tdd, thing = rows["wott-hub-test"], rows["barrel-1"]
            assert tdd["type"] == "Directory" and tdd["td_type"] == "Directory"
            assert tdd["txt"] == {"td": "/.well-known/wot", "type": "Directory", "scheme": "http"}
            assert tdd["id"] == directory.own_id and tdd["port"] == server.port
            assert thing["type"] == "Thing" and thing["txt"]["td"] == f"/things/{barrel['id']}"
            assert thing["txt"]["type"] == "Thing" and thing["txt"]["scheme"] == "http"
            assert thing["id"] == barrel["id"] and thing["addresses"] == ["127.0.0.1"]

            # the directory is under the subtype AND the parent type (RFC 6763 7.1)
            other = AsyncZeroconf(interfaces=["127.0.0.1"])
            seen: dict[str, set[str]] = {WOT_TCP: set(), DIRECTORY_SUBTYPE: set()}
            gone: dict[str, set[str]] = {WOT_TCP: set(), DIRECTORY_SUBTYPE: set()}

            def on_change(zeroconf, service_type, name, state_change):
                if state_change is ServiceStateChange.Added:
                    seen[service_type].add(name)
                elif state_change is ServiceStateChange.Removed:
                    gone[service_type].add(name)

            browsers = [AsyncServiceBrowser(other.zeroconf, t, handlers=[on_change]) for t in seen]
            ours = {"wott-hub-test._wot._tcp.local.", "barrel-1._wot._tcp.local."}
            # waits for ours, not for any two: another hub on this machine may announce its own
            tdd_name = "wott-hub-test._wot._tcp.local."
            await wait_for(lambda: ours <= seen[WOT_TCP] and tdd_name in seen[DIRECTORY_SUBTYPE])
            assert seen[DIRECTORY_SUBTYPE] & ours == {tdd_name}  # the Thing is not a directory

            # withdrawing sends goodbyes for both PTRs (of ours: only what we withdrew)
            await announcer.withdraw("wott-hub-test")
            await wait_for(lambda: tdd_name in gone[WOT_TCP] and tdd_name in gone[DIRECTORY_SUBTYPE])
            assert {t: names & ours for t, names in gone.items()} == {WOT_TCP: {tdd_name},
                                                                      DIRECTORY_SUBTYPE: {tdd_name}}
            for b in browsers:
                await b.async_cancel()
            await other.async_close()
        finally:
            await announcer.close()
            await aiozc.async_close()
            client.close()
            await server.stop()

    run(scenario(), 90)


def test_wot_device_is_picked_up_lost_and_updated_on_a_new_address(registry, wait_for, run, device_sim):
    # discoverer-must-support-intros, -fetching, -merge-intros, -td-identify, -track
    events: list[tuple[str, FoundThing]] = []

    def ours(kind):  # any other hub on this machine announces its Things too: only the simulated device
        return lambda f: events.append((kind, f)) if f.id == "urn:example:wot-skin-7" else None

    async def scenario():
        explorer = Explorer(on_found=ours("found"), on_updated=ours("updated"), on_lost=ours("lost"),
                            claim=registry.claim)
        aiozc = AsyncZeroconf(interfaces=["127.0.0.1"])
        browser = Browser(aiozc, explorer.service_added, explorer.service_updated, explorer.service_removed)
        await browser.start()
        sim = await device_sim("127.0.0.1").start()
        try:
            await wait_for(lambda: events)
            kind, found = events[0]
            assert kind == "found" and found.id == "urn:example:wot-skin-7"
            assert found.url == sim.url and found.td["title"] == "skin-7"
            assert found.config == DeviceConfig("urn:example:wot-skin-7", "wot-tactile",
                                                {"td_url": sim.url.removesuffix("td")})
            assert found.sources == {"mdns:skin-7._wot._tcp.local."}

            await sim.stop()  # the device leaves (goodbye packets)
            await wait_for(lambda: len(events) >= 2)
            assert events[1][0] == "lost" and not events[1][1].present

            sim = await device_sim("127.0.0.2").start()  # ... and comes back on another address
            await wait_for(lambda: len(events) >= 3)
            kind, again = events[2]
            assert kind == "updated" and again is found  # the same Thing, not a second one
            assert again.url == sim.url and "127.0.0.2" in again.url
            assert again.td["base"].startswith("http://127.0.0.2:")
            assert again.present and "urn:example:wot-skin-7" in explorer.things
        finally:
            await sim.stop()
            await browser.stop()
            await explorer.close()
            await aiozc.async_close()

    run(scenario(), 120)


def test_things_registered_in_a_known_directory(registry, wait_for, run):
    # discoverer-fetch-tdd, exploration via a directory: listing first, then its events
    events: list[tuple[str, str]] = []

    async def scenario():
        server = await DirectoryServer(Directory(DirectorySettings(token=TOKEN))).start()
        client = DirectoryClient(server.url, token=TOKEN)
        skin = build_tactile_td(example_device("cylinder"), base="http://127.0.0.1:9/")
        skin["id"] = "urn:example:remote-skin"
        await client.put(skin)
        plain = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": "urn:example:lamp", "title": "lamp",
                 "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc"}
        explorer = Explorer(on_found=lambda f: events.append(("found", f.id, f.config)),
                            on_updated=lambda f: events.append(("updated", f.id, f.config)),
                            on_lost=lambda f: events.append(("lost", f.id, f.config)),
                            claim=registry.claim, own_ids={"urn:example:mine"})
        try:
            explorer.add_directory(server.url)
            await wait_for(lambda: events)
            assert events == [("found", "urn:example:remote-skin",
                               DeviceConfig("urn:example:remote-skin", "wot-tactile",
                                            {"td_url": "http://127.0.0.1:9/"}))]
            found = explorer.things["urn:example:remote-skin"]
            assert "registration" not in found.td and found.sources == {f"tdd:{server.url}"}
            await client.put(plain)  # not tactile: found, but no plugin claims it
            await client.put({**plain, "id": "urn:example:mine"})  # the hub's own: skipped
            await client.patch("urn:example:remote-skin", {"title": "renamed"})
            # the explorer fetches an updated TD when told of the change: deleted before it does, the
            # change is gone with the Thing (a 404, logged) and only the deletion is seen
            await wait_for(lambda: len(events) >= 3)
            await client.delete("urn:example:remote-skin")
            await wait_for(lambda: len(events) >= 4)
            assert events[1:] == [("found", "urn:example:lamp", None),
                                  ("updated", "urn:example:remote-skin", events[0][2]),
                                  ("lost", "urn:example:remote-skin", events[0][2])]
            assert explorer.things["urn:example:remote-skin"].td["title"] == "renamed"
        finally:
            await explorer.close()
            client.close()
            await server.stop()

    run(scenario())


def test_txt_records_follow_the_spec():
    from wott_hub.discovery import txt_record

    assert txt_record("/td") == {"td": "/td", "type": "Thing", "scheme": "http"}
    for bad in (("td",), ("/td", "Lamp"), ("/td", "Thing", "coap")):
        with pytest.raises(ValueError):
            txt_record(*bad)
