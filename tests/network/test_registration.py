"""A hub registers its Things into other directories with a ttl and keeps them fresh: a clean stop
deletes them, a hub that dies (SIGKILL) leaves them to expire. The fleet directory is a real
standalone directory server on 127.0.0.1."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
from pathlib import Path
from typing import Any

from wott_directory import Directory, DirectoryClient, DirectoryServer, DirectorySettings

from wott_hub.config import HubConfig
from wott_hub.hub import Hub
from wott_hub.network import DirectoryConfig, Registration

WOTT_HUB = Path(sys.executable).with_name("wott-hub")
TOKEN = "fleet-t0ken"


async def fleet_directory() -> tuple[DirectoryServer, DirectoryClient]:
    server = await DirectoryServer(Directory(DirectorySettings(token=TOKEN, purge_interval=0.2))).start()
    return server, DirectoryClient(server.url)


async def hub_ids(client: DirectoryClient) -> dict[str, dict[str, Any]]:
    return {td["id"]: td for td in await client.list() if td["id"].startswith("urn:wott-hub:")}


def test_registered_with_a_ttl_followed_and_deleted_on_a_clean_stop(tmp_path, press_scene, run):
    async def scenario() -> None:
        server, fleet = await fleet_directory()
        cfg = HubConfig(name="edge-1", http_port=0, ws_port=0, database=str(tmp_path / "hub.db"),
                        devices=(press_scene("pad"), press_scene("cyl", "cylinder")),
                        directory=DirectoryConfig(register_to=(Registration(server.url, TOKEN),), ttl_s=30))
        hub = Hub(cfg)
        ids = hub._identity  # every Thing id carries the hub's id (docs/scale-out.md)
        await hub.start()
        try:
            await hub.sync_directories()
            tds = await hub_ids(fleet)
            assert set(tds) == {ids.device_id("pad"), ids.device_id("cyl"),
                                ids.hub_thing_id}
            reg = tds[ids.device_id("pad")]["registration"]
            assert reg["ttl"] == 30 and "expires" in reg
            assert tds[ids.device_id("pad")]["forms"] == hub._server.things.get("pad").td["forms"]
            await hub.remove_device("cyl")
            await hub.sync_directories()
            assert set(await hub_ids(fleet)) == {ids.device_id("pad"), ids.hub_thing_id}
        finally:
            await hub.stop()
        assert await hub_ids(fleet) == {}  # a clean stop: they are gone now, not in 30 s
        fleet.close()
        await server.stop()

    run(scenario())


CONFIG = """
[hub]
name = "edge-2"
http_port = 0
ws_port = 0
database = "hub.db"

[directory]
register_to = [{{ url = "{url}", token = "{token}" }}]
ttl_s = 3.0

[discovery]
mdns = false
browse = false

[[device]]
id = "pad"
family = "scene"
shape = "flat"
step = [{{ kind = "press", at = [11.25, 11.25, 4.0], start_s = 0.5, duration_s = 0.5, depth_mm = 1.0 }}]
"""


def test_the_things_of_a_hub_that_dies_expire(tmp_path, wait_for, run):
    async def scenario() -> None:
        server, fleet = await fleet_directory()
        (tmp_path / "hub.toml").write_text(CONFIG.format(url=server.url, token=TOKEN))
        proc = await asyncio.create_subprocess_exec(
            str(WOTT_HUB), "run", "--config", str(tmp_path / "hub.toml"), "--json", cwd=tmp_path,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        try:
            line = await asyncio.wait_for(proc.stdout.readline(), 60)
            assert line, (await proc.stderr.read()).decode()
            info = json.loads(line)
            assert info["registered_to"] == [server.url] and info["directory"] == info["http"] + "/"
            pad, hub_thing = f"urn:wott-hub:{info['hub_id']}:device:pad", f"urn:wott-hub:{info['hub_id']}:hub"

            async def registered() -> bool:
                return set(await hub_ids(fleet)) == {pad, hub_thing}

            await wait_for(registered, what="registered")
            first = (await fleet.get(pad))["registration"]
            # longer than the ttl (3 s, refreshed every 1 s: only a 2 s stall lets it lapse): still
            # there, because the hub refreshes
            await asyncio.sleep(4.0)
            assert await registered()
            again = (await fleet.get(pad))["registration"]
            assert again["expires"] > first["expires"] and again["modified"] == first["modified"]

            proc.send_signal(signal.SIGKILL)  # dies without unregistering anything
            await proc.wait()

            async def expired() -> bool:
                return await hub_ids(fleet) == {}

            # nothing else deletes them (killed, the hub unregistered nothing): their ttl ran out; how
            # soon after the kill is a timing, bounded here only against a hang
            await wait_for(expired, timeout=60, what="expired ttl seconds after the last refresh")
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
            fleet.close()
            await server.stop()

    run(scenario())
