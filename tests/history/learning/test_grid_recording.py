"""A taxel array that records its pressure grid (``record_raw_hz``) on a real hub: ``pressureGridRecorded``
events in history, declared in its TD, exported as ``observation.tactile.<id>.pressure`` held row by row."""

from __future__ import annotations

import json
import time

import numpy as np

from .lerobot_check import check_lerobot


def test_a_recorded_grid_is_exported_as_held(tmp_path, hub_thread, cli, reader_of):
    from wott_hub.config import HubConfig
    from wott_hub.plugins import DeviceConfig

    db = tmp_path / "hub.db"
    device = DeviceConfig("grid", "taxel-array", {"simulate": True, "record_raw_hz": 20.0})
    ht = hub_thread(HubConfig(http_port=0, ws_port=None, database=str(db), devices=(device,))).start()
    try:
        import httpx

        td = httpx.get(f"{ht.url}/wot/grid").json()
        assert td["events"]["pressureGridRecorded"]["@type"] == "tac:PressureGridRecorded"
        time.sleep(2.5)
    finally:
        ht.stop()
    reader = reader_of(db)
    grids = [r for page in reader.pages("grid", names=["pressureGridRecorded"]) for r in page]
    assert len(grids) >= 20, len(grids)  # ~20 a second
    first = json.loads(grids[0].data)
    assert (first["rows"], first["cols"]) == (16, 16) and first["timeStamp"] == grids[0].t_ns
    out = tmp_path / "grid"
    done = cli(
        "history",
        "export",
        "--format",
        "lerobot",
        "-o",
        str(out),
        "--device",
        "grid",
        "--database",
        str(db),
        "--fps",
        "10",
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    loaded = check_lerobot(out)
    assert loaded.features["observation.tactile.grid.pressure"]["shape"] == [16, 16]
    start = json.loads((out / "meta/wott.json").read_text())["episodes"][0]["start_ns"]
    data = loaded.data.with_format("numpy")
    for k in range(len(data)):
        t = start + k * 10**9 // 10
        held = max((g for g in grids if g.t_ns <= t), key=lambda g: (g.t_ns, g.seq), default=None)
        want = (
            np.float32(json.loads(held.data)["pressure"])
            if held is not None
            else np.zeros((16, 16), np.float32)
        )
        assert np.array_equal(data[k]["observation.tactile.grid.pressure"], want), k
