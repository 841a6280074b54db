"""Times on the command line: ISO 8601, relative (``-10m``), or a number since the epoch."""

from __future__ import annotations

import datetime as dt
import math
import re
import time

from wott_hub.errors import InvalidInput

__all__ = ["MAX_NS", "format_ns", "parse_time"]

MAX_NS = (1 << 63) - 1
"""The last instant history can store (a signed 64-bit count of ns: 2262-04-11)."""

_REL = re.compile(r"^-(\d+(?:\.\d+)?)\s*(ms|s|m|h|d)$")
_UNIT = {"ms": 1e-3, "s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}


def parse_time(text: str, now_ns: int | None = None) -> int:
    """Nanoseconds since the epoch, checked to lie in [1970, 2262] (what the database's 64-bit
    column holds); anything else, ``nan`` and ``inf`` included, is ``InvalidInput``.

    See ``_parse`` for the forms."""
    try:
        t = _parse(text, now_ns)
    except (OverflowError, ValueError) as e:  # inf/nan, year 99999: never Python's own message
        if isinstance(e, InvalidInput):
            raise
        raise InvalidInput(f"not a time: {text!r} (ISO 8601, -10m, now, or seconds since the epoch)") \
            from None
    if not 0 <= t <= MAX_NS:
        raise InvalidInput(f"time out of range: {text!r} (between 1970-01-01 and 2262-04-11)")
    return t


def _parse(text: str, now_ns: int | None = None) -> int:
    """Nanoseconds since the epoch from ``2026-11-22T10:00:00`` (local time unless it has an
    offset or ``Z``), ``-10m`` / ``-2h`` / ``-500ms`` (before now), ``now``, or a number
    (seconds, or nanoseconds when it is larger than 1e14)."""
    s = text.strip()
    now_ns = now_ns if now_ns is not None else time.time_ns()
    if s == "now":
        return now_ns
    m = _REL.match(s)
    if m:
        return now_ns - int(float(m.group(1)) * _UNIT[m.group(2)] * 1e9)
    try:
        whole = int(s)  # exact: nanoseconds do not survive a float
    except ValueError:
        pass
    else:
        return whole if whole > 10**14 else whole * 10**9
    try:
        number = float(s)
    except ValueError:
        pass
    else:
        if not math.isfinite(number):
            raise InvalidInput(f"not a time: {text!r} (a finite number of seconds since the epoch)")
        return int(number) if number > 1e14 else int(number * 1e9)
    try:
        when = dt.datetime.fromisoformat(s.replace("Z", "+00:00"))
    except ValueError:
        raise InvalidInput(f"not a time: {text!r} (ISO 8601, -10m, now, or seconds since the epoch)") \
            from None
    if when.tzinfo is None:
        when = when.astimezone()  # local time
    return int(when.timestamp() * 1e9)


def format_ns(t_ns: int | None) -> str:
    if t_ns is None:
        return "-"
    return dt.datetime.fromtimestamp(t_ns / 1e9).astimezone().isoformat(timespec="milliseconds")
