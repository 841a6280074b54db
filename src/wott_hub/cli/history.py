"""``wott-hub history``: what is recorded, and export a range as JSON Lines."""

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
        dur = f"{(t.last_t_ns - t.first_t_ns) / 1e9:.1f} s" if t.count else "-"
        seqs = f"{t.first_seq}..{t.last_seq}" if t.count else "-"
        table.add_row(t.id, t.family, str(t.count), format_ns(t.first_t_ns), format_ns(t.last_t_ns),
                      dur, seqs)
    Console().print(table)


@app.command()
def export(
    device: str = typer.Option(..., "--device", help="Device id (see `wott-hub history list`)."),
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    t_to: str = typer.Option(None, "--to", help="End, same forms as --from."),
    name: list[str] = typer.Option(None, "--name", help="Only these affordances (repeatable)."),
    output: Path = typer.Option(None, "--output", "-o", help="File to write (default: standard output)."),
    database: str = _DB,
    config: Path = _CFG,
) -> None:
    """Write a device's records in a time range as JSON Lines (one record per line, in order)."""
    from wott_hub.history import export_jsonl

    lo, hi = time_range(t_from, t_to)
    reader = open_reader(resolve_database(database, config))
    if reader.key(device) is None:
        typer.echo(f"error: no recorded device {device!r}", err=True)
        raise typer.Exit(1)
    if output is None:
        n = export_jsonl(reader, sys.stdout, device, t_from_ns=lo, t_to_ns=hi, names=name or None)
    else:
        with output.open("w") as f:
            n = export_jsonl(reader, f, device, t_from_ns=lo, t_to_ns=hi, names=name or None)
    typer.echo(f"{n} records", err=True)
