"""Configuration declared once: typed fields with bounds, read by msgspec, errors naming file, table and key.

Every table the hub reads (``[hub]``, ``[directory]``, ``[discovery]``, each
device family's settings) is a msgspec ``Struct`` whose field types carry their
bounds (``Meta(ge=..., le=...)``) and the words a person is told when a value
is wrong (``says``). That one declaration gives the check, the default, the
error message and the JSON Schema the docs show (docs/configuration.md), so the
three can no longer drift apart as hand-written checks did.

Why every number has an upper bound too: NaN fails every comparison and
infinity fails every finite ``le``, so both are refused by the same bound that
keeps ``workers = 100000`` from forking the machine to death.

Errors are ``wott_hub.errors.ConfigError`` and read
``hub.toml: [hub].workers: a whole number of processes, got 100000; must be from 0 to 64``.
This module imports msgspec and ``wott_hub.errors`` only: reading a config stays cheap.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from typing import Annotated, Any, cast, get_type_hints

import msgspec
import msgspec.inspect as mi
import msgspec.json

from wott_hub.errors import ConfigError

__all__ = ["ConfigError", "Flag", "Model", "bounded", "check", "doc", "explain", "json_schema", "range_text",
           "read", "says", "table_of"]


class Model(msgspec.Struct, kw_only=True, forbid_unknown_fields=True):
    """Base of a declared table: keyword-only, and a key it does not declare is an error."""


def says(phrase: str, **meta: Any) -> msgspec.Meta:
    """msgspec constraints ``meta`` plus the ``phrase`` an error says is expected, for ``Annotated``:
    ``Annotated[int, says("a port number (0: any free port)", ge=0, le=65535)]``."""
    return msgspec.Meta(**meta, extra={"expects": phrase})


Flag = Annotated[bool, says("true or false")]
"""A yes/no setting (TOML ``true``/``false``)."""


def bounded(phrase: str, *, ge: float | None = None, gt: float | None = None,
            le: float | None = None, lt: float | None = None) -> msgspec.Meta:
    """``says`` for a number: an upper bound is required, so neither NaN nor infinity gets in."""
    if le is None and lt is None:
        raise TypeError("a bounded number needs an upper bound (le or lt)")
    given = {"ge": ge, "gt": gt, "le": le, "lt": lt}
    return says(phrase, **{k: v for k, v in given.items() if v is not None})


def read(model: type[Any], data: Any, where: str) -> Any:
    """``data`` (a TOML table) converted to ``model``; a wrong value raises ConfigError naming
    ``where`` (``"hub.toml: [hub]"``) and the key."""
    try:
        return msgspec.convert(data, model)
    except msgspec.ValidationError as e:
        raise ConfigError(explain(model, data, str(e), where)) from None


def json_schema(model: type[Any]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``model``: bounds, defaults and descriptions included."""
    return msgspec.json.schema(model)


def doc(text: str) -> dict[str, str]:
    """Field metadata: the description a derived table (``table_of``) shows in its JSON Schema."""
    return {"doc": text}


def table_of(cls: type[Any], name: str, *, exclude: tuple[str, ...] = (),
             types: Mapping[str, Any] | None = None) -> type[Model]:
    """The ``Model`` of a config table, derived from the frozen dataclass ``cls`` its values live in.

    Why derived: the dataclass is what the hub and embedding programs build and
    ``dataclasses.replace``; declaring its fields (type with bounds, default,
    ``doc``) once and deriving the reader keeps the two from disagreeing. ``types``
    gives a field another type in the file (``register_to``: a URL or a table).
    """
    hints = get_type_hints(cls, include_extras=True)
    fields: list[tuple[str, Any, Any]] = []
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        tp = (types or {}).get(f.name, hints[f.name])
        if "doc" in f.metadata:
            tp = Annotated[tp, msgspec.Meta(description=f.metadata["doc"])]
        if f.default is not dataclasses.MISSING:
            default: Any = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = msgspec.field(default_factory=f.default_factory)
        else:
            default = msgspec.NODEFAULT
        fields.append((f.name, tp, default))
    return cast("type[Model]", msgspec.defstruct(name, fields, bases=(Model,), module=cls.__module__))


def check(obj: Any, model: type[Model], where: str) -> None:
    """Check the fields of a dataclass built in Python (not read from a file) against its table."""
    read(model, {n: getattr(obj, n) for n in model.__struct_fields__}, where)


# -- turning msgspec's message into one that names the key --------------------------------------

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
    place = where + "".join(f".{s}" if isinstance(s, str) else f"[{s}]" for s in steps)
    info, phrase = _walk(mi.type_info(model), steps, value)
    if (u := _UNKNOWN.match(msg)) is not None:
        known = ", ".join(sorted(f.encode_name for f in getattr(info, "fields", ())))
        return f"{place}.{u['key']}: unknown key (known: {known})"
    if (r := _MISSING.match(msg)) is not None:
        return f"{place}.{r['key']}: required, missing"
    if isinstance(info, mi.StructType) and not isinstance(value, Mapping):
        return f"{place} must be a table, got {value!r}"
    declared = phrase is not None  # a declared phrase says the length itself ("an interface address")
    phrase = phrase or _PLAIN.get(type(info).__name__) or msg[0].lower() + msg[1:]
    text = f"{place}: {phrase}, got {value!r}"
    bounds = range_text(info)
    if bounds:
        return f"{text}; must be {bounds}"
    size = "" if declared else _size_text(info)
    return f"{text}; must have {size}" if size else text


def _size_text(info: Any) -> str:
    """``"2 items"``, ``"at least 1 character"``...: the length bounds of a list or string, or ''."""
    low, high = getattr(info, "min_length", None), getattr(info, "max_length", None)
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


_PLAIN: dict[str, str] = {  # what a msgspec.inspect type is called when its declaration gives no phrase
    "FloatType": "a number", "IntType": "a whole number", "BoolType": "true or false",
    "StrType": "a string", "ListType": "a list", "VarTupleType": "a list",
}


def range_text(info: Any) -> str:
    """``"from 0 to 64"``, ``"above 0 and at most 60000"``...: the bounds of a number type, or ''."""
    ge, gt, le, lt = (getattr(info, k, None) for k in ("ge", "gt", "le", "lt"))
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
    "VarTupleType": (list, tuple),
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
        if not leaf and value is None and isinstance(inner, mi.StructType | mi.ListType | mi.VarTupleType):
            return inner, inner_phrase or phrase
    if len(members) == 1:
        inner, inner_phrase = _unwrap(members[0], None)
        return inner, phrase or inner_phrase
    return info, phrase
