"""An export's memory does not grow with the length of the recording (issue 46: no whole-hour arrays in
RAM). Measured as the Python heap's peak (``tracemalloc``: pages, payload strings, NumPy blocks, in
every thread; not SQLite's page cache or x264's own buffers, which do not depend on the length) while
exporting a quarter of a camera's recording, then all of it: a camera is what made it grow (its
images read 20,000 records a page).
"""

from __future__ import annotations

import base64
import io
import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, encode
from wott_hub.history.learning.export import DatasetRequest, export_dataset
from wott_hub.history.learning.resample import PAGE_BYTES, page_groups

from .conftest import new_history
from .lerobot_check import check_lerobot

T0 = 1_710_000_000 * 10**9
SECONDS = 480
IMAGE_HZ = 2
FPS = 5


def _noise_pngs(n: int, h: int = 120, w: int = 160) -> list[str]:
    """Images PNG cannot shrink (noise): ~77 kB a record, as base64 in its JSON."""
    from PIL import Image

    rng = np.random.default_rng(5)
    out = []
    for _ in range(n):
        buf = io.BytesIO()
        Image.fromarray(rng.integers(0, 256, (h, w, 3), dtype=np.uint8)).save(buf, format="PNG")
        out.append(base64.b64encode(buf.getvalue()).decode())
    return out


@pytest.fixture(scope="module")
def long_camera(tmp_path_factory) -> Path:
    """``eye``: a camera ``front`` at 2 images/s and its contacts at 30 Hz, over 480 s."""
    db = tmp_path_factory.mktemp("long") / "hub.db"
    engine, w = new_history(db)
    td = {
        "title": "eye",
        "properties": {"contactInformation": {"type": "object"}},
        "events": {
            "rawImageRecorded": {
                "title": "rawImageRecorded",
                "data": {"type": "object", "properties": {"camera": {"type": "string", "enum": ["front"]}}},
            }
        },
    }
    seq = w.register_thing("eye", title="eye", family="test", td=json.dumps(td), static_values="{}")
    images = _noise_pngs(12)
    w.start()
    for second in range(SECONDS):
        batch = []
        t = T0 + second * 10**9
        for k in range(IMAGE_HZ):
            seq += 1
            at = t + k * 10**9 // IMAGE_HZ
            image = {"timeStamp": at, "camera": "front", "width": 160, "height": 120, "channels": 3}
            image["image"] = images[(second * IMAGE_HZ + k) % len(images)]
            batch.append(Record("eye", seq, KIND_EVENT, "rawImageRecorded", at, json.dumps(image)))
        for k in range(30):
            seq += 1
            contacts = {
                "numOfContacts": 1,
                "contactLocations": [{"x": float(k), "y": 1.0, "z": 0.0}],
                "contactForces": [{"x": 0.0, "y": 0.0, "z": 0.1 * k}],
            }
            batch.append(
                Record("eye", seq, KIND_PROPERTY, "contactInformation", t + k * 10**9 // 30, encode(contacts))
            )
        for r in batch:
            w.submit(r)
        assert w.flush(60)
    w.stop()
    engine.dispose()
    return db


def _peak_mb(reader, out: Path, seconds: int) -> float:
    req = DatasetRequest("lerobot", out, ["eye"], fps=FPS, t_from_ns=T0, t_to_ns=T0 + seconds * 10**9 - 1)
    tracemalloc.start()
    try:
        summary = export_dataset(reader, req)
        peak = tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()
    assert summary.frames == seconds * FPS
    return peak


def test_the_export_peak_does_not_grow_with_the_recording(long_camera, reader_of, tmp_path):
    reader = reader_of(long_camera)
    quarter = _peak_mb(reader, tmp_path / "quarter", SECONDS // 4)
    whole = _peak_mb(reader, tmp_path / "whole", SECONDS)
    check_lerobot(tmp_path / "whole")
    images_mb = SECONDS * IMAGE_HZ * 0.077  # what the whole recording's images are as text
    # before pages were bounded in bytes the whole recording was one page (15,360 records), its images
    # held two and three times over (~220 MB here, 55 MB for the quarter)
    assert whole < images_mb, (quarter, whole)
    assert whole < 1.25 * quarter + 8, (quarter, whole)  # four times the recording, about the same peak


def test_large_records_are_read_in_pages_of_their_own():
    sizes = {"contactInformation": 120, "skinDisplacement": 160, "rawImageRecorded": 400_000, "grid": 2_000}
    groups = page_groups(sizes, 20_000)
    assert groups[0] == (["contactInformation", "skinDisplacement"], 20_000)
    assert dict((g[0], p) for g, p in groups[1:]) == {
        "grid": PAGE_BYTES // 2_000,
        "rawImageRecorded": PAGE_BYTES // 400_000,
    }
    assert page_groups({"huge": 50 * 2**20}, 20_000) == [(["huge"], 4)]
    assert page_groups({}, 20_000) == []
