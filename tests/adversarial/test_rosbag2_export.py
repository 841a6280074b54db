"""Issue 48, item 11: the rosbag2 export and a full disk, through the real ``wott-hub`` command and hub.

The recording comes from a real hub (``uv run wott-hub run``, a pressed flat pad, SQLite); each export is
``wott-hub history export --format rosbag2`` in a subprocess. Measured: exit codes, what reached stderr
(one ``error:`` line, never a traceback), what is left on disk, and whether the bag that was written reads
back whole (``rosbags``' reader). A full disk is a small tmpfs mounted for the test (the test runs as
root, as CI does).

- ``-o`` a dangling symlink: before, a ``WriterError`` traceback; now one line, the link untouched;
- two exports into one new folder at once: before, a traceback (and the loser's clean-up could delete the
  winner's folder); now one bag that reads back whole and one line;
- a full disk: before, the partial folder was left behind (at some sizes); now nothing is left;
- a hub whose database and spool are on a full disk, stopped: before, "stopping the hub failed: OSError"
  (the spool's buffered tail flushed at close); now the stop says what was not recorded, within its bound.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from . import surroundings as S

WOTT_HUB = str(Path(sys.executable).parent / "wott-hub")
STOP_S = 15.0


def _config(folder: Path, database: str, rate_hz: float = 60.0) -> Path:
    cfg = folder / "hub.toml"
    cfg.write_text(textwrap.dedent(f"""
        [hub]
        http_port = 0
        ws_port = 0
        database = "{database}"
    """) + S.press_table("pad", rate_hz))
    return cfg


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, running_hub) -> Path:
    """A database a real hub recorded a pressed pad into for a few seconds."""
    folder = tmp_path_factory.mktemp("recorded")
    hub = running_hub(["-c", str(_config(folder, "hub.db", 120.0))], folder)
    try:
        hub.ready(60)
        time.sleep(6)
        hub.signal(signal.SIGTERM)
        assert hub.wait(60) is not None, hub.log()[-3000:]
    finally:
        hub.kill()
    return folder / "hub.db"


def _export(db: Path, out: Path, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([WOTT_HUB, "history", "export", "-d", str(db), "--device", "pad", "--format",
                             "rosbag2", "-o", str(out)], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _finish(p: subprocess.Popen) -> tuple[int, str, str]:
    out, err = p.communicate(timeout=120)
    return p.returncode, out, err


def _one_line(err: str) -> str:
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("Bytecode compiled")]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


def _messages(bag: Path) -> int:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        return sum(1 for _ in reader.messages())


def test_a_dangling_symlink_output_is_one_line_and_left_alone(recorded, tmp_path):
    link = tmp_path / "bag"
    link.symlink_to(tmp_path / "nowhere" / "at-all")
    rc, _, err = _finish(_export(recorded, link, tmp_path))
    print(f"dangling -o: exit {rc}, {err.strip()!r}")
    assert rc == 2 and "exists" in _one_line(err)
    assert link.is_symlink() and not link.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]  # no partial folder beside it


def test_two_exports_into_one_folder_at_once_give_one_whole_bag_and_one_line(recorded, tmp_path):
    out = tmp_path / "bag"
    runs = [_export(recorded, out, tmp_path) for _ in range(2)]
    results = sorted((_finish(p) for p in runs), key=lambda r: r[0])
    print(f"two at once: exits {[r[0] for r in results]}, {results[1][2].strip()!r}")
    (ok, out_ok, err_ok), (refused, _, err) = results
    assert ok == 0 and refused == 2, results
    assert "exists" in _one_line(err)
    said = [ln for ln in (out_ok + err_ok).splitlines() if ln.strip().endswith(" records")]  # the count
    records = int(said[-1].split()[0].replace(",", ""))
    assert records > 0 and _messages(out) >= records  # whole: every record, plus the mesh and /tf_static
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]  # no partial folder left


def test_a_full_disk_leaves_no_partial_bag(recorded, tmp_path):
    rc, _, err = _finish(_export(recorded, tmp_path / "whole", tmp_path))
    assert rc == 0, err
    whole = sum(p.stat().st_size for p in (tmp_path / "whole").iterdir())
    left = {}
    for size in ("8k", f"{whole // 2048}k"):  # full at the first writes, and half way through the bag
        with S.small_disk(tmp_path / f"disk-{size}", size) as disk:
            rc, _, err = _finish(_export(recorded, disk / "bag", tmp_path))
            left[size] = sorted(os.listdir(disk))
            print(f"full disk ({size}): exit {rc}, {err.strip()!r}, left {left[size]}")
            assert rc == 1 and "No space left on device" in _one_line(err)
    assert all(v == [] for v in left.values()), left


def test_a_stop_with_the_database_and_spool_on_a_full_disk_is_bounded_and_says_what_was_lost(
        tmp_path, running_hub, eventually):
    with S.small_disk(tmp_path / "disk", "1m") as disk:
        hub = running_hub(["-c", str(_config(tmp_path, str(disk / "hub.db"), 120.0))], tmp_path)
        try:
            hub.ready(60)
            eventually(lambda: "cannot spool" in hub.log(), 120, lambda: f"disk full: {hub.log()[-2000:]}")
            t0 = time.monotonic()
            hub.signal(signal.SIGTERM)
            rc = hub.wait(60)
            took = time.monotonic() - t0
            log = hub.log()
        finally:
            hub.kill()
    print(f"stop on a full disk: exit {rc} in {took:.1f} s; "
          f"{[ln[24:] for ln in log.splitlines() if 'stopped;' in ln or 'stopping the hub' in ln]}")
    assert rc is not None and took < STOP_S, f"the stop took {took:.1f} s: {log[-3000:]}"
    assert "stopping the hub failed" not in log, log[-3000:]
    assert "Traceback" not in log, log[-3000:]
    assert "not recorded" in log, log[-3000:]  # what became of the records, said
