"""Issue 48 item 12, a real hub announcing on mDNS (loopback only) and a real browser: a replay stopped
right after it starts is never announced. Before, its announcement (probing ~0.75 s) went on after the
stop, the service appeared ~1.2 s later, then was withdrawn: a browser listed a Thing that was gone."""

from __future__ import annotations

import asyncio
import time

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig

WOT_TCP = "_wot._tcp.local."


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene, tmp_path_factory):
    db = tmp_path_factory.mktemp("replay-mdns") / "hub.db"
    cfg = HubConfig(http_port=0, ws_port=0, database=str(db), history_batch_ms=20,
                    devices=(press_scene("pad"),),
                    discovery=DiscoveryConfig(mdns=True, browse=False, interfaces=("127.0.0.1",)))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


def test_a_replay_stopped_at_once_is_never_announced(hub):
    from zeroconf import ServiceStateChange
    from zeroconf.asyncio import AsyncServiceBrowser, AsyncZeroconf

    time.sleep(2.0)  # something recorded to replay

    async def scenario() -> tuple[list[str], list[str], str]:
        zc = AsyncZeroconf(interfaces=["127.0.0.1"])
        added: list[str] = []

        def on_change(zeroconf, service_type, name, state_change) -> None:
            if state_change is ServiceStateChange.Added:
                added.append(name)

        browser = AsyncServiceBrowser(zc.zeroconf, WOT_TCP, handlers=[on_change])
        try:
            await asyncio.sleep(2.0)  # the hub's own services, announced before
            before = list(added)
            ids = []
            async with httpx.AsyncClient(timeout=30) as c:
                for _ in range(3):
                    r = await c.post(f"{hub.url}/wot/hub/actions/replay",
                                     json={"device": "pad", "from": "-2s"})
                    assert r.status_code == 200, r.text
                    thing = r.json()["thing"]
                    ids.append(thing)
                    s = await c.post(f"{hub.url}/wot/hub/actions/stopReplay", json={"thing": thing})
                    assert s.status_code == 200, s.text
            await asyncio.sleep(3.0)  # before: announced ~1.2 s after the stop
            return before, added[len(before):], " ".join(ids)
        finally:
            await browser.async_cancel()
            await zc.async_close()

    before, after, ids = asyncio.run(asyncio.wait_for(scenario(), 60))
    assert any("pad" in n for n in before), before  # the browser sees the hub's announcements
    replays = [n for n in after if any(part in n for part in ids.split())] or [
        n for n in after if "replay" in n.lower()]
    assert replays == [], f"stopped replays announced: {replays}"
