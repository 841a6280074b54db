"""Issue 48 item 1, against a real hub with a real SQLite history: ``historyExport`` with one device id
repeated 1,000 times. Before the fix (``history/merge.py`` de-duplicates the Things, a page floor per
stream) N = 1,000 took 161 s and left the hub at 4.66 GB (from 567 MB), never given back. Measured:
the hub's memory during and after, that it answers, a bystander's events per second, and that the file
is byte for byte the one-id export."""

from __future__ import annotations

import threading
import time

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig

from . import surroundings as S

EVENT = "skinDeformedDetection"
REPEATS = 1_000


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene, tmp_path_factory):
    db = tmp_path_factory.mktemp("export") / "hub.db"
    cfg = HubConfig(http_port=0, ws_port=0, database=str(db), history_batch_ms=20,
                    discovery=DiscoveryConfig.off(), devices=(press_scene("pad"), press_scene("bystander")))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


def export(hub, devices: list[str], t_from: float, t_to: float) -> httpx.Response:
    return httpx.post(f"{hub.url}/wot/hub/actions/historyExport",
                      json={"devices": devices, "from": t_from, "to": t_to}, timeout=120)


def test_an_export_naming_one_device_a_thousand_times_is_the_one_device_export(hub):
    meter = S.GapMeter(f"{hub.url}/wot/bystander/events/{EVENT}").start()
    t_from = time.time()
    time.sleep(4.0)  # the recorded range: ~4 s of a 60 Hz skin pressed now and then
    t_to = time.time()
    time.sleep(1.0)  # committed
    once = export(hub, ["pad"], t_from, t_to)
    assert once.status_code == 200 and len(once.content) > 10_000, once.text[:500]
    rest = S.rss_mb()
    peak = [rest]
    done = threading.Event()

    def sample() -> None:
        while not done.is_set():
            peak[0] = max(peak[0], S.rss_mb())
            time.sleep(0.05)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    r0 = time.monotonic() - 3.0
    t0 = time.monotonic()
    try:
        many = export(hub, ["pad"] * REPEATS, t_from, t_to)  # the client's patience: 120 s (before: 161 s)
        t1 = time.monotonic()
    finally:
        done.set()
        sampler.join(5)
        meter.stop()
    after = S.rss_mb()
    rest_rate = sum(1 for t in meter.times if r0 < t <= t0) / (t0 - r0)
    under = sum(1 for t in meter.times if t0 < t <= t1) / max(t1 - t0, 1.0)
    print(f"export x{REPEATS}: {t1 - t0:.2f} s, RSS {rest:.0f} -> peak {peak[0]:.0f} -> {after:.0f} MB, "
          f"bystander {rest_rate:.1f} -> {under:.1f}/s, {len(many.content)} bytes")
    assert many.status_code == 200, many.text[:500]
    assert many.content == once.content  # the same Thing once: the same file
    assert peak[0] < 2 * rest and peak[0] - rest < 200, f"RSS {rest:.0f} -> {peak[0]:.0f} MB"
    assert after - rest < 100, f"RSS kept {after - rest:.0f} MB after the export"
