"""The database's errors (SQLAlchemy's, and the driver's own) as the hub's error tree, in one place.

Why one place: every caller used to unwrap SQLAlchemy's ``e.orig`` itself to find the driver's
message, and each decided on its own which failures mean "these rows can never be written"
(isolate them, give them up) and which "the database cannot be used now" (retry, report).

Contract:
- ``database_error(e, doing)`` is the error of the tree for ``e``: ``RecordRefused`` when the
  database refused the rows' *data* (a unique key, a value its column cannot hold: the same rows
  can never succeed, so a writer isolates and gives them up), else ``HistoryError`` (locked,
  unreachable, corrupted, a table missing: worth retrying later). Its message is ``doing``, a
  colon and the driver's message, or the driver's message alone when ``doing`` is empty (a
  ``HistoryError`` already is one: it is kept).
- ``translated(doing)``: a block whose database errors leave it as ``database_error``; the
  hub's own errors (``WottHubError``) and anything else pass unchanged.
- ``driver_message(e)``: the first line of the driver's message, without SQLAlchemy's
  statement dump and background link.
- ``is_database_error(e)``: SQLAlchemy's errors, and the PEP 249 errors of a driver's cursor
  used directly (no SQLAlchemy class wraps those).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import sqlalchemy as sa

from wott_hub.errors import HistoryError, RecordRefused

__all__ = ["database_error", "driver_message", "is_database_error", "translated"]

_PEP249 = ("DatabaseError", "InterfaceError")
"""The base classes of every error a PEP 249 driver raises (``sqlite3``, ``psycopg``)."""
_DATA = ("IntegrityError", "DataError")
"""PEP 249's (and SQLAlchemy's, which are named after them) errors about the rows themselves."""


def _named(e: BaseException, names: tuple[str, ...]) -> bool:
    return any(c.__name__ in names for c in type(e).__mro__)


def _cause(e: BaseException) -> BaseException:
    """The driver's error under SQLAlchemy's wrapper, else ``e``."""
    if isinstance(e, sa.exc.StatementError) and isinstance(e.orig, BaseException):
        return e.orig
    return e


def driver_message(e: BaseException) -> str:
    text = str(_cause(e))
    return text.splitlines()[0] if text else type(e).__name__


def is_database_error(e: BaseException) -> bool:
    return isinstance(e, sa.exc.SQLAlchemyError) or _named(e, _PEP249)


def _refuses_data(e: BaseException) -> bool:
    """Does ``e`` say the rows themselves can never be written (not the database's state)?"""
    return _named(_cause(e), _DATA)


def database_error(e: BaseException, doing: str = "") -> HistoryError:
    if isinstance(e, HistoryError):
        return e
    message = f"{doing}: {driver_message(e)}" if doing else driver_message(e)
    return RecordRefused(message) if _refuses_data(e) else HistoryError(message)


@contextmanager
def translated(doing: str = "") -> Iterator[None]:
    try:
        yield
    except Exception as e:
        if not is_database_error(e):
            raise
        raise database_error(e, doing) from None
