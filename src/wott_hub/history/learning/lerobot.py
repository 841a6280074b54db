"""A LeRobotDataset v3.0 written block by block (``--format lerobot``): parquet, videos, meta, card.

Layout (lerobot v0.6.1, what every release from 0.4 to 0.6 reads)::

    meta/info.json  meta/stats.json  meta/tasks.parquet  meta/episodes/chunk-000/file-000.parquet
    data/chunk-XXX/file-XXX.parquet            many episodes a file, a new file past 100 MB
    videos/<key>/chunk-XXX/file-XXX.mp4        per camera, many episodes a file (video.py)
    README.md                                  the dataset card (card.py)

An episode's rows go straight to the data file (written in a thread of its own, ``behind.py``); its
stats' first pass runs on each block and spills the values (``work/*.spill``), read back once at the
episode's end for the second pass (``stats.FeatureStats``: the histogram needs the episode's min and
max). Memory holds a block of
frames, never an episode. Rows: ``index`` counts frames over the dataset,
``frame_index`` within the episode, ``timestamp`` is ``frame_index / fps``; tasks are numbered in the
order they first appear.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .behind import WriterBehind
from .lerobot_files import (
    CHUNKS_SIZE,
    CODEBASE_VERSION,
    DATA_FILE_MB,
    arrow_array,
    data_path,
    schema,
    serialised,
    write_episodes,
    write_json,
    write_tasks,
)
from .stats import FeatureStats, aggregate
from .video import VIDEO_FILE_MB

if TYPE_CHECKING:
    from .features import Feature
    from .resample import Held
    from .video import CameraVideo
    from .video_process import VideoProcess

__all__ = ["LeRobotWriter"]


class LeRobotWriter:
    """Writes a dataset into ``root`` (a new, empty folder): ``begin``, ``block``..., ``end`` per episode,
    then ``finish``."""

    def __init__(
        self,
        root: Path,
        fps: int,
        features: list[Feature],
        cameras: Sequence[CameraVideo | VideoProcess],
        robot_type: str | None = None,
    ) -> None:
        self.root, self.fps, self.robot_type = root, fps, robot_type
        self.features = features  # the videos' too, in info.json's order
        self.columns = [f for f in features if f.dtype != "video"]
        self.schema = schema(features)
        self.cameras = cameras
        self.tasks: list[str] = []
        self.episodes: list[dict[str, Any]] = []
        self.stats: dict[str, dict[str, np.ndarray]] | None = None
        self.frames = 0
        self.chunk, self.index = 0, 0
        self._data: WriterBehind | None = None
        self._data_frames = 0
        self._work = root / "work"  # the stats' spill files
        self._stats: dict[str, FeatureStats] = {}
        self._row: dict[str, Any] = {}

    # --- episodes -----------------------------------------------------------------------------

    def task_index(self, task: str) -> int:
        if task not in self.tasks:
            self.tasks.append(task)
        return self.tasks.index(task)

    def begin(self, episode: int, task: str, frames: int) -> None:
        self._work.mkdir(parents=True, exist_ok=True)
        self._next_data_file(frames)
        self._stats = {
            f.key: FeatureStats(f.dtype, f.shape, self._work / f"{i}.spill")
            for i, f in enumerate(self.columns)
        }
        self._row = {
            "episode_index": episode,
            "tasks": [task],
            "length": frames,
            "data/chunk_index": self.chunk,
            "data/file_index": self.index,
            "dataset_from_index": self.frames,
            "dataset_to_index": self.frames + frames,
        }
        for cam in self.cameras:
            self._row.update(cam.begin(frames))

    def block(self, values: dict[str, np.ndarray], images: list[Held]) -> None:
        """One block of frames: every column's values (frames x shape), each camera's held images."""
        import pyarrow as pa

        assert self._data is not None
        self._data.write(pa.table([arrow_array(f, values[f.key]) for f in self.columns], schema=self.schema))
        for f in self.columns:
            self._stats[f.key].first(values[f.key])
        for cam, held in zip(self.cameras, images, strict=True):
            cam.write(held)

    def end(self) -> None:
        """The episode's stats (their second pass) and its row of meta/episodes."""
        frames = int(self._row["length"])
        stats = {key: st.result() for key, st in self._stats.items()}
        for cam in self.cameras:
            self._row.update(cam.end())
            assert cam.stats is not None
            stats[cam.key] = cam.stats.result()
        self._row["stats"] = stats
        self._row.update({"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0})
        self.episodes.append(self._row)
        self.stats = aggregate(self.stats, stats)
        self.frames += frames
        self._data_frames += frames

    def _next_data_file(self, frames: int) -> None:
        """lerobot's rule: a new file when this one's size and the episode's (at this file's bytes per
        frame) reach ``DATA_FILE_MB``."""
        import pyarrow.parquet as pq

        path = self.root / data_path(self.chunk, self.index)
        if self._data is not None:
            self._data.flush()
            size = path.stat().st_size / 2**20
            if size + size / max(self._data_frames, 1) * frames < DATA_FILE_MB:
                return
            self._data.close()
            self.index += 1
            if self.index == CHUNKS_SIZE:
                self.chunk, self.index = self.chunk + 1, 0
            path = self.root / data_path(self.chunk, self.index)
            self._data_frames = 0
        path.parent.mkdir(parents=True, exist_ok=True)
        self._data = WriterBehind(
            pq.ParquetWriter(path, self.schema, compression="snappy", use_dictionary=False)
        )

    # --- the end ------------------------------------------------------------------------------

    def finish(self, provenance: dict[str, Any]) -> None:
        """Close the files and write the meta folder and the card."""
        from .card import card

        if self._data is not None:
            self._data.close()
            self._data = None
        for cam in self.cameras:
            cam.close()
        if self._work.exists():
            self._work.rmdir()
        write_tasks(self.tasks, self.root)
        write_episodes(self.episodes, self.root)
        write_json(serialised(self.stats or {}), self.root / "meta/stats.json")
        write_json(self.info(), self.root / "meta/info.json")
        write_json(provenance, self.root / "meta/wott.json")
        (self.root / "README.md").write_text(card(self.info(), provenance), encoding="utf-8")

    def info(self) -> dict[str, Any]:
        """``meta/info.json``: the keys of lerobot's ``create_empty_dataset_info``, in its order."""
        features = {}
        for f in self.features:
            d = f.declared()
            if f.dtype == "video":
                cam = next(c for c in self.cameras if c.key == f.key)
                d["info"] = cam.settings.info(cam.height, cam.width, self.fps)
            features[f.key] = d
        n = len(self.episodes)
        return {
            "codebase_version": CODEBASE_VERSION,
            "robot_type": self.robot_type,
            "total_episodes": n,
            "total_frames": self.frames,
            "total_tasks": len(self.tasks),
            "chunks_size": CHUNKS_SIZE,
            "data_files_size_in_mb": DATA_FILE_MB,
            "video_files_size_in_mb": VIDEO_FILE_MB,
            "fps": self.fps,
            "splits": {"train": f"0:{n}"},
            "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
            "video_path": (
                "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
                if self.cameras
                else None
            ),
            "features": json.loads(json.dumps(features)),
        }

    def abort(self) -> None:
        """Close what is open (the folder is removed by the caller)."""
        if self._data is not None:
            self._data.close(check=False)
            self._data = None
        for st in self._stats.values():
            st.close()
        for cam in self.cameras:
            cam.close()
