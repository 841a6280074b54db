"""Export a range of history as JSON Lines, one record per line.

Each line is ``{"thing", "seq", "t_ns", "kind", "name", "data"}``; ``data`` is
the payload exactly as subscribers received it (spliced in as stored, not
decoded and re-encoded).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Iterable
from typing import IO

from wott_hub.events.record import KIND_NAMES, Record

from .storage import StorageReader

__all__ = ["export_jsonl", "jsonl"]


_quoted = functools.lru_cache(maxsize=4096)(json.dumps)
"""A Thing id's or an affordance name's JSON: a handful of them, each quoted once."""


def jsonl(records: Iterable[Record]) -> str:
    """The records' lines: every line is ``record.to_dict()`` as JSON, its payload spliced in."""
    q = _quoted
    return "".join(f'{{"thing":{q(r.thing)},"seq":{r.seq},"t_ns":{r.t_ns},'
                   f'"kind":"{KIND_NAMES.get(r.kind, r.kind)}","name":{q(r.name)},"data":{r.data}}}\n'
                   for r in records)


def export_jsonl(reader: StorageReader, out: IO[str], thing: str, *, t_from_ns: int | None = None,
                 t_to_ns: int | None = None, names: list[str] | None = None) -> int:
    """Write the records of ``thing`` in [t_from, t_to] to ``out``; returns how many."""
    n = 0
    for page in reader.pages(thing, t_from_ns, t_to_ns, names):
        out.write(jsonl(page))
        n += len(page)
    return n
