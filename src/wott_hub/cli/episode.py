"""``wott-hub episode``: mark the episodes of a recording on a running hub, and list those recorded.

``start TASK`` and ``end`` invoke the hub Thing's ``startEpisode`` and ``endEpisode`` actions over HTTP
(``--url``, default http://127.0.0.1:8080 or ``WOTT_HUB_URL``; a token with the ``control`` scope where
the hub asks for one); ``list`` reads the marks from a history database, as ``history export --format
lerobot`` will cut it (docs/learning.md). Errors are one line and an exit code (2 bad input, 3 no
history, 4 an episode already open or none open).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .devices import TokenOption, UrlOption, _hub, _request

__all__ = ["app"]

app = typer.Typer(
    help="Mark episodes while recording (start, end) and list the recorded ones.",
    short_help="Mark episodes while recording.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@app.command(short_help="Start an episode with its task.")
def start(
    task: str = typer.Argument(..., help="What is being done, one line (e.g. 'pick up the cup')."),
    url: str = UrlOption,
    token: str = TokenOption,
) -> None:
    """Start an episode on the running hub (one at a time)."""
    out = _request("POST", f"{_hub(url)}/actions/startEpisode", token, {"task": task})
    typer.echo(f"episode started: {out['task']}")


@app.command(short_help="End the open episode.")
def end(url: str = UrlOption, token: str = TokenOption) -> None:
    """End the episode open on the running hub."""
    out = _request("POST", f"{_hub(url)}/actions/endEpisode", token, {})
    typer.echo(f"episode ended: {out['task']} ({(out['to'] - out['from']) / 1e9:.1f} s)")


@app.command("list", short_help="The episodes marked in a history database.")
def list_episodes(
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    t_to: str = typer.Option(None, "--to", help="End, same forms as --from."),
    as_json: bool = typer.Option(False, "--json", help="JSON Lines for scripts."),
    database: str = typer.Option(
        None, "--database", "-d", help="Database file or URL (default: the config's, else ./wott-hub.db)."
    ),
    config: Path = typer.Option(None, "--config", "-c", exists=True, dir_okay=False, help="Hub config."),
) -> None:
    """The episodes marked in history (each start paired with its end), oldest first."""
    from wott_hub.history import format_ns
    from wott_hub.history.learning.episodes import marked

    from ._db import open_reader, resolve_database, time_range

    lo, hi = time_range(t_from, t_to)
    reader = open_reader(resolve_database(database, config), integrity=False)
    episodes = marked(reader, lo, hi)
    if not episodes and not as_json:
        typer.echo("no episode marked in that range (wott-hub episode start TASK, while recording)", err=True)
    for i, e in enumerate(episodes):
        if as_json:
            typer.echo(json.dumps({"episode": i, "task": e.task, "from": e.start_ns, "to": e.end_ns}))
        else:
            typer.echo(f"{i:>4}  {format_ns(e.start_ns)}  {(e.end_ns - e.start_ns) / 1e9:9.1f} s  {e.task}")
