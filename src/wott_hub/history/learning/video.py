"""A camera's frames as lerobot v3.0 videos: one mp4 per file index holding many episodes, through PyAV.

As lerobot's writer leaves them (``dataset_writer._save_episode_video``, ``video_utils``): H.264 or AV1
(``libsvtav1``), ``yuv420p``, a keyframe every 2 frames (``g=2``), crf 30, one frame per dataset row at
``fps``; the episodes of a file follow each other, episode ``e`` from ``from_timestamp`` (the file's
duration before it) to ``to_timestamp`` (``from + frames / fps``); a file is closed and the next one
begun at an episode that starts once it holds ``video_files_size_in_mb`` (200 MB; lerobot decides
before adding the episode, knowing its size; here it is known after, so a file can pass the limit by
one episode). Frame ``k`` of a file has pts ``k`` in a time base of ``1 / fps`` (what the muxer makes
of it is checked: every frame is found within 1e-4 s of its timestamp, ``tests/history/learning``).

A held image (zero-order hold: the same recorded image for many frames) is decoded and converted to
``yuv420p`` once; before a camera's first image its frames are black. Stats come from the images of
the frames lerobot would sample (``stats.ImageStats``).
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from wott_hub.errors import InvalidInput

from .stats import ImageStats

if TYPE_CHECKING:
    from .features import CameraSource
    from .resample import Held

__all__ = ["CODECS", "VIDEO_FILE_MB", "CameraVideo", "VideoSettings"]

VIDEO_FILE_MB = 200
CODECS = {"h264": ("libx264", "ultrafast"), "av1": ("libsvtav1", 12)}
"""``--codec`` -> (FFmpeg encoder, preset). H.264 by default: ``libsvtav1`` at its fastest preset encodes
4x slower here (2 cores), lerobot's default all the same."""


class VideoSettings:
    """How every camera of an export is encoded, and what ``info.json`` says of it."""

    def __init__(self, codec: str = "h264", crf: int = 30, gop: int = 2) -> None:
        if codec not in CODECS:
            raise InvalidInput(f"--codec {codec!r}: expected one of {', '.join(CODECS)}")
        self.codec, self.crf, self.gop = codec, crf, gop
        self.encoder, self.preset = CODECS[codec]

    def options(self) -> dict[str, str]:
        return {"g": str(self.gop), "crf": str(self.crf), "preset": str(self.preset)}

    def info(self, height: int, width: int, fps: int) -> dict[str, Any]:
        """The ``info`` of a video feature, as lerobot's ``get_video_info`` writes it."""
        return {"video.height": height, "video.width": width, "video.codec": self.codec,
                "video.pix_fmt": "yuv420p", "video.fps": fps, "video.channels": 3, "has_audio": False,
                "video.g": self.gop, "video.crf": self.crf, "video.preset": self.preset, "video.fast_decode": 0,
                "video.video_backend": "pyav", "video.extra_options": {}, "is_depth_map": False}


class _File:
    def __init__(self, path: Path, fps: int, height: int, width: int, settings: VideoSettings) -> None:
        import av

        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.container: Any = av.open(str(path), "w")
        self.stream: Any = self.container.add_stream(settings.encoder, rate=fps, options=settings.options())
        self.stream.pix_fmt = "yuv420p"
        self.stream.width, self.stream.height = width, height
        self.stream.time_base = Fraction(1, fps)
        self.frames = 0

    def write(self, frame: Any) -> None:
        frame.pts = self.frames
        self.frames += 1
        self.container.mux(self.stream.encode(frame))

    def close(self) -> None:
        self.container.mux(self.stream.encode(None))
        self.container.close()

    def size_mb(self) -> float:
        return self.path.stat().st_size / 2**20 if self.path.exists() else 0.0


class CameraVideo:
    """One camera's video files under ``root`` (``videos/<key>/chunk-XXX/file-XXX.mp4``)."""

    def __init__(self, source: CameraSource, root: Path, fps: int, settings: VideoSettings,
                 chunks_size: int = 1000, file_mb: float = VIDEO_FILE_MB) -> None:
        self.source = source
        self.key = source.features[0].key
        self.root, self.fps, self.settings = root, fps, settings
        self.height, self.width, _ = source.features[0].shape
        self.chunks_size, self.file_mb = chunks_size, file_mb
        self.chunk, self.index = 0, -1
        self.file: _File | None = None
        self._image: tuple[int, Any, np.ndarray] | None = None  # (seq of the record, yuv frame, rgb)
        self._black: Any = None
        self.stats: ImageStats | None = None
        self._episode_start = 0
        self._frame = 0

    def _next_file(self) -> None:
        if self.file is not None:
            self.file.close()
        self.index += 1
        if self.index == self.chunks_size:
            self.chunk, self.index = self.chunk + 1, 0
        path = self.root / f"videos/{self.key}/chunk-{self.chunk:03d}/file-{self.index:03d}.mp4"
        self.file = _File(path, self.fps, self.height, self.width, self.settings)

    def begin(self, frames: int) -> dict[str, Any]:
        """Start an episode of ``frames`` frames: its ``videos/<key>/*`` columns but ``to_timestamp``."""
        if self.file is None or self.file.size_mb() >= self.file_mb:
            self._next_file()
        assert self.file is not None
        self.stats = ImageStats(frames)
        self._wanted = np.array(self.stats.wanted, np.int64)
        self._frame = 0
        self._episode_start = self.file.frames
        return {f"videos/{self.key}/chunk_index": self.chunk, f"videos/{self.key}/file_index": self.index,
                f"videos/{self.key}/from_timestamp": self._episode_start / self.fps}

    def end(self) -> dict[str, Any]:
        assert self.file is not None
        return {f"videos/{self.key}/to_timestamp": self.file.frames / self.fps}

    def _frame_of(self, rec: Any) -> tuple[Any, np.ndarray]:
        import av

        if rec is None:
            if self._black is None:
                rgb = np.zeros((self.height, self.width, 3), np.uint8)
                self._black = (av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(format="yuv420p"), rgb)
            return self._black  # type: ignore[no-any-return]
        if self._image is None or self._image[0] != rec.seq:
            rgb = self.source.image(rec)
            yuv = av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(format="yuv420p")
            self._image = (rec.seq, yuv, rgb)
        return self._image[1], self._image[2]

    def write(self, held: Held) -> None:
        """The block's frames: each the image held then."""
        assert self.file is not None and self.stats is not None
        first = self._frame
        n = len(held.index)
        sampled = self._wanted[(self._wanted >= first) & (self._wanted < first + n)] - first
        picks = np.bincount(held.index[sampled] + 1, minlength=len(held.samples) + 1)
        for k in range(n):
            i = int(held.index[k])
            rec = held.samples[i] if i >= 0 else None
            frame, rgb = self._frame_of(rec)
            if picks[i + 1]:
                self.stats.add(rgb, int(picks[i + 1]))
                picks[i + 1] = 0
            self.file.write(frame)
        self._frame += n

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None
