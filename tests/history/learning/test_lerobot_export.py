"""``history export --format lerobot`` of real recordings, checked as lerobot loads a dataset
(``lerobot_check``), value by value against history (zero-order hold, row by row), and its stats against
a one-shot computation of lerobot's (v0.6.1) rules."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from .lerobot_check import Invalid, check_lerobot

FPS = 30


def _marks(db: Path) -> list[tuple[int, int, str]]:
    """The episodes as marked in the database, read without the exporter's code."""
    import sqlite3

    rows = (
        sqlite3.connect(db)
        .execute(
            "select e.name, e.t_ns, e.data from events e join things t on t.key = e.thing_key "
            "where t.id = 'episodes' order by e.t_ns"
        )
        .fetchall()
    )
    out, start = [], None
    for name, t, data in rows:
        if name == "episodeStarted":
            start = (t, json.loads(data)["task"])
        else:
            out.append((start[0], t, start[1]))
    return out


def _records(reader, thing: str, name: str) -> list:
    return [r for page in reader.pages(thing, names=[name]) for r in page]


def _held(records: list, t: int):
    """The last record at or before ``t`` (by time, then seq), or None."""
    best = None
    for r in records:
        if r.t_ns <= t and (best is None or (r.t_ns, r.seq) >= (best.t_ns, best.seq)):
            best = r
    return best


@pytest.fixture(scope="module")
def exported(hub_session, tmp_path_factory, cli):
    out = tmp_path_factory.mktemp("out") / "pads"
    done = cli(
        "history",
        "export",
        "--format",
        "lerobot",
        "-o",
        str(out),
        "--device",
        "pad-a",
        "--device",
        "pad-b",
        "--database",
        str(hub_session),
        "--fps",
        str(FPS),
        "--state",
        "contact_force",
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert "2 episodes" in done.stderr
    return out


def test_the_export_of_a_real_session_loads_as_lerobot_loads_it(exported, hub_session):
    loaded = check_lerobot(exported)
    marks = _marks(hub_session)
    assert [ep["tasks"] for ep in loaded.episodes] == [[m[2]] for m in marks]
    # every frame k with start + (k * 1e9) // fps at or before the end mark
    assert [ep["length"] for ep in loaded.episodes] == [
        max(k for k in range(10 * FPS) if a + k * 10**9 // FPS <= b) + 1 for a, b, _ in marks
    ]
    assert list(loaded.tasks.index) == ["press the flat pad", "press it again"]
    assert loaded.features["observation.state"]["names"] == [
        f"{d}.contact_force.{a}" for d in ("pad-a", "pad-b") for a in "xyz"
    ]
    assert "action" not in loaded.features  # no --action: observation only
    assert (exported / "README.md").read_text().startswith("---\nlicense")
    assert not list(exported.parent.glob(".*partial*"))


def test_zero_order_hold_is_exact_row_by_row(exported, hub_session, reader_of):
    """Every exported value is the last recorded one at or before its frame's time, its age the time since."""
    reader = reader_of(hub_session)
    loaded = check_lerobot(exported)
    data = loaded.data.with_format("numpy")
    nodes = json.loads((exported / "meta/wott.json").read_text())["nodes"]
    for thing in ("pad-a", "pad-b"):
        skins = _records(reader, thing, "skinDeformedDetection")
        contacts = _records(reader, thing, "contactInformation")
        row_of = {n: i for i, n in enumerate(nodes[thing])}
        ages = loaded.features[f"age.{thing}"]["names"]
        for ep, (start, _, _) in zip(loaded.episodes, _marks(hub_session), strict=True):
            rows = data[ep["dataset_from_index"] : ep["dataset_to_index"]]
            for k in range(ep["length"]):
                t = start + k * 10**9 // FPS
                skin, contact = _held(skins, t), _held(contacts, t)
                want = np.zeros(len(row_of), np.float32)
                if skin is not None:
                    for node in json.loads(skin.data)["arrayOfDeformedNodes"]:
                        want[row_of[node["deformedNodeID"]]] = node["deformedNodeIntensity"]
                assert np.array_equal(rows[f"observation.tactile.{thing}.deformation"][k], want), (thing, k)
                age = rows[f"age.{thing}"][k][ages.index("deformation")]
                assert age == (np.float32((t - skin.t_ns) / 1e9) if skin is not None else -1), (thing, k)
                c = (
                    json.loads(contact.data)
                    if contact is not None
                    else {"numOfContacts": 0, "contactForces": []}
                )
                force = np.array([[f["x"], f["y"], f["z"]] for f in c["contactForces"]]).reshape(-1, 3).sum(0)
                assert rows[f"observation.tactile.{thing}.contact_count"][k] == c["numOfContacts"]
                assert np.array_equal(
                    rows[f"observation.tactile.{thing}.contact_force"][k], force.astype(np.float32)
                )
            assert np.array_equal(
                rows["observation.state"][:, :3] if thing == "pad-a" else rows["observation.state"][:, 3:],
                rows[f"observation.tactile.{thing}.contact_force"],
            )


def _quantiles(rows: np.ndarray) -> dict[str, np.ndarray]:
    """lerobot's quantiles of ``rows`` (n x d) in one go: 5000 bins from min - 1e-10 to max + 1e-10 in the
    rows' dtype, the target count's bin found on the cumulative counts, linear within it."""
    out: dict[str, list[float]] = {}
    for i in range(rows.shape[1]):
        col = rows[:, i]
        edges = np.linspace(col.min() - 1e-10, col.max() + 1e-10, 5001)
        cum = np.cumsum(np.histogram(col, bins=edges)[0])
        for q in (0.01, 0.10, 0.50, 0.90, 0.99):
            target = q * len(col)
            j = int(np.searchsorted(cum, target))
            if j == 0:
                v = edges[0]
            elif j >= len(cum):
                v = edges[-1]
            else:
                inside = cum[j] - cum[j - 1]
                v = (
                    edges[j]
                    if inside == 0
                    else edges[j] + (target - cum[j - 1]) / inside * (edges[j + 1] - edges[j])
                )
            out.setdefault(f"q{int(q * 100):02d}", []).append(float(v))
    return {k: np.array(v) for k, v in out.items()}


def _episode_stats(values: np.ndarray, dtype: str) -> dict[str, np.ndarray]:
    rows = values.reshape(len(values), -1) if values.ndim == 1 else values
    rows = rows.reshape(-1, rows.shape[-1]).astype(np.result_type(np.dtype(dtype), np.float32))
    mean = rows.astype(np.float64).mean(0)
    var = (rows.astype(np.float64) ** 2).mean(0) - mean**2
    return {
        "min": rows.min(0),
        "max": rows.max(0),
        "mean": mean,
        "std": np.sqrt(np.maximum(var, 0)),
        "count": np.array([len(values)]),
        **_quantiles(rows),
    }


def test_stats_are_lerobots(exported):
    loaded = check_lerobot(exported)
    data = loaded.data.with_format("numpy")
    total: dict[str, dict[str, np.ndarray]] = {}
    for ep in loaded.episodes:
        rows = data[ep["dataset_from_index"] : ep["dataset_to_index"]]
        for key, ft in loaded.features.items():
            if ft["dtype"] == "video":
                continue
            mine = _episode_stats(np.asarray(rows[key]), ft["dtype"])
            for stat, value in mine.items():
                assert np.allclose(
                    np.asarray(ep[f"stats/{key}/{stat}"], np.float64), value, rtol=1e-5, atol=1e-6
                ), (key, stat)
            if key not in total:
                total[key] = mine
                continue
            a, b = total[key], mine  # aggregate_stats([total, episode])
            n = a["count"] + b["count"]
            mean = (a["mean"] * a["count"] + b["mean"] * b["count"]) / n
            var = (
                (a["std"] ** 2 + (a["mean"] - mean) ** 2) * a["count"]
                + (b["std"] ** 2 + (b["mean"] - mean) ** 2) * b["count"]
            ) / n
            total[key] = {
                "min": np.minimum(a["min"], b["min"]),
                "max": np.maximum(a["max"], b["max"]),
                "mean": mean,
                "std": np.sqrt(var),
                "count": n,
                **{q: (a[q] * a["count"] + b[q] * b["count"]) / n for q in a if q.startswith("q")},
            }
    for key, stats in total.items():
        for stat, value in stats.items():
            assert np.allclose(
                np.asarray(loaded.stats[key][stat], np.float64), value, rtol=1e-5, atol=1e-6
            ), (key, stat)


def _rewrite(root: Path, change) -> None:
    for path in (root / "data").glob("*/*.parquet"):
        table = pq.read_table(path)
        pq.write_table(change(table), path)


def _shift(table):
    import pyarrow as pa

    i = table.schema.get_field_index("timestamp")
    ts = table.column("timestamp").to_numpy() + np.float32(0.5 / FPS)
    return table.set_column(i, table.schema.field(i), pa.array(ts.astype(np.float32)))


def _drop_frame_index(table):
    return table.drop_columns(["frame_index"])


def _break_index(table):
    import pyarrow as pa

    i = table.schema.get_field_index("index")
    index = table.column("index").to_numpy().copy()
    index[len(index) // 2] += 1
    return table.set_column(i, table.schema.field(i), pa.array(index))


def _declare_wrong_shape(root: Path) -> None:
    info = json.loads((root / "meta/info.json").read_text())
    info["features"]["observation.tactile.pad-a.contact_force"]["shape"] = [4]
    (root / "meta/info.json").write_text(json.dumps(info))


@pytest.mark.parametrize(
    "broken", ["half-frame timestamps", "wrong declared shape", "no frame_index", "broken index"]
)
def test_the_check_rejects_a_broken_dataset(exported, tmp_path, broken):
    root = tmp_path / "copy"
    shutil.copytree(exported, root)
    check_lerobot(root)  # intact: passes
    if broken == "half-frame timestamps":
        _rewrite(root, _shift)
    elif broken == "wrong declared shape":
        _declare_wrong_shape(root)
    elif broken == "no frame_index":
        _rewrite(root, _drop_frame_index)
    else:
        _rewrite(root, _break_index)
    with pytest.raises(Invalid):
        check_lerobot(root)


def test_zarr_export_holds_the_same_values(exported, hub_session, tmp_path, cli):
    import zarr

    out = tmp_path / "pads.zarr"
    done = cli(
        "history",
        "export",
        "--format",
        "zarr",
        "-o",
        str(out),
        "--device",
        "pad-a",
        "--device",
        "pad-b",
        "--database",
        str(hub_session),
        "--fps",
        str(FPS),
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    root = zarr.open_group(str(out), mode="r")
    assert root.metadata.zarr_format == 2  # what diffusion_policy's zarr 2.12 opens
    loaded = check_lerobot(exported)
    data = loaded.data.with_format("numpy")
    ends = root["meta/episode_ends"][:]
    assert ends.tolist() == np.cumsum([ep["length"] for ep in loaded.episodes]).tolist()
    for key in ("pad-a_deformation", "pad-b_contact_force", "pad-a_contact_count", "age_pad-b"):
        lerobot_key = (
            key.replace("_", ".", 1)
            if key.startswith("age")
            else f"observation.tactile.{key.replace('_', '.', 1)}"
        )
        assert np.array_equal(root["data"][key][:], np.asarray(data[lerobot_key])), key
    start = _marks(hub_session)[0][0]
    assert root["data/timestamp"][1] == (start + 10**9 // FPS) / 1e9
    assert root.attrs["episodes"][1]["task"] == "press it again"


def test_a_camera_a_grid_and_an_action(camera_session, tmp_path, cli, reader_of):
    """Camera images as a video (every frame found within 1e-4 s, each the image held then), a pressure
    grid, ``--action`` from another Thing's property, episodes given as ranges."""
    import av

    from .conftest import T0

    db, frames = camera_session
    out = tmp_path / "cam"
    s = lambda t: str(t / 1e9)  # noqa: E731
    done = cli(
        "history",
        "export",
        "--format",
        "lerobot",
        "-o",
        str(out),
        "--device",
        "cam",
        "--database",
        str(db),
        "--fps",
        "20",
        "--action",
        "arm.jointPositions",
        "--episodes",
        f"{s(T0)}..{s(T0 + 1_200_000_000)}=look",
        "--episodes",
        f"{s(T0 + 1_500_000_000)}..{s(T0 + 2_900_000_000)}",
        "--task",
        "look again",
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    loaded = check_lerobot(out)
    assert list(loaded.tasks.index) == ["look", "look again"]
    key = "observation.images.cam.top"
    assert (
        loaded.features[key]["shape"] == [48, 64, 3] and loaded.features[key]["info"]["video.codec"] == "h264"
    )
    assert loaded.stats[key]["mean"][0][0][0] > 0 and np.array(loaded.stats[key]["max"]).shape == (3, 1, 1)
    assert loaded.features["action"]["names"] == ["jointPositions.shoulder", "jointPositions.elbow"]
    reader = reader_of(db)
    images = _records(reader, "cam", "rawImageRecorded")
    for ep, start in zip(loaded.episodes, [T0, T0 + 1_500_000_000], strict=True):  # lerobot's image stats
        n = ep["length"]
        sampled = np.round(np.linspace(0, n - 1, min(n, 100))).astype(int)  # sample_indices below 100 frames
        held = [_held(images, start + k * 10**9 // 20) for k in sampled]
        pixels = np.stack(
            [frames[images.index(h)] if h is not None else np.zeros((48, 64, 3), np.uint8) for h in held]
        )  # 48 x 64: under 300 px, not downsampled
        want = _episode_stats(pixels, "uint8")
        want = {k: v if k == "count" else v / 255.0 for k, v in want.items()}
        for stat, value in want.items():
            got = np.asarray(ep[f"stats/{key}/{stat}"], np.float64)
            assert got.shape == ((1,) if stat == "count" else (3, 1, 1)), stat
            assert np.allclose(got.reshape(-1), value, rtol=1e-5, atol=1e-6), (stat, got.ravel(), value)
    arm = _records(reader, "arm", "jointPositions")
    grids = _records(reader, "cam", "pressureGridRecorded")
    data = loaded.data.with_format("numpy")
    starts = [T0, T0 + 1_500_000_000]
    for ep, start in zip(loaded.episodes, starts, strict=True):
        rows = data[ep["dataset_from_index"] : ep["dataset_to_index"]]
        path = out / f"videos/{key}/chunk-000/file-000.mp4"
        with av.open(str(path)) as container:
            decoded = {
                round(float(f.pts * f.time_base) * 20): f.to_ndarray(format="rgb24")
                for f in container.decode(video=0)
            }
        first = round(ep[f"videos/{key}/from_timestamp"] * 20)
        for k in range(ep["length"]):
            t = start + k * 10**9 // 20
            a, g = _held(arm, t), _held(grids, t)  # none yet at the first frame: the rest value, zeros
            a = json.loads(a.data) if a is not None else {"shoulder": 0, "elbow": 0}
            assert np.array_equal(rows["action"][k], np.float32([a["shoulder"], a["elbow"]]))
            grid = json.loads(g.data)["pressure"] if g is not None else np.zeros((4, 5))
            assert np.array_equal(rows["observation.tactile.cam.pressure"][k], np.float32(grid))
            img = _held(images, t)
            want = frames[images.index(img)] if img is not None else np.zeros((48, 64, 3), np.uint8)
            err = np.abs(decoded[first + k].astype(int) - want.astype(int)).mean()
            assert err < 6, (k, err)  # lossy, but this image and no other (the next differs by ~20)
