"""``wott-hub history``: what is recorded, export a range (JSON Lines, MCAP, rosbag2, learning datasets),
the audit trail.

``list`` reads only the ends of each device's indexes (its first and last seq and time), so
it answers as fast on a day of history as on a minute; the exact number of records is a scan
(``--count``) and the whole file's integrity check another (``--check``), both on request.
``export`` shows a progress bar on a terminal.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ._db import open_reader, resolve_database, time_range

if TYPE_CHECKING:
    from wott_hub.history.reader import HistoryReader

__all__ = ["app"]

app = typer.Typer(help="Recorded events: list devices and time ranges, export them, read the audit trail.",
                  short_help="Recorded events: list, export, audit trail.", no_args_is_help=True,
                  rich_markup_mode=None)

_DB = typer.Option(None, "--database", "-d", help="Database file or URL (default: the config's, "
                   "else ./wott-hub.db).")
_CFG = typer.Option(None, "--config", "-c", exists=True, dir_okay=False,
                    help="Hub config naming the database.")
_PROGRESS = typer.Option(True, "--progress/--no-progress", help="A progress bar on stderr (a terminal only).")


@app.command("list", short_help="Recorded devices: time range, seq range.")
def list_history(database: str = _DB, config: Path = _CFG,
                 count: bool = typer.Option(False, "--count", help="Also count each device's records "
                                            "exactly (reads its whole index: ~0.1 s per million)."),
                 check: bool = typer.Option(False, "--check", help="First check every page of the "
                                            "database file (SQLite quick_check: ~1 s per GB)."),
                 as_json: bool = typer.Option(False, "--json", help="Print JSON for scripts.")) -> None:
    """Every recorded device: first and last time, duration, sequence range (and record count)."""
    import datetime as dt

    from wott_hub.history.db import describe

    from ._table import Column, render

    reader = open_reader(resolve_database(database, config), integrity=check)
    things = reader.things(count=count)
    if as_json:
        typer.echo(json.dumps([t.to_dict() for t in things], indent=2))
        return
    rows = []
    for t in things:
        first, last = t.first_t_ns, t.last_t_ns  # None exactly when nothing is recorded
        rows.append({"device": t.id, "family": t.family, "count": t.count,
                     "from": _local(first), "to": _local(last),
                     "duration": "-" if first is None or last is None else f"{(last - first) / 1e9:.1f} s",
                     "seq": f"{t.first_seq}..{t.last_seq}" if t.first_seq is not None else "-"})
    offset = dt.datetime.now().astimezone().strftime("%z")
    zone = f"UTC{offset[:-2]}:{offset[-2:]}"  # the times are local: their zone, once
    columns = [Column("device", "device"), Column("family", "family", drop=2),
               *([Column("records", "count", drop=1, align=">")] if count else []),
               Column(f"from ({zone})", "from"), Column("to", "to"),
               Column("duration", "duration", drop=3, align=">"),
               Column("seq", "seq", drop=4)]
    title = f"history: {describe(reader.engine.url)}"
    if not things:
        typer.echo(f"{title}: nothing recorded yet")
        return
    typer.echo("\n".join(render(columns, rows, title=title)))


@app.command(short_help="A time range as JSON Lines or MCAP.")
def export(
    device: list[str] = typer.Option(..., "--device", help="Device id (see wott-hub history list); "
                                     "repeatable: MCAP puts several devices on one time base."),
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    t_to: str = typer.Option(None, "--to", help="End, same forms as --from."),
    name: list[str] = typer.Option(None, "--name", help="Only these affordances (repeatable)."),
    output: Path = typer.Option(None, "--output", "-o", help="File to write (default: standard output; "
                                "required for mcap), or the new folder of a rosbag2."),
    fmt: str = typer.Option("jsonl", "--format", help="jsonl (one record per line), mcap (Foxglove), "
                            "rosbag2 (ROS 2: `ros2 bag play DIR`; docs/robotics.md), lerobot (LeRobotDataset "
                            "v3.0) or zarr (diffusion-policy replay buffer; docs/learning.md)."),
    fps: int = typer.Option(30, "--fps", help="lerobot, zarr: frames per second of the dataset (1-1000)."),
    episodes: list[str] = typer.Option(None, "--episodes", help="lerobot, zarr: an episode FROM..TO or "
                                       "FROM..TO=TASK (repeatable; default: those marked while recording, "
                                       "else the whole range)."),
    task: str = typer.Option(None, "--task", help="lerobot, zarr: the task of an episode given without "
                             "one."),
    state: list[str] = typer.Option(None, "--state", help="lerobot, zarr: also flatten this feature into "
                                    "observation.state (ID.FEATURE or FEATURE, e.g. contact_force; "
                                    "repeatable)."),
    action: str = typer.Option(None, "--action", help="lerobot, zarr: THING.PROPERTY, a recorded property "
                               "of another Thing as the action column."),
    codec: str = typer.Option("h264", "--codec", help="lerobot: camera videos as h264 or av1."),
    scene: bool = typer.Option(True, "--scene/--no-scene", help="mcap: Foxglove scene channels (mesh, "
                               "deformation)."),
    scene_hz: float = typer.Option(30.0, "--scene-hz", help="mcap: deformation scenes per second at most."),
    progress: bool = _PROGRESS,
    check: bool = typer.Option(True, "--check/--no-check", help="First check every page of the database "
                               "file (SQLite quick_check, ~1 s per GB; nothing is written from a corrupted "
                               "one)."),
    database: str = _DB,
    config: Path = _CFG,
) -> None:
    """Write devices' records in a time range as JSON Lines (in order), an MCAP file, a rosbag2 folder or a
    learning dataset (LeRobot, zarr)."""
    if fmt in ("lerobot", "zarr"):
        from ._learning import export_dataset

        export_dataset(fmt, device, t_from, t_to, output, database, config, fps=fps,
                       episodes=episodes or [], task=task, state=state or [], action=action, codec=codec,
                       progress=progress, check=check)
        return
    n = _export(device, t_from, t_to, name, output, database, config, fmt=fmt, scene=scene, scene_hz=scene_hz,
                progress=progress, check=check)
    typer.echo(f"{n} records", err=True)


def _export(devices: list[str] | str, t_from: str | None, t_to: str | None, name: list[str] | None,
            output: Path | None, database: str | None, config: Path | None, *, fmt: str = "jsonl",
            scene: bool = True, scene_hz: float = 30.0, progress: bool = False, check: bool = True) -> int:
    import math

    from wott_hub.errors import InvalidInput, NotFound

    from ._progress import Bar, Tracked, wanted

    devices = [devices] if isinstance(devices, str) else list(devices)
    if fmt not in ("jsonl", "mcap", "rosbag2"):
        raise InvalidInput(f"--format {fmt!r}: expected jsonl, mcap, rosbag2, lerobot or zarr")
    if fmt in ("mcap", "rosbag2") and output is None:
        raise InvalidInput(f"--output is required with --format {fmt} (binary, not for a terminal)")
    if not (math.isfinite(scene_hz) and scene_hz > 0):
        raise InvalidInput(f"--scene-hz must be a number > 0, got {scene_hz}")
    lo, hi = time_range(t_from, t_to)
    if output is not None and not output.parent.is_dir():
        raise InvalidInput(f"--output {str(output)!r}: the folder {str(output.parent)!r} does not exist")
    reader = open_reader(resolve_database(database, config), integrity=check)
    for device in devices:
        if not reader.recorded(device):
            raise NotFound(f"no recorded device {device!r} (see `wott-hub history list`)")
    if fmt == "rosbag2":
        from ._robotics import export_bag

        assert output is not None
        return export_bag(reader, output, devices, lo, hi, name or None)
    spans = Tracked.spans(reader, devices, lo, hi)
    with Bar(f"export {', '.join(devices)}", Tracked.total(spans), wanted(progress)) as bar:
        tracked: Any = Tracked(reader, spans, bar)
        if output is None:
            return _jsonl(tracked, sys.stdout, devices, lo, hi, name)
        try:
            f = output.open("wb" if fmt == "mcap" else "w")
        except OSError as e:
            raise InvalidInput(f"--output {str(output)!r}: {e.strerror or e}") from None
        try:
            with f:
                if fmt == "mcap":
                    from wott_hub.history.mcap import export_mcap

                    return export_mcap(tracked, f, devices, t_from_ns=lo, t_to_ns=hi, names=name or None,
                                       scene=scene, scene_hz=scene_hz).records
                return _jsonl(tracked, f, devices, lo, hi, name)
        except OSError as e:  # a full disk (or /dev/full): the file is incomplete
            from wott_hub.errors import WottHubError

            raise WottHubError(f"--output {str(output)!r}: {e.strerror or e}; the file is incomplete") \
                from None


def _local(t_ns: int | None) -> str:
    """A time as a table shows it: local, to the millisecond, the zone said once in the title."""
    import datetime as dt

    if t_ns is None:
        return "-"
    return dt.datetime.fromtimestamp(t_ns / 1e9).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]


def _jsonl(reader: HistoryReader, out: Any, devices: list[str], lo: int | None, hi: int | None,
           names: list[str] | None) -> int:
    from wott_hub.history.export import export_jsonl

    return sum(export_jsonl(reader, out, d, t_from_ns=lo, t_to_ns=hi, names=names or None) for d in devices)


@app.command(short_help="The audit trail: writes, actions, refusals.")
def audit(
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    who: str = typer.Option(None, "--who", help="Only this token's name ('-': no valid token)."),
    limit: int = typer.Option(100, "--limit", min=1, max=1_000_000, help="The newest this many."),
    as_json: bool = typer.Option(False, "--json", help="JSON Lines for scripts."),
    database: str = _DB,
    config: Path = _CFG,
) -> None:
    """The audit trail (docs/security.md): writes, actions and refused credentials, oldest first.

    Reads (TDs, properties, event streams) are not audited: a hub only read has an empty trail.
    """
    from wott_hub.history import format_ns
    from wott_hub.history.db import describe
    from wott_hub.security import read_audit

    lo, _ = time_range(t_from, None)
    reader = open_reader(resolve_database(database, config), integrity=False)
    entries = read_audit(reader.engine, limit=limit, who=who, since_ns=lo)
    if not entries and not as_json:
        only = "".join([f" by {who!r}" if who is not None else "", f" since {t_from}" if t_from else ""])
        typer.echo(f"no audited request{only} in {describe(reader.engine.url)}: the trail holds writes, "
                   "actions and refused credentials; reads (TDs, properties, events) are not audited",
                   err=True)
        return
    for e in entries:
        if as_json:
            typer.echo(json.dumps({"t_ns": e.t_ns, "who": e.who, "action": e.action, "target": e.target,
                                   "address": e.address, "status": e.status}))
        else:
            typer.echo(f"{format_ns(e.t_ns)}  {e.status}  {e.who:<20} {e.action:<7} {e.target}  "
                       f"from {e.address}")
