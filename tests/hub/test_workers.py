"""``[hub] workers``: devices run and are processed in worker processes; the hub serves the same."""

from __future__ import annotations

import httpx

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT
from wott_hub.plugins import DeviceConfig
from wott_hub.td.validate import validate_td


def test_devices_in_a_worker_process_stream_and_record_like_local_ones(tmp_path, hub_thread, scene,
                                                                       sse_events):
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), workers=1,
                    devices=(scene("pad", "flat"), scene("cyl", "cylinder"),
                             DeviceConfig("broken", "scene", {"shape": "flat"})))  # no scene: fails
    ht = hub_thread(cfg).start()
    try:
        hub = ht.hub
        assert set(hub.devices) == {"pad", "cyl"} and "broken" in hub.describe()["failed"]
        assert hub.devices["pad"].processor is None  # processed in the worker
        td = httpx.get(hub.td_url("pad")).json()
        assert validate_td(td) == [] and td["properties"]["skinNodes"]
        assert httpx.get(f"{hub.td_url('pad')}/properties/skinNodes").json()["numOfNodes"] == 256
        got = [(int(ev.id), ev.data) for ev in sse_events(f"{hub.td_url('pad')}/events", 30, timeout=20)]
        assert ht.call(lambda: hub.writer.flush())
        recs, _ = hub.reader.rows("pad", 0, 1 << 62, (KIND_EVENT, None), limit=10**6)
        recorded = {r.seq: r.data for r in recs}
        assert all(recorded[i] == d for i, d in got)
        ids = [i for i, _ in got]
        assert ids == [s for s in sorted(recorded) if ids[0] <= s <= ids[-1]]
        health = httpx.get(f"{hub.td_url('hub')}/properties/health").json()
        assert health["devices"]["pad"]["frames"] > 0
    finally:
        ht.stop()
    assert not any(p.is_alive() for p in hub.pool.procs)  # the workers are gone
