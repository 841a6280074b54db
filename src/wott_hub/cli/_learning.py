"""``wott-hub history export --format lerobot|zarr``: a learning dataset, with a progress bar on stderr.

Kept beside ``history.py`` (which only dispatches to it), as ``_robotics.py`` is for rosbag2:
``history/learning/export.py`` does the work; this reads the options and draws the bar (frames done
of all the episodes' frames, on a terminal only).
"""

from __future__ import annotations

from pathlib import Path

import typer

from wott_hub.errors import InvalidInput

from ._db import open_reader, resolve_database, time_range

__all__ = ["export_dataset"]


def export_dataset(
    fmt: str,
    devices: list[str],
    t_from: str | None,
    t_to: str | None,
    output: Path | None,
    database: str | None,
    config: Path | None,
    *,
    fps: int,
    episodes: list[str],
    task: str | None,
    state: list[str],
    action: str | None,
    codec: str,
    progress: bool,
    check: bool,
) -> None:
    from wott_hub.history.db import describe
    from wott_hub.history.learning import export as learning
    from wott_hub.history.learning.episodes import DEFAULT_TASK, parse_episode, task_text

    from ._progress import Bar, wanted

    if output is None:
        raise InvalidInput(f"--output is required with --format {fmt}: the dataset's new folder")
    default_task = task_text(task, "--task") if task is not None else DEFAULT_TASK
    given = [parse_episode(e, default_task) for e in episodes] or None
    lo, hi = time_range(t_from, t_to)
    reader = open_reader(resolve_database(database, config), integrity=check)
    req = learning.DatasetRequest(
        fmt,
        output,
        list(devices),
        fps=fps,
        t_from_ns=lo,
        t_to_ns=hi,
        episodes=given,
        task=default_task,
        state=list(state),
        action=action,
        codec=codec,
        database=describe(reader.engine.url),
    )
    with Bar(f"{fmt} {', '.join(devices)}", 1, wanted(progress)) as bar:
        summary = learning.export_dataset(reader, req, bar.update)
    counted = f"{summary.episodes} episode{'s' if summary.episodes != 1 else ''}"
    typer.echo(f"{counted}, {summary.frames} frames ({summary.records} records) in {output}", err=True)
