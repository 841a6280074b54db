"""What the history commands share: which database (``--database``, else ``--config``'s, else the
default) and how a ``--from``/``--to`` range is read.

Contract: the history commands only *read*: ``open_reader`` never creates a
file, never migrates, and refuses (``HistoryError``) a missing, empty, foreign,
newer or (when it checks the whole file) corrupted database; a page found corrupted
by any read is a ``HistoryError`` too. Their errors are ``WottHubError``s, which end the
command with one line and an exit code (``wott_hub.cli``, one place for every command).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from wott_hub.errors import InvalidInput

if TYPE_CHECKING:  # imported inside the functions: --help stays fast
    from wott_hub.history.reader import HistoryReader

__all__ = ["open_reader", "resolve_database", "time_range"]


def resolve_database(database: str | None, config: Path | None) -> str:
    if database:
        return database
    from wott_hub.config import HubConfig

    if config is not None:
        return HubConfig.load(config).database
    return HubConfig().database


def open_reader(database: str, *, integrity: bool = True) -> HistoryReader:
    """A HistoryReader on an existing history database (never creates or migrates one);
    ``integrity``: every page checked first (a full read of the file: commands that read a
    little of it, such as ``history list``, leave it to ``--check``)."""
    from wott_hub.history.db import open_existing
    from wott_hub.history.reader import HistoryReader

    return HistoryReader(open_existing(database, integrity=integrity))


def time_range(t_from: str | None, t_to: str | None) -> tuple[int | None, int | None]:
    """``--from``/``--to`` as ns (None = open end); InvalidInput if unreadable, out of range or
    reversed."""
    from wott_hub.history import parse_time

    lo = parse_time(t_from) if t_from else None
    hi = parse_time(t_to) if t_to else None
    if lo is not None and hi is not None and lo > hi:
        raise InvalidInput(f"--from {t_from!r} is after --to {t_to!r}: nothing can be in that range")
    return lo, hi
