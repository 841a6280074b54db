"""A LeRobotDataset v3.0 checked the way lerobot loads it, without torch (lerobot v0.6.1's load path).

lerobot needs torch (and Python >= 3.12 since 0.5): it cannot run here. What it does on load is
repeated with ``datasets``, ``pyarrow``, pandas and PyAV, each step raising ``Invalid`` with what is
wrong, as lerobot would fail (or silently train on a broken dataset):

- ``meta/info.json`` read as ``DatasetInfo.from_dict`` takes it (every key it knows, nothing else);
  the features get ``datasets`` types by ``get_hf_features_from_features``; the data files are loaded
  by ``Dataset.from_parquet(paths, features=...)`` (``load_nested_dataset``; kept in memory here, not in
  ``datasets``' cache, which a test that rewrites a file would otherwise read again), and the episodes'
  by ``load_nested_dataset(meta/episodes)``;
- every row has each feature's declared shape and dtype; ``index`` is 0..total_frames-1 in order, each
  episode's rows are ``dataset_from_index``..``dataset_to_index`` with ``frame_index`` 0..length-1,
  ``episode_index`` its own, ``timestamp`` exactly ``float32(frame_index / fps)``; the episode's data
  file (``data/chunk_index``, ``data/file_index``) holds those rows;
- ``meta/tasks.parquet`` read by pandas has the index ``task`` and ``task_index`` 0..n-1, each row's
  ``task_index`` is one of them and its episode's ``tasks`` names it;
- ``meta/stats.json`` (``cast_stats_to_numpy``, ``_assert_type_and_shape``): every numeric feature has
  min, max, mean, std, count, q01, q10, q50, q90, q99, each of the shape lerobot's stats give;
- every video frame lerobot would ask for (``from_timestamp + timestamp`` of each row) is found by PyAV
  within ``tolerance_s`` = 1e-4 s (``decode_video_frames_pyav``: seek, decode, nearest frame).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["INFO_KEYS", "Invalid", "Loaded", "check_lerobot", "hf_features"]

TOLERANCE_S = 1e-4
INFO_KEYS = {
    "codebase_version",
    "fps",
    "features",
    "total_episodes",
    "total_frames",
    "total_tasks",
    "chunks_size",
    "data_files_size_in_mb",
    "video_files_size_in_mb",
    "data_path",
    "video_path",
    "robot_type",
    "splits",
}
DEFAULTS = {
    "timestamp": "float32",
    "frame_index": "int64",
    "episode_index": "int64",
    "index": "int64",
    "task_index": "int64",
}
STAT_KEYS = {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}


class Invalid(AssertionError):
    """What lerobot's load path would trip on."""


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise Invalid(message)


def hf_features(features: dict[str, dict[str, Any]]) -> Any:
    """lerobot's ``get_hf_features_from_features``."""
    import datasets

    out = {}
    for key, ft in features.items():
        shape = tuple(ft["shape"])
        if ft["dtype"] == "video":
            continue
        if ft["dtype"] == "image":
            out[key] = datasets.Image()
        elif shape == (1,):
            out[key] = datasets.Value(dtype=ft["dtype"])
        elif len(shape) == 1:
            out[key] = datasets.Sequence(length=shape[0], feature=datasets.Value(dtype=ft["dtype"]))
        elif len(shape) == 2:
            out[key] = datasets.Array2D(shape=shape, dtype=ft["dtype"])
        elif len(shape) == 3:
            out[key] = datasets.Array3D(shape=shape, dtype=ft["dtype"])
        else:
            raise Invalid(f"feature {key!r}: shape {shape} has no datasets type")
    return datasets.Features(out)


class Loaded:
    """What the check read: info, the data and episodes as ``datasets``, tasks, stats."""

    def __init__(self, root: Path) -> None:
        import datasets
        import pandas as pd
        import pyarrow.parquet as pq

        self.root = root
        self.info = json.loads((root / "meta/info.json").read_text())
        _require(
            set(self.info) == INFO_KEYS,
            f"info.json keys {sorted(set(self.info) ^ INFO_KEYS)} differ from DatasetInfo's",
        )
        _require(self.info["codebase_version"] == "v3.0", "codebase_version is not v3.0")
        _require(isinstance(self.info["fps"], int) and self.info["fps"] > 0, "fps is not a positive integer")
        self.fps = self.info["fps"]
        self.features = self.info["features"]
        for key, dtype in DEFAULTS.items():
            _require(
                key in self.features
                and self.features[key]["dtype"] == dtype
                and tuple(self.features[key]["shape"]) == (1,),
                f"default feature {key!r} missing or wrong",
            )
        for key in self.features:
            _require("/" not in key, f"feature {key!r} has a '/'")
        paths = sorted(str(p) for p in (root / "data").glob("*/*.parquet"))
        _require(bool(paths), "no data parquet file")
        try:
            self.data = datasets.Dataset.from_parquet(
                paths, features=hf_features(self.features), keep_in_memory=True
            )
        except (ValueError, TypeError, KeyError, datasets.exceptions.DatasetGenerationError) as e:
            raise Invalid(f"datasets cannot load the data with the declared features: {e!r}") from None
        self.files = {p: pq.ParquetFile(p).metadata.num_rows for p in paths}
        self.episodes = datasets.Dataset.from_parquet(
            sorted(str(p) for p in (root / "meta/episodes").glob("*/*.parquet")), keep_in_memory=True
        )
        self.tasks = pd.read_parquet(root / "meta/tasks.parquet")
        self.stats = json.loads((root / "meta/stats.json").read_text())


def _rows(loaded: Loaded) -> None:
    info, data = loaded.info, loaded.data
    _require(len(data) == info["total_frames"], f"{len(data)} rows, info says {info['total_frames']}")
    columns = {k for k, f in loaded.features.items() if f["dtype"] != "video"}
    _require(
        set(data.column_names) == columns,
        f"columns {sorted(set(data.column_names) ^ columns)} differ from the declared features",
    )
    for start in range(0, len(data), 4096):
        batch = data.with_format("numpy")[start : start + 4096]
        n = len(batch["index"])
        for key in columns:
            ft = loaded.features[key]
            shape = tuple(ft["shape"])
            want = (n,) if shape == (1,) else (n, *shape)
            got = np.asarray(batch[key])
            _require(got.shape == want, f"{key!r}: rows of shape {got.shape[1:]}, declared {shape}")
            _require(got.dtype == np.dtype(ft["dtype"]), f"{key!r}: {got.dtype}, declared {ft['dtype']}")
        _require(
            bool((batch["index"] == np.arange(start, start + n)).all()), f"index is not 0..N-1 at row {start}"
        )
        ts = batch["timestamp"]
        _require(
            bool((ts == (batch["frame_index"] / loaded.fps).astype(np.float32)).all()),
            f"timestamp is not frame_index / fps near row {start}",
        )


def _episodes(loaded: Loaded) -> None:
    info, eps = loaded.info, loaded.episodes
    _require(len(eps) == info["total_episodes"], f"{len(eps)} episodes, info says {info['total_episodes']}")
    tasks = loaded.tasks
    _require(
        tasks.index.name == "task" and list(tasks.columns) == ["task_index"],
        "tasks.parquet is not indexed by task",
    )
    _require(list(tasks["task_index"]) == list(range(len(tasks))), "task_index is not 0..n-1")
    _require(len(tasks) == info["total_tasks"], "total_tasks differs from tasks.parquet")
    data = loaded.data.with_format("numpy")
    at = 0
    offsets = {}
    for p, n in loaded.files.items():
        offsets[p] = (at, at + n)
        at += n
    for i, ep in enumerate(eps):
        _require(ep["episode_index"] == i, f"episode {i} has episode_index {ep['episode_index']}")
        lo, hi = ep["dataset_from_index"], ep["dataset_to_index"]
        _require(hi - lo == ep["length"] > 0, f"episode {i}: from/to index and length disagree")
        _require(
            lo == (eps[i - 1]["dataset_to_index"] if i else 0), f"episode {i} does not follow the previous"
        )
        rows = data[lo:hi]
        _require(bool((rows["episode_index"] == i).all()), f"episode {i}: rows of another episode")
        _require(
            bool((rows["frame_index"] == np.arange(hi - lo)).all()), f"episode {i}: frame_index is not 0.."
        )
        path = str(
            loaded.root
            / info["data_path"].format(chunk_index=ep["data/chunk_index"], file_index=ep["data/file_index"])
        )
        _require(
            path in offsets and offsets[path][0] <= lo and hi <= offsets[path][1],
            f"episode {i}: its data file does not hold its rows",
        )
        names = [tasks.iloc[t].name for t in np.unique(rows["task_index"])]
        _require(
            all(0 <= t < len(tasks) for t in np.unique(rows["task_index"])),
            f"episode {i}: unknown task_index",
        )
        _require(
            sorted(names) == sorted(ep["tasks"]), f"episode {i}: tasks {ep['tasks']} but rows say {names}"
        )
        for key in loaded.features:
            if loaded.features[key]["dtype"] != "string":
                _require(f"stats/{key}/count" in ep, f"episode {i}: no stats of {key!r}")


def _stats(loaded: Loaded) -> None:
    for key, ft in loaded.features.items():
        if ft["dtype"] == "string":
            continue
        _require(key in loaded.stats, f"stats.json has no {key!r}")
        st = {k: np.atleast_1d(np.array(v)) for k, v in loaded.stats[key].items()}
        _require(set(st) == STAT_KEYS, f"{key!r}: stats {sorted(st)}")
        shape = tuple(ft["shape"])
        want = (3, 1, 1) if ft["dtype"] in ("video", "image") else (shape[-1],)
        for name, value in st.items():
            _require(
                value.shape == ((1,) if name == "count" else want),
                f"{key!r} {name}: shape {value.shape}, lerobot makes {want}",
            )
            if "image" in key and name != "count":  # _assert_type_and_shape
                _require(value.shape in ((3, 1, 1), (1, 1, 1)), f"{key!r} {name}: not an image's shape")
        _require(int(st["count"][0]) > 0, f"{key!r}: count 0")


def _videos(loaded: Loaded) -> None:
    import av

    videos = [k for k, f in loaded.features.items() if f["dtype"] == "video"]
    data = loaded.data.with_format("numpy")
    for key in videos:
        ft = loaded.features[key]
        for i, ep in enumerate(loaded.episodes):
            path = loaded.root / loaded.info["video_path"].format(
                video_key=key,
                chunk_index=ep[f"videos/{key}/chunk_index"],
                file_index=ep[f"videos/{key}/file_index"],
            )
            _require(path.exists(), f"{key!r} episode {i}: no {path}")
            start = ep[f"videos/{key}/from_timestamp"]
            wanted = start + data[ep["dataset_from_index"] : ep["dataset_to_index"]]["timestamp"].astype(
                np.float64
            )
            with av.open(str(path)) as container:
                stream = container.streams.video[0]
                _require(
                    (stream.height, stream.width) == tuple(ft["shape"][:2]),
                    f"{key!r}: frames of another size",
                )
                container.seek(
                    max(0, round(float(wanted[0]) / stream.time_base) - 1),
                    backward=True,
                    any_frame=False,
                    stream=stream,
                )
                found = []
                for frame in container.decode(stream):
                    if frame.pts is None:
                        continue
                    found.append(float(frame.pts * stream.time_base))
                    if found[-1] >= wanted[-1]:
                        break
            found_ts = np.sort(np.array(found))
            _require(len(found_ts) > 0, f"{key!r} episode {i}: no frame decoded")
            at = (
                np.clip(np.searchsorted(found_ts, wanted), 1, len(found_ts) - 1)
                if len(found_ts) > 1
                else np.zeros(len(wanted), np.int64)
            )
            nearest = np.minimum(
                np.abs(found_ts[at] - wanted), np.abs(found_ts[np.maximum(at - 1, 0)] - wanted)
            )
            bad = np.nonzero(nearest >= TOLERANCE_S)[0]
            _require(
                not len(bad),
                f"{key!r} episode {i}: {len(bad)} rows have no frame within {TOLERANCE_S} s "
                f"(first at {wanted[bad[0]] if len(bad) else 0:.6f} s)",
            )


def check_lerobot(root: Path) -> Loaded:
    """Every check of the module's docstring; the loaded parts for the caller's own checks."""
    loaded = Loaded(root)
    _rows(loaded)
    _episodes(loaded)
    _stats(loaded)
    _videos(loaded)
    return loaded
