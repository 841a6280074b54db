"""The files of a LeRobotDataset v3.0 other than the videos, written with pyarrow as lerobot writes them.

From lerobot's own writer (v0.6.1: ``dataset_writer.py``, ``dataset_metadata.py``, ``io_utils.py``,
``feature_utils.get_hf_features_from_features``), so that ``LeRobotDataset`` and ``datasets`` read them
as their own:

- ``data/chunk-XXX/file-XXX.parquet``: one row per frame, the features but the videos (snappy, dictionary
  encoding), a (1,) feature as a plain column, (k,) as a fixed-size list, (a, b) as ``datasets.Array2D``
  (its storage, a list of lists, named as its extension type); the schema's ``huggingface`` metadata holds
  the ``datasets`` features, so ``datasets`` loads the files as lerobot's own with or without them;
- ``meta/info.json`` and ``meta/stats.json`` (``json.dump(indent=4)``, arrays as lists);
- ``meta/tasks.parquet``: the pandas frame lerobot writes (index ``task``, column ``task_index``), with
  the pandas metadata that makes ``task`` the index again;
- ``meta/episodes/chunk-000/file-000.parquet``: one row per episode, its per-episode stats flattened to
  ``stats/<feature>/<stat>`` columns (``flatten_dict``).
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pyarrow as pa

    from .features import Feature

__all__ = [
    "CODEBASE_VERSION",
    "DATA_FILE_MB",
    "DEFAULT_FEATURES",
    "arrow_array",
    "data_path",
    "hf_features",
    "write_episodes",
    "write_json",
    "write_tasks",
]

CODEBASE_VERSION = "v3.0"
DATA_FILE_MB = 100
CHUNKS_SIZE = 1000
DEFAULT_FEATURES = {  # lerobot.utils.constants.DEFAULT_FEATURES, in its order
    "timestamp": ("float32", (1,)),
    "frame_index": ("int64", (1,)),
    "episode_index": ("int64", (1,)),
    "index": ("int64", (1,)),
    "task_index": ("int64", (1,)),
}


def data_path(chunk: int, index: int) -> str:
    return f"data/chunk-{chunk:03d}/file-{index:03d}.parquet"


def _arrow_type(f: Feature) -> pa.DataType:
    import pyarrow as pa

    value = pa.float32() if f.dtype == "float32" else pa.int64()
    if f.shape == (1,):
        return value
    if len(f.shape) == 1:
        return pa.list_(value, f.shape[0])
    return pa.list_(pa.list_(value))


def arrow_array(f: Feature, values: np.ndarray) -> pa.Array:
    """A block of ``f``'s values (frames x shape) as its column."""
    import pyarrow as pa

    numbers = np.ascontiguousarray(values, np.float32 if f.dtype == "float32" else np.int64).reshape(-1)
    flat = _wrap(numbers)
    n = len(values)
    if f.shape == (1,):
        return flat
    if len(f.shape) == 1:
        return pa.FixedSizeListArray.from_arrays(flat, f.shape[0])
    rows, cols = f.shape
    inner = pa.ListArray.from_arrays(_offsets(n * rows, cols), flat)
    return pa.ListArray.from_arrays(_offsets(n, rows), inner)


def _wrap(numbers: np.ndarray) -> pa.Array:
    """An array over the numbers' own buffer (``pa.array`` copies them, ~7 ns a number here)."""
    import pyarrow as pa

    return pa.Array.from_buffers(
        pa.from_numpy_dtype(numbers.dtype), len(numbers), [None, pa.py_buffer(numbers)]
    )


@functools.lru_cache(maxsize=16)
def _offsets(n: int, step: int) -> pa.Array:
    """Offsets of ``n`` lists of ``step`` items (the same for every full block)."""
    return _wrap(np.arange(0, n * step + 1, step, dtype=np.int32))


def _hf_value(f: Feature) -> dict[str, Any]:
    value = {"dtype": f.dtype, "_type": "Value"}
    if f.shape == (1,):
        return value
    if len(f.shape) == 1:
        return {"feature": value, "length": f.shape[0], "_type": "List"}
    return {"shape": list(f.shape), "dtype": f.dtype, "_type": f"Array{len(f.shape)}D"}


def hf_features(features: list[Feature]) -> dict[str, Any]:
    """``datasets.Features.to_dict()`` of the parquet columns (``get_hf_features_from_features``'s)."""
    return {f.key: _hf_value(f) for f in features if f.dtype != "video"}


def schema(features: list[Feature]) -> pa.Schema:
    import pyarrow as pa

    columns = [f for f in features if f.dtype != "video"]
    meta = {"huggingface": json.dumps({"info": {"features": hf_features(columns)}})}
    return pa.schema(
        [pa.field(f.key, _arrow_type(f), metadata=_extension(f)) for f in columns], metadata=meta
    )


def _extension(f: Feature) -> dict[bytes, bytes] | None:
    """An (a, b) column is stored as ``datasets.Array2D`` stores it: its storage type, named as that
    extension type (``datasets`` reads it back as an Array2D; without ``datasets`` it is a list of lists)."""
    if len(f.shape) < 2:
        return None
    return {
        b"ARROW:extension:name": f"datasets.features.features.Array{len(f.shape)}DExtensionType".encode(),
        b"ARROW:extension:metadata": json.dumps([list(f.shape), f.dtype]).encode(),
    }


def write_json(data: Any, path: Path) -> None:
    """lerobot's ``write_json``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=4, ensure_ascii=False)


def write_tasks(tasks: list[str], root: Path) -> None:
    """``meta/tasks.parquet`` as lerobot writes it: ``DataFrame({"task_index": ...},
    index=Index(tasks, name="task")).to_parquet``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    pandas = {
        "index_columns": ["task"],
        "column_indexes": [
            {
                "name": None,
                "field_name": None,
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": {"encoding": "UTF-8"},
            }
        ],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": "task",
                "field_name": "task",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.3",
    }
    table = pa.table(
        {"task_index": pa.array(range(len(tasks)), pa.int64()), "task": pa.array(tasks, pa.string())},
        metadata={"pandas": json.dumps(pandas)},
    )
    path = root / "meta/tasks.parquet"
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path)


def _listed(value: Any) -> Any:
    return value.tolist() if isinstance(value, np.ndarray) else value


def write_episodes(rows: list[dict[str, Any]], root: Path) -> None:
    """``meta/episodes/chunk-000/file-000.parquet``: one row per episode (``pa.Table.from_pydict``, as
    ``_flush_metadata_buffer`` makes it), its stats as ``stats/<feature>/<stat>`` lists."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns: dict[str, list[Any]] = {}
    for row in rows:
        for k, v in row.items():
            if k != "stats":
                columns.setdefault(k, []).append(_listed(v))
                continue
            for key, stats in v.items():
                for stat, value in stats.items():
                    columns.setdefault(f"stats/{key}/{stat}", []).append(_listed(value))
    path = root / "meta/episodes/chunk-000/file-000.parquet"
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pydict(columns), path, compression="snappy", use_dictionary=True)


def serialised(stats: dict[str, dict[str, np.ndarray]]) -> dict[str, dict[str, Any]]:
    """``serialize_dict``: every array as its list."""
    return {k: {s: _listed(v) for s, v in st.items()} for k, st in stats.items()}
