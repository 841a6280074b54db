"""Every hub serves a W3C WoT TDD listing its Things: a real hub on 127.0.0.1, its directory at the
host root, fed by what the hub exposes and removes, in the hub's own database."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

import httpx
import pytest
from wott_directory import DirectoryClient, ProblemError
from wott_directory.validation import check_td

from wott_hub.config import HubConfig
from wott_hub.hub import Hub
from wott_hub.network import DirectoryConfig

LAMP = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "id": "urn:example:lamp", "title": "lamp",
        "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}}, "security": "nosec_sc"}


async def listing(hub: Hub) -> dict[str, dict[str, Any]]:
    await hub.sync_directories()
    async with httpx.AsyncClient(timeout=10) as http:
        resp = await http.get(f"{hub.http_url}/things")
    assert resp.status_code == 200 and resp.headers["Content-Type"] == "application/ld+json"
    return {td["id"]: td for td in resp.json()}


def test_the_hub_lists_every_thing_it_serves_and_follows_adds_and_removals(tmp_path, press_scene, run):
    db = str(tmp_path / "hub.db")

    async def first_run() -> None:
        hub = Hub(HubConfig(name="lab", http_port=0, ws_port=0, database=db, history_batch_ms=10,
                            devices=(press_scene("pad"), press_scene("cyl", "cylinder"))))
        await hub.start()
        client = DirectoryClient(f"{hub.http_url}/")
        try:
            tds = await listing(hub)
            own = hub._network.directory.directory.own_id
            served = {t.td["id"]: t.td for t in hub._server.things}
            assert set(tds) == {*served, own}
            assert set(served) == {hub._identity.device_id("pad"), hub._identity.device_id("cyl"),
                                   hub._identity.hub_thing_id}
            for tid, td in served.items():
                listed = tds[tid]
                assert {k: v for k, v in listed.items() if k not in ("@context", "registration")} == \
                    {k: v for k, v in td.items() if k != "@context"}
                assert "expires" not in listed["registration"]  # the hub's own: no ttl, it is the hub's
                check_td(td)  # what the directory validates (TD 1.1 and Discovery schemas)
            wk = (await client.directory_description())
            assert wk["base"] == f"{hub.http_url}/" and wk["id"] == own and wk["title"] == "lab directory"
            found = await client.search('$[?@["tac:family"]=="scene"].id')
            assert sorted(found) == [hub._identity.device_id("cyl"), hub._identity.device_id("pad")]

            async with client.events() as stream:
                await hub.remove_device("pad")  # removed from the hub: gone from the directory
                ev = await stream.next(10)
                assert (ev.type, ev.data) == ("thing_deleted", {"id": hub._identity.device_id("pad")})
                assert hub._identity.device_id("pad") not in await listing(hub)
                await hub.add_device(press_scene("pad2"))
                ev = await stream.next(10)
                assert (ev.type, ev.data) == ("thing_created", {"id": hub._identity.device_id("pad2")})
                out = await hub._replay.replay("cyl", speed=0)  # replay Things too
                ev = await stream.next(10)
                assert (ev.type, ev.data) == ("thing_created", {"id": hub._identity.replay_id("cyl")})
                await hub._replay.stop(out["thing"])
                ev = await stream.next(10)
                assert (ev.type, ev.data) == ("thing_deleted", {"id": hub._identity.replay_id("cyl")})

            # no token configured and the hub on loopback: loopback clients register freely
            await client.put(LAMP)
            assert "urn:example:lamp" in await listing(hub)
        finally:
            client.close()
            await hub.stop()

    async def second_run() -> None:
        """Same database, a different fleet: the TDs of the previous run's Things are gone, the
        lamp (registered by someone else) is still there."""
        hub = Hub(HubConfig(name="lab", http_port=0, ws_port=0, database=db,
                            devices=(press_scene("cyl", "cylinder"),)))
        await hub.start()
        try:
            tds = await listing(hub)
            assert set(tds) - {hub._network.directory.directory.own_id} == {
                hub._identity.device_id("cyl"), hub._identity.hub_thing_id, "urn:example:lamp"}
        finally:
            await hub.stop()

    run(first_run())
    run(second_run())


def test_writes_need_the_token_when_one_is_set_and_a_hub_without_history_keeps_it_in_memory(press_scene,
                                                                                              run):
    async def scenario() -> None:
        hub = Hub(HubConfig(http_port=0, ws_port=0, history=False, devices=(press_scene("pad"),),
                            directory=DirectoryConfig(token="s3cret")))
        await hub.start()
        anonymous = DirectoryClient(f"{hub.http_url}/")
        trusted = DirectoryClient(f"{hub.http_url}/", token="s3cret")
        try:
            assert hub._history.engine is None and hub._identity.device_id("pad") in await listing(hub)
            with pytest.raises(ProblemError) as refused:  # a write without the token is not accepted
                await anonymous.put(LAMP)
            assert refused.value.status == 401
            assert await trusted.put(LAMP) is True
            wk = await anonymous.directory_description()
            assert wk["actions"]["createThing"]["forms"][0]["security"] == ["bearer_sc"]
        finally:
            anonymous.close()
            trusted.close()
            await hub.stop()

    run(scenario())


def test_a_directory_request_during_start_up_waits_for_the_directory(tmp_path, press_scene, run):
    """The TDs are served before the database opens; /things asked meanwhile answers once the
    directory is there, with every Thing in it; a registration sent meanwhile is applied."""
    async def scenario() -> None:
        hub = Hub(HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "h.db"),
                            devices=(press_scene("pad"),)))
        opened = asyncio.Event()
        real = hub._history.open

        def slow_open() -> None:
            import time

            opened.set()
            time.sleep(0.5)
            real()

        hub._history.open = slow_open
        start = asyncio.ensure_future(hub.start())
        await opened.wait()
        async with httpx.AsyncClient(timeout=10) as http:
            put, resp = await asyncio.gather(  # a write (with its body) and a read, both held
                http.put(f"{hub.http_url}/things/urn:example:lamp", json=LAMP),
                http.get(f"{hub.http_url}/things"))
        try:
            assert put.status_code == 201
            assert resp.status_code == 200
            assert hub._identity.device_id("pad") in {td["id"] for td in resp.json()}
        finally:
            await start
            with contextlib.suppress(Exception):
                await hub.stop()

    run(scenario())
