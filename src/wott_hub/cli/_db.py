"""What the history commands share: which database (``--database``, else ``--config``'s, else the
default) and how a ``--from``/``--to`` range is read."""

from __future__ import annotations

from pathlib import Path

import typer


def resolve_database(database: str | None, config: Path | None) -> str:
    if database:
        return database
    from wott_hub.config import ConfigError, HubConfig

    if config is not None:
        try:
            return HubConfig.load(config).database
        except ConfigError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2) from None
    return HubConfig().database


def open_reader(database: str):
    """A HistoryReader on an existing, up-to-date database (never creates one)."""
    from wott_hub.history import HistoryError, HistoryReader, create_engine, database_url, upgrade

    url = database_url(database)
    if url.startswith("sqlite:///") and not Path(url.removeprefix("sqlite:///")).exists():
        typer.echo(f"error: no history database at {url.removeprefix('sqlite:///')}", err=True)
        raise typer.Exit(1)
    engine = create_engine(url)
    try:
        upgrade(engine)
    except HistoryError as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(1) from None
    return HistoryReader(engine)


def time_range(t_from: str | None, t_to: str | None) -> tuple[int | None, int | None]:
    """``--from``/``--to`` as ns (None = open end); exit 2 with the parser's message if unreadable."""
    from wott_hub.history import parse_time

    try:
        return (parse_time(t_from) if t_from else None, parse_time(t_to) if t_to else None)
    except ValueError as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(2) from None
