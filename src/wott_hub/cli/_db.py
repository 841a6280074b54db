"""Which history database a command reads: ``--database``, else ``--config``'s, else the default."""

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
