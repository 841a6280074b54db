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
``yuv420p`` once, and a GOP that shows the same images as the one before is muxed again, not encoded
again (``_File.gop``); each episode starts with a keyframe. Before a camera's first image its frames
are black. Stats come from the images of the frames lerobot would sample (``stats.ImageStats``).
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

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
        self.reuse = codec == "h264"  # each frame's packet out at once: a held image's GOP muxed again
        self.extra = {"tune": "zerolatency"} if codec == "h264" else {}

    def options(self) -> dict[str, str]:
        return {"g": str(self.gop), "crf": str(self.crf), "preset": str(self.preset), **self.extra}

    def info(self, height: int, width: int, fps: int) -> dict[str, Any]:
        """The ``info`` of a video feature, as lerobot's ``get_video_info`` writes it."""
        return {
            "video.height": height,
            "video.width": width,
            "video.codec": self.codec,
            "video.pix_fmt": "yuv420p",
            "video.fps": fps,
            "video.channels": 3,
            "has_audio": False,
            "video.g": self.gop,
            "video.crf": self.crf,
            "video.preset": self.preset,
            "video.fast_decode": 0,
            "video.video_backend": "pyav",
            "video.extra_options": dict(self.extra),
            "is_depth_map": False,
        }


class _File:
    """One mp4 being written. Frames go in by GOP (``gop`` frames from a keyframe): a GOP whose frames
    show the same held images as the GOP before is not encoded again; its packets are muxed again at
    its own times (H.264 without B-frames: an IDR and its P-frames decode alone, the same bytes, as a
    ZOH-held image is the same picture). A camera recording 1 image/s at 30 fps is then encoded once
    an image, not 30 times (a 640 x 480 frame costs ~1 ms of x264 here)."""

    def __init__(self, path: Path, fps: int, height: int, width: int, settings: VideoSettings) -> None:
        import av

        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.fps = fps
        self.settings = settings
        self.container: Any = cast(Any, av.open(str(path), "w"))
        options = settings.options()
        self.stream: Any = cast(Any, self.container).add_stream(settings.encoder, rate=fps, options=options)
        self.stream.pix_fmt = "yuv420p"
        self.stream.width, self.stream.height = width, height
        self.stream.time_base = Fraction(1, fps)
        self.frames = 0  # frames in the file
        self.encoded = 0  # frames the encoder saw since its last keyframe
        self._last: tuple[tuple[int, ...], list[tuple[bytes, bool]]] | None = None  # a GOP's images, packets

    def gop(self, keys: tuple[int, ...], frames: list[Any], new_episode: bool) -> None:
        """The next ``len(frames)`` frames (a GOP, or the end of one), showing the images ``keys``."""
        import av

        full = len(frames) == self.settings.gop and self.encoded % self.settings.gop == 0 and not new_episode
        if full and self._last is not None and self._last[0] == keys:
            for k, (data, key) in enumerate(self._last[1]):
                packet = av.Packet(data)
                packet.time_base = Fraction(1, self.fps)  # the frames' (the muxer's own is finer)
                packet.pts = packet.dts = self.frames + k
                packet.stream = self.stream
                packet.is_keyframe = key
                self.container.mux(packet)
            self.frames += len(frames)
            return
        packets: list[tuple[bytes, bool]] = []
        for k, frame in enumerate(frames):
            frame.pts = self.frames
            frame.time_base = Fraction(1, self.fps)
            force = k == 0 and (new_episode or self.encoded % self.settings.gop) and self.frames > 0
            # an episode starts with a keyframe; the frame object is a held image's, used again: set each time
            frame.pict_type = av.video.frame.PictureType.I if force else av.video.frame.PictureType.NONE
            if force:
                self.encoded = 0
            out = self.stream.encode(frame)
            packets += [(bytes(p), bool(p.is_keyframe)) for p in out]
            self.container.mux(out)
            self.frames += 1
            self.encoded += 1
        # kept for the next GOP only if each frame came out at once (x264 zerolatency; not svt-av1)
        ok = full and self.settings.reuse and len(packets) == len(frames) and packets[0][1]
        self._last = (keys, packets) if ok else None

    def close(self) -> None:
        self.container.mux(self.stream.encode(None))
        self.container.close()

    def size_mb(self) -> float:
        return self.path.stat().st_size / 2**20 if self.path.exists() else 0.0


class CameraVideo:
    """One camera's video files under ``root`` (``videos/<key>/chunk-XXX/file-XXX.mp4``)."""

    def __init__(
        self,
        source: CameraSource,
        root: Path,
        fps: int,
        settings: VideoSettings,
        chunks_size: int = 1000,
        file_mb: float = VIDEO_FILE_MB,
    ) -> None:
        self.source = source
        self.key = source.features[0].key
        self.root, self.fps, self.settings = root, fps, settings
        self.height, self.width, _ = source.features[0].shape
        self.chunks_size, self.file_mb = chunks_size, file_mb
        self.chunk, self.index = 0, -1
        self.file: _File | None = None
        self._image: tuple[int, Any, np.ndarray] | None = None  # (seq of the record, yuv frame, rgb)
        self._black: Any = None
        self._yuv: Any = None  # the rgb24 -> yuv420p converter (``_to_yuv``)
        self.stats: ImageStats | None = None
        self._episode_start = 0
        self._frame = 0
        self._gop: list[tuple[int, Any]] = []
        self._first_gop = True

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
        self._gop = []
        self._first_gop = True
        self._episode_start = self.file.frames
        return {
            f"videos/{self.key}/chunk_index": self.chunk,
            f"videos/{self.key}/file_index": self.index,
            f"videos/{self.key}/from_timestamp": self._episode_start / self.fps,
        }

    def end(self) -> dict[str, Any]:
        assert self.file is not None
        self._flush()
        return {f"videos/{self.key}/to_timestamp": self.file.frames / self.fps}

    def _to_yuv(self, rgb: np.ndarray) -> Any:
        """An image as a ``yuv420p`` frame, by swscale as ``VideoFrame.reformat`` converts it (the same
        bytes), through one converter kept for the camera and in this thread: ``reformat`` makes a
        new swscale context an image, with a pool of threads (its default, ``threads=0``), which cost
        ~0.6 ms of setup and, beside the export's other process on a 2-core machine, waits for its
        threads (2.2 ms an image, 1.1 ms so; docs/learning.md, section 6)."""
        import av
        from av.video.reformatter import VideoReformatter

        if self._yuv is None:
            self._yuv = VideoReformatter()
        frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
        return self._yuv.reformat(frame, format="yuv420p", threads=1)

    def _frame_of(self, rec: Any) -> tuple[Any, np.ndarray]:
        if rec is None:
            if self._black is None:
                rgb = np.zeros((self.height, self.width, 3), np.uint8)
                self._black = (self._to_yuv(rgb), rgb)
            return self._black  # type: ignore[no-any-return]
        if self._image is None or self._image[0] != rec.seq:
            rgb = self.source.image(rec)
            self._image = (rec.seq, self._to_yuv(rgb), rgb)
        return self._image[1], self._image[2]

    def write(self, held: Held) -> None:
        """The block's frames, each the image held then: decoded, converted and encoded (in a process of
        its own for an export: ``video_process``)."""
        assert self.file is not None and self.stats is not None
        first = self._frame
        n = len(held.which)
        sampled = self._wanted[(self._wanted >= first) & (self._wanted < first + n)] - first
        picks = np.bincount(held.which[sampled] + 1, minlength=len(held.samples) + 1)
        for k in range(n):
            i = int(held.which[k])
            rec = held.samples[i] if i >= 0 else None
            frame, rgb = self._frame_of(rec)
            if picks[i + 1]:
                self.stats.add(rgb, int(picks[i + 1]))
                picks[i + 1] = 0
            self._gop.append((rec.seq if rec is not None else -1, frame))
            if len(self._gop) == self.settings.gop:
                self._flush()
        self._frame += n

    def _flush(self) -> None:
        assert self.file is not None
        if self._gop:
            self.file.gop(tuple(k for k, _ in self._gop), [f for _, f in self._gop], self._first_gop)
            self._gop, self._first_gop = [], False

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None
