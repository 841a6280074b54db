"""Recorded sources keep their time (issue 14): ``t_s`` from the container or the ``fps``
of an image sequence, paced at that rate with ``realtime``, as fast as read without."""

import time

import numpy as np
import pytest
from wott_vision.camera import open_source


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    import cv2

    d = tmp_path_factory.mktemp("rec")
    rng = np.random.default_rng(0)
    frames = [(rng.random((48, 64)) * 255).astype(np.uint8) for _ in range(12)]
    avi = cv2.VideoWriter(str(d / "clip.avi"), cv2.VideoWriter_fourcc(*"FFV1"), 24.0, (64, 48), False)
    for k, f in enumerate(frames):
        cv2.imwrite(str(d / f"f_{k:03d}.png"), f)
        avi.write(f)
    avi.release()
    return d, len(frames)


def _times(reader):
    out = []
    while True:
        ok, _ = reader.read()
        if not ok:
            return out
        out.append(reader.t_s)


def test_video_file_frames_carry_their_container_timestamps(recordings):
    d, n = recordings
    cam = open_source(str(d / "clip.avi"), realtime=False)
    assert cam.recorded and not cam.sequence
    np.testing.assert_allclose(_times(cam), np.arange(n) / 24.0, atol=1e-3)
    assert "ended after 12 frames" in cam.failure


def test_image_sequence_frames_are_fps_apart(recordings):
    d, n = recordings
    cam = open_source(str(d / "f_%03d.png"), fps=10.0, realtime=False)
    assert cam.sequence
    np.testing.assert_allclose(_times(cam), np.arange(n) / 10.0, atol=1e-9)


def test_realtime_paces_at_the_recorded_rate_and_batch_does_not(recordings):
    d, n = recordings
    t0 = time.monotonic()
    _times(open_source(str(d / "f_%03d.png"), fps=40.0))
    paced = time.monotonic() - t0
    t0 = time.monotonic()
    _times(open_source(str(d / "f_%03d.png"), fps=4.0, realtime=False))  # 2.75 s of recording
    batch = time.monotonic() - t0
    assert paced >= 0.95 * (n - 1) / 40.0  # pacing only makes it later: a bound no load breaks
    assert batch < (n - 1) / 4.0  # not paced: sooner than the recording lasts (a busy machine included)
