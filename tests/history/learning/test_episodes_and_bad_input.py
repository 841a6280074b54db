"""Episodes marked on a running hub three ways (HTTP, ``wott-hub episode``, ``wott_client``), bad export input
answered with one line and an exit code and nothing left behind, and an export's heavy libraries loaded
only by an export."""

from __future__ import annotations

import json
import subprocess
import sys

import httpx
import pytest


@pytest.fixture(scope="module")
def hub(tmp_path_factory, hub_thread, press_scene):
    from wott_hub.config import HubConfig

    db = tmp_path_factory.mktemp("marks") / "hub.db"
    ht = hub_thread(
        HubConfig(http_port=0, ws_port=None, database=str(db), devices=(press_scene("pad"),))
    ).start()
    yield ht, db
    ht.stop()


def _problem(r: httpx.Response, status: int, field: str) -> None:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    assert field in r.json()["detail"]


def test_episode_actions_over_http(hub):
    ht, _ = hub
    base = f"{ht.url}/wot/hub/actions"
    td = httpx.get(f"{ht.url}/wot/hub").json()
    assert {"startEpisode", "endEpisode"} <= set(td["actions"])
    with httpx.Client(timeout=30) as c:
        _problem(c.post(f"{base}/startEpisode", json={}), 400, "'task'")
        _problem(c.post(f"{base}/startEpisode", json={"task": "  "}), 400, "'task'")
        _problem(c.post(f"{base}/startEpisode", json={"task": "x" * 1001}), 400, "'task'")
        _problem(c.post(f"{base}/startEpisode", json={"task": 3}), 400, "'task'")
        _problem(c.post(f"{base}/startEpisode", content=b"[1"), 400, "JSON")
        _problem(c.post(f"{base}/endEpisode", json={}), 409, "no episode is open")
        started = c.post(f"{base}/startEpisode", json={"task": "wipe the table"}).json()
        _problem(c.post(f"{base}/startEpisode", json={"task": "another"}), 409, "wipe the table")
        ended = c.post(f"{base}/endEpisode", json={}).json()
    assert ended["task"] == "wipe the table" and ended["from"] == started["from"] < ended["to"]
    marks = httpx.get(f"{ht.url}/wot/episodes").json()  # the recorded Thing whose events are the marks
    assert set(marks["events"]) == {"episodeStarted", "episodeEnded"} and marks["id"].endswith(":episodes")


def test_episodes_from_the_cli_and_the_client_are_history_records(hub, cli):
    from wott_client import Client

    ht, db = hub
    done = cli("episode", "start", "pick up the cup", "--url", ht.url)
    assert done.returncode == 0 and "episode started: pick up the cup" in done.stdout, done.stderr
    again = cli("episode", "start", "twice", "--url", ht.url)
    assert (
        again.returncode == 4 and again.stderr.startswith("error: ") and len(again.stderr.splitlines()) == 1
    )
    done = cli("episode", "end", "--url", ht.url)
    assert done.returncode == 0 and "episode ended: pick up the cup" in done.stdout, done.stderr
    with Client() as client:
        history = client.history(f"{ht.url}/wot/hub")
        started = history.start_episode("put it back")
        ended = history.end_episode()
    assert started["task"] == ended["task"] == "put it back"
    assert ht.hub.flush_history()
    listed = cli("episode", "list", "--json", "--database", str(db))
    episodes = [json.loads(line) for line in listed.stdout.splitlines()]
    assert [e["task"] for e in episodes][-2:] == ["pick up the cup", "put it back"]  # after the HTTP test's
    assert episodes[-1]["from"] == started["from"] and episodes[-1]["to"] == ended["to"]


def test_a_hub_without_history_has_nothing_to_mark(hub_thread):
    from wott_hub.config import HubConfig

    ht = hub_thread(HubConfig(http_port=0, ws_port=None, history=False)).start()
    try:
        _problem(httpx.post(f"{ht.url}/wot/hub/actions/startEpisode", json={"task": "t"}), 404, "no history")
    finally:
        ht.stop()


@pytest.mark.parametrize(
    "args, code, says",
    [
        (["--from", "2001-01-01T00:00:00Z", "--to", "2001-01-01T00:01:00Z"], 2, "no records"),
        (["--device", "nobody"], 3, "no recorded device 'nobody'"),
        (["--fps", "0"], 2, "--fps"),
        (["--fps", "10000"], 2, "--fps"),
        (["--episodes", "-1m"], 2, "FROM..TO"),
        (["--action", "pad"], 2, "THING.PROPERTY"),
        (["--state", "nothing"], 2, "--state 'nothing'"),
        (["--codec", "mpeg2"], 2, "--codec"),
    ],
)
def test_bad_export_input_is_one_line_and_leaves_nothing(camera_session, tmp_path, cli, args, code, says):
    db, _ = camera_session
    for fmt in ("lerobot", "zarr"):
        out = tmp_path / fmt
        done = cli(
            "history",
            "export",
            "--format",
            fmt,
            "-o",
            str(out),
            "--device",
            "cam",
            "--database",
            str(db),
            *args,
        )
        assert done.returncode == code, done.stderr
        assert (
            done.stderr.startswith("error: ") and len(done.stderr.splitlines()) == 1 and says in done.stderr
        )
        assert list(tmp_path.iterdir()) == []


def test_an_existing_output_folder_is_left_as_it_was(camera_session, tmp_path, cli):
    db, _ = camera_session
    out = tmp_path / "taken"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    done = cli(
        "history", "export", "--format", "lerobot", "-o", str(out), "--device", "cam", "--database", str(db)
    )
    assert done.returncode == 2 and "exists" in done.stderr and len(done.stderr.splitlines()) == 1
    assert [p.name for p in tmp_path.iterdir()] == ["taken"] and (out / "mine.txt").read_text() == "keep"


LAZY = r"""
import asyncio, json, sys
from wott_hub.config import HubConfig
from wott_hub.hub import Hub

async def main():
    async with Hub(HubConfig(http_port=0, ws_port=None, database=sys.argv[1])) as hub:
        hub.describe()
asyncio.run(main())
import wott_hub.cli
heavy = {"pyarrow", "av", "zarr", "numcodecs", "datasets"}
print(json.dumps(sorted({m.split(".")[0] for m in sys.modules} & heavy)))
"""


def test_the_hub_and_the_cli_load_no_export_library(tmp_path):
    done = subprocess.run(
        [sys.executable, "-c", LAZY, str(tmp_path / "h.db")], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
