"""The LeRobot export's videos are written by a child process (``video_process.py``): a failure there is
the export's one clear error, nothing is left behind, and no child outlives the export."""

from __future__ import annotations

import base64
import io
import json
import os
from pathlib import Path

import numpy as np
import pytest

from wott_hub.errors import InvalidInput
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history.learning.export import DatasetRequest, export_dataset

from .conftest import new_history

T0 = 1_710_000_000 * 10**9


def _png(h: int, w: int) -> str:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.full((h, w, 3), 90, np.uint8)).save(buf, format="PNG")
    return base64.b64encode(buf.getvalue()).decode()


def _children() -> list[str]:
    """The command lines of this process's children that are video processes."""
    out = []
    for task in Path(f"/proc/{os.getpid()}/task").iterdir():
        for pid in (task / "children").read_text().split():
            try:
                cmd = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
            except FileNotFoundError:
                continue
            if "video_process" in cmd:
                out.append(cmd)
    return out


@pytest.fixture
def resized_camera(tmp_path) -> Path:
    """``eye``: a camera whose images are 120 x 160 for 5 s, then 60 x 80."""
    db = tmp_path / "hub.db"
    engine, w = new_history(db)
    td = {"title": "eye", "events": {"rawImageRecorded": {"title": "rawImageRecorded", "data": {
        "type": "object", "properties": {"camera": {"type": "string", "enum": ["front"]}}}}}}
    seq = w.register_thing("eye", title="eye", family="test", td=json.dumps(td), static_values="{}")
    w.start()
    for second in range(10):
        seq += 1
        h, w_ = (120, 160) if second < 5 else (60, 80)
        at = T0 + second * 10**9
        image = {"timeStamp": at, "camera": "front", "width": w_, "height": h, "channels": 3,
                 "image": _png(h, w_)}
        w.submit(Record("eye", seq, KIND_EVENT, "rawImageRecorded", at, json.dumps(image)))
    assert w.flush(60)
    w.stop()
    engine.dispose()
    return db


def test_a_video_failure_in_the_child_is_the_exports_error_and_leaves_nothing(resized_camera, reader_of,
                                                                             tmp_path):
    out = tmp_path / "ds"
    req = DatasetRequest("lerobot", out, ["eye"], fps=5, t_from_ns=T0, t_to_ns=T0 + 10 * 10**9 - 1)
    with pytest.raises(InvalidInput, match="camera 'front' changed size"):
        export_dataset(reader_of(resized_camera), req)
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".ds")]  # no temporary folder either
    assert _children() == []


def test_the_first_five_seconds_export_and_the_child_ends(resized_camera, reader_of, tmp_path):
    from .lerobot_check import check_lerobot

    out = tmp_path / "ds"
    req = DatasetRequest("lerobot", out, ["eye"], fps=5, t_from_ns=T0, t_to_ns=T0 + 5 * 10**9 - 1)
    assert export_dataset(reader_of(resized_camera), req).frames == 25
    check_lerobot(out)
    assert _children() == []
