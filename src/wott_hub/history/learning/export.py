"""``history export --format lerobot|zarr``: episodes of recorded Things as a learning dataset.

Contract: the output folder must not exist; everything is written into a hidden folder beside it
(``.<name>.partial-<pid>``) and renamed to it only once complete, so an export that fails (bad input,
a full disk, Ctrl-C) leaves nothing behind, and a reader never sees half a dataset. Bad input is a
``WottHubError`` naming it before anything is written: an fps outside [1, ``MAX_FPS``], an unknown
device, an episode shorter than two frames (lerobot's stats need two), a range with no record.

Episodes: those given (``--episodes``), else those marked in history within the range
(``episodes.marked``), else the range itself (from the first record of the Things in it to the last)
as one episode of ``task``. Each episode is resampled (``resample.py``) a block of ``BLOCK`` frames (and at
most ``BLOCK_S`` seconds) at a time and handed to the format's writer (``lerobot.py``,
``replay_buffer.py``). A block's memory is then the same at any length and any fps: its values, and
the records it holds (a camera's images of ``BLOCK_S`` seconds at most, ~20 MB at 1 image/s).
"""

from __future__ import annotations

import datetime as dt
import functools
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from wott_hub.errors import InvalidInput, NotFound

from .episodes import DEFAULT_TASK, Episode, marked
from .features import CameraSource, Feature, block_values
from .plan import Plan, plan, state_values
from .resample import ThingReader, frame_times

if TYPE_CHECKING:
    from ..storage import StorageReader
    from .resample import Held

__all__ = [
    "BLOCK",
    "BLOCK_S",
    "FORMATS",
    "MAX_FPS",
    "DatasetRequest",
    "DatasetSummary",
    "export_dataset",
    "frames_of",
]

FORMATS = ("lerobot", "zarr")
MAX_FPS = 1000
"""Frames per second at most: above it a frame is closer than most devices' own sample period."""
BLOCK = 1024
BLOCK_S = 35
"""Seconds of an episode a block holds at most (1024 frames at 30 fps: 34 s)."""

Progress = Callable[[int, int], None]
"""Called after each block with the frames done and the frames in all."""


@dataclass
class DatasetRequest:
    fmt: str
    out_dir: Path
    things: list[str]
    fps: int = 30
    t_from_ns: int | None = None
    t_to_ns: int | None = None
    episodes: list[Episode] | None = None  # given on the command line; None: marked, else the range
    task: str = DEFAULT_TASK
    state: list[str] = field(default_factory=list)
    action: str | None = None
    codec: str = "h264"
    database: str = ""


@dataclass
class DatasetSummary:
    episodes: int = 0
    frames: int = 0
    records: int = 0


def frames_of(e: Episode, fps: int) -> int:
    """Frames of an episode: every ``k`` whose time ``start + (k * 10**9) // fps`` is at or before its end."""
    return ((e.end_ns - e.start_ns + 1) * fps - 1) // 10**9 + 1


def _episodes(reader: StorageReader, req: DatasetRequest) -> list[Episode]:
    if req.episodes is not None:
        episodes = sorted(req.episodes, key=lambda e: e.start_ns)
    else:
        episodes = marked(reader, req.t_from_ns, req.t_to_ns)
        if not episodes:
            spans = [
                (s.first_t_ns, s.last_t_ns)
                for s in reader.things(count=False)
                if s.id in req.things and s.first_t_ns is not None and s.last_t_ns is not None
            ]
            if spans:
                start = max(min(a for a, _ in spans), req.t_from_ns if req.t_from_ns is not None else 0)
                end = min(max(b for _, b in spans), req.t_to_ns if req.t_to_ns is not None else 1 << 63)
                episodes = [Episode(start, end, req.task)] if start < end else []

    def has_records(e: Episode) -> bool:
        first = reader.first_time(req.things, e.start_ns)
        return first is not None and first <= e.end_ns

    if not any(has_records(e) for e in episodes):
        raise InvalidInput(f"no records of {', '.join(req.things)} in that range: nothing to export")
    for a, b in zip(episodes, episodes[1:], strict=False):
        if b.start_ns <= a.end_ns:
            raise InvalidInput("episodes overlap: each frame belongs to one episode")
    for e in episodes:
        if frames_of(e, req.fps) < 2:
            raise InvalidInput(
                f"an episode of {(e.end_ns - e.start_ns) / 1e9:g} s has less than 2 frames at "
                f"{req.fps} fps (lerobot's stats need two)"
            )
    return episodes


def _check(reader: StorageReader, req: DatasetRequest) -> None:
    if req.fmt not in FORMATS:
        raise InvalidInput(f"format {req.fmt!r}: expected one of {', '.join(FORMATS)}")
    if isinstance(req.fps, bool) or not isinstance(req.fps, int) or not 1 <= req.fps <= MAX_FPS:
        raise InvalidInput(f"--fps must be an integer in [1, {MAX_FPS}], got {req.fps!r}")
    if not req.things:
        raise InvalidInput("no --device: name at least one recorded device")
    for thing in req.things:
        if not reader.recorded(thing):
            raise NotFound(f"no recorded device {thing!r} (see `wott-hub history list`)")
    if req.out_dir.exists():
        raise InvalidInput(f"{str(req.out_dir)!r} exists: a dataset export writes a new folder")
    if not req.out_dir.parent.is_dir():
        raise InvalidInput(f"{str(req.out_dir)!r}: the folder {str(req.out_dir.parent)!r} does not exist")


def export_dataset(
    reader: StorageReader, req: DatasetRequest, progress: Progress | None = None
) -> DatasetSummary:
    """Write the dataset ``req`` asks for; see the module's contract."""
    req.things = list(dict.fromkeys(req.things))
    _check(reader, req)
    episodes = _episodes(reader, req)
    p = plan(reader, req.things, episodes[-1].end_ns, action=req.action, state=req.state)
    partial = req.out_dir.with_name(f".{req.out_dir.name}.partial-{os.getpid()}")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir()
    try:
        summary = _write(reader, req, p, episodes, partial, progress)
        if req.out_dir.exists():
            raise InvalidInput(f"{str(req.out_dir)!r} appeared while exporting: the dataset is not written")
        partial.rename(req.out_dir)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    return summary


class DatasetWriter(Protocol):
    """A format's writer (``lerobot.LeRobotWriter``, ``replay_buffer.ReplayBufferWriter``)."""

    def task_index(self, task: str) -> int: ...

    def begin(self, episode: int, task: str, frames: int) -> None: ...

    def block(self, values: dict[str, np.ndarray], images: list[Held]) -> None:
        """A block of frames: every column's values (``t_ns``: the frames' times), each camera's images."""
        ...

    def end(self) -> None: ...

    def finish(self, provenance: dict[str, Any]) -> None: ...

    def abort(self) -> None: ...


def _writer(req: DatasetRequest, p: Plan, root: Path) -> DatasetWriter:
    from .video import CameraVideo, VideoSettings

    settings = VideoSettings(req.codec)
    if req.fmt == "lerobot":
        from .lerobot import LeRobotWriter
        from .lerobot_files import DEFAULT_FEATURES
        from .video_process import VideoProcess

        defaults = [Feature(k, dtype, shape) for k, (dtype, shape) in DEFAULT_FEATURES.items()]
        # each camera's video in a process of its own (video_process.py: the export's other core)
        videos = [VideoProcess(cam, root, req.fps, settings) for cam in p.cameras()]
        return LeRobotWriter(root, req.fps, [*p.features(), *defaults], videos)
    from .replay_buffer import ReplayBufferWriter

    return ReplayBufferWriter(root, p.features(), [CameraVideo(cam, root, req.fps, settings)
                                                   for cam in p.cameras()])


def _write(
    reader: StorageReader,
    req: DatasetRequest,
    p: Plan,
    episodes: list[Episode],
    root: Path,
    progress: Progress | None,
) -> DatasetSummary:
    writer = _writer(req, p, root)
    summary = DatasetSummary()
    total = sum(frames_of(e, req.fps) for e in episodes)
    rows: list[dict[str, Any]] = []
    try:
        for number, episode in enumerate(episodes):
            n = frames_of(episode, req.fps)
            writer.begin(number, episode.task, n)
            moved = (
                functools.partial(_moved, progress, summary.frames, total) if progress is not None else None
            )
            summary.records += _episode(reader, req.fps, p, episode, number, n, writer, summary.frames, moved)
            writer.end()
            rows.append(
                {
                    "episode": number,
                    "task": episode.task,
                    "start_ns": episode.start_ns,
                    "end_ns": episode.end_ns,
                    "frames": n,
                }
            )
            summary.frames += n
            summary.episodes += 1
        writer.finish(_provenance(req, p, rows))
    except BaseException:
        writer.abort()
        raise
    return summary


def _moved(progress: Progress, before: int, total: int, frames: int) -> None:
    progress(before + frames, total)


def _episode(
    reader: StorageReader,
    fps: int,
    p: Plan,
    episode: Episode,
    number: int,
    n: int,
    writer: DatasetWriter,
    before: int,
    moved: Callable[[int], None] | None,
) -> int:
    readers = [ThingReader(reader, t.thing, t.sources, episode.start_ns, episode.end_ns) for t in p.things]
    task = writer.task_index(episode.task)
    block = max(1, min(BLOCK, BLOCK_S * fps))
    for k0 in range(0, n, block):
        k1 = min(n, k0 + block)
        times = frame_times(episode.start_ns, fps, k0, k1)
        values: dict[str, np.ndarray] = {}
        images: list[Held] = []
        for t, tr in zip(p.things, readers, strict=True):
            held = tr.hold(times)
            for source, h in zip(t.sources, held, strict=True):
                if isinstance(source, CameraSource):
                    images.append(h)
                else:
                    values.update(zip((f.key for f in source.features), block_values(source, h), strict=True))
            values[t.age.key] = np.stack([h.age_s for h in held], axis=1)
        if p.state:
            values["observation.state"] = state_values(p, values, k1 - k0)
        frame = np.arange(k0, k1, dtype=np.int64)
        values.update(
            {
                "timestamp": (frame / fps).astype(np.float32),
                "frame_index": frame,
                "episode_index": np.full(k1 - k0, number, np.int64),
                "index": before + frame,
                "task_index": np.full(k1 - k0, task, np.int64),
                "t_ns": times,
            }
        )
        writer.block(values, images)
        if moved is not None:
            moved(k1)
    return sum(tr.records for tr in readers)


def _provenance(req: DatasetRequest, p: Plan, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """``meta/wott.json`` (the zarr group's attributes): where the dataset came from, the node order."""
    return {
        "exported": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "database": req.database,
        "things": [t.thing for t in p.things],
        "fps": req.fps,
        "action": req.action,
        "state": req.state,
        "nodes": {t.thing: t.nodes for t in p.things if t.nodes},
        "episodes": rows,
    }
