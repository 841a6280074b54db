"""The fleet end to end on loopback: one standalone directory on PostgreSQL, three hubs (processes,
hub ids cell-1..3) registering into it with a short ttl, one Mosquitto.

A client finds every device of every hub with ONE JSONPath query and receives the events of all
of them from ONE MQTT subscription (``wott/+/+/events/...``). One hub is SIGKILLed: its Things
expire from the directory within the ttl while the others keep streaming; restarted, it serves
the same ids and its history (the event sequence) continues."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import socket
import sys
from pathlib import Path

from wott_directory import DirectoryClient

WOTT_HUB = Path(sys.executable).with_name("wott-hub")
WOTT_DIRECTORY = Path(sys.executable).with_name("wott-directory")
TOKEN = "fleet-t0ken"
TTL_S = 4.0
EVENT = "skinDeformedDetection"
FLEET_FILTER = f"wott/+/+/events/{EVENT}"
FIND_DEVICES = '$[?@["tac:family"]=="scene"]'

HUB_CONFIG = """
[hub]
id = "{hub_id}"
name = "{hub_id}"
http_port = 0
ws_port = false
database = "{hub_id}.db"

[directory]
enabled = false
register_to = [{{ url = "{directory}", token = "{token}" }}]
ttl_s = {ttl}

[discovery]
mdns = false
browse = false

[mqtt]
url = "{broker}"

[[device]]
id = "pad"
family = "scene"
shape = "flat"
loop = true
rate_hz = 60.0
step = [{{ kind = "press", at = [11.25, 11.25, 4.0], start_s = 0.1, duration_s = 0.3, depth_mm = 1.0 }}]
"""


class HubProcess:
    def __init__(self, folder: Path, hub_id: str, directory: str, broker: str) -> None:
        self.hub_id = hub_id
        self.folder = folder
        self.config = folder / f"{hub_id}.toml"
        self.config.write_text(HUB_CONFIG.format(hub_id=hub_id, directory=directory, token=TOKEN, ttl=TTL_S,
                                                 broker=broker))
        self.proc: asyncio.subprocess.Process | None = None
        self.info: dict = {}

    async def start(self) -> HubProcess:
        self.proc = await asyncio.create_subprocess_exec(
            str(WOTT_HUB), "run", "--config", str(self.config), "--json", cwd=self.folder,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        line = await asyncio.wait_for(self.proc.stdout.readline(), 60)
        assert line, f"{self.hub_id} did not start"
        self.info = json.loads(line)
        return self

    def kill(self) -> None:
        assert self.proc is not None
        self.proc.send_signal(signal.SIGKILL)

    async def stop(self) -> None:
        if self.proc is not None and self.proc.returncode is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                await asyncio.wait_for(self.proc.wait(), 20)
            except TimeoutError:
                self.proc.kill()
                await self.proc.wait()


async def start_directory(db_url: str, port: int) -> asyncio.subprocess.Process:
    proc = await asyncio.create_subprocess_exec(
        str(WOTT_DIRECTORY), "--port", str(port), "--db", db_url, "--token", TOKEN, "--purge-interval", "0.2",
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE)
    return proc


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def test_three_hubs_one_directory_one_broker(tmp_path, pg_cluster, broker, mqtt_reader, run, wait_for,
                                              sse_events):
    db_url = pg_cluster.url(pg_cluster.create_database("fleet"))

    async def scenario() -> None:
        port = _free_port()
        directory = await start_directory(db_url, port)
        url = f"http://127.0.0.1:{port}/"
        client = DirectoryClient(url)
        hubs = {i: HubProcess(tmp_path, f"cell-{i}", url, broker.url) for i in (1, 2, 3)}
        try:
            async def directory_up() -> bool:
                if directory.returncode is not None:
                    err = (await directory.stderr.read()).decode()[-2000:]
                    raise AssertionError(f"wott-directory exited: {err}")
                try:
                    await client.directory_description()
                    return True
                except OSError:
                    return False

            await wait_for(directory_up, timeout=30, what="the standalone directory on PostgreSQL")
            await asyncio.gather(*(h.start() for h in hubs.values()))

            # ONE JSONPath query finds every device of every hub (ids distinct by hub id)
            async def devices() -> dict[str, dict]:
                return {td["id"]: td for td in await client.search(FIND_DEVICES)}

            expected = {f"urn:wott-hub:cell-{i}:device:pad" for i in hubs}
            await wait_for(lambda: _same(devices(), expected), timeout=20,
                           what="every hub's device registered")
            found = await devices()
            filters = [f["mqv:filter"] for td in found.values() for f in td["events"][EVENT]["forms"]
                       if "mqv:filter" in f]
            assert sorted(filters) == [f"wott/cell-{i}/pad/events/{EVENT}" for i in (1, 2, 3)]

            # ONE MQTT subscription receives the events of all of them
            async with mqtt_reader(broker.url, FLEET_FILTER) as fleet:
                def per_hub() -> dict[str, int]:
                    out = {f"cell-{i}": 0 for i in hubs}
                    for topic, _, _ in fleet.messages:
                        out[topic.split("/")[1]] += 1
                    return out

                await wait_for(lambda: min(per_hub().values()) >= 10, timeout=20,
                               what=lambda: f"events from every hub {per_hub()}")
                cell2 = hubs[2]
                stream = f"{cell2.info['http']}/wot/pad/events/{EVENT}"
                before = await asyncio.to_thread(sse_events, stream, 3)
                last_seq = int(before[-1].id)

                cell2.kill()  # SIGKILL: no unregistering, no MQTT goodbye
                await cell2.proc.wait()
                killed_at = asyncio.get_running_loop().time()
                survivors = {f"urn:wott-hub:cell-{i}:device:pad" for i in (1, 3)}
                await wait_for(lambda: _same(devices(), survivors), timeout=TTL_S + 3,
                               what="cell-2's Things expired from the directory within the ttl")
                assert asyncio.get_running_loop().time() - killed_at <= TTL_S + 3
                counts = per_hub()
                await wait_for(lambda: all(per_hub()[h] >= counts[h] + 10 for h in ("cell-1", "cell-3")),
                               timeout=15, what="the others keep streaming")
                assert per_hub()["cell-2"] == counts["cell-2"]

                await cell2.start()  # restarted: same ids, its history continues
                await wait_for(lambda: _same(devices(), expected), timeout=20, what="cell-2 back")
                assert cell2.info["hub_id"] == "cell-2"
                stream = f"{cell2.info['http']}/wot/pad/events/{EVENT}"  # a new port
                after = await asyncio.to_thread(sse_events, stream, 1)
                assert int(after[0].id) > last_seq  # the sequence continues above what was handed out
                await wait_for(lambda: per_hub()["cell-2"] >= counts["cell-2"] + 10, timeout=20,
                               what="cell-2 streaming on MQTT again")
        finally:
            await asyncio.gather(*(h.stop() for h in hubs.values()))
            client.close()
            directory.terminate()
            await directory.wait()

    run(scenario(), timeout=120)


async def _same(found, expected: set[str]) -> bool:
    return set(await found) == expected
