"""Recorded sources keep their time (issue 14): a tap played from a PNG sequence or an AVI file
gives the same actions as the live simulator, frames carry the recorded time, and
``realtime`` paces the playback at the recorded rate."""

import asyncio
import time

import numpy as np
import pytest
from wott_driver_flatpad.geometry import PadLayout
from wott_driver_flatpad.settings import open_pad
from wott_driver_flatpad.simulator import PadSimulator

from wott_hub.sim.scene import Scene
from wott_hub.tactile.processing import FrameProcessor, processing_params

FPS = 30.0
TAP = {"step": [{"kind": "tap", "at": [16.5, 11.25, 0.0], "start_s": 0.2, "duration_s": 0.25,
                 "depth_mm": 1.5, "radius_mm": 5.0}]}


def _frames(driver, limit_s=120.0):
    async def go():
        return [f async for f in driver.frames()]

    return asyncio.run(asyncio.wait_for(go(), limit_s))


def _actions(frames, description):
    proc = FrameProcessor(description.mesh, processing_params(description))
    return [a for f in frames for a in proc.process(f).actions]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """The simulator's frames of the tap, as a PNG sequence and a lossless (FFV1) AVI; the live actions."""
    import cv2

    scene = Scene.from_dict(TAP)
    n = int(scene.duration_s * FPS) + 1
    sim = PadSimulator(PadLayout(), scene)
    d = tmp_path_factory.mktemp("tap")
    avi = cv2.VideoWriter(str(d / "tap.avi"), cv2.VideoWriter_fourcc(*"FFV1"), FPS, (640, 480), False)
    for k in range(n):
        img, _ = sim.render(k / FPS)
        cv2.imwrite(str(d / f"tap_{k:04d}.png"), img)
        avi.write(img)
    avi.release()
    path = d / "scene.toml"
    path.write_text('[[step]]\nkind = "tap"\nat = [16.5, 11.25, 0.0]\nstart_s = 0.2\nduration_s = 0.25\n'
                    'depth_mm = 1.5\nradius_mm = 5.0\n')
    live = open_pad("live", {"source": "sim", "scene": str(path), "fps": FPS, "realtime": False})
    frames = _frames(live)
    assert len(frames) == n
    return d, n, _actions(frames, live.description), frames


def test_png_sequence_gives_the_live_simulators_actions_and_times(recording):
    d, n, live_actions, live = recording
    assert live_actions == ["touch", "pat", "release"]  # a 0.25 s tap (issue 14: touch press slip)
    pad = open_pad("png", {"source": str(d / "tap_%04d.png"), "fps": FPS, "realtime": False}, max_frames=n)
    frames = _frames(pad)
    assert _actions(frames, pad.description) == live_actions
    t = np.array([f.t_ns for f in frames])
    np.testing.assert_allclose(np.diff(t) / 1e9, 1 / FPS, atol=1e-6)  # the recorded time, not decode time
    for f, g in zip(frames, live, strict=True):
        np.testing.assert_allclose(f.displacement, g.displacement, atol=1e-9)  # lossless: the same frames


def test_avi_file_plays_on_its_container_timestamps(recording):
    d, n, live_actions, _ = recording
    pad = open_pad("avi", {"source": str(d / "tap.avi"), "realtime": False}, max_frames=n)
    frames = _frames(pad)
    assert _actions(frames, pad.description) == live_actions
    np.testing.assert_allclose(np.diff([f.t_ns for f in frames]) / 1e9, 1 / FPS, atol=1e-3)


def test_realtime_playback_keeps_the_recorded_rate_and_a_loop_continues_forwards(recording):
    d, n, _, _ = recording
    pad = open_pad("rt", {"source": str(d / "tap_%04d.png"), "fps": FPS, "backoff_initial_s": 0.01,
                          "backoff_cap_s": 0.02}, max_frames=n + 5)
    t0 = time.monotonic()
    frames = _frames(pad)
    elapsed = time.monotonic() - t0
    assert elapsed >= 0.9 * (n - 1) / FPS  # not at decode speed
    assert pad.reconnects == 1  # the sequence ended once and was replayed
    t = np.array([f.t_ns for f in frames])
    assert (np.diff(t) > 0).all()  # the replay continues after the last frame, never back in time
    np.testing.assert_allclose(np.diff(t[:n]) / 1e9, 1 / FPS, atol=1e-6)


def test_each_action_has_its_details_and_the_td_declares_them(recording):
    from wott_hub.td.builder import build_tactile_td

    *_, live = recording
    pad = open_pad("details", {})
    proc = FrameProcessor(pad.description.mesh, processing_params(pad.description))
    details = [d for f in live for d in proc.process(f).action_details()]
    assert [d["action"] for d in details] == ["touch", "pat", "release"]
    for d in details:
        assert 0.5 <= d["confidence"] <= 1.0
        assert d["evidence"]["contacts"] >= 0 and d["evidence"]["speedMmPerS"] >= 0
    pat = details[1]
    assert pat["evidence"]["durationS"] == pytest.approx(0.25, abs=2 / FPS)  # the recorded tap's length
    td = build_tactile_td(pad.description)
    assert td["events"]["actionDetails"]["data"]["required"] == ["action", "confidence", "evidence"]
    assert td["events"]["actionDetection"]["data"]["type"] == "string"  # the paper's event unchanged

