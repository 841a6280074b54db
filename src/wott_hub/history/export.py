"""Export a range of history as JSON Lines, one record per line.

Each line is ``{"thing", "seq", "t_ns", "kind", "name", "data"}``; ``data`` is
the payload exactly as subscribers received it (spliced in as stored, not
decoded and re-encoded).
"""

from __future__ import annotations

import json
from typing import IO

from wott_hub.events.record import KIND_NAMES

from .reader import HistoryReader

__all__ = ["export_jsonl"]


def export_jsonl(reader: HistoryReader, out: IO[str], thing: str, *, t_from_ns: int | None = None,
                 t_to_ns: int | None = None, names: list[str] | None = None) -> int:
    """Write the records of ``thing`` in [t_from, t_to] to ``out``; returns how many."""
    head = '{"thing":' + json.dumps(thing) + ',"seq":'
    n = 0
    for page in reader.pages(thing, t_from_ns, t_to_ns, names):
        out.write("".join(
            f'{head}{seq},"t_ns":{t},"kind":"{KIND_NAMES.get(k, k)}","name":{json.dumps(name)},'
            f'"data":{data}}}\n'
            for seq, t, k, name, data in page))
        n += len(page)
    return n
