"""What ``xela_server`` sends over its WebSocket (default port 5000), and the sensor models it names.

Documented by the public MIT ROS wrappers (omron-sinicx/xela_server_ros: ``scripts/xela_service``,
``message_parser``/``on_message``, and ``notes/websocket-data-structure.md``): a first message whose
``message`` is ``"Welcome"``, then about 100 a second, each a JSON object with ``message`` (a running
number), ``time``, and one key per sensor position (``"1"``, ``"2"``, ...) holding ``model``
(``uSPa44``: 4 x 4 taxels, ``uSPa46``: 4 x 6, ``uSPa22``: 2 x 2), ``time``, ``taxels`` (their number),
``data`` (x, y, z per taxel, 16-bit counts resting near 30,000: comma-separated hex up to server
1.7.6, a list of integers from 1.7.7) and, when the server's calibration is on, ``calibrated`` (x, y,
z force per taxel, N). Taxels are numbered row by row from the top left (the note's 4 x 4 figure).

Anything else is a ``Problem`` with a reason naming the position and the field: a message that is not
JSON, a model this hub does not know, a ``data`` or ``calibrated`` of the wrong size; never an exception
that ends the stream.
"""

from __future__ import annotations

import json
from typing import Any, NamedTuple

import numpy as np

__all__ = ["MODELS", "Problem", "Reading", "Update", "Welcome", "parse", "reading_of"]

MODELS = {"uSPa22": (2, 2), "uSPa44": (4, 4), "uSPa46": (4, 6)}
"""Model -> (rows, cols) of taxels."""


class Welcome(NamedTuple):
    """The server's first message."""


class Problem(NamedTuple):
    reason: str


class Reading(NamedTuple):
    model: str
    counts: np.ndarray  # (taxels, 3) raw x, y, z counts
    forces: np.ndarray | None  # (taxels, 3) N, when the server's calibration is on


class Update(NamedTuple):
    """One data message: its running number and each position's entry, not yet read."""

    number: int | None
    sensors: dict[str, Any]


def parse(text: str | bytes) -> Welcome | Update | Problem:
    """One message of the server (its sensors' entries are read by ``reading_of`` when wanted)."""
    try:
        msg = json.loads(text)
    except ValueError as e:
        return Problem(f"a message that is not JSON ({e})")
    if not isinstance(msg, dict):
        return Problem(f"a message that is a JSON {type(msg).__name__}, not an object")
    number = msg.get("message")
    if number == "Welcome":
        return Welcome()
    if not isinstance(number, int) or isinstance(number, bool):
        number = None
    return Update(number, {k: v for k, v in msg.items() if k.isdigit()})


def reading_of(position: str, entry: Any) -> Reading | Problem:
    """A position's entry read and checked against its model."""
    where = f"position {position}"
    if not isinstance(entry, dict):
        return Problem(f"{where}: its entry is a {type(entry).__name__}, not an object")
    model = entry.get("model")
    shape = MODELS.get(model) if isinstance(model, str) else None
    if shape is None:
        return Problem(f"{where}: model {model!r} is not one this hub knows ({', '.join(MODELS)})")
    n = shape[0] * shape[1]
    counts = _values(entry.get("data"), n, hexadecimal=True)
    if isinstance(counts, str):
        return Problem(f"{where}: 'data' {counts}, {model} has {n} taxels x 3 = {3 * n}")
    forces: np.ndarray | None = None
    if entry.get("calibrated") is not None:
        got = _values(entry["calibrated"], n, hexadecimal=False)
        if isinstance(got, str):
            return Problem(f"{where}: 'calibrated' {got}, {model} has {n} taxels x 3 = {3 * n}")
        forces = got
    return Reading(str(model), counts, forces)


def _values(raw: Any, n: int, *, hexadecimal: bool) -> np.ndarray | str:
    """(n, 3) floats, or what is wrong with them: ``data`` is hex text or integers, ``calibrated``
    numbers."""
    items = raw.split(",") if isinstance(raw, str) and hexadecimal else raw
    if not isinstance(items, list):
        return f"is a {type(raw).__name__}"
    if len(items) != 3 * n:
        return f"holds {len(items)} values"
    try:
        values = [int(v, 16) if isinstance(v, str) and hexadecimal else _number(v, hexadecimal)
                  for v in items]
    except (TypeError, ValueError):
        return "holds a value that is not a number"
    out = np.array(values, dtype=np.float64).reshape(n, 3)
    if not np.isfinite(out).all():
        return "holds a value that is not finite"
    return out


def _number(v: Any, integer: bool) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or (integer and not isinstance(v, int)):
        raise TypeError(f"not a {'count' if integer else 'number'}: {v!r}")
    return float(v)
