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

from .conftest import new_history, write_all

T0 = 1_710_000_000 * 10**9


def _png(h: int, w: int) -> str:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.full((h, w, 3), 90, np.uint8)).save(buf, format="PNG")
    return base64.b64encode(buf.getvalue()).decode()


def _children() -> list[str]:
    """The command lines of this process's children that are video processes."""
    return [cmd for cmd in map(_cmdline, _children_of(os.getpid())) if "video_process" in cmd]


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


def test_a_ctrl_c_mid_export_ends_it_leaving_nothing_and_no_child(tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) while blocks of images go to the
    video process: the export ends, no dataset, no partial folder, no child left, no traceback. (Seen
    by hand before the blocks were sent by a thread: a block cut by the interrupt, the ``close`` that
    followed read by the child as the rest of it, both waiting for each other for ever; and a child
    interrupted while it started printed a traceback. Where the interrupt lands is left to chance.)"""
    import signal
    import subprocess
    import sys
    import time

    from PIL import Image

    db = tmp_path / "hub.db"
    engine, w = new_history(db)
    td = {"title": "eye", "events": {"rawImageRecorded": {"title": "rawImageRecorded", "data": {
        "type": "object", "properties": {"camera": {"type": "string", "enum": ["front"]}}}}}}
    seq = w.register_thing("eye", title="eye", family="test", td=json.dumps(td), static_values="{}")
    rng = np.random.default_rng(5)
    pngs = []
    for _ in range(10):  # noise: ~80 kB of base64 an image, a block of images far beyond a pipe's buffer
        buf = io.BytesIO()
        Image.fromarray(rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)).save(buf, format="PNG")
        pngs.append(base64.b64encode(buf.getvalue()).decode())
    records = []
    for k in range(1200):  # 10 images a second for 2 minutes
        at = T0 + k * 10**8
        image = {"timeStamp": at, "camera": "front", "width": 160, "height": 120, "channels": 3,
                 "image": pngs[k % 10]}
        records.append(Record("eye", seq + 1 + k, KIND_EVENT, "rawImageRecorded", at, json.dumps(image)))
    write_all(engine, w, records)
    out = tmp_path / "ds"
    wott_hub = Path(sys.executable).with_name("wott-hub")
    proc = subprocess.Popen([str(wott_hub), "history", "export", "--format", "lerobot", "-o", str(out),
                             "--device", "eye", "--database", str(db), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        for _ in range(600):  # until the export has its video process (a wait, not a bound)
            if _children_of(proc.pid) or proc.poll() is not None:
                break
            time.sleep(0.1)
        children = _children_of(proc.pid)
        assert children, proc.communicate()
        time.sleep(0.5)  # into the blocks
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode != 0 and "Traceback" not in err, err
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".ds")]
    assert not any("video_process" in _cmdline(pid) for pid in children)  # ended, and waited for


def _children_of(pid: int) -> list[int]:
    try:
        tasks = list(Path(f"/proc/{pid}/task").iterdir())
        return [int(c) for t in tasks for c in (t / "children").read_text().split()]
    except (FileNotFoundError, ProcessLookupError):
        return []


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except (FileNotFoundError, ProcessLookupError):
        return ""
