"""Tables the listing commands print: as wide as the terminal (80 columns when the output is not
one), never cutting a value.

Why not rich's ``Table``: at a width its columns do not fit, it shortens every cell with an
ellipsis (``2026-11-…``, ``http://127.0.…``) or folds it mid-word; an id, a time or a URL cut
like that cannot be read or pasted. Here a value is never cut: columns are dropped by
priority (the least useful first, as ``kubectl`` and ``docker ps`` keep their wide columns
for ``-o wide``), a column of prose wraps at spaces, and when even the essential columns
do not fit each row is printed as a block of ``name: value`` lines. A footer names the
columns left out; ``--json`` always has every field.
"""

from __future__ import annotations

import shutil
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

__all__ = ["Column", "render", "terminal_width"]

GAP = 2
"""Spaces between two columns."""

MIN_WRAP = 16
"""A prose column narrower than this is not worth wrapping into: the table becomes blocks."""


@dataclass(frozen=True)
class Column:
    """A column: its heading, the row key it shows, when it is dropped (0: never; a higher number
    goes first), whether it is prose that may wrap at spaces, its alignment (``<`` or ``>``), and
    how wide a wrapping column may be at most (the rest of the room goes to the others)."""

    title: str
    key: str
    drop: int = 0
    wrap: bool = False
    align: str = "<"
    most: int = 0  # a prose column: at most this wide when it must wrap (0: its share of the room)


def terminal_width() -> int:
    """The terminal's columns (``COLUMNS`` if set), 80 when the output is not a terminal."""
    return shutil.get_terminal_size((80, 24)).columns


def render(columns: Sequence[Column], rows: Sequence[Mapping[str, object]], width: int | None = None,
           title: str | None = None) -> list[str]:
    """The table's lines, each at most ``width`` wide unless a single value is longer."""
    width = width or terminal_width()
    cells = [{c.key: _text(r.get(c.key)) for c in columns} for r in rows]
    shown = list(columns)

    def natural(c: Column) -> int:
        return max([len(c.title), *(len(line) for cell in cells for line in cell[c.key].splitlines())])

    def total(cols: Sequence[Column], widths: Mapping[str, int]) -> int:
        return sum(widths[c.key] for c in cols) + GAP * (len(cols) - 1)

    widths = {c.key: natural(c) for c in columns}
    # prose wraps before a column is dropped: drop only while the table is too wide with every prose
    # column at its narrowest (MIN_WRAP, or its longest word)
    narrow = {c.key: min(widths[c.key], max(MIN_WRAP, _longest_word(c, cells))) if c.wrap else widths[c.key]
              for c in columns}
    while total(shown, narrow) > width and any(c.drop for c in shown):
        worst = max((c for c in shown if c.drop), key=lambda c: (c.drop, shown.index(c)))
        shown.remove(worst)
    wrapping = [c for c in shown if c.wrap]
    if total(shown, widths) > width and wrapping:
        room = width - total([c for c in shown if not c.wrap], widths) - GAP * len(wrapping)
        order = sorted(wrapping, key=lambda c: c.most or width)
        for k, c in enumerate(order):  # an equal share each, leaving the others their narrowest
            reserve = sum(narrow[r.key] for r in order[k + 1:])
            share = max(narrow[c.key], min(room // (len(order) - k), room - reserve))
            widths[c.key] = min(widths[c.key], share, max(c.most, narrow[c.key]) if c.most else share)
            room -= widths[c.key]
    out = [title] if title else []
    if total(shown, widths) > width:  # the essentials alone are too wide: one block per row
        return [*out, *_blocks(columns, cells)]
    out.append(_line([c.title for c in shown], shown, widths))
    out.append(_line(["-" * widths[c.key] for c in shown], shown, widths))
    for cell in cells:
        parts = {c.key: _wrapped(cell[c.key], widths[c.key]) if c.wrap else cell[c.key].splitlines() or [""]
                 for c in shown}
        for k in range(max(len(p) for p in parts.values())):
            line = [parts[c.key][k] if k < len(parts[c.key]) else "" for c in shown]
            out.append(_line(line, shown, widths))
    left = [c.title for c in columns if c not in shown]
    if left and rows:
        out.append(f"({', '.join(left)}: not shown at {width} columns; a wider terminal or --json "
                   "shows them)")
    return out


def _longest_word(c: Column, cells: Sequence[Mapping[str, str]]) -> int:
    return max((len(w) for cell in cells for w in cell[c.key].split()), default=0)


def _text(value: object) -> str:
    return "" if value is None else str(value)


def _wrapped(text: str, width: int) -> list[str]:
    lines = []
    for para in text.splitlines() or [""]:
        lines += textwrap.wrap(para, width, break_long_words=False, break_on_hyphens=False) or [""]
    return lines


def _line(values: Sequence[str], cols: Sequence[Column], widths: Mapping[str, int]) -> str:
    parts = [f"{v:{c.align}{widths[c.key]}}" for v, c in zip(values, cols, strict=True)]
    return (" " * GAP).join(parts).rstrip()


def _blocks(columns: Sequence[Column], cells: Sequence[Mapping[str, str]]) -> list[str]:
    out: list[str] = []
    pad = max(len(c.title) for c in columns)
    for cell in cells:
        if out:
            out.append("")
        for c in columns:
            lines = cell[c.key].splitlines() or [""]
            out.append(f"{c.title + ':':<{pad + 1}} {lines[0]}".rstrip())
            out += [f"{'':<{pad + 1}} {line}" for line in lines[1:]]
    return out
