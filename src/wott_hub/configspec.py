"""The hub's config tables: declared with ``wott_configspec``, their errors in the hub's tree.

Every table the hub reads (``[hub]``, ``[directory]``, ``[discovery]``, ``[mqtt]``,
``[security]``, a ``[[device]]`` table, each device family's settings, a scene file) is a
msgspec ``Struct`` whose field types carry their bounds and the words a person is told
when a value is wrong: one declaration gives the check, the default, the error message
and the JSON Schema the docs show (docs/configuration.md). The machinery is
``wott_configspec``'s, shared with the Thing Description Directory so both word their
errors alike; this module is the hub's one door to it. Hub modules import these names
from here, never from ``wott_configspec``: ``read`` and ``check`` raise
``wott_hub.errors.ConfigError`` (or the subclass the caller names: ``SettingsError``,
``SceneError``) instead of the library's own error, translated here once.

Errors read ``hub.toml: [hub].workers: a whole number of processes, got 100000; must be
from 0 to 64``. ``read`` stops at the first; ``problems`` finds every wrong key of a table
(``wott-hub config check``, and a config that ``run`` refuses: a person fixes them all at
once instead of one per start), and says "did you mean" for a misspelt key (``suggest``).
This module imports msgspec, ``wott_configspec`` and ``wott_hub.errors`` only: reading a
config stays cheap.
"""

from __future__ import annotations

import copy
import difflib
import re
from collections.abc import Iterable
from typing import Any

import msgspec
import msgspec.inspect as mi
import wott_configspec
from wott_configspec import Flag, Model, bounded, doc, json_schema, says, table_of

from wott_hub.errors import ConfigError

__all__ = ["ConfigError", "Flag", "Model", "bounded", "check", "doc", "json_schema", "problems", "read",
           "says", "suggest", "table_of"]

MAX_PROBLEMS = 200
"""A table reports at most this many problems (each one costs a conversion of the table)."""

_AT = re.compile(r" - at `\$(?P<path>[^`]*)`$")
_STEP = re.compile(r"\.([A-Za-z_][\w-]*)|\[(\d+)\]")
_UNKNOWN = re.compile(r"^Object contains unknown field `(?P<key>[^`]*)`")
_MISSING = re.compile(r"^Object missing required field `(?P<key>[^`]*)`")


def read(model: type[Any], data: Any, where: str, error: type[ConfigError] = ConfigError) -> Any:
    """``data`` (a TOML table) converted to ``model``; a wrong value raises ``error`` naming
    ``where`` (``"hub.toml: [hub]"``; a file ends in a space: ``"scene.toml: "``) and the key."""
    try:
        return wott_configspec.read(model, data, where)
    except wott_configspec.ConfigError as e:
        raise error(str(e)) from None


def check(obj: Any, model: type[Any], where: str) -> None:
    """Check the fields of a dataclass built in Python (not read from a file) against its table."""
    try:
        wott_configspec.check(obj, model, where)
    except wott_configspec.ConfigError as e:
        raise ConfigError(str(e)) from None


def suggest(word: str, choices: Iterable[str], form: str = "{!r}") -> str:
    """``"; did you mean 'simulate'?"`` when one of ``choices`` is close to ``word`` (shown by
    ``form``: ``"[{}]"`` for a table), else ``""``. The one choice ``word`` begins, if any, before the
    closest spelling: "taxel" is the start of "taxel-array" more than a misspelt "xela"."""
    choices = list(choices)
    begun = [c for c in choices if word and c.startswith(word)]
    close = begun if len(begun) == 1 else difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    return f"; did you mean {form.format(close[0])}?" if close else ""


def problems(model: type[Any], data: Any, where: str) -> list[str]:
    """Every wrong key of the table ``data`` against ``model``, one line each, worded as ``read``
    words the first; [] when ``read`` would accept it.

    msgspec stops at the first error: the key at fault is taken out of a copy of the table and
    the rest converted again, until it converts or only missing keys are left (all of them are
    then named at once). An unknown key says which declared key it is probably a typo of.
    """
    data = copy.deepcopy(data)
    out: list[str] = []
    removed: set[tuple[str | int, ...]] = set()
    for _ in range(MAX_PROBLEMS):
        try:
            msgspec.convert(data, model)
            return out
        except msgspec.ValidationError as e:
            message = str(e)
        m = _AT.search(message)
        steps: list[str | int] = [s or int(i) for s, i in _STEP.findall(m["path"])] if m else []
        head = message[:m.start()] if m else message
        if (missing := _MISSING.match(head)) is not None:
            fields = _struct_fields(model, steps)
            present = _at(data, steps)
            names = [f.encode_name for f in fields if f.required] if fields else [missing["key"]]
            out += [f"{_place(where, [*steps, name])}: required, missing" for name in names
                    if not (isinstance(present, dict) and name in present) and (*steps, name) not in removed]
            if not steps:  # the table itself lacks them: nothing more can be learnt from converting it
                return out
        else:
            line = wott_configspec.explain(model, data, message, where)
            if (unknown := _UNKNOWN.match(head)) is not None:
                key = unknown["key"]
                declared = _struct_fields(model, steps) or ()
                line += suggest(key, [f.encode_name for f in declared])
                steps = [*steps, key]
            out.append(line)
        # take the key at fault out; an item of a list goes with its whole list (indexes must stay)
        while steps and isinstance(steps[-1], int):
            steps.pop()
        if not steps or not _remove(data, steps):
            return out
        removed.add(tuple(steps))
    return out


def _place(where: str, steps: list[str | int]) -> str:
    """``where`` and the key path, joined as ``wott_configspec`` joins them."""
    path = "".join(f".{s}" if isinstance(s, str) else f"[{s}]" for s in steps)
    return where + (path[1:] if path.startswith(".") and (not where or where[-1].isspace()) else path)


def _at(data: Any, steps: list[str | int]) -> Any:
    for step in steps:
        try:
            data = data[step]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def _remove(data: Any, steps: list[str | int]) -> bool:
    parent = _at(data, steps[:-1])
    if isinstance(parent, dict) and steps[-1] in parent:
        del parent[steps[-1]]
        return True
    return False


def _struct_fields(model: type[Any], steps: list[str | int]) -> tuple[Any, ...] | None:
    """The declared fields of the table at ``steps`` of ``model``, or None if that is no table."""
    info = _table(mi.type_info(model))
    for step in steps:
        if isinstance(step, str) and isinstance(info, mi.StructType):
            field = next((f for f in info.fields if f.encode_name == step), None)
            info = _table(field.type) if field is not None else None
        elif isinstance(step, int) and isinstance(info, mi.ListType | mi.VarTupleType):
            info = _table(info.item_type)
        else:
            return None
    return info.fields if isinstance(info, mi.StructType) else None


def _table(info: Any) -> Any:
    """``info`` without its metadata; of a union (``T | None``), the table or list member."""
    while isinstance(info, mi.Metadata):
        info = info.type
    if isinstance(info, mi.UnionType):
        members = [_table(t) for t in info.types]
        return next((t for t in members if isinstance(t, mi.StructType | mi.ListType | mi.VarTupleType)),
                    info)
    return info
