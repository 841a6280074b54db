"""Camera sources: an OpenCV ``VideoCapture`` on a device index, a file or a URL.

``open_source`` fails loudly (``CameraError`` with the reason: a ``DriverError``,
and an ``OSError`` as it was before the hub's error tree) instead of returning a
capture that silently reads nothing, so a driver can report *why* it is
disconnected. A source that stops delivering (unplugged device, a video
file at its end, a dropped stream) shows as ``read()`` returning
``(False, None)``; ``CameraReader.failure`` then says which, and the driver
reopens it with backoff.

Recorded sources keep their time (issue 14): a video file's frames carry their
container timestamps (``CAP_PROP_POS_MSEC``, or frame index / the container's
``CAP_PROP_FPS`` where the backend gives none); an image sequence
(``frames/%04d.png``) has no timestamps: frame k is at k / ``fps`` (the
``fps`` setting, default the container's, else 30). ``t_s`` is the time of the
frame last read, from the first frame; ``recorded`` says the reader has one.
With ``realtime`` (default) ``read()`` paces the frames at that recorded rate,
like a camera; without, it returns them as fast as they are read, still with
their recorded ``t_s`` (batch evaluation).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from wott_hub.plugin_api import DriverError

__all__ = ["CameraError", "CameraReader", "open_source", "parse_spec"]


class CameraError(DriverError, OSError):
    """A camera source that cannot be opened or has stopped delivering frames."""


def parse_spec(spec: int | str) -> int | str:
    """A device index stays an int (``"0"`` too); anything else is a path or URL."""
    if isinstance(spec, bool):
        raise CameraError(f"camera source must be a device index, file or URL, got {spec!r}")
    if isinstance(spec, int | np.integer):
        if spec < 0:
            raise CameraError(f"camera index must be >= 0, got {spec}")
        return int(spec)
    if isinstance(spec, str):
        s = spec.strip()
        if not s:
            raise CameraError("empty camera source")
        if s.isdigit():
            return int(s)
        return s
    raise CameraError(f"camera source must be a device index, file or URL, got {spec!r}")


class CameraReader:
    """A ``VideoCapture`` with a name, a frame count and the reason it stopped."""

    def __init__(self, capture: Any, spec: int | str, *, fps: float | None = None,
                 realtime: bool = True) -> None:
        self._cap = capture
        self.spec = spec
        self.frames_read = 0
        self.failure = ""
        self.realtime = realtime
        self.recorded = self.is_file
        self.sequence = isinstance(spec, str) and "%" in spec
        self.t_s: float | None = None
        self._fps = fps
        self._t0: float | None = None  # monotonic time of the first frame (realtime pacing)

    @property
    def is_file(self) -> bool:
        return isinstance(self.spec, str) and "://" not in self.spec

    def read(self) -> tuple[bool, np.ndarray | None]:
        start = time.monotonic()  # the first frame's decoding is its reading, not every frame's delay
        ok, frame = self._cap.read()
        if not ok or frame is None:
            if self.is_file and self.frames_read:
                self.failure = f"video file {self.spec} ended after {self.frames_read} frames"
            elif self.frames_read:
                self.failure = f"camera {self.spec!r} stopped delivering frames after {self.frames_read}"
            else:
                self.failure = f"camera {self.spec!r} opened but delivered no frame"
            return False, None
        self.frames_read += 1
        if self.recorded:
            self.t_s = self._recorded_time()
            if self.realtime:
                now = time.monotonic()
                if self._t0 is None:
                    self._t0 = start - self.t_s
                due = self._t0 + self.t_s
                if due > now:
                    time.sleep(due - now)
        return True, frame

    @property
    def fps(self) -> float:
        """The recorded frame rate: the setting, else the container's, else 30."""
        if self._fps:
            return float(self._fps)
        import cv2

        container = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        return container if 0 < container < 10_000 else 30.0

    def _recorded_time(self) -> float:
        """Time of the frame just read, s from the first frame (see module doc)."""
        k = self.frames_read - 1
        if self.sequence or self._fps:
            return k / self.fps
        import cv2

        ms = float(self._cap.get(cv2.CAP_PROP_POS_MSEC) or 0.0)
        t = ms / 1000.0
        if k > 0 and (self.t_s is None or t <= self.t_s):  # a backend without timestamps
            t = k / self.fps
        return t

    def isOpened(self) -> bool:  # noqa: N802 - VideoCapture's name
        return bool(self._cap.isOpened())

    def release(self) -> None:
        self._cap.release()

    def __enter__(self) -> CameraReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __repr__(self) -> str:
        return f"CameraReader({self.spec!r}, frames_read={self.frames_read})"


def open_source(spec: int | str, *, fps: float | None = None, realtime: bool = True) -> CameraReader:
    """Open a device index, a video/image-sequence file or a stream URL, or raise ``CameraError``.

    ``fps`` and ``realtime`` apply to files (see the module doc): the recorded rate of an image
    sequence, and whether to play at it."""
    import cv2

    src = parse_spec(spec)
    if isinstance(src, str) and "://" not in src and "%" not in src and not Path(src).exists():
        raise CameraError(f"camera source {src!r}: no such file")
    cap = cv2.VideoCapture(src)
    if not cap.isOpened():
        cap.release()
        kind = "camera device" if isinstance(src, int) else "video source"
        raise CameraError(f"cannot open {kind} {src!r} (missing, busy or unsupported format)")
    return CameraReader(cap, src, fps=fps, realtime=realtime)
