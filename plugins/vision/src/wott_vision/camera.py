"""Camera sources: an OpenCV ``VideoCapture`` on a device index, a file or a URL.

``open_source`` fails loudly (``CameraError`` with the reason) instead of
returning a capture that silently reads nothing, so a driver can report *why*
it is disconnected. A source that stops delivering (unplugged device, a video
file at its end, a dropped stream) shows as ``read()`` returning
``(False, None)``; ``CameraReader.failure`` then says which, and the driver
reopens it with backoff.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CameraError", "CameraReader", "open_source", "parse_spec"]


class CameraError(OSError):
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

    def __init__(self, capture: Any, spec: int | str) -> None:
        self._cap = capture
        self.spec = spec
        self.frames_read = 0
        self.failure = ""

    @property
    def is_file(self) -> bool:
        return isinstance(self.spec, str) and "://" not in self.spec

    def read(self) -> tuple[bool, np.ndarray | None]:
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
        return True, frame

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


def open_source(spec: int | str) -> CameraReader:
    """Open a device index, a video/image-sequence file or a stream URL, or raise ``CameraError``."""
    import cv2

    src = parse_spec(spec)
    if isinstance(src, str) and "://" not in src and "%" not in src and not Path(src).exists():
        raise CameraError(f"camera source {src!r}: no such file")
    cap = cv2.VideoCapture(src)
    if not cap.isOpened():
        cap.release()
        kind = "camera device" if isinstance(src, int) else "video source"
        raise CameraError(f"cannot open {kind} {src!r} (missing, busy or unsupported format)")
    return CameraReader(cap, src)
