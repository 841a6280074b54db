"""Hub identity: Thing ids unique per hub and stable across restarts, mDNS names carrying the hub
id, and a hub refusing to take over the id of another live hub in a shared directory."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
from wott_directory import Directory, DirectoryClient, DirectoryServer, DirectorySettings

from wott_hub.config import HubConfig
from wott_hub.errors import ConfigError, Conflict
from wott_hub.hub import Hub
from wott_hub.hub.identity import hub_identity
from wott_hub.network import DirectoryConfig, Registration
from wott_hub.network.discovery import HubDiscovery

TOKEN = "fleet-t0ken"


def test_the_hub_id_is_made_once_kept_beside_the_database_and_unique_per_hub(tmp_path, press_scene, run):
    a = HubConfig(http_port=0, ws_port=None, database=str(tmp_path / "a.db"), devices=(press_scene("pad"),))
    first = hub_identity(a)
    assert Path(first.source) == tmp_path / "a.db.hub-id"
    assert (tmp_path / "a.db.hub-id").read_text().strip() == first.id
    assert hub_identity(a) == first  # a restart: the same id
    other = hub_identity(HubConfig(database=str(tmp_path / "b.db")))
    assert other.id != first.id

    async def scenario() -> None:
        async with Hub(a) as hub:
            assert hub.hub_id == first.id and hub.describe()["hub_id"] == first.id
            assert hub._server.things.get("pad").td["id"] == f"urn:wott-hub:{first.id}:device:pad"
            assert hub._server.things.get("hub").td["id"] == f"urn:wott-hub:{first.id}:hub"
            assert hub.td_url("pad").endswith("/wot/pad")  # URL paths keep the short names

    run(scenario())


def test_a_configured_hub_id_wins_and_a_bad_one_is_refused(tmp_path):
    cfg = HubConfig.from_dict({"hub": {"id": "cell-3", "database": str(tmp_path / "h.db")}})
    ident = hub_identity(cfg)
    assert (ident.id, ident.source) == ("cell-3", "config")
    assert ident.device_id("barrel-1") == "urn:wott-hub:cell-3:device:barrel-1"
    assert not (tmp_path / "h.db.hub-id").exists()
    with pytest.raises(ConfigError, match=r"\[hub\]\.id"):
        HubConfig.from_dict({"hub": {"id": "Cell 3"}})
    (tmp_path / "x.db.hub-id").write_text("not/an id\n")
    with pytest.raises(ConfigError, match="x.db.hub-id"):
        hub_identity(HubConfig(database=str(tmp_path / "x.db")))


class _Port:
    def __init__(self, hub_id: str) -> None:
        self.hub_id = hub_id


def test_mdns_names_carry_the_hub_id_even_when_cut():
    names = set()
    for hub_id in ("cell-1", "cell-2"):
        disc = HubDiscovery.__new__(HubDiscovery)
        disc.hub = _Port(hub_id)
        long_one = disc._instance("a-device-with-a-very-long-name-indeed on wott-hub-of-the-lab")
        assert long_one.endswith(f" {hub_id}") and len(long_one.encode()) <= 55
        names.add(disc._instance("barrel-1 on wott-hub"))
    assert names == {"barrel-1 on wott-hub cell-1", "barrel-1 on wott-hub cell-2"}


def _dead_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_hub_refuses_the_id_of_another_live_hub_and_takes_over_a_dead_ones(tmp_path, press_scene, run):
    async def scenario() -> None:
        server = await DirectoryServer(Directory(DirectorySettings(token=TOKEN))).start()
        fleet = DirectoryClient(server.url, token=TOKEN)

        def cfg(name: str) -> HubConfig:  # three hubs given one id by mistake
            return HubConfig(id="cell-1", name=name, http_port=0, ws_port=None,
                             database=str(tmp_path / f"{name}.db"), devices=(press_scene("pad"),),
                             directory=DirectoryConfig(register_to=(Registration(server.url, TOKEN),),
                                                       ttl_s=30))

        try:
            first = Hub(cfg("first"))
            await first.start()
            try:
                await first.sync_directories()
                tid = first._identity.hub_thing_id
                assert (await fleet.get(tid))["base"] == f"{first.http_url}/"
                second = Hub(cfg("second"))
                with pytest.raises(Conflict, match="cell-1.*taken.*live hub"):
                    await second.start()
                await second.stop()
                assert (await fleet.get(tid))["base"] == f"{first.http_url}/"  # not overwritten
            finally:
                await first.stop()

            # a registration left by a hub that is gone (its base does not answer): taken over
            stale = {**(await _hub_td(first)), "base": f"http://127.0.0.1:{_dead_port()}/",
                     "registration": {"ttl": 30}}
            await fleet.put(stale)
            third = Hub(cfg("third"))
            await third.start()
            try:
                await third.sync_directories()
                assert (await fleet.get(third._identity.hub_thing_id))["base"] == f"{third.http_url}/"
            finally:
                await third.stop()
        finally:
            fleet.close()
            await server.stop()

    run(scenario())


async def _hub_td(hub: Hub) -> dict:
    return dict(hub._server.things.get("hub").td)
