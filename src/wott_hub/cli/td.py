"""``wott-hub td``: print and validate Tactile Thing Descriptions."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path

import typer

app = typer.Typer(help="Print and validate Tactile Thing Descriptions.", no_args_is_help=True,
                  rich_markup_mode=None)

__all__ = ["app"]


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


@app.command(short_help="Check a TD (a file, a URL or -) against TD 1.1 and Tactile.")
def validate(
    source: str = typer.Argument(..., help="A TD: a JSON file, an http(s) URL (a served TD), or - for "
                                           "standard input."),
    td_only: bool = typer.Option(False, help="Check TD 1.1 only, not the Tactile vocabulary."),
    token: str = typer.Option(None, "--token", envvar="WOTT_HUB_TOKEN",
                              help="Bearer token, for a URL of a hub that asks for one."),
) -> None:
    """Check a TD against TD 1.1, the Tactile vocabulary and the interop rules.

    Prints each failing field with its JSON path; exit code 1 if any fail or the URL
    cannot be fetched, 2 if the source is not a readable JSON document, 3 if the URL
    has no TD (404).
    """
    from wott_hub.td.validate import validate_td

    doc = _load(source, token)
    problems = validate_td(doc, tactile=not td_only, interop=not td_only)
    for p in problems:
        typer.echo(f"{source}: {p}")
    if problems:
        typer.echo(f"{source}: {len(problems)} problem(s)", err=True)
        raise typer.Exit(1)
    typer.echo(f"{source}: valid")


def _read(source: str, token: str | None) -> str:
    """The text at ``source`` (a file, a URL, ``-``); a WottHubError saying why it cannot be read."""
    import sys

    from wott_hub.errors import InvalidInput, NotFound, WottHubError

    if source == "-":
        return sys.stdin.read()
    if source.startswith(("http://", "https://")):
        import httpx

        headers = {"Accept": "application/td+json, application/json"}
        if token:
            headers["Authorization"] = f"Bearer {token}"
        try:
            r = httpx.get(source, headers=headers, timeout=30, follow_redirects=True)
        except httpx.HTTPError as e:
            raise WottHubError(f"{source}: cannot fetch: {e}") from None
        if r.status_code == 404:
            raise NotFound(f"{source}: no TD there (HTTP 404)")
        if r.status_code >= 400:
            raise WottHubError(f"{source}: HTTP {r.status_code} {r.reason_phrase}")
        return r.text
    try:
        return Path(source).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InvalidInput(f"{source}: no such file (a TD file, an http(s) URL or -)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise InvalidInput(f"{source}: cannot read: {getattr(e, 'strerror', None) or e}") from None


def _load(source: str, token: str | None) -> object:
    from wott_hub.errors import InvalidInput

    text = _read(source, token)
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise InvalidInput(f"{source}: not JSON: {e}") from None
