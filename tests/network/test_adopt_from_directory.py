"""A hub adopts the tactile devices registered in a directory it knows ([discovery] directories):
hub A registers its Things into a fleet directory, hub B explores that directory and re-exposes A's
device; when A removes it, B's copy is reported disconnected. Without ``adopt_hub_things`` B leaves
another hub's Things to that hub."""

from __future__ import annotations

from typing import Any

from wott_directory import Directory, DirectoryServer, DirectorySettings

from wott_hub.config import HubConfig
from wott_hub.hub import Hub
from wott_hub.network import DirectoryConfig, DiscoveryConfig, Registration

TOKEN = "t"


def test_adopted_from_a_known_directory_and_lost_when_deleted_there(press_scene, wait_for, run):
    async def scenario() -> Any:
        server = await DirectoryServer(Directory(DirectorySettings(token=TOKEN))).start()
        a = Hub(HubConfig(name="a", http_port=0, ws_port=0, history=False, devices=(press_scene("pad"),),
                          directory=DirectoryConfig(register_to=(Registration(server.url, TOKEN),))))
        b = Hub(HubConfig(name="b", http_port=0, ws_port=0, history=False, directory=DirectoryConfig(
            enabled=False), discovery=DiscoveryConfig(mdns=False, browse=False, directories=(server.url,),
                                                      adopt_hub_things=True)))
        shy = Hub(HubConfig(name="shy", http_port=0, ws_port=0, history=False, directory=DirectoryConfig(
            enabled=False), discovery=DiscoveryConfig(mdns=False, browse=False, directories=(server.url,))))
        await a.start()
        await a.sync_directories()
        await b.start()
        await shy.start()
        try:
            await wait_for(lambda: "pad" in b.devices and b.devices["pad"].health_state()[0] == "ok",
                           what="b adopts a's pad")
            assert b._network.discovery.adopted == {a._identity.device_id("pad"): "pad"}
            assert b.devices["pad"].family == "wot-remote"
            assert b.devices["pad"].driver.td["base"] == f"{a.http_url}/"
            assert a._identity.hub_thing_id in b._network.discovery.unclaimed  # found, not tactile
            assert shy.devices == {} and shy._network.discovery.unclaimed == {}  # another hub's Things

            await a.remove_device("pad")  # deleted from the fleet directory: b's copy is disconnected
            await wait_for(lambda: b.devices["pad"].health_state()[0] == "disconnected", what="lost")
            assert "pad" in b.devices
        finally:
            await shy.stop()
            await b.stop()
            await a.stop()
            await server.stop()

    run(scenario(), 60)
