import numpy as np
import pytest
from wott_vision.camera import CameraError, open_source, parse_spec
from wott_vision.markers import detect_markers
from wott_vision.render import render_markers


def _write_video(path, frames, fps=30.0):
    import cv2

    h, w = frames[0].shape
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h), False)
    assert writer.isOpened()
    for f in frames:
        writer.write(f)
    writer.release()


def test_video_file_source_reads_markers_then_reports_its_end(tmp_path):
    pts = np.array([[100.0 + 40 * i, 200.0] for i in range(8)])
    frames = [render_markers(pts + [k, 0.5 * k], 6.0) for k in range(4)]
    path = tmp_path / "markers.avi"
    _write_video(path, frames)
    with open_source(str(path)) as cam:
        assert cam.isOpened() and cam.is_file
        for k in range(4):
            ok, frame = cam.read()
            assert ok and frame.shape[:2] == (480, 640)
            found = detect_markers(frame)
            found = found[np.argsort(found[:, 0])]
            np.testing.assert_allclose(found, pts + [k, 0.5 * k], atol=0.25)  # MJPEG costs a little
        ok, frame = cam.read()
        assert not ok and frame is None
        assert "ended after 4 frames" in cam.failure


def test_missing_sources_raise_with_the_reason(tmp_path):
    with pytest.raises(CameraError, match="no such file"):
        open_source(str(tmp_path / "nope.avi"))
    with pytest.raises(CameraError, match="cannot open camera device 63"):
        open_source(63)
    (tmp_path / "junk.avi").write_bytes(b"not a video")
    with pytest.raises(CameraError, match="cannot open"):
        open_source(str(tmp_path / "junk.avi"))


def test_parse_spec():
    assert parse_spec(0) == 0 and parse_spec(" 2 ") == 2
    assert parse_spec("rtsp://cam/stream") == "rtsp://cam/stream"
    for bad in (-1, "", True, 1.5):
        with pytest.raises(CameraError):
            parse_spec(bad)


def test_importing_the_package_loads_no_opencv():
    import subprocess
    import sys

    code = ("import sys, wott_vision.markers, wott_vision.tracking, wott_vision.render, "
            "wott_vision.camera, wott_vision.driver\nsys.exit('cv2' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0
