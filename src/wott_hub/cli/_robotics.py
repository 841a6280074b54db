"""``wott-hub history export --format rosbag2``: the export with a progress bar on stderr.

Kept beside ``history.py`` (which only dispatches to it) so the rosbag2 path and its progress
are one small module: ``history/rosbag2.py`` does the work.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from wott_hub.errors import InvalidInput

if TYPE_CHECKING:
    from wott_hub.history.reader import HistoryReader

__all__ = ["export_bag"]


def _span(reader: HistoryReader, devices: list[str], lo: int | None, hi: int | None) -> tuple[int, int]:
    """The recorded time the export covers (its first and last record's time, at most)."""
    summaries = {t.id: t for t in reader.things()}
    firsts = [s.first_t_ns for d in devices if (s := summaries.get(d)) and s.first_t_ns is not None]
    lasts = [s.last_t_ns for d in devices if (s := summaries.get(d)) and s.last_t_ns is not None]
    start = max(min(firsts, default=0), lo if lo is not None else 0)
    end = min(max(lasts, default=0), hi if hi is not None else 2**63)
    return start, end


def export_bag(reader: HistoryReader, output: Path, devices: list[str], lo: int | None, hi: int | None,
               names: list[str] | None) -> int:
    """The records exported; a bar on stderr follows the recorded time done."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from wott_hub.history.rosbag2 import export_rosbag2

    if not output.parent.is_dir():
        raise InvalidInput(f"--output {str(output)!r}: the folder {str(output.parent)!r} does not exist")
    start, end = _span(reader, devices, lo, hi)
    if start > end or reader.first_time(devices, lo) is None:
        raise InvalidInput(f"no records of {', '.join(devices)} in that range: nothing to export")
    with Progress(TextColumn("rosbag2"), BarColumn(), TextColumn("{task.fields[records]:>10,} records"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True),
                  transient=True) as bar:
        task = bar.add_task("export", total=max(1, end - start), records=0)

        def progress(records: int, t_ns: int) -> None:
            bar.update(task, completed=max(0, t_ns - start), records=records)

        return export_rosbag2(reader, output, devices, t_from_ns=lo, t_to_ns=hi, names=names,
                              progress=progress).records
