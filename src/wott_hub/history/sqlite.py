"""The SQLite engine: one file, one writer at a time, and pages read as one joined row.

Writing is ``SqlStorage``'s (multi-row INSERTs of tuples), with SQLite's limits: at most 999
parameters a statement before SQLite 3.32; a Thing's registration waits out another process
holding the write lock for long (the busy timeout covers the usual case); the integrity check is
``PRAGMA quick_check`` (``db.check_integrity``).

Reading (``reader.HistoryReader`` on SQLite): a page is read as one row whose columns SQLite
joined (``JOINED``). A row per record costs the driver ~1 µs in Python (a tuple, five objects,
the lock taken back after each step), most of a replay's reading; a joined page is one step,
run without the lock, and strings that NumPy and ``str.split`` read in C.
"""

from __future__ import annotations

import sqlite3
import time
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from wott_hub.errors import HistoryError

from .db import check_integrity
from .sql import SqlStorage

__all__ = ["JOINED", "JoinedPage", "SqliteStorage", "joined_page"]


class SqliteStorage(SqlStorage):
    max_params = 999 if sqlite3.sqlite_version_info < (3, 32) else 30_000

    def register(self, thing: str, *, title: str, family: str, td: str | None, static_values: str | None,
                 ahead: int) -> int:
        for attempt in range(8):
            try:
                return super().register(thing, title=title, family=family, td=td, static_values=static_values,
                                        ahead=ahead)
            except HistoryError as e:  # another process holds SQLite's write lock long
                if "locked" not in str(e) or attempt == 7:
                    raise
                time.sleep(0.05 * 2 ** attempt)
        raise AssertionError("unreachable")

    def check_integrity(self) -> None:
        check_integrity(self.engine)


JOINED = """SELECT count(*), group_concat(seq), group_concat(t_ns), group_concat(kind),
group_concat(name, char(0)), group_concat(length(data)), CAST(group_concat(data, '') || zeroblob(16) AS BLOB)
FROM (SELECT seq, t_ns, kind, name, data FROM events
      WHERE thing_key = ? AND seq > ? AND seq <= ? AND t_ns >= ? AND t_ns <= ?{names} ORDER BY seq LIMIT ?)"""
"""A page of records (seq order, a time and a name filter) as one row: each column's values
joined by SQLite, the payloads one after the other (16 NUL bytes after them:
``codec.decode_joined``). SQLite 3.40 has no ORDER BY within an aggregate: the page is used only
if its seqs come out ascending (= in seq order), else read row by row."""


class JoinedPage(NamedTuple):
    """A page of ``JOINED`` checked, its payloads not yet decoded."""

    seqs: npt.NDArray[np.int64]
    times: npt.NDArray[np.int64]
    kinds: npt.NDArray[np.int64]
    names: list[str]
    sizes: npt.NDArray[np.int64]
    joined: bytes


def joined_page(raw: sqlite3.Connection, key: int, after: int, upto: int, t_from_ns: int, t_to_ns: int,
                names: list[str] | None, limit: int) -> JoinedPage | None:
    """The page of ``JOINED`` (no seqs: nothing left); None where the page cannot be read so (a
    page beyond SQLite's longest value, seqs out of order, a payload stored as text that is not
    ASCII, whose ``length`` counts characters): the caller reads it row by row."""
    sql = JOINED.format(names=f" AND name IN ({', '.join('?' * len(names))})" if names else "")
    cur = raw.cursor()
    try:
        cur.execute(sql, (key, after, upto, t_from_ns, t_to_ns, *(names or ()), limit))
        count, seqs, times, kinds, names_, sizes, joined = cur.fetchone()
    except sqlite3.DataError:  # longer than SQLITE_MAX_LENGTH
        return None
    finally:
        cur.close()
    if not count:
        empty = np.empty(0, np.int64)
        return JoinedPage(empty, empty, empty, [], empty, bytes(16))
    seq = np.fromstring(seqs, np.int64, sep=",")
    t_ns = np.fromstring(times, np.int64, sep=",")
    kind = np.fromstring(kinds, np.int64, sep=",")
    size = np.fromstring(sizes, np.int64, sep=",")
    name = names_.split("\0")
    if not (len(seq) == len(t_ns) == len(kind) == len(size) == len(name) == count) \
            or (np.diff(seq) <= 0).any() or int(size.sum()) + 16 != len(joined):
        return None
    return JoinedPage(seq, t_ns, kind, name, size, joined)
