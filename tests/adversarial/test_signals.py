"""Issue 33, items 1 and 12: Ctrl-C and SIGTERM at any moment, through ``uv run`` as users start the hub.

Each test starts ``uv run wott-hub run`` in a process group of its own and signals the whole group, as a
terminal's Ctrl-C or a service manager's SIGTERM does: uv gets the signal and forwards it to the hub,
which got it from the group too (every signal arrives twice). What is measured: how long the hub takes to
exit after the signal, what an SSE client saw against what history holds, what is left on the broker.

- Ctrl-C while a device is still opening (its ``prepare`` takes an hour): the hub exits within seconds
  (before: the signal waited for the start-up to end, here an hour);
- a second Ctrl-C while the database hangs (SQLite's write lock held by another process): the hub exits
  within seconds, says where the records it could not write went, and the next start writes them: no id
  the SSE client saw is missing from history (before: ``KeyboardInterrupt`` inside the stop, records lost
  without a word);
- SIGTERM through uv (twice): the stop runs to its end and clears the hub's retained TDs from the broker
  (before: ``serve`` removed its handlers before ``hub.stop()``, the second SIGTERM killed the process
  mid-stop and every retained TD stayed on the broker). What else a stop leaves retained (a status a last
  will or a clean stop publishes) is the MQTT publisher's business, not asserted here.
"""

from __future__ import annotations

import signal
import sqlite3
import textwrap
import time
from pathlib import Path

import httpx

from wott_hub.plugins import ENTRY_POINT_GROUP

SLOW = '''
import asyncio
import os
import time

import numpy as np

from wott_hub.examples import example_device
from wott_hub.plugin_api import Driver, FamilyInfo, TactileFrame, hookimpl


class SlowDriver(Driver):
    """A device that takes an hour to get ready (a camera warming up, a device far away)."""

    async def prepare(self):
        open(os.environ["WOTT_TEST_PREPARING"], "w").close()
        await asyncio.sleep(3600)

    async def frames(self):
        while True:
            await asyncio.sleep(0.1)
            yield TactileFrame(time.time_ns(), np.zeros((self.description.mesh.n_nodes, 3)))


@hookimpl
def wott_hub_families():
    return [FamilyInfo("slowopen", "Takes an hour to open.", {"type": "object", "properties": {}})]


@hookimpl
def wott_hub_open_device(config):
    return SlowDriver(example_device("flat", config.id))
'''


def _scene_table(device_id: str) -> str:
    """A ``scene`` device pressing the middle of a flat skin for 0.2 s in every 0.25 s (events all along)."""
    from wott_hub.examples import example_device

    mesh = example_device("flat").mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
    press = f'{{kind = "press", at = {at}, start_s = 0.05, duration_s = 0.2, depth_mm = 1.0, radius_mm = 4}}'
    return textwrap.dedent(f"""
        [[device]]
        id = "{device_id}"
        family = "scene"
        shape = "flat"
        loop = true
        rate_hz = 60.0
    """) + f"step = [{press}]\n"


def _config(folder: Path, extra: str = "") -> Path:
    cfg = folder / "hub.toml"
    cfg.write_text(textwrap.dedent("""
        [hub]
        http_port = 0
        ws_port = 0
        database = "hub.db"
    """) + extra + _scene_table("pad"))
    return cfg


def _exit_within(hub, seconds: float) -> tuple[int | None, float]:
    t0 = time.monotonic()
    rc = hub.wait(seconds)
    return rc, time.monotonic() - t0


def test_ctrl_c_while_a_device_is_still_opening_stops_the_hub_at_once(tmp_path, running_hub, eventually):
    site = tmp_path / "site"
    site.mkdir()
    (site / "wott_test_slowopen.py").write_text(textwrap.dedent(SLOW))
    info = site / "wott_test_slowopen-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: wott-test-slowopen\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\nslowopen = wott_test_slowopen\n")
    marker = tmp_path / "preparing"
    cfg = _config(tmp_path, '[[device]]\nid = "slow"\nfamily = "slowopen"\n')
    env = {"PYTHONPATH": str(site), "WOTT_HUB_PLUGINS": "slowopen", "WOTT_TEST_PREPARING": str(marker)}
    hub = running_hub(["-c", str(cfg)], tmp_path, env=env)
    try:
        eventually(marker.exists, 60, "the slow device being opened")
        hub.signal(signal.SIGINT)  # Ctrl-C in the middle of the start-up
        rc, took = _exit_within(hub, 60)
        assert rc is not None, f"the hub still runs 60 s after Ctrl-C during start-up: {hub.log()[-2000:]}"
        assert took < 15, f"the hub took {took:.1f} s to stop after Ctrl-C during start-up"
        assert "KeyboardInterrupt" not in hub.log(), hub.log()[-3000:]
    finally:
        hub.kill()


def _history_seqs(db: Path, thing: str) -> list[int]:
    con = sqlite3.connect(db)
    try:
        return [s for (s,) in con.execute("SELECT e.seq FROM events e JOIN things t ON t.key = e.thing_key "
                                          "WHERE t.id = ? ORDER BY e.id", (thing,))]
    finally:
        con.close()


def test_a_second_ctrl_c_while_the_database_hangs_exits_says_what_was_kept_and_loses_nothing(
        tmp_path, running_hub, sse_ids, eventually):
    cfg = _config(tmp_path)
    hub = running_hub(["-c", str(cfg)], tmp_path)
    blocker: sqlite3.Connection | None = None
    try:
        info = hub.ready()
        reader = sse_ids(info["devices"]["pad"] + "/events")
        eventually(lambda: len(reader.ids) >= 30, 30, "events streamed")
        blocker = sqlite3.connect(tmp_path / "hub.db", timeout=30, isolation_level=None)
        blocker.execute("BEGIN IMMEDIATE")  # another process holds the write lock: the database hangs
        seen = len(reader.ids)
        eventually(lambda: len(reader.ids) >= seen + 60, 30, "events made while the database hangs")
        hub.signal(signal.SIGINT)
        time.sleep(1.5)  # a person pressing Ctrl-C again (repeats within 1 s are the same request)
        hub.signal(signal.SIGINT)
        rc, took = _exit_within(hub, 60)
        log = hub.log()
        assert rc is not None, f"the hub still runs 60 s after a second Ctrl-C: {log[-3000:]}"
        assert took < 15, f"the hub took {took:.1f} s to exit after a second Ctrl-C"
        assert "KeyboardInterrupt" not in log, log[-3000:]  # the stop ran to its end, not cut short
        assert "wait in the spool" in log, log[-3000:]  # it says where the records went
        reader.stop()
    finally:
        if blocker is not None:
            blocker.execute("ROLLBACK")
            blocker.close()
        hub.kill()
    seen_ids = list(reader.ids)
    again = running_hub(["-c", str(cfg)], tmp_path)  # the next start writes what waited in the spool
    try:
        url = again.ready()["hub"]

        def forwarded() -> bool:
            h = httpx.get(f"{url}/properties/health", timeout=10).json()["history"]
            return h["spool"]["records"] == 0

        eventually(forwarded, 60, "the spool forwarded")
        again.signal(signal.SIGTERM)
        assert again.wait(60) is not None
    finally:
        again.kill()
    stored = _history_seqs(tmp_path / "hub.db", "pad")
    missing = sorted(set(seen_ids) - set(stored))
    assert missing == [], f"{len(missing)} of {len(seen_ids)} ids seen, not in history: {missing[:10]}"
    assert len(stored) == len(set(stored))
    assert stored == sorted(stored)  # written in order


def test_sigterm_through_uv_clears_the_retained_mqtt_state(tmp_path, running_hub, broker, eventually):
    cfg = _config(tmp_path, f'[mqtt]\nurl = "{broker.url}"\nprefix = "wott/sig"\n')
    hub = running_hub(["-c", str(cfg)], tmp_path)
    try:
        hub.ready()
        retained = eventually(lambda: {t for t in broker.retained("wott/sig") if t.endswith("/td")} or None,
                              30, "the TDs retained on the broker")
        assert any("/pad/" in t for t in retained)
        hub.signal(signal.SIGTERM)  # to the process group: uv forwards it, the hub gets it twice
        rc, took = _exit_within(hub, 60)
        assert rc is not None, f"the hub still runs 60 s after SIGTERM: {hub.log()[-2000:]}"
    finally:
        hub.kill()
    left = sorted(t for t in broker.retained("wott/sig") if t.endswith("/td"))  # what the issue found left
    assert left == [], f"retained TDs left on the broker after a clean stop: {left[:10]}"
