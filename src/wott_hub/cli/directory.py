"""``wott-hub directory``: query this hub's or any W3C Thing Description Directory.

``--url`` defaults to ``WOTT_DIRECTORY_URL``, else this hub on 127.0.0.1:8080.
Wherever the directory's API is mounted, the host's ``/.well-known/wot`` TD
names it (its ``base``), so a bare host URL is enough.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import typer

app = typer.Typer(help="Query a W3C WoT Thing Description Directory.", no_args_is_help=True,
                  rich_markup_mode=None)

__all__ = ["app"]

DEFAULT_URL = "http://127.0.0.1:8080/"

UrlOption = typer.Option(DEFAULT_URL, "--url", envvar="WOTT_DIRECTORY_URL",
                         help="The directory's API base URL.")
TokenOption = typer.Option(None, "--token", envvar="WOTT_DIRECTORY_TOKEN",
                           help="Bearer token, if the directory protects reads.")


async def _client(url: str, token: str | None) -> Any:
    """A client of the directory at ``url``, or of the one the host's ``/.well-known/wot`` names."""
    from wott_directory import DirectoryClient, ProblemError

    client = DirectoryClient(url, token=token)
    try:
        td = await client.directory_description()
    except (ProblemError, OSError, ValueError):
        return client
    kinds = td.get("@type") if isinstance(td.get("@type"), list) else [td.get("@type")]
    if "ThingDirectory" in kinds and isinstance(td.get("base"), str) and td["base"] != client.url:
        client.close()
        return DirectoryClient(td["base"], token=token)
    return client


def _run(coro: Any) -> Any:
    from wott_directory import ProblemError

    try:
        return asyncio.run(coro)
    except ProblemError as e:
        typer.echo(f"directory error: {e}", err=True)
        raise typer.Exit(1) from None
    except OSError as e:
        typer.echo(f"cannot reach the directory: {e}", err=True)
        raise typer.Exit(2) from None


@app.command()
def query(
    jsonpath: str = typer.Argument(..., help="RFC 9535 JSONPath over the array of all TDs, e.g. "
                                             "'$[?@.properties.skinShape].title' (the title of "
                                             "every tactile device) or "
                                             "'$[?search(@.title, \"[Bb]arrel\")].id'."),
    url: str = UrlOption,
    token: str = TokenOption,
    compact: bool = typer.Option(False, help="One line of JSON instead of indented."),
) -> None:
    """Run a JSONPath search on the directory and print the JSON result."""

    async def go() -> Any:
        client = await _client(url, token)
        try:
            return await client.search(jsonpath)
        finally:
            client.close()

    result = _run(go())
    typer.echo(json.dumps(result, ensure_ascii=False, indent=None if compact else 2))


@app.command("list")
def list_things(url: str = UrlOption, token: str = TokenOption,
                as_json: bool = typer.Option(False, "--json",
                                             help="Print the TDs' id and title as JSON.")) -> None:
    """List the TDs of the directory: id and title."""

    async def go() -> Any:
        client = await _client(url, token)
        try:
            return await client.list()
        finally:
            client.close()

    rows = [{"id": td.get("id", "?"), "title": td.get("title", "")} for td in _run(go())]
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    from ._table import Column, render

    typer.echo("\n".join(render([Column("id", "id"), Column("title", "title", wrap=True)], rows)))
