"""``wott-hub history``: what is recorded, and export a range as JSON Lines or MCAP."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import typer

from ._db import open_reader, resolve_database, time_range

app = typer.Typer(help="Recorded events: list devices and time ranges, export as JSON Lines.",
                  no_args_is_help=True)

_DB = typer.Option(None, "--database", "-d", help="Database file or URL (default: the config's, "
                   "else ./wott-hub.db).")
_CFG = typer.Option(None, "--config", "-c", exists=True, dir_okay=False,
                    help="Hub config naming the database.")


@app.command("list")
def list_history(database: str = _DB, config: Path = _CFG,
                 as_json: bool = typer.Option(False, "--json", help="Print JSON for scripts.")) -> None:
    """Every recorded device: event count, first and last time, sequence range."""
    from wott_hub.history import format_ns

    reader = open_reader(resolve_database(database, config))
    things = reader.things()
    if as_json:
        typer.echo(json.dumps([t.to_dict() for t in things], indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"history: {reader.engine.url}")
    for col in ("device", "family", "events", "from", "to", "duration", "seq"):
        table.add_column(col, justify="right" if col in ("events", "duration") else "left")
    for t in things:
        first, last = t.first_t_ns, t.last_t_ns  # None exactly when count is 0
        dur = f"{(last - first) / 1e9:.1f} s" if first is not None and last is not None else "-"
        seqs = f"{t.first_seq}..{t.last_seq}" if t.count else "-"
        table.add_row(t.id, t.family, str(t.count), format_ns(t.first_t_ns), format_ns(t.last_t_ns),
                      dur, seqs)
    Console().print(table)


@app.command()
def export(
    device: list[str] = typer.Option(..., "--device", help="Device id (see `wott-hub history list`); "
                                     "repeatable: MCAP puts several devices on one time base."),
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    t_to: str = typer.Option(None, "--to", help="End, same forms as --from."),
    name: list[str] = typer.Option(None, "--name", help="Only these affordances (repeatable)."),
    output: Path = typer.Option(None, "--output", "-o", help="File to write (default: standard output; "
                                "required for mcap), or the new folder of a rosbag2."),
    fmt: str = typer.Option("jsonl", "--format", help="jsonl (one record per line), mcap (Foxglove) or "
                            "rosbag2 (ROS 2: `ros2 bag play DIR`; docs/robotics.md)."),
    scene: bool = typer.Option(True, "--scene/--no-scene", help="mcap: Foxglove scene channels (mesh, "
                               "deformation)."),
    scene_hz: float = typer.Option(30.0, "--scene-hz", help="mcap: deformation scenes per second at most."),
    database: str = _DB,
    config: Path = _CFG,
) -> None:
    """Write devices' records in a time range as JSON Lines (in order) or as an MCAP file."""
    n = _export(device, t_from, t_to, name, output, database, config, fmt=fmt, scene=scene, scene_hz=scene_hz)
    typer.echo(f"{n} records", err=True)


def _export(devices: list[str] | str, t_from: str | None, t_to: str | None, name: list[str] | None,
            output: Path | None, database: str | None, config: Path | None, *, fmt: str = "jsonl",
            scene: bool = True, scene_hz: float = 30.0) -> int:
    import math

    from wott_hub.errors import InvalidInput, NotFound
    from wott_hub.history.export import export_jsonl

    devices = [devices] if isinstance(devices, str) else list(devices)
    if fmt not in ("jsonl", "mcap", "rosbag2"):
        raise InvalidInput(f"--format {fmt!r}: expected jsonl, mcap or rosbag2")
    if fmt in ("mcap", "rosbag2") and output is None:
        raise InvalidInput(f"--output is required with --format {fmt} (binary, not for a terminal)")
    if not (math.isfinite(scene_hz) and scene_hz > 0):
        raise InvalidInput(f"--scene-hz must be a number > 0, got {scene_hz}")
    lo, hi = time_range(t_from, t_to)
    if output is not None and not output.parent.is_dir():
        raise InvalidInput(f"--output {str(output)!r}: the folder {str(output.parent)!r} does not exist")
    reader = open_reader(resolve_database(database, config))
    for device in devices:
        if not reader.recorded(device):
            raise NotFound(f"no recorded device {device!r} (see `wott-hub history list`)")
    if fmt == "rosbag2":
        from ._robotics import export_bag

        assert output is not None
        return export_bag(reader, output, devices, lo, hi, name or None)
    if output is None:
        return sum(export_jsonl(reader, sys.stdout, d, t_from_ns=lo, t_to_ns=hi, names=name or None)
                   for d in devices)
    try:
        f = output.open("wb" if fmt == "mcap" else "w")
    except OSError as e:
        raise InvalidInput(f"--output {str(output)!r}: {e.strerror or e}") from None
    with f:
        if fmt == "mcap":
            from wott_hub.history.mcap import export_mcap

            return export_mcap(reader, f, devices, t_from_ns=lo, t_to_ns=hi, names=name or None,
                               scene=scene, scene_hz=scene_hz).records
        return sum(export_jsonl(reader, f, d, t_from_ns=lo, t_to_ns=hi, names=name or None)
                   for d in devices)


@app.command()
def audit(
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    who: str = typer.Option(None, "--who", help="Only this token's name ('-': no valid token)."),
    limit: int = typer.Option(100, "--limit", min=1, max=1_000_000, help="The newest this many."),
    as_json: bool = typer.Option(False, "--json", help="JSON Lines for scripts."),
    database: str = _DB,
    config: Path = _CFG,
) -> None:
    """The audit trail (docs/security.md): writes, actions and refused credentials, oldest first."""
    from wott_hub.history import format_ns
    from wott_hub.security import read_audit

    lo, _ = time_range(t_from, None)
    reader = open_reader(resolve_database(database, config))
    for e in read_audit(reader.engine, limit=limit, who=who, since_ns=lo):
        if as_json:
            typer.echo(json.dumps({"t_ns": e.t_ns, "who": e.who, "action": e.action, "target": e.target,
                                   "address": e.address, "status": e.status}))
        else:
            typer.echo(f"{format_ns(e.t_ns)}  {e.status}  {e.who:<20} {e.action:<7} {e.target}  "
                       f"from {e.address}")
