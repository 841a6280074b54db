"""Issue 33, item 2: PostgreSQL goes away under a running hub; nothing any client saw is lost.

A real hub (``uv run wott-hub run``) records into a PostgreSQL cluster of this test's own (the session's
shared cluster is never stopped), a real SSE client reads a device's events, and the server is stopped
(``pg_ctl stop -m fast``) and started again, twice:

- while it is down the hub keeps streaming; what it cannot write goes to its spool, whose size and age
  health shows (history "degraded"); when the server returns the spool is forwarded and health is "ok";
- a Ctrl-C while it is down stops the hub within seconds (before: ~17 s of retries, or for ever, and the
  records dropped without a word), saying how many records wait in the spool; the next start writes them.

Measured at the end, in the database: every id the SSE client saw is there, once, in the order made.
"""

from __future__ import annotations

import signal
import sys
import textwrap
import time

import httpx
import psycopg


def _cluster():
    return sys.modules["wott_tests_postgres"].PgCluster  # tests/postgres.py, loaded by the root conftest


def _server(cluster, action: str) -> None:
    """Stop (fast: connections cut) or start again, with the options ``PgCluster.start`` gave it."""
    if action == "stop":
        cluster._run("pg_ctl", "-D", str(cluster.data), "-m", "fast", "-w", "stop")
        return
    opts = (f"-c listen_addresses=127.0.0.1 -c port={cluster.port} -c unix_socket_directories={cluster.root} "
            "-c max_connections=200 -c synchronous_commit=off -c fsync=off -c full_page_writes=off")
    cluster._run("pg_ctl", "-D", str(cluster.data), "-l", str(cluster.root / "server.log"), "-w", "-t", "60",
                 "-o", opts, "start")


def _scene_table() -> str:
    from wott_hub.examples import example_device

    mesh = example_device("flat").mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
    press = f'{{kind = "press", at = {at}, start_s = 0.05, duration_s = 0.2, depth_mm = 1.0, radius_mm = 4}}'
    return ('[[device]]\nid = "pad"\nfamily = "scene"\nshape = "flat"\nloop = true\nrate_hz = 60.0\n'
            f"step = [{press}]\n")


def _health(hub_url: str) -> dict:
    return httpx.get(f"{hub_url}/properties/health", timeout=10).json()["history"]


def test_records_made_while_postgres_is_down_are_forwarded_and_a_stop_meanwhile_is_bounded(
        tmp_path, running_hub, sse_ids, eventually):
    cluster = _cluster()().start()
    running = True
    try:
        cfg = tmp_path / "hub.toml"
        cfg.write_text(textwrap.dedent(f"""
            [hub]
            http_port = 0
            ws_port = 0
            database = "{cluster.url(tcp=True)}"
        """) + _scene_table())
        hub = running_hub(["-c", str(cfg)], tmp_path)
        try:
            info = hub.ready()
            hub_url = info["hub"]
            reader = sse_ids(info["devices"]["pad"] + "/events")
            eventually(lambda: len(reader.ids) >= 30, 30, "events streamed")

            # 1. the server goes away and comes back while the hub runs
            _server(cluster, "stop")
            running = False
            seen = len(reader.ids)
            h = eventually(lambda: (h := _health(hub_url))["spool"]["records"] > 0 and h, 30,
                           "records in the spool while the database is down")
            assert h["state"] == "degraded" and h["spool"]["bytes"] > 0 and h["spool"]["oldestAgeS"] >= 0
            eventually(lambda: len(reader.ids) >= seen + 120, 30, "the stream going on meanwhile")
            _server(cluster, "start")
            running = True
            eventually(lambda: (h := _health(hub_url))["spool"]["records"] == 0 and h["state"] == "ok", 60,
                       lambda: f"the spool forwarded once the database is back: {_health(hub_url)}")

            # 2. down again, and the hub is stopped meanwhile
            _server(cluster, "stop")
            running = False
            seen = len(reader.ids)
            eventually(lambda: len(reader.ids) >= seen + 60, 30, "events made while the database is down")
            hub.signal(signal.SIGINT)
            t0 = time.monotonic()
            rc = hub.wait(60)
            took = time.monotonic() - t0
            log = hub.log()
            assert rc is not None, f"the hub still runs 60 s after Ctrl-C: {log[-3000:]}"
            assert took < 15, f"the stop took {took:.1f} s with the database down"
            assert "wait in the spool" in log, log[-3000:]  # said, not dropped without a word
            reader.stop()
        finally:
            hub.kill()

        _server(cluster, "start")
        running = True
        again = running_hub(["-c", str(cfg)], tmp_path)  # the next start forwards what waited
        try:
            url = again.ready()["hub"]
            eventually(lambda: _health(url)["spool"]["records"] == 0, 60, "the spool forwarded at start")
            again.signal(signal.SIGTERM)
            assert again.wait(60) is not None
        finally:
            again.kill()

        with psycopg.connect(host=str(cluster.root), port=cluster.port, user=cluster.user,
                             dbname="postgres") as conn:
            stored = [s for (s,) in conn.execute(
                "SELECT e.seq FROM events e JOIN things t ON t.key = e.thing_key WHERE t.id = 'pad' "
                "ORDER BY e.id")]
        missing = sorted(set(reader.ids) - set(stored))
        assert missing == [], f"{len(missing)} of {len(reader.ids)} ids seen not in history: {missing[:10]}"
        assert len(stored) == len(set(stored)), "a record written twice"
        assert stored == sorted(stored), "records written out of order"
    finally:
        if not running:
            _server(cluster, "start")
        cluster.stop()
