"""The embedding face (``wott_hub``, docs/hub.md "Python API"): a program serves a Thing of its own,
publishes its events, reads them back in process, over SSE and from history, with public names only."""

from __future__ import annotations

import asyncio
import json

import httpx
import pytest

import wott_hub
from wott_hub import Hub, HubConfig, InvalidInput, NotFound

TD = {"@context": "https://www.w3.org/2022/wot/td/v1.1", "title": "counter", "id": "urn:test:counter",
      "securityDefinitions": {"n": {"scheme": "nosec"}}, "security": "n",
      "events": {"tick": {"data": {"type": "object"}}}}


def test_a_program_publishes_its_own_things_events_to_every_reader(tmp_path, run, sse_events):
    async def scenario():
        cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"))
        async with Hub(cfg) as hub:
            await hub.expose_thing("counter", TD, record=True)
            sub = hub.subscribe("counter", "tick")
            seqs = [hub.publish("counter", "tick", {"i": i}) for i in range(3)]
            assert seqs == sorted(seqs) and len(set(seqs)) == 3
            batch = await asyncio.wait_for(anext(aiter(sub.batches())), 10)
            assert [json.loads(r.data) for r in batch] == [{"i": 0}, {"i": 1}, {"i": 2}]
            sub.close()
            # a client that comes later resumes over SSE from the first seq: history has them
            assert await asyncio.to_thread(hub.flush_history)
            url = f"{hub.td_url('counter')}/events/tick"
            got = await asyncio.to_thread(sse_events, url, 2, {"Last-Event-ID": str(seqs[0])}, 10)
            assert [(int(e.id), json.loads(e.data)) for e in got] == [(s, {"i": i + 1})
                                                                       for i, s in enumerate(seqs[1:])]
            await hub.sync_directories()  # the embedded directory has the new Thing
            listed = (await asyncio.to_thread(httpx.get, f"{hub.http_url}/things")).json()
            assert "urn:test:counter" in {t["id"] for t in listed}

    run(scenario())


def test_publishing_to_what_is_not_served_or_is_not_json_is_refused_by_name(tmp_path, run):
    async def scenario():
        async with Hub(HubConfig(http_port=0, ws_port=0, history=False)) as hub:
            await hub.expose_thing("counter", TD)
            with pytest.raises(NotFound, match="'nope'"):
                hub.publish("nope", "tick", {})
            with pytest.raises(InvalidInput, match="kind"):
                hub.publish("counter", "tick", {}, kind="action")
            with pytest.raises(InvalidInput, match="not a JSON value"):
                hub.publish("counter", "tick", {"x": float("nan")})
            with pytest.raises(NotFound):
                hub.subscribe("nope")
            assert hub.flush_history() is False  # no history: nothing will ever be committed

    run(scenario())


def test_the_embedding_face_names_the_driver_base_class():
    from wott_hub.drivers.base import Driver

    assert wott_hub.Driver is Driver and "Driver" in wott_hub.__all__
