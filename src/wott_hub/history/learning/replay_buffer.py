"""The diffusion-policy replay buffer (``--format zarr``): ``data/<key>`` arrays and ``meta/episode_ends``.

The layout of real-stanford/diffusion_policy's ``ReplayBuffer`` (``diffusion_policy/common/replay_buffer.py``,
zarr 2.12, numcodecs 0.10): a zarr group (format 2, so that zarr 2 opens it) holding ``data/`` with one
array per key, time first, all of one length, and ``meta/episode_ends`` (int64, uncompressed: the
index one past each episode's last frame). Arrays are chunked along time only, each chunk ~2 MB
(``get_optimal_chunks``), compressed with its ``resolve_compressor('default')``: Blosc lz4, level 5, no
shuffle. ``ReplayBuffer.copy_from_path`` and ``create_from_path`` open it as it is.

Keys (the lerobot features' names without their prefixes, ``.`` as ``_``; docs/learning.md):
``<id>_<feature>`` for the tactile features (``barrel-1_displacement`` (T, N, 3) ...), ``<id>_<camera>``
for camera frames (T, H, W, 3) uint8, ``action`` (``--action``), ``state`` (``--state``), ``age_<id>``,
``timestamp`` (float64 seconds since the epoch of each frame, as the real-robot buffers keep it).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .features import Feature
    from .resample import Held
    from .video import CameraVideo

__all__ = ["ReplayBufferWriter", "optimal_chunks", "zarr_key"]

TARGET_CHUNK_BYTES = 2e6


def optimal_chunks(shape: tuple[int, ...], dtype: Any, target: float = TARGET_CHUNK_BYTES) -> tuple[int, ...]:
    """diffusion_policy's ``get_optimal_chunks``: whole trailing axes while they fit ``target`` bytes, then
    as many rows of the next axis as fit."""
    itemsize = np.dtype(dtype).itemsize
    rshape = list(shape[::-1])
    split = len(shape) - 1
    for i in range(len(shape) - 1):
        this = itemsize * math.prod(rshape[:i])
        following = itemsize * math.prod(rshape[: i + 1])
        if this <= target < following:
            split = i
    rchunks = rshape[:split]
    item = itemsize * math.prod(rshape[:split])
    rchunks.append(min(rshape[split], math.ceil(target / item)))
    rchunks.extend([1] * (len(shape) - len(rchunks)))
    return tuple(rchunks[::-1])


def zarr_key(feature: Feature) -> str:
    key = feature.key
    for prefix in ("observation.tactile.", "observation.images.", "observation."):
        if key.startswith(prefix):
            key = key[len(prefix) :]
            break
    return key.replace(".", "_")


class _Array:
    """One ``data/<key>`` array, written a whole chunk at a time."""

    def __init__(self, group: Any, key: str, shape: tuple[int, ...], dtype: Any) -> None:
        import numcodecs

        # chunked as a long buffer would be (an hour at 30 fps), so short and long exports chunk alike
        self.chunks = optimal_chunks((108_000, *shape), dtype)
        self.array = group.create_array(
            key,
            shape=(0, *shape),
            chunks=self.chunks,
            dtype=dtype,
            compressors=numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.NOSHUFFLE),
        )
        self.pending: list[np.ndarray] = []
        self.rows = 0

    def add(self, values: np.ndarray) -> None:
        self.pending.append(values)
        self.rows += len(values)
        if self.rows >= self.chunks[0]:
            self.flush(whole=True)

    def flush(self, whole: bool = False) -> None:
        if not self.pending:
            return
        block = np.concatenate(self.pending)
        n = len(block) - len(block) % self.chunks[0] if whole else len(block)
        if n:
            self.array.append(block[:n])
        self.pending = [block[n:]] if n < len(block) else []
        self.rows = len(block) - n


class ReplayBufferWriter:
    """Writes ``root`` as a replay buffer: ``begin``, ``block``..., ``end`` per episode, then ``finish``."""

    def __init__(self, root: Path, features: list[Feature], cameras: list[CameraVideo]) -> None:
        import zarr

        self.root = root
        self.group = zarr.open_group(str(root), mode="w", zarr_format=2)
        data = self.group.create_group("data")
        self.columns = [f for f in features if f.dtype != "video" and f.key not in _LEROBOT_ONLY]
        self.arrays = {
            f.key: _Array(data, zarr_key(f), f.shape if f.shape != (1,) else (), f.dtype)
            for f in self.columns
        }
        self.images = [
            (cam, _Array(data, zarr_key(cam.source.features[0]), (cam.height, cam.width, 3), np.uint8))
            for cam in cameras
        ]
        self.time = _Array(data, "timestamp", (), np.float64)
        self.ends: list[int] = []
        self.frames = 0

    def task_index(self, task: str) -> int:
        """Tasks have no column here: they are in the group's attributes, with the episodes."""
        return 0

    def begin(self, episode: int, task: str, frames: int) -> None:
        self.frames += frames

    def block(self, values: dict[str, np.ndarray], images: list[Held]) -> None:
        for f in self.columns:
            v = values[f.key]
            self.arrays[f.key].add(v.reshape(len(v)) if f.shape == (1,) else v)
        for (cam, array), held in zip(self.images, images, strict=True):
            black = np.zeros((1, cam.height, cam.width, 3), np.uint8)
            last, image = -2, black
            for i in held.which.tolist():  # a frame at a time: a block of images would not fit in memory
                if i != last:
                    last, image = i, (cam.source.image(held.samples[i])[None] if i >= 0 else black)
                array.add(image)
        self.time.add(values["t_ns"] / 1e9)

    def end(self) -> None:
        self.ends.append(self.frames)

    def finish(self, attrs: dict[str, Any]) -> None:
        for a in [*self.arrays.values(), *(a for _, a in self.images), self.time]:
            a.flush()
        meta = self.group.create_group("meta")
        ends = np.array(self.ends, np.int64)
        meta.create_array("episode_ends", data=ends, chunks=(max(len(ends), 1),), compressors=None)
        self.group.attrs.update(attrs)

    def abort(self) -> None:
        """Nothing to close: the caller removes the folder."""


_LEROBOT_ONLY = {"frame_index", "episode_index", "index", "task_index", "timestamp"}
"""lerobot's default columns: the replay buffer has ``meta/episode_ends`` and an absolute ``timestamp``."""
