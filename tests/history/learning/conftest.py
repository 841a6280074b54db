"""Recorded sessions the learning exports are checked on.

``hub_session``: a real hub (two ``scene`` skins pressed in a loop, history on SQLite) recording while
two episodes are marked over HTTP (``startEpisode``/``endEpisode``), then stopped. ``camera_session``:
records written by ``HistoryWriter`` as a hub writes them (a skin whose Thing also records camera PNGs
and pressure grids, and an arm whose ``jointPositions`` property is the action), for what the scene
devices do not make.
"""

from __future__ import annotations

import base64
import io
import json
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
from sqlalchemy import Engine

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, encode
from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade

T0 = 1_700_000_000 * 10**9


def new_history(db: Path) -> tuple[Engine, HistoryWriter]:
    """A fresh history database at ``db`` (schema upgraded) and a writer on it batching every 10 ms,
    not yet started."""
    engine = create_engine(database_url(db))
    upgrade(engine)
    return engine, HistoryWriter(engine, interval_s=0.01)


def write_all(engine: Engine, w: HistoryWriter, records: list[Record]) -> None:
    """``records`` written by ``w`` (started, flushed, stopped), then the engine let go."""
    w.start()
    for r in records:
        w.submit(r)
    assert w.flush(60)
    w.stop()
    engine.dispose()


@pytest.fixture(scope="module")
def hub_session(tmp_path_factory, hub_thread, press_scene):
    from wott_hub.config import HubConfig

    d = tmp_path_factory.mktemp("session")
    db = d / "hub.db"
    ht = hub_thread(
        HubConfig(
            http_port=0,
            ws_port=None,
            database=str(db),
            devices=(press_scene("pad-a"), press_scene("pad-b", shape="cylinder", start_s=0.2)),
        )
    )
    ht.start()
    try:
        base = f"{ht.url}/wot/hub/actions"
        with httpx.Client(timeout=30) as c:
            time.sleep(0.4)
            for task in ("press the flat pad", "press it again"):
                assert c.post(f"{base}/startEpisode", json={"task": task}).status_code == 200
                time.sleep(1.2)
                assert c.post(f"{base}/endEpisode", json={}).status_code == 200
                time.sleep(0.3)
    finally:
        ht.stop()
    return db


def _png(rgb: np.ndarray) -> str:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG")
    return base64.b64encode(buf.getvalue()).decode()


def camera_frames(n: int, h: int = 48, w: int = 64) -> list[np.ndarray]:
    """Smooth images, each unlike the one before (a bright square moving on a gradient)."""
    yy, xx = np.mgrid[0:h, 0:w]
    out = []
    for k in range(n):
        img = np.stack([xx * 255 // w, yy * 255 // h, np.full((h, w), 60)], axis=-1).astype(np.uint8)
        x0 = (k * 7) % (w - 12)
        img[10:22, x0 : x0 + 12] = (250, 250, 40)
        out.append(img)
    return out


@pytest.fixture(scope="module")
def camera_session(tmp_path_factory):
    """``cam`` (flat skin, 60 Hz skin packets, a camera ``top`` at 10 Hz, a 4 x 5 pressure grid at 20 Hz) and
    ``arm`` (``jointPositions`` at 50 Hz) over 3 s; episodes are given on the command line."""
    from wott_hub.examples import example_device
    from wott_hub.td.builder import build_tactile_td, static_property_values

    d = tmp_path_factory.mktemp("camera")
    db = d / "hub.db"
    engine, w = new_history(db)
    desc = example_device("flat", "cam")
    td = build_tactile_td(desc)
    td["events"]["rawImageRecorded"] = {
        "title": "rawImageRecorded",
        "data": {"type": "object", "properties": {"camera": {"type": "string", "enum": ["top"]}}},
    }
    td["events"]["pressureGridRecorded"] = {"title": "pressureGridRecorded", "data": {"type": "object"}}
    seq = {
        "cam": w.register_thing(
            "cam",
            title="cam",
            family="test",
            td=json.dumps(td),
            static_values=encode(static_property_values(desc)),
        ),
        "arm": w.register_thing(
            "arm",
            title="arm",
            family="robot",
            td=json.dumps({"title": "arm", "properties": {"jointPositions": {"type": "object"}}}),
            static_values="{}",
        ),
    }
    n_nodes = desc.mesh.n_nodes
    records: list[Record] = []

    def put(thing: str, kind: int, name: str, t: int, data: str) -> None:
        seq[thing] += 1
        records.append(Record(thing, seq[thing], kind, name, t, data))

    frames = camera_frames(30)
    rng = np.random.default_rng(7)
    events = []
    for k in range(180):  # 60 Hz, 3 s
        ids = sorted(rng.choice(n_nodes, 6, replace=False).tolist())
        nodes = ",".join(
            f'{{"deformedNodeID":{i},"deformedNodeIntensity":{round(float(v), 3)!r}}}'
            for i, v in zip(ids, rng.uniform(0.01, 1.5, 6), strict=True)
        )
        events.append((T0 + k * 16_666_667, "skin", nodes, len(ids)))
    for k in range(30):
        events.append((T0 + 5_000_000 + k * 100_000_000, "image", k, 0))
    for k in range(60):
        events.append((T0 + 2_000_000 + k * 50_000_000, "grid", k, 0))
    for k in range(150):
        events.append((T0 + 1_000_000 + k * 20_000_000, "arm", k, 0))
    for t, what, payload, n in sorted(events, key=lambda e: e[0]):
        if what == "skin":
            put(
                "cam",
                KIND_EVENT,
                "skinDeformedDetection",
                t,
                f'{{"timeStamp":{t},"numOfDeformedNodes":{n},"arrayOfDeformedNodes":[{payload}]}}',
            )
        elif what == "image":
            img = frames[payload]
            put(
                "cam",
                KIND_EVENT,
                "rawImageRecorded",
                t,
                json.dumps(
                    {
                        "timeStamp": t,
                        "camera": "top",
                        "width": img.shape[1],
                        "height": img.shape[0],
                        "channels": 3,
                        "image": _png(img),
                    },
                    separators=(",", ":"),
                ),
            )
        elif what == "grid":
            grid = (np.arange(20).reshape(4, 5) * 0.5 + payload).round(3).tolist()
            put(
                "cam",
                KIND_EVENT,
                "pressureGridRecorded",
                t,
                json.dumps({"timeStamp": t, "rows": 4, "cols": 5, "pressure": grid}),
            )
        else:
            put(
                "arm",
                KIND_PROPERTY,
                "jointPositions",
                t,
                json.dumps({"shoulder": round(0.01 * payload, 4), "elbow": round(-0.02 * payload, 4)}),
            )
    write_all(engine, w, records)
    return db, frames


@pytest.fixture(scope="module")
def reader_of():
    from wott_hub.history.db import open_existing
    from wott_hub.history.reader import HistoryReader

    def make(db: Path) -> HistoryReader:
        return HistoryReader(open_existing(str(db), integrity=False))

    return make
