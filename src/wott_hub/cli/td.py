"""``wott-hub td``: print and validate Tactile Thing Descriptions."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path

import typer

app = typer.Typer(help="Print and validate Tactile Thing Descriptions.", no_args_is_help=True)


class Shape(StrEnum):
    barrel = "barrel"
    flat = "flat"
    cylinder = "cylinder"


@app.command()
def show(
    shape: Shape = typer.Option(Shape.barrel, help="Device shape of the example TD."),
    base: str = typer.Option("http://127.0.0.1:8080/", help="Base URL the forms are relative to."),
    values: bool = typer.Option(False, help="Also print the static property values (mesh...)."),
) -> None:
    """Print a complete Tactile TD for a device of the given shape."""
    from wott_hub.examples import example_device
    from wott_hub.td.builder import build_tactile_td, static_property_values

    desc = example_device(shape.value)
    out = build_tactile_td(desc, base=base)
    if values:
        out = {"td": out, "values": static_property_values(desc)}
    typer.echo(json.dumps(out, indent=2))


@app.command()
def validate(
    file: Path = typer.Argument(..., exists=True, dir_okay=False, help="TD JSON file."),
    td_only: bool = typer.Option(False, help="Check TD 1.1 only, not the Tactile vocabulary."),
) -> None:
    """Check a TD file against TD 1.1, the Tactile vocabulary and the interop rules.

    Prints each failing field with its JSON path; exit code 1 if any fail.
    """
    from wott_hub.td.validate import validate_td

    try:
        doc = json.loads(file.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        typer.echo(f"{file}: not JSON: {e}", err=True)
        raise typer.Exit(1) from None
    problems = validate_td(doc, tactile=not td_only, interop=not td_only)
    for p in problems:
        typer.echo(f"{file}: {p}")
    if problems:
        typer.echo(f"{file}: {len(problems)} problem(s)", err=True)
        raise typer.Exit(1)
    typer.echo(f"{file}: valid")
