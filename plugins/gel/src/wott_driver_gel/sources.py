"""Where a gel sensor's frames come from: a recording (``source``) or the sensor (``device``/``serial``).

Recordings: a video file or an image-sequence pattern (``frames/%04d.png``) are opened by
``wott_vision.camera.open_source`` (its timestamps, pacing and failure reasons); a folder of
images is read here (``FolderReader``: its images in name order, frame k at k / ``fps``). A
recording is taken as it was recorded: the shaping below is the sensor's, not a replay's.

The sensors (UVC cameras; none of this was tried on a device, docs/gel.md):

- ``MiniCamera``: a GelSight Mini's MJPEG stream at its native 3280 x 2464, asked for undecoded
  (``CAP_PROP_CONVERT_RGB`` off, where the V4L2 backend gives the JPEG bytes) and decoded at an
  eighth of its scale by libjpeg's DCT scaling (``MINI_DECODE_SCALE``, ``cv2.IMREAD_REDUCED_COLOR_8``:
  410 x 308, an eighth of a full decode's cost), then shaped as the maker's software shapes it
  (``shape_mini``).
- ``DigitCamera``: a DIGIT at one of digit-interface's streams, its LED set through the control
  digit-interface uses (``CAP_PROP_ZOOM`` carries the packed R, G, B levels), each frame turned 90°.
- ``video_device_for_serial``: the ``/dev/videoN`` of a sensor's serial number, through udev.

Every reader has the ``cv2.VideoCapture`` interface ``wott_vision.driver.CameraDriver`` runs, and is
released by the thread that reads it (the driver's worker).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from wott_vision.camera import CameraError

from .specs import DIGIT_LED_MAX, DIGIT_STREAMS, MINI_BORDER_FRACTION, MINI_DECODE_SCALE, MINI_SIZE

__all__ = ["IMAGE_SUFFIXES", "DigitCamera", "FolderReader", "MiniCamera", "decode_reduced", "rotate_digit",
           "shape_mini", "video_device_for_serial"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


class FolderReader:
    """The images of a folder, in name order, as a recorded camera at ``fps`` (``realtime``: paced)."""

    recorded = True

    def __init__(self, folder: str, fps: float, *, realtime: bool = True) -> None:
        self.folder = Path(folder)
        self.paths = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.paths:
            raise CameraError(f"source {folder!r}: a folder with no images ({', '.join(IMAGE_SUFFIXES)})")
        self.fps, self.realtime = float(fps), realtime
        self.frames_read = 0
        self.failure = ""
        self.t_s: float | None = None
        self._t0: float | None = None

    def isOpened(self) -> bool:  # noqa: N802 - VideoCapture's name
        return True

    def read(self) -> tuple[bool, np.ndarray | None]:
        # the clock starts as the first read starts: its decoding (and cv2's first import) is the first
        # frame's reading, not a delay of every frame after it (the hub stamps frames from the open)
        if self.realtime and self._t0 is None:
            self._t0 = time.monotonic()
        import cv2

        k = self.frames_read
        if k >= len(self.paths):
            self.failure = f"image folder {str(self.folder)!r} ended after {k} frames"
            return False, None
        image = cv2.imread(str(self.paths[k]), cv2.IMREAD_COLOR)
        if image is None:
            self.failure = f"image {str(self.paths[k])!r} is unreadable"
            return False, None
        self.frames_read += 1
        self.t_s = k / self.fps
        if self.realtime and self._t0 is not None:
            now = time.monotonic()
            due = self._t0 + self.t_s
            if due > now:
                time.sleep(due - now)
        return True, image

    def release(self) -> None:
        self.paths = self.paths[:self.frames_read]


def decode_reduced(jpeg: np.ndarray | bytes, reduce: int = 4) -> np.ndarray:
    """A JPEG decoded at 1/``reduce`` scale by libjpeg's DCT scaling (1, 2, 4 or 8)."""
    import cv2

    flags = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
             8: cv2.IMREAD_REDUCED_COLOR_8}[reduce]
    buf = np.frombuffer(jpeg, dtype=np.uint8) if isinstance(jpeg, bytes) else np.asarray(jpeg).reshape(-1)
    image = cv2.imdecode(buf, flags)
    if image is None:
        raise CameraError("a frame is not a JPEG image")
    return image


def shape_mini(frame: np.ndarray, size: tuple[int, int] = MINI_SIZE,
               border_fraction: float = MINI_BORDER_FRACTION) -> np.ndarray:
    """gsrobotics' ``crop_and_resize``: ``border_fraction`` of the height (of the width) cut from the top
    and the bottom (the left and the right), the rest resized to ``size`` (width, height)."""
    import cv2

    h, w = frame.shape[:2]
    by, bx = int(h * border_fraction), int(w * border_fraction)
    return cv2.resize(frame[by:h - by, bx:w - bx], size, interpolation=cv2.INTER_AREA)


def rotate_digit(frame: np.ndarray) -> np.ndarray:
    """digit-interface's turn of a DIGIT frame: transposed, then flipped about the x axis (90°
    anticlockwise), as one ``cv2.rotate``: the same pixels in one pass, without the transposed copy in
    between (a fresh 230 kB buffer each frame: where the allocator maps it anew, its pages fault in
    and the two steps cost 0.27-0.30 ms against 0.03-0.06; where it reuses them, 0.07 against 0.06)."""
    import cv2

    return cv2.rotate(frame, cv2.ROTATE_90_COUNTERCLOCKWISE)


class _Device:
    """A V4L2 camera opened by its path or index; ``failure`` says why it stopped."""

    def __init__(self, device: int | str) -> None:
        import cv2

        self.spec = device
        self._cap: Any = cv2.VideoCapture(device, cv2.CAP_V4L2)
        self.frames_read = 0
        self.failure = ""
        if not self._cap.isOpened():
            self._cap.release()
            raise CameraError(f"cannot open camera device {device!r} (missing, busy or not a camera)")

    def isOpened(self) -> bool:  # noqa: N802 - VideoCapture's name
        return bool(self._cap.isOpened())

    def _grab(self) -> np.ndarray | None:
        ok, frame = self._cap.read()
        if not ok or frame is None:
            self.failure = (f"camera {self.spec!r} stopped delivering frames after {self.frames_read}"
                            if self.frames_read else f"camera {self.spec!r} opened but delivered no frame")
            return None
        self.frames_read += 1
        return np.asarray(frame)

    def release(self) -> None:
        self._cap.release()


class MiniCamera(_Device):
    """A GelSight Mini: native MJPEG, decoded at a quarter scale, shaped (see the module doc)."""

    def __init__(self, device: int | str, size: tuple[int, int] = MINI_SIZE) -> None:
        import cv2

        super().__init__(device)
        self.size = size
        cap = self._cap
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*"MJPG"))
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, 3280)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, 2464)
        self.undecoded = bool(cap.set(cv2.CAP_PROP_CONVERT_RGB, 0))

    def read(self) -> tuple[bool, np.ndarray | None]:
        frame = self._grab()
        if frame is None:
            return False, None
        if frame.ndim == 1 or (frame.ndim == 2 and frame.shape[0] == 1):  # the JPEG bytes
            frame = decode_reduced(frame, MINI_DECODE_SCALE)
        return True, shape_mini(frame, self.size)


class DigitCamera(_Device):
    """A DIGIT at ``stream`` (``DIGIT_STREAMS``) with its LED at ``led`` (R, G, B levels 0..15)."""

    def __init__(self, device: int | str, stream: str = "QVGA60",
                 led: tuple[int, int, int] = (DIGIT_LED_MAX,) * 3) -> None:
        import cv2

        super().__init__(device)
        width, height, fps = DIGIT_STREAMS[stream]
        cap = self._cap
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        cap.set(cv2.CAP_PROP_FPS, fps)
        r, g, b = led
        cap.set(cv2.CAP_PROP_ZOOM, (r << 8) | (g << 4) | b)  # digit-interface's set_intensity_rgb

    def read(self) -> tuple[bool, np.ndarray | None]:
        frame = self._grab()
        if frame is None:
            return False, None
        return True, rotate_digit(frame)


def video_device_for_serial(serial: str) -> str:
    """The ``/dev/videoN`` capture node of the USB camera whose udev ``ID_SERIAL_SHORT`` is ``serial``.

    Not tried on a device (docs/gel.md): it reads udev's database through pyudev as
    ``udevadm info`` shows it; a camera with several nodes gives its capture node (index 0).
    """
    import pyudev

    found = []
    for dev in pyudev.Context().list_devices(subsystem="video4linux"):
        props = dev.properties
        if props.get("ID_SERIAL_SHORT") == serial and dev.device_node:
            found.append((props.get("ID_V4L_CAPABILITIES", ""), dev.attributes.get("index"), dev.device_node))
    for caps, index, node in sorted(found, key=lambda f: str(f[2])):
        if ":capture:" in str(caps) or index in (None, b"0"):
            return str(node)
    raise CameraError(f"no video device with serial {serial!r} (is the sensor plugged in?)")
