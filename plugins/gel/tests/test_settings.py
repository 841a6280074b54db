"""Each bad setting gives one line naming the field; a source that is not a video, unreadable, or ends."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys

import numpy as np
import pytest
from wott_driver_gel.evaluation import write_recording
from wott_driver_gel.settings import open_gel

from wott_hub.plugin_api import Health, SettingsError


@pytest.fixture
def folder(mini, tmp_path):
    write_recording(tmp_path / "f", mini.background, mini.presses[:1], rest=3)
    return tmp_path / "f"


@pytest.mark.parametrize("settings, field", [
    ({}, "source"),
    ({"source": "SRC", "device": "/dev/video0"}, "source"),
    ({"source": "/nonexistent/mini.avi"}, "source"),
    ({"source": "SRC", "mm_per_px": -1}, "mm_per_px"),
    ({"source": "SRC", "markers": "dots"}, "markers"),
    ({"source": "SRC", "rest_frames": 0}, "rest_frames"),
    ({"source": "SRC", "material": "steel"}, "material"),
    ({"source": "SRC", "radius_fraction": 1.5}, "radius_fraction"),
    ({"source": "SRC", "stream": "HD"}, "stream"),
    ({"source": "SRC", "led": [1, 2, 16]}, "led"),
    ({"source": "SRC", "colour": 1}, "colour"),
])
def test_a_bad_setting_is_one_line_naming_it(settings, field, folder):
    settings = {k: (str(folder) if v == "SRC" else v) for k, v in settings.items()}
    family = "digit" if field in ("stream", "led") else "gelsight-mini"
    with pytest.raises(SettingsError) as e:
        open_gel("g", family, settings)
    text = str(e.value)
    assert "\n" not in text and field in text, text


def test_a_file_that_is_no_video_is_refused_naming_source(tmp_path):
    bad = tmp_path / "notes.avi"
    bad.write_bytes(b"this is not a video\n" * 100)
    with pytest.raises(SettingsError, match="^source: "):
        open_gel("g", "gelsight-mini", {"source": str(bad)})


def test_an_unreadable_image_in_a_folder_disconnects_with_the_reason(folder):
    driver = open_gel("g", "gelsight-mini", {"source": str(folder), "realtime": False, "rest_frames": 3})
    (folder / "00003.png").write_bytes(b"broken")

    async def go() -> str:
        async for _f in driver.frames():
            pass  # the rest frame
            break
        it = driver.frames()
        task = asyncio.ensure_future(it.__anext__())
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 60
        while driver.health().state is not Health.disconnected:
            assert loop.time() < deadline, driver.health()
            await asyncio.sleep(0.01)
        task.cancel()
        await driver.close()
        return driver.health().reason

    assert "00003.png' is unreadable" in asyncio.run(go())


def test_a_source_that_ends_disconnects_saying_so_and_replays(mini, tmp_path):
    write_recording(tmp_path / "f", mini.background, mini.presses[:1], rest=2)
    driver = open_gel("g", "gelsight-mini", {"source": str(tmp_path / "f"), "realtime": False,
                                             "rest_frames": 2, "backoff_initial_s": 0.01})
    seen = []

    async def go() -> None:
        async for f in driver.frames():
            seen.append(len(f.contacts or ()))
            if driver.reconnects and len(seen) >= 7:
                break
        await driver.close()

    asyncio.run(go())
    assert driver.reconnects >= 1 and seen.count(1) >= 2  # the press again after the replay


def test_config_check_open_on_an_ffv1_avi_never_aborts(mini, tmp_path):
    """Issue 44: exit 134 ("terminate called without an active exception") in 5 of 7 runs, when the
    capture was released by another thread than the worker that read it. Run several times."""
    import cv2

    avi = tmp_path / "mini.avi"
    w = cv2.VideoWriter(str(avi), cv2.VideoWriter.fourcc(*"FFV1"), 25.0, (640, 480))
    for f in [mini.background] * 5 + [x for p in mini.presses[:6] for x in (p, mini.background)]:
        w.write(f)
    w.release()
    gel, pad = tmp_path / "gel.toml", tmp_path / "pad.toml"
    gel.write_text(f'[[device]]\nid = "mini"\nfamily = "gelsight-mini"\nsource = "{avi}"\n')
    pad.write_text(f'[[device]]\nid = "pad"\nfamily = "flat-vision"\nsource = "{avi}"\n')
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    for _ in range(3):
        # the gel opens it (its first frame within 60 s, however loaded the machine); the pad finds no
        # markers and gives up after 2 s, with its reader mid-stream: the case that aborted
        for cfg, wait, codes in ((gel, "60", (0,)), (pad, "2", (5,))):
            cmd = [sys.executable, "-c", "from wott_hub.cli import main; main()", "config", "check", "--open",
                   "-c", str(cfg), "--wait", wait]
            run = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=180)
            assert run.returncode in codes, (cfg.name, run.returncode, run.stderr[-2000:])
            assert "terminate called" not in run.stderr


def test_digit_frames_from_the_device_are_turned_like_digit_interface():
    from wott_driver_gel.sources import rotate_digit, shape_mini

    qvga = np.arange(240 * 320 * 3, dtype=np.uint32).reshape(240, 320, 3).astype(np.uint8)
    turned = rotate_digit(qvga)
    assert turned.shape == (320, 240, 3)
    assert (turned[0, 0] == qvga[0, 319]).all()  # 90° anticlockwise: the top-right corner comes top-left
    import cv2

    assert np.array_equal(turned, cv2.flip(cv2.transpose(qvga), 0))  # digit-interface's own two steps
    native = np.zeros((2464, 3280, 3), np.uint8)
    assert shape_mini(native).shape == (240, 320, 3)


def test_a_serial_no_camera_has_is_one_line_saying_so():
    """``serial``: udev's database read through pyudev (the real one here: no sensor is plugged in)."""
    from wott_driver_gel.sources import video_device_for_serial
    from wott_vision.camera import CameraError

    with pytest.raises(CameraError, match="no video device with serial 'NOSUCHSERIAL'"):
        video_device_for_serial("NOSUCHSERIAL")
