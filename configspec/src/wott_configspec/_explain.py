"""msgspec's message (``Expected `int` <= 64 - at `$.workers```) as one line that names the key.

The line is ``<where><key path>: <what is expected>, got <value>; must be <bounds>``; the
expected words are the field's ``says`` phrase, else a plain name of its type. ``where``
names the table (``hub.toml: [hub]``, then ``.workers``), or the file when it ends in a
space (``scene.toml: ``, then ``step[2].to``), or nothing (``""``, then ``page_size``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import msgspec.inspect as mi

__all__ = ["explain", "range_text"]

_AT = re.compile(r"^(?P<msg>.*) - at `\$(?P<path>[^`]*)`$", re.S)
_STEP = re.compile(r"\.([A-Za-z_][\w-]*)|\[(\d+)\]")
_UNKNOWN = re.compile(r"Object contains unknown field `(?P<key>[^`]*)`")
_MISSING = re.compile(r"Object missing required field `(?P<key>[^`]*)`")


def explain(model: type[Any], data: Any, message: str, where: str) -> str:
    """One line: ``where`` + the key path, what is expected there, what was given, and the bounds."""
    m = _AT.match(message)
    msg, path = (m["msg"], m["path"]) if m else (message, "")
    steps: list[str | int] = [s or int(i) for s, i in _STEP.findall(path)]
    value: Any = data
    for step in steps:
        try:
            value = value[step]
        except (KeyError, IndexError, TypeError):
            value = None
            break
    info, phrase = _walk(mi.type_info(model), steps, value)
    if (u := _UNKNOWN.match(msg)) is not None:
        fields = info.fields if isinstance(info, mi.StructType) else ()
        known = ", ".join(sorted(f.encode_name for f in fields))
        return f"{_place(where, [*steps, u['key']])}: unknown key (known: {known})"
    if (r := _MISSING.match(msg)) is not None:
        return f"{_place(where, [*steps, r['key']])}: required, missing"
    place = _place(where, steps)
    if isinstance(info, mi.StructType) and not isinstance(value, Mapping):
        return f"{place} must be a table, got {value!r}"
    choices = _choices(info)
    if choices is not None and value not in choices:
        return f"{place}: {value!r} is not one of {', '.join(str(c) for c in choices)}"
    declared = phrase is not None  # a declared phrase says the length itself ("an interface address")
    phrase = phrase or _PLAIN.get(type(info).__name__) or msg[0].lower() + msg[1:]
    text = f"{place}: {phrase}, got {value!r}"
    bounds = range_text(info)
    if bounds:
        return f"{text}; must be {bounds}"
    size = "" if declared else _size_text(info)
    return f"{text}; must have {size}" if size else text


def _place(where: str, steps: list[str | int]) -> str:
    """``where`` and the key path: ``hub.toml: [hub].workers``, ``scene.toml: step[2].to``, ``page_size``."""
    path = "".join(f".{s}" if isinstance(s, str) else f"[{s}]" for s in steps)
    return where + (path[1:] if path.startswith(".") and (not where or where[-1].isspace()) else path)


def _choices(info: Any) -> tuple[Any, ...] | None:
    """The values a ``Literal`` or an ``Enum`` allows, or None for any other type."""
    if isinstance(info, mi.LiteralType):
        return tuple(info.values)
    if isinstance(info, mi.EnumType):
        return tuple(m.value for m in info.cls)
    return None


def _size_text(info: Any) -> str:
    """``"2 items"``, ``"at least 1 character"``...: the length bounds of a list or string, or ''."""
    if not isinstance(info, _SIZED):
        return ""
    low, high = info.min_length, info.max_length
    unit = "character" if isinstance(info, mi.StrType) else "item"
    if low is None and high is None:
        return ""
    if low == high:
        count = f"{low}"
    elif high is None:
        count = f"at least {low}"
    elif low is None:
        count = f"at most {high}"
    else:
        count = f"{low} to {high}"
    return f"{count} {unit}" if count.split()[-1] == "1" else f"{count} {unit}s"


_SIZED = (mi.StrType, mi.BytesType, mi.ListType, mi.VarTupleType, mi.SetType, mi.FrozenSetType, mi.DictType)

_PLAIN: dict[str, str] = {  # what a msgspec.inspect type is called when its declaration gives no phrase
    "FloatType": "a number", "IntType": "a whole number", "BoolType": "true or false",
    "StrType": "a string", "ListType": "a list", "VarTupleType": "a list", "TupleType": "a list",
    "DictType": "a table",
}


def range_text(info: Any) -> str:
    """``"from 0 to 64"``, ``"above 0 and at most 60000"``...: the bounds of a number type, or ''."""
    if not isinstance(info, mi.IntType | mi.FloatType):
        return ""
    ge, gt, le, lt = info.ge, info.gt, info.le, info.lt
    if ge is not None and le is not None:
        return f"from {_num(ge)} to {_num(le)}"
    low = f"at least {_num(ge)}" if ge is not None else f"above {_num(gt)}" if gt is not None else ""
    high = f"at most {_num(le)}" if le is not None else f"below {_num(lt)}" if lt is not None else ""
    return " and ".join(p for p in (low, high) if p)


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


def _walk(info: Any, steps: list[str | int], value: Any) -> tuple[Any, str | None]:
    """The inspected type at ``steps`` (metadata unwrapped) and the nearest ``expects`` phrase."""
    phrase: str | None = None
    info, phrase = _unwrap(info, phrase)
    for step in steps:
        info, phrase = _pick(info, None, phrase, leaf=False)
        if isinstance(step, str) and isinstance(info, mi.StructType):
            field = next((f for f in info.fields if f.encode_name == step), None)
            if field is None:
                return info, phrase
            info, phrase = _unwrap(field.type, None)
        elif isinstance(step, int) and isinstance(info, mi.ListType | mi.VarTupleType | mi.SetType):
            info, phrase = _unwrap(info.item_type, phrase)
        elif isinstance(step, int) and isinstance(info, mi.TupleType) and step < len(info.item_types):
            info, phrase = _unwrap(info.item_types[step], phrase)
        elif isinstance(step, str) and isinstance(info, mi.DictType):
            info, phrase = _unwrap(info.value_type, phrase)
        else:
            return info, phrase
    return _pick(info, value, phrase, leaf=True)


def _unwrap(info: Any, phrase: str | None) -> tuple[Any, str | None]:
    while isinstance(info, mi.Metadata):
        phrase = (info.extra or {}).get("expects", phrase)
        info = info.type
    return info, phrase


_KINDS: dict[str, tuple[type, ...]] = {  # the Python values a msgspec.inspect type takes
    "StrType": (str,), "BoolType": (bool,), "IntType": (int,), "FloatType": (int, float),
    "StructType": (Mapping,), "DictType": (Mapping,), "ListType": (list, tuple),
    "VarTupleType": (list, tuple), "TupleType": (list, tuple),
}


def _pick(info: Any, value: Any, phrase: str | None, leaf: bool) -> tuple[Any, str | None]:
    """In a union, the member a value of this kind belongs to (a string to the URL, a table to
    the struct); elsewhere ``info`` itself."""
    if not isinstance(info, mi.UnionType):
        return info, phrase
    members = [m for m in info.types if not isinstance(m, mi.NoneType)]
    for member in members:
        inner, inner_phrase = _unwrap(member, None)
        kinds = _KINDS.get(type(inner).__name__, ())
        if value is not None and isinstance(value, kinds) and not (isinstance(value, bool)
                                                                    and inner.__class__ is not mi.BoolType):
            return inner, inner_phrase or phrase
        if not leaf and value is None and isinstance(inner, mi.StructType | mi.ListType | mi.VarTupleType
                                                     | mi.TupleType | mi.DictType):
            return inner, inner_phrase or phrase
    if len(members) == 1:
        inner, inner_phrase = _unwrap(members[0], None)
        return inner, phrase or inner_phrase
    return info, phrase
